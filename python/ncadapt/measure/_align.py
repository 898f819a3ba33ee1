"""Rigid alignment of measured points to a CAD nominal: a least-squares best fit on the distances to
the CAD faces, or an RPS / 3-2-1 alignment on datum points.

The transform takes a measured point m (the measurement's frame) to the CAD frame:

    x = R m + t,        R = Rz(rz) · Ry(ry) · Rx(rx)

— rotations about the fixed X, then Y, then Z axes of the CAD frame, through its origin (scipy's
``Rotation.from_euler("xyz", [rx, ry, rz])``, lower-case: extrinsic). The six parameters are the
degrees of freedom ``x, y, z`` (t, mm) and ``rx, ry, rz`` (degrees in results, radians inside).

Both alignments are Gauss–Newton on those parameters with the exact derivative of the residuals:

- best fit: r_i = n_i · (R m_i + t − p_i) − ρ, p_i the nearest point of the CAD faces to the moved
  point, n_i the face's outward normal there, ρ the probe radius — the signed point-to-surface
  distance, whose gradient in x is n_i (point-to-plane ICP, re-projected every iteration);
- datums: r_j = d_j · (R m_j + t − p_j) for each constrained direction d_j of a datum point — six
  equations for six parameters, solved exactly.

A degree of freedom is *undetermined* when the columns of the residuals' Jacobian are rank
deficient — its singular values below ``RANK_TOL`` times the largest, the columns scaled to a motion
of 1 mm of the farthest point (a rotation column divided by that point's distance from the origin). The
degrees of freedom that carry the null space (their diagonal of the null-space projector above
``NULL_SHARE``) are named — a plane cannot fix ``x, y, rz``; a cylinder about z cannot fix ``z, rz``.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..constants import COORD_MAX
from ..errors import InputError, cut

#: The degrees of freedom, in the order of the parameter vector: translations (mm), rotations.
DOF = ("x", "y", "z", "rx", "ry", "rz")

#: Relative singular value below which the chosen degrees of freedom are not fixed by the data: a
#: motion of the farthest point by 1 mm that changes the distances by less than 1e-6 mm against the
#: best-fixed motion. Far below any real geometry's conditioning and far above the round-off of a
#: projection (about 1e-12).
RANK_TOL = 1e-6
#: Share of a degree of freedom in the null space above which it is named as undetermined.
NULL_SHARE = 0.01
#: Convergence: the last step moved every point by less than this, mm.
STEP_TOL = 1e-7
#: Gauss–Newton iterations before refusing as not converged.
MAX_ITERATIONS = 60
#: A datum alignment must leave its equations within this, mm (it is exact: 6 equations, 6 unknowns).
DATUM_TOL = 1e-9

MODES = ("none", "bestfit", "datums")


@dataclass(frozen=True)
class Alignment:
    """A rigid transform x = R m + t from the measurement's frame to the CAD frame.

    Attributes
    ----------
    mode : str
        ``"none"``, ``"bestfit"`` or ``"datums"``.
    translation : (3,) float, mm
        t.
    rotation : (3,) float, degrees
        (rx, ry, rz): R = Rz(rz) · Ry(ry) · Rx(rx), rotations about the fixed X, Y, Z axes of the CAD
        frame through its origin, applied in that order.
    matrix : (4, 4) float
        The homogeneous transform [[R, t], [0, 1]] (mm).
    rms : float, mm
        Root mean square of the residuals after alignment: the point-to-surface distances of every
        point used (best fit; this includes the form error), the datum equations (datums, 0 within
        round-off), the distances as measured (none).
    dof : tuple of str
        The degrees of freedom solved for (the others are held at 0).
    iterations : int
        Gauss–Newton iterations taken.
    converged : bool
        Whether the last step was below ``STEP_TOL`` (a result that did not converge is refused,
        so this is True in every returned alignment).
    points : int
        Points (best fit) or constraints (datums) the alignment used.
    std : (6,) float
        Standard uncertainty of (x, y, z) in mm and (rx, ry, rz) in degrees, rms² (JᵀJ)⁻¹ from the
        residuals (best fit; a form error counts as noise here); 0 for the parameters held and for
        an exact datum alignment. A large one says the faces fix that degree of freedom poorly.
    """

    mode: str
    translation: np.ndarray
    rotation: np.ndarray
    matrix: np.ndarray
    rms: float
    dof: tuple[str, ...]
    iterations: int
    converged: bool
    points: int
    std: np.ndarray

    def apply(self, points) -> np.ndarray:
        """The points (n, 3), mm, moved into the CAD frame: R m + t."""
        p = np.asarray(points, float).reshape(-1, 3)
        return p @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    def as_dict(self) -> dict:
        """The alignment for JSON: ``translation`` [3] mm, ``rotation`` [3] deg, ``rms`` mm, and
        ``mode``, ``dof``, ``matrix`` (4 × 4), ``iterations``, ``converged``, ``points``, ``std``
        {``translation`` [3] mm, ``rotation`` [3] deg}."""
        return {
            "mode": self.mode,
            "translation": [float(v) for v in self.translation],
            "rotation": [float(v) for v in self.rotation],
            "rms": float(self.rms),
            "dof": list(self.dof),
            "matrix": [[float(v) for v in row] for row in self.matrix],
            "iterations": int(self.iterations),
            "converged": bool(self.converged),
            "points": int(self.points),
            "std": {"translation": [float(v) for v in self.std[:3]], "rotation": [float(v) for v in self.std[3:]]},
        }


def rotation_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """R = Rz(rz) · Ry(ry) · Rx(rx) (3, 3) for angles in radians about the fixed X, Y, Z axes."""
    return _rotations(np.array([rx, ry, rz], float))[0]


def _rotations(a: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """R and its derivatives dR/drx, dR/dry, dR/drz at angles ``a`` (radians)."""
    cx, sx, cy, sy, cz, sz = (
        math.cos(a[0]),
        math.sin(a[0]),
        math.cos(a[1]),
        math.sin(a[1]),
        math.cos(a[2]),
        math.sin(a[2]),
    )
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    gx = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]])
    gy = np.array([[0, 0, 1], [0, 0, 0], [-1, 0, 0]])
    gz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 0]])
    return rz @ ry @ rx, [rz @ ry @ gx @ rx, rz @ gy @ ry @ rx, gz @ rz @ ry @ rx]


def _matrix(theta: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = _rotations(theta[3:])[0]
    out[:3, 3] = theta[:3]
    return out


def parse_dof(dof, source: str | None = None) -> tuple[str, ...]:
    """Degrees of freedom from a list or a comma-separated string of ``x, y, z, rx, ry, rz`` (in
    ``DOF``'s order, no repeats); None gives all six."""
    if dof is None:
        return DOF
    items = [s.strip().lower() for s in (dof.split(",") if isinstance(dof, str) else dof)]
    bad = [s for s in items if s not in DOF]
    if bad or not items:
        raise InputError(f"--align-dof: {cut(bad[0]) if bad else 'nothing'} is not one of {', '.join(DOF)}", source)
    if len(set(items)) != len(items):
        raise InputError(f"--align-dof: {', '.join(items)} repeats a degree of freedom", source)
    return tuple(d for d in DOF if d in items)


def _jacobian(m: np.ndarray, n: np.ndarray, theta: np.ndarray, cols: list[int]) -> np.ndarray:
    """d/dθ of n · (R m + t) for the chosen parameters (n rows, one column each)."""
    _, dr = _rotations(theta[3:])
    full = np.empty((len(m), 6))
    full[:, :3] = n
    for k in range(3):
        full[:, 3 + k] = np.einsum("ij,ij->i", n, m @ dr[k].T)
    return full[:, cols]


def _undetermined(jac: np.ndarray, names: tuple[str, ...], lever: float) -> list[str]:
    """The degrees of freedom that carry the (numerical) null space of ``jac``'s columns, each
    column scaled to the change of the residuals per mm of motion of the farthest point (``lever``
    mm from the origin): a translation column as is, a rotation column times 1/lever."""
    if len(jac) < jac.shape[1]:
        return list(names)
    scale = np.array([1.0 if d in DOF[:3] else 1.0 / lever for d in names])
    _, s, vt = np.linalg.svd(jac * scale, full_matrices=False)
    if s[0] == 0:
        return list(names)
    null = vt[s < RANK_TOL * s[0]]
    share = (null**2).sum(axis=0)
    return [d for d, w in zip(names, share) if w > NULL_SHARE]


def _refuse_undetermined(jac, names, lever, what: str, hint: str, source) -> None:
    bad = _undetermined(jac, names, lever)
    if bad:
        raise InputError(
            f"--align {what}: the {_what_data(what)} do not determine {', '.join(bad)} "
            f"(--align-dof {','.join(names)}); {hint}",
            source,
        )


def _what_data(what: str) -> str:
    return "measured points on these faces" if what == "bestfit" else "datums"


def _gauss_newton(m, residuals, names, what, hint, source):
    """Minimise Σ r² over the parameters ``names`` from 0; ``residuals(theta)`` returns
    (r, normals, used) for the points ``m[used]``. Returns (theta, r, iterations, converged, used,
    the Jacobian at the solution)."""
    cols = [DOF.index(d) for d in names]
    theta = np.zeros(6)
    r, n, used = residuals(theta)
    scale = max(1.0, float(np.linalg.norm(m, axis=1).max()))
    for it in range(1, MAX_ITERATIONS + 1):
        if used.sum() < len(cols):
            raise InputError(
                f"--align {what}: {int(used.sum())} point(s) lie on the faces, fewer than the {len(cols)} "
                "degrees of freedom",
                source,
            )
        jac = _jacobian(m[used], n, theta, cols)
        if it == 1:
            _refuse_undetermined(jac, names, scale, what, hint, source)
        norms = np.linalg.norm(jac, axis=0)
        norms[norms == 0] = 1.0
        step = np.linalg.lstsq(jac / norms, -r, rcond=None)[0] / norms
        full = np.zeros(6)
        full[cols] = step
        # how far the Gauss-Newton step moves a point of the part at most, mm (rotations act
        # through the lever): below STEP_TOL the gradient vanishes and the fit has converged
        move = float(np.linalg.norm(full[:3]) + np.linalg.norm(full[3:]) * scale)
        cost = float(r @ r) / len(r)
        for _ in range(30):
            r2, n2, used2 = residuals(theta + full)
            if used2.sum() >= len(cols) and float(r2 @ r2) / len(r2) <= cost * (1 + 1e-9) + 1e-30:
                theta, r, n, used = theta + full, r2, n2, used2
                break
            full /= 2
        else:
            if move >= STEP_TOL:
                raise InputError(f"--align {what}: no step lowers the residual (iteration {it})", source)
        if move < STEP_TOL:
            jac = _jacobian(m[used], n, theta, cols)
            _refuse_undetermined(jac, names, scale, what, hint, source)
            return theta, r, it, True, used, jac
    raise InputError(
        f"--align {what}: did not converge in {MAX_ITERATIONS} iterations (last step {move:.3g} mm); "
        "bring the measurement nearer the CAD model first",
        source,
    )


def _result(mode, theta, r, names, it, converged, npts, jac) -> Alignment:
    rms = float(np.sqrt(np.mean(r * r))) if len(r) else 0.0
    std = np.zeros(6)
    dof_left = len(r) - len(names)
    if dof_left > 0:
        cov = np.linalg.pinv(jac.T @ jac) * float(r @ r) / dof_left
        std[[DOF.index(d) for d in names]] = np.sqrt(np.clip(np.diag(cov), 0, None))
    std[3:] = np.degrees(std[3:])
    return Alignment(
        mode=mode,
        translation=theta[:3].copy(),
        rotation=np.degrees(theta[3:]),
        matrix=_matrix(theta),
        rms=rms,
        dof=tuple(names),
        iterations=it,
        converged=converged,
        points=npts,
        std=std,
    )


def identity(rms: float = 0.0) -> Alignment:
    """No alignment (``mode="none"``): the measurement's frame is the CAD frame."""
    return Alignment("none", np.zeros(3), np.zeros(3), np.eye(4), float(rms), (), 0, True, 0, np.zeros(6))


def nearest_on_faces(faces, points) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The nearest point (n, 3) of the nearest of ``faces`` (OpenCASCADE faces) to each point, the
    face's outward normal there (n, 3), the distance (n,), mm (inf: off every face's trimmed
    area) and the index of the face in ``faces`` (n,)."""
    from .. import cad

    q = np.asarray(points, float).reshape(-1, 3)
    best = np.full(len(q), np.inf)
    p = np.full((len(q), 3), np.nan)
    n = np.full((len(q), 3), np.nan)
    which = np.full(len(q), -1)
    for k, f in enumerate(faces):
        pk, nk, dk = cad.face_project(f, q)
        better = dk < best
        best[better], p[better], n[better], which[better] = dk[better], pk[better], nk[better], k
    return p, n, best, which


def align_to_cad(
    points,
    faces,
    *,
    dof=None,
    probe_radius: float = 0.0,
    source: str | None = None,
) -> Alignment:
    """The least-squares rigid transform of measured ``points`` onto CAD ``faces`` (best fit).

    Parameters
    ----------
    points : (n, 3) float, mm
        Measured points in the measurement's frame (probe-tip centres when ``probe_radius`` > 0).
    faces : list of OpenCASCADE faces, or a shape
        The nominal (:func:`ncadapt.cad.faces` of :func:`ncadapt.cad.read_shape`).
    dof : sequence of str or str, optional
        The degrees of freedom to solve for, among ``x, y, z, rx, ry, rz`` (default all six); the
        others are held at 0.
    probe_radius : float, mm
        The tip radius: a tip centre lies this far outside the surface.
    source : str, optional
        The measurement file, for messages.

    Returns
    -------
    Alignment
        The transform x = R m + t minimising Σ (n_i · (x_i − p_i) − ρ)², p_i the nearest face point.

    Raises
    ------
    InputError
        When the chosen degrees of freedom are not determined by the points on these faces (naming
        them), when fewer points than degrees of freedom lie on the faces, or when the iteration
        does not converge.

    Notes
    -----
    Point-to-plane ICP (Chen & Medioni, "Object modelling by registration of multiple range images",
    Image and Vision Computing 10(3), 1992, pp. 145–155, DOI 10.1016/0262-8856(92)90066-C) with the
    parameters of the module docstring and a step halved until the residual does not grow. It finds
    the nearest minimum: the measurement must start near the part (within a fraction of its
    features' size). Points off every face's trimmed area are left out of an iteration; the
    deviations after it refuse them (``against_cad``'s ``max_distance``).

    Examples
    --------
    >>> from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    >>> from ncadapt import cad, measure
    >>> box = cad.faces(BRepPrimAPI_MakeBox(100.0, 80.0, 50.0).Shape())
    >>> g = np.linspace(10, 40, 4)
    >>> top = [(x, y, 50.0) for x in 2 * g for y in g]
    >>> front = [(x, 0.0, z) for x in 2 * g for z in g]
    >>> left = [(0.0, y, z) for y in g for z in g]
    >>> pts = np.array(top + front + left) + [0.1, -0.2, 0.05]
    >>> a = measure.align_to_cad(pts, box)
    >>> np.round(a.translation, 6) + 0.0
    array([-0.1 ,  0.2 , -0.05])
    """
    from .. import cad

    if not isinstance(faces, (list, tuple)):
        faces = cad.faces(faces)
    names = parse_dof(dof, source)
    m = np.asarray(points, float).reshape(-1, 3)
    if not np.isfinite(m).all() or (np.abs(m) > COORD_MAX).any():
        raise InputError("--align bestfit: the points must be finite coordinates within ±1e6 mm", source)

    def residuals(theta):
        x = m @ _rotations(theta[3:])[0].T + theta[:3]
        p, n, d, _ = nearest_on_faces(faces, x)
        used = np.isfinite(d)
        return np.einsum("ij,ij->i", x[used] - p[used], n[used]) - probe_radius, n[used], used

    hint = "hold them with --align-dof (e.g. a plane fixes only z,rx,ry), measure more faces, or use --align datums"
    theta, r, it, ok, used, jac = _gauss_newton(m, residuals, names, "bestfit", hint, source)
    return _result("bestfit", theta, r, names, it, ok, int(used.sum()), jac)


# ------------------------------------------------------------------------------------ datums
@dataclass(frozen=True)
class Datum:
    """One datum point of an RPS / 3-2-1 alignment.

    Attributes
    ----------
    name : str
        Its name, for messages.
    nominal : (3,) float, mm
        The datum point on the CAD model (CAD frame).
    measured : (3,) float, mm, or None
        Its measured coordinates (measurement's frame), or None when ``label`` names a point of
        the measurements.
    label : str or None
        The id of the measured point in the measurements file.
    directions : (k, 3) float
        The unit directions this point fixes (CAD frame), 1 to 3 of them.
    line : int
        The line of its ``[[datum]]`` table in the file.
    """

    name: str
    nominal: np.ndarray
    measured: np.ndarray | None
    label: str | None
    directions: np.ndarray
    line: int


_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def read_datums(path) -> list[Datum]:
    """Datum points of an RPS alignment from a TOML file.

    The file holds one ``[[datum]]`` table per point::

        [[datum]]
        name = "A1"                # optional: its name in messages (default "datum N")
        nominal = [20.0, 10.0, 0.0]  # the point on the CAD model, mm
        measured = "P7"            # the id of a point of MEASUREMENTS, or [x, y, z] mm
        constrains = "z"           # the CAD axes it fixes: "x", "y", "z" or several ("xy")
        # direction = [0.0, 0.6, 0.8]   # instead of constrains: one unit direction

    A 3-2-1 alignment is three points constraining the primary plane's normal, two the secondary's
    and one the tertiary's — six constraints for six degrees of freedom. Any unknown key, a missing
    or malformed value, a non-unit direction or a repeated name is an :class:`InputError` at the
    table's line.
    """
    from .._io import read_text

    src = str(Path(path))
    text = read_text(path)
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(
            f"not valid TOML: {e}", src, getattr(e, "lineno", 0) or 0, getattr(e, "colno", 0) or 0
        ) from None
    starts = [k for k, ln in enumerate(text.splitlines(), 1) if ln.strip().startswith("[[datum]]")]
    extra = sorted(set(d) - {"datum"})
    if extra:
        raise InputError(f"unknown key {cut(extra[0])}; the file holds [[datum]] tables", src)
    tables = d.get("datum")
    if not isinstance(tables, list) or not tables:
        raise InputError("no [[datum]] table", src)
    out: list[Datum] = []
    seen: dict[str, int] = {}
    for k, t in enumerate(tables):
        line = starts[k] if k < len(starts) else 0

        def fail(msg, line=line):
            raise InputError(msg, src, line)

        unknown = sorted(set(t) - {"name", "nominal", "measured", "constrains", "direction"})
        if unknown:
            fail(f"[[datum]] unknown key {cut(unknown[0])} (name, nominal, measured, constrains or direction)")
        name = t.get("name", f"datum {k + 1}")
        if not isinstance(name, str) or not name.strip():
            fail(f"[[datum]] name must be a text, got {cut(name)}")
        if name in seen:
            fail(f"datum {name!r} repeats the one at line {seen[name]}")
        seen[name] = line
        nominal = _xyz(t.get("nominal"), f"datum {name!r}: nominal", fail)
        meas = t.get("measured")
        if isinstance(meas, str) and meas.strip():
            label, measured = meas.strip(), None
        else:
            label, measured = None, _xyz(meas, f"datum {name!r}: measured (a point id or [x, y, z])", fail)
        if ("constrains" in t) == ("direction" in t):
            fail(f"datum {name!r}: give constrains (axes) or direction (a unit vector), one of them")
        if "constrains" in t:
            c = t["constrains"]
            if (
                not isinstance(c, str)
                or not c
                or any(a not in _AXES for a in c.lower())
                or len(set(c.lower())) != len(c)
            ):
                fail(f'datum {name!r}: constrains must name axes among x, y, z once each ("z", "xy"), got {cut(c)}')
            dirs = np.array([_AXES[a] for a in c.lower()])
        else:
            v = _xyz(t["direction"], f"datum {name!r}: direction", fail)
            if abs(np.linalg.norm(v) - 1) > 1e-6:
                fail(f"datum {name!r}: direction must be a unit vector, |d| = {np.linalg.norm(v):.6g}")
            dirs = (v / np.linalg.norm(v))[None, :]
        out.append(Datum(name, nominal, measured, label, dirs, line))
    return out


def _xyz(v, what, fail) -> np.ndarray:
    ok = isinstance(v, list) and len(v) == 3 and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in v)
    if not ok:
        fail(f"{what} must be [x, y, z] numbers, got {cut(v)}")
    a = np.asarray(v, float)
    if not np.isfinite(a).all() or (np.abs(a) > COORD_MAX).any():
        fail(f"{what} must be finite and within ±{COORD_MAX:g} mm, got {cut(v)}")
    return a


def align_datums(datums: Sequence[Datum], *, points=None, ids=None, dof=None, source: str | None = None) -> Alignment:
    """The rigid transform that puts each datum's measured point on its nominal along the
    directions it constrains (RPS / 3-2-1): d_j · (R m + t − p) = 0 for every constraint.

    Parameters
    ----------
    datums : list of Datum
        From :func:`read_datums`.
    points : (n, 3) float, mm, optional
        The measured points that ``label`` datums name, with their ``ids``.
    ids : sequence of str, optional
        The ids of ``points``.
    dof : sequence of str or str, optional
        The degrees of freedom to solve for (default all six); the constraints must be as many.
    source : str, optional
        The datums file, for messages.

    Returns
    -------
    Alignment
        ``rms`` is that of the constraint equations: 0 within round-off, the alignment is exact.

    Raises
    ------
    InputError
        When a label names no measured point, when the constraints are not as many as the degrees
        of freedom, or when they do not fix them (naming those left free: e.g. three datum points
        on a line leave a rotation about it), or when the solution does not converge.

    Examples
    --------
    >>> from ncadapt.measure import Datum, align_datums
    >>> z, y, x = np.eye(3)[2:], np.eye(3)[1:2], np.eye(3)[:1]
    >>> def datum(p, d):
    ...     return Datum("d", np.array(p, float), np.array(p, float) - [1.0, 2.0, 3.0], None, d, 0)
    >>> rps = [datum((0, 0, 0), z), datum((50, 0, 0), z), datum((0, 40, 0), z),
    ...        datum((10, 0, 5), y), datum((40, 0, 5), y), datum((0, 20, 5), x)]
    >>> align_datums(rps).translation
    array([1., 2., 3.])
    """
    names = parse_dof(dof, source)
    lookup = {s: k for k, s in enumerate(ids)} if ids is not None else {}
    m_rows, p_rows, d_rows = [], [], []
    for dt in datums:
        if dt.label is not None:
            if dt.label not in lookup or points is None:
                raise InputError(f"datum {dt.name!r}: no measured point with id {dt.label!r}", source, dt.line)
            m = np.asarray(points, float)[lookup[dt.label]]
        else:
            m = np.asarray(dt.measured, float)
        for d in dt.directions:
            m_rows.append(m)
            p_rows.append(dt.nominal)
            d_rows.append(d)
    if len(d_rows) != len(names):
        raise InputError(
            f"--align datums: {len(d_rows)} constraints for {len(names)} degrees of freedom "
            f"({','.join(names)}); an RPS alignment needs one constraint per degree of freedom "
            "(3-2-1: three on the primary plane, two on the secondary, one on the tertiary)",
            source,
        )
    m_all, p_all, d_all = np.array(m_rows), np.array(p_rows), np.array(d_rows)

    def residuals(theta):
        x = m_all @ _rotations(theta[3:])[0].T + theta[:3]
        return np.einsum("ij,ij->i", x - p_all, d_all), d_all, np.ones(len(x), bool)

    hint = "choose datum points that span each plane (not along one line) and constrain all six"
    theta, r, it, ok, _, jac = _gauss_newton(m_all, residuals, names, "datums", hint, source)
    if np.abs(r).max() > DATUM_TOL * max(1.0, float(np.abs(m_all).max())):
        raise InputError(
            f"--align datums: the equations are left {np.abs(r).max():.3g} mm from exact; the datums contradict "
            "each other",
            source,
        )
    return _result("datums", theta, r, names, it, ok, len(d_rows), jac)
