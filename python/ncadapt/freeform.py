"""Freeform compensation in one call: :func:`run` does what ``ncadapt compensate`` does."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .errors import InputError
from .processes import freeform as pf
from .processes import rounds

__all__ = ["Result", "run"]


@dataclass(frozen=True)
class Result:
    """What :func:`run` made.

    ``measurements``: the :class:`~ncadapt.measure.Measurements` (n points; with a CAD nominal, the
    actual points projected onto the faces, after the alignment); ``analysis``: the gate
    (:class:`~ncadapt.processes.freeform.Analysis`); ``decomposition``: systematic + random parts,
    (n,) mm each (:class:`~ncadapt.processes.freeform.Decomposition`); ``compensation``: a
    :class:`~ncadapt.processes.freeform.Compensation` (a nominal from the measured points: the dF
    grid (nu, nv) mm over the frame's (u, v)) or a :class:`~ncadapt.processes.freeform.PartCompensation`
    (a CAD nominal: one grid per face, the compensated part); ``alignment``: the
    :class:`~ncadapt.measure.Alignment` (None without a CAD nominal); ``correction``: what the next
    round needs (:class:`~ncadapt.processes.rounds.Correction`, dF in mm); ``frame``: the
    :class:`~ncadapt.surfaces.Frame` whose (u, v) carry the grid (None with a CAD nominal);
    ``program``: the NC correction's summary (None without ``program``); ``files``: {what: path}
    of the files written (``program``, ``surface``, ``part``)."""

    measurements: object
    analysis: pf.Analysis
    decomposition: pf.Decomposition
    compensation: object
    alignment: object
    correction: rounds.Correction
    frame: object
    program: object
    files: dict


def run(
    measurements,
    nominal=None,
    program=None,
    *,
    output=None,
    tool_radius: float | None = None,
    faces: list[int | str] | None = None,
    face_sets: list[list[int | str]] | None = None,
    max_distance: float = 1.0,
    align: str = "none",
    align_dof=None,
    datums=None,
    previous=None,
    gain: float = 1.0,
    method: str = "bilateral",
    sigma_c: float | None = None,
    sigma_s: float | None = None,
    p: float | None = None,
    auto: bool = False,
    border: str = pf.BORDER,
    outside: str = "error",
    limit: float | None = None,
    surface=None,
    part=None,
    probe_radius: float = 0.0,
    units: str | None = None,
    alpha: float = 0.05,
    **moran_options,
) -> Result:
    """Analyse, decompose and compensate a measured freeform part; correct its NC program.

    Parameters
    ----------
    measurements : path
        The measurement file (as ``ncadapt compensate``; with ``nominal``, actual points: CSV
        x, y, z, DMIS ``FA`` points, QIF measured points and point sets, or a paired file whose own
        nominals are checked against the CAD, :func:`ncadapt.measure.read_actuals`).
    nominal : path, optional
        The CAD model (STEP/IGES): each face compensated in its own (u, v); ``faces`` (1-based ids
        or the STEP file's face names), ``max_distance`` mm, ``align`` ("none", "bestfit", "datums"),
        ``align_dof``, ``datums``, ``face_sets`` (faces decomposed together in one (u, v),
        :func:`ncadapt.processes.freeform.compensate_cad`) as :func:`ncadapt.measure.project_on_cad`.
        Without it the nominal is fitted through the measured nominal points over the frame of their normals (the frame is chosen here).
    program : path, optional
        An NC program corrected by −dF·n into ``output`` (required with it), the tool a ball end of
        ``tool_radius`` mm (required; 0: the programmed point is the contact point); ``outside``,
        ``limit`` mm as ``compensate``.
    previous : path or Correction, optional
        A later round: the previous round's ``correction`` (a ``compensate --json`` file, or
        :attr:`Result.correction`); the new dF is previous + ``gain`` × damping × the systematic part
        (:mod:`ncadapt.processes.rounds`).
    surface, part : path, optional
        Write the compensated surface (STEP/IGES) and, with ``nominal``, the whole part (STEP).

    Notes
    -----
    The filter options (``method``, ``sigma_c`` mm, ``sigma_s`` mm, ``p``, ``auto``, ``border``) and
    the gate's (``alpha``, ``moran_options``) are those of :func:`ncadapt.processes.freeform.decompose`
    and :func:`~ncadapt.processes.freeform.analyze`. Refused inputs raise :class:`~ncadapt.InputError`.
    """
    from . import cad, constants, measure
    from . import nc as ncmod

    if (program is None) != (output is None):
        raise InputError("program and output go together")
    if program is not None and tool_radius is None:
        raise InputError("program needs tool_radius (mm; 0 when the programmed point is the contact point)")
    prev = previous if isinstance(previous, rounds.Correction) or previous is None else rounds.read(previous)
    src = str(previous) if previous is not None and not isinstance(previous, rounds.Correction) else "previous"
    limit = constants.LIMIT if limit is None else limit
    files: dict = {}
    options = dict(method=method, sigma_c=sigma_c, sigma_s=sigma_s, p=p, auto=auto, border=border)
    if nominal is not None:
        proj = measure.project_on_cad(
            measurements,
            nominal,
            faces=faces,
            max_distance=max_distance,
            probe_radius=probe_radius,
            units=units,
            align=align,
            align_dof=align_dof,
            datums=datums,
            face_sets=face_sets,
        )
        meas = proj.measurements
        if prev is not None:
            rounds.check_nominal(prev, nominal, {int(f) for f in proj.face}, src)
        a = pf.analyze(meas, coords=meas.nominal, alpha=alpha, **moran_options)
        comp = pf.compensate_cad(
            proj,
            **options,  # type: ignore[arg-type]
            alpha=alpha,
            previous=None if prev is None else {g.face: g.at for g in prev.grids},
            gain=gain,
            **moran_options,
        )
        d = pf.part_decomposition(comp, meas, alpha=alpha, **moran_options)
        field = comp.field(tool_radius or 0.0, outside)
        correction = rounds.Correction(
            "faces",
            tuple(rounds.Grid(f.u, f.v, f.df_grid, f.face) for f in comp.faces),
            1 if prev is None else prev.round + 1,
            nominal={"path": str(nominal), "sha256": rounds.file_digest(nominal)},
            gains={f.face: f.gain for f in comp.faces},
        )
        frame = None
        if surface is not None:
            cad.write_shape(comp.surfaces(), surface)
            files["surface"] = Path(surface)
        if part is not None:
            cad.write_shape(comp.part, part)
            files["part"] = Path(part)
    else:
        if part is not None or faces or face_sets or align != "none" or datums is not None or align_dof is not None:
            raise InputError("part, faces, face_sets, align, align_dof and datums need a CAD nominal")
        meas = measure.read(measurements, probe_radius=probe_radius, units=units)
        frame = pf.frame_of(meas)
        if prev is not None:
            rounds.check_frame(prev, frame.axes, src)
        a = pf.analyze(meas, frame=frame, alpha=alpha, **moran_options)
        d = pf.decompose(
            meas, method, sigma_c=sigma_c, sigma_s=sigma_s, p=p, auto=auto, frame=frame, alpha=alpha, **moran_options
        )
        surf = pf.fit_height_surface(meas.nominal, frame=frame)
        ext = pf.nominal_extrapolation(surf, meas.nominal, frame)
        if ext.max_distance > 0:
            raise InputError(
                f"the compensated surface would reach {ext.max_distance:.3g} mm beyond the measured points: there its "
                "nominal would be extrapolated (use the command with --extrapolate-nominal)",
                str(measurements),
            )
        base, g = None, 1.0
        if prev is not None:
            base = prev.grids[0].at
            g = gain * rounds.damping(method, frame.uv(meas.nominal), d.systematic, d.parameters)
        comp = pf.compensate(surf, meas, d.systematic, frame=frame, border=border, base=base, gain=g)
        field = comp.field(tool_radius or 0.0, outside)
        correction = rounds.Correction(
            "frame",
            (rounds.Grid(surf.u, surf.v, comp.df_grid),),
            1 if prev is None else prev.round + 1,
            frame=frame.axes,
            gains={0: comp.gain},
        )
        if surface is not None:
            cad.write(comp.compensated, surface)
            files["surface"] = Path(surface)
    corr = None
    if program is not None:
        corr = ncmod.read(program).correct_to(output, field, limit=limit)
        files["program"] = Path(output)
    return Result(meas, a, d, comp, meas.alignment, correction, frame, corr, files)
