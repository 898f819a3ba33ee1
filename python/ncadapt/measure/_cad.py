"""Measured points against a CAD nominal: each actual point projected onto the nearest of the
selected faces (OpenCASCADE through OCP), the deviation along the face's outward normal there."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ._actuals import Actuals, read_actuals
from ._core import Measurements, from_arrays


@dataclass(frozen=True)
class CadProjection:
    """Measured points on a CAD part: the measurements (nominal = the nearest face point), the
    face each point fell on (``face`` (n,) 1-based ids), its (u, v) parameters there (``uv`` (n, 2),
    the face's own units: mm, or rad for an angle) and the part (``shape``, its ``faces`` in
    OpenCASCADE's order; ``chosen`` the ids the points were projected onto; ``names`` the CAD file's
    names of all its faces, None for an unnamed one; ``file_nominals`` the check of the measurement
    file's own nominals against the CAD, None for a file of actual points only; ``sets`` the face
    sets, each the ids of faces analysed and decomposed together in one (u, v), no face in two)."""

    measurements: Measurements
    face: np.ndarray
    uv: np.ndarray
    shape: object
    faces: tuple
    chosen: tuple[int, ...]
    nominal: str
    names: tuple[str | None, ...] = ()
    #: the measurement file's own nominal points checked against the CAD (None when it has none):
    #: ``points`` (how many), ``max_distance`` (mm, the largest distance to the chosen faces, after
    #: the alignment), ``line`` (the file's line of that nominal), ``from_deviation`` (the actual
    #: points are the file's nominal + deviation × normal)
    file_nominals: dict | None = None
    sets: tuple[tuple[int, ...], ...] = ()

    def face_set_of(self, face_id: int) -> int | None:
        """The index in ``sets`` of the set face ``face_id`` belongs to (None for a face on its own)."""
        return next((k for k, ids in enumerate(self.sets) if face_id in ids), None)

    def name_of(self, face_id: int) -> str | None:
        """The CAD file's name of face ``face_id`` (1-based; None when it has none)."""
        return self.names[face_id - 1] if self.names else None

    def faces_used(self) -> list[dict]:
        """The faces the points fell on, in id order: ``id``, ``name`` (None when the CAD file names
        none) and ``n_points``."""
        ids, counts = np.unique(self.face, return_counts=True)
        return [{"id": int(i), "name": self.name_of(int(i)), "n_points": int(c)} for i, c in zip(ids, counts)]


def project_on_cad(
    path,
    nominal,
    *,
    faces: list[int | str] | None = None,
    max_distance: float = 1.0,
    probe_radius: float = 0.0,
    units: str | None = None,
    align: str = "none",
    align_dof=None,
    datums=None,
    face_sets: list[list[int | str]] | None = None,
) -> CadProjection:
    """:func:`against_cad` with the face and the (u, v) of each point, the part itself and the check
    of the measurement file's own nominal points (:attr:`CadProjection.file_nominals`).

    ``face_sets``: lists of faces (ids or names, as ``faces``) each analysed and decomposed together
    in one (u, v) (:func:`ncadapt.processes.freeform.compensate_cad`); their faces are projected onto
    besides ``faces``. Refused: an empty set, a face in two sets."""
    from .. import cad
    from ._align import MODES, align_datums, align_to_cad, identity, read_datums

    src = str(Path(path))
    if align not in MODES:
        raise InputError(f"--align must be one of {', '.join(MODES)}, got {align!r}", src)
    if (align == "datums") != (datums is not None):
        raise InputError("--align datums and a datums file go together", src)
    if align == "none" and align_dof is not None:
        raise InputError("--align-dof needs --align bestfit or datums", src)
    actuals = read_actuals(path, units)
    _check_compensation(actuals, probe_radius)
    m, lines, ids = actuals.points, actuals.lines, actuals.ids
    noms, nom_lines = actuals.nominals, actuals.nominal_lines
    part = cad.read_part(nominal)
    shape, all_faces = part.shape, list(part.faces)
    chosen = part.select(faces)
    sets = _face_sets(part, face_sets or [])
    if faces:
        chosen += [f for ids in sets for f in ids if f not in chosen]
    selected = [all_faces[f - 1] for f in chosen]
    alignment = None
    if align == "bestfit":
        alignment = align_to_cad(m, selected, dof=align_dof, probe_radius=probe_radius, source=src)
    elif align == "datums":
        rps = read_datums(datums)
        named = [d for d in rps if d.ids]
        if named and probe_radius:
            raise InputError(
                f"datum {named[0].name!r} names a measured point, which is a probe-tip centre with "
                "--probe-radius; give the datum's surface coordinates as measured = [x, y, z] (a feature: "
                "a list of them)",
                str(datums),
                named[0].line,
            )
        alignment = align_datums(rps, points=m, ids=ids, dof=align_dof, source=str(datums))
        if named:
            keep = np.ones(len(m), bool)
            keep[[ids.index(i) for d in named for i in d.ids]] = False  # type: ignore[union-attr]
            m, lines = m[keep], lines[keep]
            if noms is not None and nom_lines is not None:
                noms, nom_lines = noms[keep], nom_lines[keep]
            ids = tuple(i for i, k in zip(ids, keep) if k)  # type: ignore[arg-type]
            if not len(m):
                raise InputError("every point is a datum: no point is left for the deviations", src)
    if alignment is not None:
        m = alignment.apply(m)
        if noms is not None:
            noms = alignment.apply(noms)
    checked = None
    if noms is not None and nom_lines is not None:
        checked = _check_file_nominals(noms, nom_lines, selected, max_distance, alignment is not None, src)
        checked["from_deviation"] = actuals.from_deviation
    best_d = np.full(len(m), np.inf)
    uv = np.full((len(m), 2), np.nan)
    face_of = np.zeros(len(m), dtype=int)
    for f in chosen:
        q, d = cad.face_parameters(all_faces[f - 1], m)
        better = d < best_d
        best_d[better], uv[better], face_of[better] = d[better], q[better], f
    far = np.flatnonzero(~(best_d <= max_distance))
    if len(far):
        i = int(far[0])
        how = "on no face" if not np.isfinite(best_d[i]) else f"{best_d[i]:.4g} mm from the nearest face"
        raise InputError(
            f"{len(far)} point(s) farther than --max-distance {max_distance:g} mm from the CAD faces"
            + (" after the alignment" if alignment is not None else "")
            + f"; this one is {how}",
            src,
            int(lines[i]),
        )
    p = np.empty((len(m), 3))
    n = np.empty((len(m), 3))
    for f in np.unique(face_of):
        k = face_of == f
        p[k], n[k], _ = cad.face_evaluate(all_faces[f - 1], uv[k, 0], uv[k, 1])
    meas = from_arrays(p, n, measured=m, ids=ids, lines=lines, source=src, probe_radius=probe_radius)
    if alignment is None:
        alignment = identity(float(np.sqrt(np.mean(meas.deviation**2))))
    meas = dataclasses.replace(meas, alignment=alignment)
    return CadProjection(
        meas, face_of, uv, shape, tuple(all_faces), tuple(chosen), str(nominal), part.names, checked, sets
    )


def _check_file_nominals(noms, nom_lines, faces, max_distance: float, aligned: bool, src: str) -> dict:
    """The measurement file's own nominal points (NaN rows: none) against the CAD ``faces``: each
    must lie within ``max_distance`` mm of them, else an :class:`InputError` at its line. Returns
    ``points``, ``max_distance`` (mm) and ``line`` (of the farthest)."""
    from ._align import nearest_on_faces

    has = np.flatnonzero(np.isfinite(noms).all(axis=1))
    if not len(has):
        return {"points": 0, "max_distance": None, "line": None}
    _, _, d, _ = nearest_on_faces(faces, noms[has])
    far = np.flatnonzero(~(d <= max_distance))
    after = " after the alignment" if aligned else ""
    if len(far):
        i = int(far[0])
        how = "on no face of the CAD" if not np.isfinite(d[i]) else f"{d[i]:.4g} mm off the CAD"
        raise InputError(
            f"the file's nominal point is {how}{after}: another frame or another part? ({len(far)} of the file's "
            f"{len(has)} nominal points are farther than --max-distance {max_distance:g} mm from the chosen faces; "
            "with --nominal the file's own nominals must lie on the CAD)",
            src,
            int(nom_lines[has[i]]),
        )
    j = int(np.argmax(d))
    return {"points": len(has), "max_distance": float(d[j]), "line": int(nom_lines[has[j]])}


def _check_compensation(actuals: Actuals, probe_radius: float) -> None:
    """What a measurement file says of the probe radius (a QIF point set's ``Compensated`` and
    ``ProbeRadius``) against ``probe_radius``: tip centres need it, compensated points refuse it,
    and a stated radius must be the one given."""
    src = actuals.source
    c = actuals.compensated
    if c is not None:
        centres = np.flatnonzero(c == 0)
        if len(centres) and not probe_radius:
            i = int(centres[0])
            r = actuals.probe_radii[i] if actuals.probe_radii is not None else np.nan
            said = f", ProbeRadius {r:g} mm" if np.isfinite(r) else ""
            raise InputError(
                f"the file says this point is a probe-tip centre, not compensated for the probe radius (Compensated "
                f"false{said}); {len(centres)} such point(s): give --probe-radius",
                src,
                int(actuals.lines[i]),
            )
        done = np.flatnonzero(c == 1)
        if len(done) and probe_radius:
            raise InputError(
                f"the file says this point is already compensated for the probe radius (Compensated true); "
                f"--probe-radius {probe_radius:g} would take it off twice: leave --probe-radius out",
                src,
                int(actuals.lines[int(done[0])]),
            )
    r = actuals.probe_radii
    if r is not None and probe_radius:
        off = np.flatnonzero(np.isfinite(r) & (np.abs(r - probe_radius) > 1e-6))
        if len(off):
            i = int(off[0])
            raise InputError(
                f"the file states the probe radius {r[i]:g} mm for this point; --probe-radius {probe_radius:g} disagrees",
                src,
                int(actuals.lines[i]),
            )


def _face_sets(part, face_sets) -> tuple[tuple[int, ...], ...]:
    """The face sets as ids (:meth:`ncadapt.cad.Part.select`), a face in at most one."""
    out: list[tuple[int, ...]] = []
    for wanted in face_sets:
        if not wanted:
            raise InputError("--face-set: an empty set of faces", part.source)
        ids = tuple(part.select(list(wanted), "--face-set"))
        for f in ids:
            other = next((o for o in out if f in o), None)
            if other is not None:
                raise InputError(
                    f"--face-set: face {f} is in two sets ({','.join(map(str, other))} and "
                    f"{','.join(map(str, ids))}); a face is decomposed in one (u, v)",
                    part.source,
                )
        out.append(ids)
    return tuple(out)


def against_cad(
    path,
    nominal,
    *,
    faces: list[int | str] | None = None,
    max_distance: float = 1.0,
    probe_radius: float = 0.0,
    units: str | None = None,
    align: str = "none",
    align_dof=None,
    datums=None,
) -> Measurements:
    """Actual points of ``path`` (see :func:`read_actuals`) against the faces of the STEP/IGES file
    ``nominal`` (``faces``: 1-based ids or the STEP file's face names, :meth:`ncadapt.cad.Part.select`;
    all by default): the nominal point is the nearest point of the nearest
    face, the normal the face's outward normal there, e = (m − p)·n. A point farther than
    ``max_distance`` mm from every face (or off every face's trimmed area) is refused with its line.
    A file with nominal points of its own (:attr:`Actuals.nominals`) gives its actual points, and
    each of its nominals must lie within ``max_distance`` of the faces after the alignment, else it
    is refused at the nominal's line (another frame or another part).
    ``probe_radius``: the points are probe-tip centres (moved back along the normal; a QIF point set
    that says its points are compensated refuses it, one that says they are not needs it, and a
    stated probe radius must agree); ``units``: the length unit of a file that declares none (mm by
    default; DMIS and QIF files declare theirs, which must agree).

    ``align``: ``"none"`` (the measurement's frame is the CAD frame), ``"bestfit"``
    (:func:`align_to_cad` on the selected faces, over the degrees of freedom ``align_dof``) or
    ``"datums"`` (:func:`align_datums` on the TOML file ``datums``; the points it names by id are
    alignment points and are left out of the deviations). The deviations are taken after the
    alignment; the result's ``alignment`` holds it (the identity with ``"none"``, its ``rms`` that of
    the deviations)."""
    return project_on_cad(
        path,
        nominal,
        faces=faces,
        max_distance=max_distance,
        probe_radius=probe_radius,
        units=units,
        align=align,
        align_dof=align_dof,
        datums=datums,
    ).measurements
