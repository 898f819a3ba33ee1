"""Rigid alignment of measured points to a CAD nominal: a least-squares best fit on the distances to
the CAD faces, or an RPS / 3-2-1 alignment on datum points and features.

The transform takes a measured point m (the measurement's frame) to the CAD frame:

    x = R m + t,        R = Rz(rz) · Ry(ry) · Rx(rx)

— rotations about the fixed X, then Y, then Z axes of the CAD frame, through its origin (scipy's
``Rotation.from_euler("xyz", [rx, ry, rz])``, lower-case: extrinsic). The six parameters are the
degrees of freedom ``x, y, z`` (t, mm) and ``rx, ry, rz`` (degrees in results, radians inside).

Both alignments are Gauss–Newton on those parameters with the exact derivative of the residuals:

- best fit: r_i = n_i · (R m_i + t − p_i) − ρ, p_i the nearest point of the CAD faces to the moved
  point, n_i the face's outward normal there, ρ the probe radius — the signed point-to-surface
  distance, whose gradient in x is n_i (point-to-plane ICP, re-projected every iteration);
- datums: r_j = d_j · (R m_j + t − p_j) for each constrained direction d_j of a datum point, of a
  fitted feature's centre (circle, cylinder, sphere) or of a plane's or line's centroid, and
  r_j = L e_j · (R v) for a fitted plane's normal or line's direction v that must be square to the
  nominal's e_j (the tilt as the distance it makes over the feature's size L) — solved exactly when
  they are as many as the degrees of freedom, in the weighted least-squares sense when they are
  more.

A degree of freedom is *undetermined* when the columns of the residuals' Jacobian are rank
deficient — its singular values below ``RANK_TOL`` times the largest, the columns scaled to a motion
of 1 mm of the farthest point (a rotation column divided by that point's distance from the origin). The
degrees of freedom that carry the null space (their diagonal of the null-space projector above
``NULL_SHARE``) are named — a plane cannot fix ``x, y, rz``; a cylinder about z cannot fix ``z, rz``.
"""

from __future__ import annotations

import dataclasses
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
#: A datum alignment with as many equations as unknowns must leave them within this, mm (it is exact).
DATUM_TOL = 1e-9
#: Default largest residual of a datum in an over-determined alignment, mm (the TOML key
#: ``tolerance``, for the file or one datum): beyond it the datum contradicts the others. 0.05 mm is
#: the flatness a datum face of 100 mm holds at IT8 (ISO 286-1: 54 µm for 80–120 mm), the coarsest
#: grade a machined reference surface is commonly held to; set it to the part's datum tolerances.
DATUM_RESIDUAL_TOL = 0.05

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
        residuals (best fit, over-determined datums; a form error counts as noise here); 0 for the
        parameters held and for an exact datum alignment. A large one says the faces fix that degree
        of freedom poorly.
    datums : tuple of DatumResidual
        Each datum's fit and residual after the alignment (datums; empty otherwise).
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
    datums: tuple[DatumResidual, ...] = ()

    def apply(self, points) -> np.ndarray:
        """The points (n, 3), mm, moved into the CAD frame: R m + t."""
        p = np.asarray(points, float).reshape(-1, 3)
        return p @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    def as_dict(self) -> dict:
        """The alignment for JSON: ``translation`` [3] mm, ``rotation`` [3] deg, ``rms`` mm, and
        ``mode``, ``dof``, ``matrix`` (4 × 4), ``iterations``, ``converged``, ``points``, ``std``
        {``translation`` [3] mm, ``rotation`` [3] deg}, ``datums`` (one
        :meth:`DatumResidual.as_dict` per datum; empty unless ``mode`` is ``"datums"``)."""
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
            "datums": [d.as_dict() for d in self.datums],
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


def _jacobian(m: np.ndarray, n: np.ndarray, theta: np.ndarray, cols: list[int], tau=None) -> np.ndarray:
    """d/dθ of n · (R m + τ t) for the chosen parameters (n rows, one column each); τ = 1 unless
    ``tau`` (n,) says otherwise (0: a direction, which a translation does not move)."""
    _, dr = _rotations(theta[3:])
    full = np.empty((len(m), 6))
    full[:, :3] = n if tau is None else n * tau[:, None]
    for k in range(3):
        full[:, 3 + k] = np.einsum("ij,ij->i", n, m @ dr[k].T)
    return full[:, cols]


def _undetermined(jac: np.ndarray, names: tuple[str, ...], lever: float) -> list[str]:
    """The degrees of freedom that carry the (numerical) null space of ``jac``'s columns, each
    column scaled to the change of the residuals per mm of motion of the farthest point (``lever``
    mm from the origin): a translation column as is, a rotation column times 1/lever."""
    scale = np.array([1.0 if d in DOF[:3] else 1.0 / lever for d in names])
    _, s, vt = np.linalg.svd(jac * scale, full_matrices=True)
    s = np.concatenate([s, np.zeros(len(vt) - len(s))])  # fewer rows than columns: the rest is null
    if len(s) == 0 or s[0] == 0:
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


def _gauss_newton(m, residuals, names, what, hint, source, tau=None):
    """Minimise Σ r² over the parameters ``names`` from 0; ``residuals(theta)`` returns
    (r, normals, used) for the points ``m[used]`` (``tau``: see :func:`_jacobian`; only with every
    point used). Returns (theta, r, iterations, converged, used, the Jacobian at the solution)."""
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
        jac = _jacobian(m[used], n, theta, cols, tau)
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
            jac = _jacobian(m[used], n, theta, cols, tau)
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
#: The kinds of datum: a point, or a feature fitted to several measured points.
FEATURES = ("point", "plane", "line", "circle", "cylinder", "sphere")


@dataclass(frozen=True)
class Datum:
    """One datum of an RPS / 3-2-1 alignment: a point, or a feature measured by several points.

    Attributes
    ----------
    name : str
        Its name, for messages.
    nominal : (3,) float, mm
        On the CAD model (CAD frame): the datum point; a point of the plane, of the line or of the
        cylinder's axis; the circle's or the sphere's centre.
    measured : (3,) float (point) or (k, 3) float (feature), mm, or None
        Its measured coordinates (measurement's frame), or None when ``label`` / ``labels`` name
        points of the measurements.
    label : str or None
        A point datum's measured point: its id in the measurements file.
    directions : (k, 3) float
        The unit directions (CAD frame) along which it fixes its position: a point's ``constrains``
        (1 to 3); a plane's normal; the one direction a line fixes; a circle's or a cylinder's two
        directions square to its normal or axis (or those given); a sphere's x, y, z (or those
        given).
    line : int
        The line of its ``[[datum]]`` table in the file.
    feature : str
        One of ``FEATURES``.
    labels : tuple of str
        A feature's measured points: their ids in the measurements file (empty with ``measured``).
    normal : (3,) float or None
        The nominal unit normal of a plane or of a circle's plane.
    axis : (3,) float or None
        The nominal unit direction of a line or of a cylinder's axis.
    radius : float or None, mm
        The nominal radius of a circle, cylinder or sphere, if given (reported beside the fitted
        one; it does not constrain).
    weight : float
        The weight of its equations in an over-determined alignment (default 1).
    tolerance : float, mm
        The largest residual it may be left with in an over-determined alignment.
    """

    name: str
    nominal: np.ndarray
    measured: np.ndarray | None
    label: str | None
    directions: np.ndarray
    line: int
    feature: str = "point"
    labels: tuple[str, ...] = ()
    normal: np.ndarray | None = None
    axis: np.ndarray | None = None
    radius: float | None = None
    weight: float = 1.0
    tolerance: float = DATUM_RESIDUAL_TOL

    @property
    def ids(self) -> tuple[str, ...]:
        """The ids of the measured points it names (empty when it gives coordinates)."""
        return (self.label,) if self.label is not None else tuple(self.labels)

    @property
    def constraints(self) -> int:
        """How many equations it gives: a plane 3 (its position along the normal and two tilts), a
        line 2 (its position along the fixed direction and its turn towards it), the others one
        per direction."""
        return {"plane": 3, "line": 2}.get(self.feature, len(self.directions))


@dataclass(frozen=True)
class DatumResidual:
    """A datum after the alignment.

    Attributes
    ----------
    name, feature : str
        The datum and its kind.
    line : int
        Its table's line in the datums file.
    constraints : int
        The equations it gave.
    weight : float
        Their weight.
    residual : float, mm
        The root sum of squares of its equations after the alignment: how far the aligned datum is
        from its nominal along the directions it fixes (a tilt counts as the distance it makes over
        the feature's size). 0 within round-off when the alignment is exact.
    tolerance : float, mm
        The largest ``residual`` allowed when over-determined.
    points : int
        The measured points of the datum.
    form_rms, form_max : float, mm
        The feature fit's residuals (root mean square, largest magnitude): flatness, straightness,
        roundness or cylindricity as least squares sees it; 0 for a point.
    radius : float or None, mm
        The fitted radius (circle, cylinder, sphere).
    radius_nominal : float or None, mm
        The nominal radius when the file gives it.
    """

    name: str
    feature: str
    line: int
    constraints: int
    weight: float
    residual: float
    tolerance: float
    points: int
    form_rms: float
    form_max: float
    radius: float | None
    radius_nominal: float | None

    def as_dict(self) -> dict:
        """For JSON: ``name``, ``feature``, ``line``, ``constraints``, ``weight``, ``residual_mm``,
        ``tolerance_mm``, ``points``, ``form_rms_mm``, ``form_max_mm``, ``radius_mm`` and
        ``radius_nominal_mm`` (null when not a circle, cylinder or sphere, or not given)."""
        return {
            "name": self.name,
            "feature": self.feature,
            "line": int(self.line),
            "constraints": int(self.constraints),
            "weight": float(self.weight),
            "residual_mm": float(self.residual),
            "tolerance_mm": float(self.tolerance),
            "points": int(self.points),
            "form_rms_mm": float(self.form_rms),
            "form_max_mm": float(self.form_max),
            "radius_mm": None if self.radius is None else float(self.radius),
            "radius_nominal_mm": None if self.radius_nominal is None else float(self.radius_nominal),
        }


_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
_KEYS = ("name", "feature", "nominal", "measured", "constrains", "direction", "normal", "axis", "radius", "weight",
         "tolerance")  # fmt: skip
#: The keys each kind of datum takes beyond name, feature, nominal, measured, weight, tolerance:
#: those it needs and those it may have.
_NEEDS = {
    "point": ((), ("constrains", "direction")),
    "plane": (("normal",), ()),
    "line": (("axis",), ("constrains", "direction")),
    "circle": (("normal",), ("radius", "constrains", "direction")),
    "cylinder": (("axis",), ("radius", "constrains", "direction")),
    "sphere": ((), ("radius", "constrains", "direction")),
}


def read_datums(path) -> list[Datum]:
    """Datum points and features of an RPS alignment from a TOML file.

    The file holds one ``[[datum]]`` table per datum; a point::

        [[datum]]
        name = "A1"                # optional: its name in messages (default "datum N")
        nominal = [20.0, 10.0, 0.0]  # the point on the CAD model, mm
        measured = "P7"            # the id of a point of MEASUREMENTS, or [x, y, z] mm
        constrains = "z"           # the CAD axes it fixes: "x", "y", "z" or several ("xy")
        # direction = [0.0, 0.6, 0.8]   # instead of constrains: one unit direction

    or a feature fitted by least squares to several measured points (``measured``: a list of ids or
    of [x, y, z])::

        [[datum]]
        name = "A"
        feature = "plane"          # plane, line, circle, cylinder, sphere (default point)
        nominal = [0.0, 0.0, 0.0]  # a point of the plane
        normal = [0.0, 0.0, 1.0]   # its unit normal
        measured = ["P1", "P2", "P3", "P4"]

    A line takes ``axis`` (its direction) and the one direction it fixes (``constrains`` or
    ``direction``, square to the axis); a circle ``normal`` (of its plane), a cylinder ``axis``; a
    circle, a cylinder and a sphere an optional ``radius`` and optionally the directions their centre
    fixes (default: the two square to the normal or axis; x, y, z for a sphere). Any datum may take
    ``weight`` (default 1) and ``tolerance`` (mm, the largest residual it may be left with when the
    datums over-determine the alignment); a top-level ``tolerance`` sets the default for all
    (``DATUM_RESIDUAL_TOL`` otherwise).

    Any unknown key, a key that the kind of datum does not take, a missing or malformed value, a
    non-unit direction, too few points for the feature or a repeated name is an
    :class:`InputError` at the table's line.
    """
    from .._io import read_text
    from ._fit import MIN_POINTS

    src = str(Path(path))
    text = read_text(path)
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(
            f"not valid TOML: {e}", src, getattr(e, "lineno", 0) or 0, getattr(e, "colno", 0) or 0
        ) from None
    starts = [k for k, ln in enumerate(text.splitlines(), 1) if ln.strip().startswith("[[datum]]")]
    extra = sorted(set(d) - {"datum", "tolerance"})
    if extra:
        raise InputError(f"unknown key {cut(extra[0])}; the file holds [[datum]] tables and a tolerance", src)
    default_tol = _positive(d.get("tolerance", DATUM_RESIDUAL_TOL), "tolerance (mm)", lambda m: _raise(m, src, 0))
    tables = d.get("datum")
    if not isinstance(tables, list) or not tables:
        raise InputError("no [[datum]] table", src)
    out: list[Datum] = []
    seen: dict[str, int] = {}
    for k, t in enumerate(tables):
        line = starts[k] if k < len(starts) else 0

        def fail(msg, line=line):
            _raise(msg, src, line)

        unknown = sorted(set(t) - set(_KEYS))
        if unknown:
            fail(f"[[datum]] unknown key {cut(unknown[0])} ({', '.join(_KEYS)})")
        name = t.get("name", f"datum {k + 1}")
        if not isinstance(name, str) or not name.strip():
            fail(f"[[datum]] name must be a text, got {cut(name)}")
        if name in seen:
            fail(f"datum {name!r} repeats the one at line {seen[name]}")
        seen[name] = line
        feature = t.get("feature", "point")
        if feature not in FEATURES:
            fail(f"datum {name!r}: feature must be one of {', '.join(FEATURES)}, got {cut(feature)}")
        needs, may = _NEEDS[feature]
        for key in needs:
            if key not in t:
                fail(f"datum {name!r}: a {feature} needs {key}")
        others = sorted(set(t) - {"name", "feature", "nominal", "measured", "weight", "tolerance", *needs, *may})
        if others:
            fail(f"datum {name!r}: a {feature} does not take {others[0]}")
        nominal = _xyz(t.get("nominal"), f"datum {name!r}: nominal", fail)
        normal = _unit(t["normal"], f"datum {name!r}: normal", fail) if "normal" in t else None
        axis = _unit(t["axis"], f"datum {name!r}: axis", fail) if "axis" in t else None
        radius = _positive(t["radius"], f"datum {name!r}: radius (mm)", fail) if "radius" in t else None
        weight = _positive(t.get("weight", 1.0), f"datum {name!r}: weight", fail)
        tol = _positive(t.get("tolerance", default_tol), f"datum {name!r}: tolerance (mm)", fail)
        meas = t.get("measured")
        label: str | None = None
        labels: tuple[str, ...] = ()
        measured = None
        if feature == "point":
            if isinstance(meas, str) and meas.strip():
                label = meas.strip()
            else:
                measured = _xyz(meas, f"datum {name!r}: measured (a point id or [x, y, z])", fail)
        else:
            what = f"datum {name!r}: measured (a list of point ids or of [x, y, z])"
            if not isinstance(meas, list) or not meas:
                fail(f"{what}, got {cut(meas)}")
            if all(isinstance(v, str) and v.strip() for v in meas):
                labels = tuple(str(v).strip() for v in meas)
                twice = [i for i in labels if labels.count(i) > 1]
                if twice:
                    fail(f"datum {name!r}: measured names point {twice[0]!r} twice")
            else:
                measured = np.array([_xyz(v, what, fail) for v in meas])
            count = len(labels) or len(measured)  # type: ignore[arg-type]
            if count < MIN_POINTS[feature]:
                fail(f"datum {name!r}: a {feature} needs at least {MIN_POINTS[feature]} measured points, got {count}")
        dirs = _directions(t, feature, name, normal, axis, fail)
        out.append(
            Datum(name, nominal, measured, label, dirs, line, feature, labels, normal, axis, radius, weight, tol)
        )
    return out


def _raise(msg, src, line):
    raise InputError(msg, src, line)


def _directions(t, feature, name, normal, axis, fail) -> np.ndarray:
    """The directions along which a datum fixes its position (see :class:`Datum`)."""
    from ._fit import _basis

    given = "constrains" in t or "direction" in t
    if "constrains" in t and "direction" in t:
        fail(f"datum {name!r}: give constrains (axes) or direction (a unit vector), not both")
    if feature == "point" and not given:
        fail(f"datum {name!r}: give constrains (axes) or direction (a unit vector), one of them")
    if feature == "line" and not given:
        fail(f"datum {name!r}: a line needs the one direction it fixes (constrains or direction), square to its axis")
    if "constrains" in t:
        c = t["constrains"]
        if not isinstance(c, str) or not c or any(a not in _AXES for a in c.lower()) or len(set(c.lower())) != len(c):
            fail(f'datum {name!r}: constrains must name axes among x, y, z once each ("z", "xy"), got {cut(c)}')
        dirs = np.array([_AXES[a] for a in c.lower()])
    elif "direction" in t:
        dirs = _unit(t["direction"], f"datum {name!r}: direction", fail)[None, :]
    elif feature == "plane":
        dirs = normal[None, :]
    elif feature in ("circle", "cylinder"):
        about = normal if feature == "circle" else axis
        assert about is not None  # read_datums requires it
        dirs = np.array(_basis(about))
    else:  # sphere
        dirs = np.eye(3)
    if feature == "line" and len(dirs) != 1:
        fail(f"datum {name!r}: a line fixes one direction, got {len(dirs)}")
    if feature in ("line", "cylinder"):
        off = np.abs(dirs @ axis).max()
        if off > 1e-6:
            fail(f"datum {name!r}: the directions a {feature} fixes must be square to its axis (cosine {off:.3g})")
    return dirs


def _xyz(v, what, fail) -> np.ndarray:
    ok = isinstance(v, list) and len(v) == 3 and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in v)
    if not ok:
        fail(f"{what} must be [x, y, z] numbers, got {cut(v)}")
    a = np.asarray(v, float)
    if not np.isfinite(a).all() or (np.abs(a) > COORD_MAX).any():
        fail(f"{what} must be finite and within ±{COORD_MAX:g} mm, got {cut(v)}")
    return a


def _unit(v, what, fail) -> np.ndarray:
    a = _xyz(v, what, fail)
    if abs(np.linalg.norm(a) - 1) > 1e-6:
        fail(f"{what} must be a unit vector, |d| = {np.linalg.norm(a):.6g}")
    return a / np.linalg.norm(a)


def _positive(v, what, fail) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not 0 < v <= COORD_MAX:
        fail(f"{what} must be a positive number, got {cut(v)}")
    return float(v)


@dataclass(frozen=True)
class _Rows:
    """The equations of the datums: r = √w d · (R m + τ t − p), one row each; ``owner`` the datum's
    index."""

    m: np.ndarray
    d: np.ndarray
    p: np.ndarray
    tau: np.ndarray
    sw: np.ndarray
    owner: np.ndarray

    def take(self, keep: np.ndarray) -> _Rows:
        k = keep[self.owner]
        return _Rows(self.m[k], self.d[k], self.p[k], self.tau[k], self.sw[k], self.owner[k])


def _datum_rows(dt: Datum, fit, m) -> list[tuple]:
    """(m, d, p, τ) of each equation of ``dt``: its position along each direction it fixes and, for
    a plane or a line, the tilt of its fitted normal or direction (times the feature's size)."""
    from ._fit import _basis

    if fit is None:
        return [(m, d, dt.nominal, 1.0) for d in dt.directions]
    rows = [(fit.centre, d, dt.nominal, 1.0) for d in dt.directions]
    lever = fit.extent * fit.direction
    if dt.feature == "plane" and dt.normal is not None:
        rows += [(lever, e, np.zeros(3), 0.0) for e in _basis(dt.normal)]
    elif dt.feature == "line":
        rows.append((lever, dt.directions[0], np.zeros(3), 0.0))
    return rows


def align_datums(datums: Sequence[Datum], *, points=None, ids=None, dof=None, source: str | None = None) -> Alignment:
    """The rigid transform that puts each datum on its nominal along the directions it fixes
    (RPS / 3-2-1 on points and fitted features).

    Each datum gives equations (see the module): a point d · (R m + t − p) = 0 per direction it
    constrains; a feature is first fitted to its measured points by least squares
    (:func:`ncadapt.measure.fit_feature`) and its centroid or centre takes the place of m, and a
    plane's fitted normal v gives L e · (R v) = 0 for the two e square to the nominal normal (a
    line's direction, the one for its fixed direction), L the feature's size. As many equations as
    degrees of freedom are solved exactly; more are solved by weighted least squares (each datum's
    ``weight``) and each datum's residual must stay within its ``tolerance``.

    Parameters
    ----------
    datums : list of Datum
        From :func:`read_datums`.
    points : (n, 3) float, mm, optional
        The measured points that the datums name by id, with their ``ids``.
    ids : sequence of str, optional
        The ids of ``points``.
    dof : sequence of str or str, optional
        The degrees of freedom to solve for (default all six).
    source : str, optional
        The datums file, for messages.

    Returns
    -------
    Alignment
        ``rms`` is that of the equations (mm; 0 within round-off when exact), ``points`` their
        number, ``datums`` each datum's fit and residual, ``std`` the parameters' uncertainty
        when over-determined.

    Raises
    ------
    InputError
        At the datum's line: a label that names no measured point, a feature whose points do not
        determine it. Then: datums that do not fix the degrees of freedom (naming those left free:
        e.g. three datum points on a line leave a rotation about it; five constraints for six leave
        one), a datum left beyond its tolerance (naming it, and saying whether the others agree
        without it), a solution that does not converge.

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
    from ._fit import fit_feature

    names = parse_dof(dof, source)
    lookup = {s: k for k, s in enumerate(ids)} if ids is not None else {}
    rows: list[tuple] = []
    fits = []
    for j, dt in enumerate(datums):
        for label in dt.ids:
            if label not in lookup or points is None:
                raise InputError(f"datum {dt.name!r}: no measured point with id {label!r}", source, dt.line)
        coords = dt.measured if not dt.ids else np.asarray(points, float)[[lookup[i] for i in dt.ids]]
        if dt.feature == "point":
            fit, m = None, np.asarray(coords, float).reshape(3)
        else:
            try:
                fit = fit_feature(dt.feature, coords, axis=dt.axis)
            except InputError as e:
                raise InputError(f"datum {dt.name!r}: {e.message}", source, dt.line) from None
            m = None
        fits.append(fit)
        rows += [(*r, math.sqrt(dt.weight), j) for r in _datum_rows(dt, fit, m)]
    col = [np.array([r[k] for r in rows], float) for k in range(5)]
    eq = _Rows(col[0], col[1], col[2], col[3], col[4], np.array([r[5] for r in rows], int))
    theta, r, it, ok, jac = _solve_datums(eq, names, source)
    res = _per_datum(eq, r, len(datums))
    exact = len(r) == len(names)
    if exact and np.abs(r).max() > DATUM_TOL * max(1.0, float(np.abs(eq.m).max())):
        raise InputError(
            f"--align datums: the equations are left {np.abs(r).max():.3g} mm from exact; the datums contradict "
            "each other",
            source,
        )
    if not exact:
        _refuse_contradiction(datums, eq, res, names, source)
    summary = tuple(_datum_residual(dt, fit, float(res[j])) for j, (dt, fit) in enumerate(zip(datums, fits)))
    out = _result("datums", theta, r, names, it, ok, len(r), jac)
    raw = r / eq.sw
    return dataclasses.replace(out, rms=float(np.sqrt(np.mean(raw * raw))), datums=summary)


def _datum_residual(dt: Datum, fit, residual: float) -> DatumResidual:
    if fit is None:
        return DatumResidual(dt.name, "point", dt.line, dt.constraints, dt.weight, residual, dt.tolerance, 1, 0.0, 0.0,
                             None, None)  # fmt: skip
    radius = fit.radius if dt.feature in ("circle", "cylinder", "sphere") else None
    return DatumResidual(
        dt.name,
        dt.feature,
        dt.line,
        dt.constraints,
        dt.weight,
        residual,
        dt.tolerance,
        len(fit.residuals),
        fit.form_rms,
        fit.form_max,
        radius,
        dt.radius,
    )


def _solve_datums(eq: _Rows, names, source):
    """Gauss–Newton on the datum equations; the free degrees of freedom refused by name."""
    cols = [DOF.index(d) for d in names]
    hint = (
        "choose datums that span each plane (not along one line) and constrain all six "
        "(3-2-1: a plane or three points, a line or two points, a point)"
    )

    def residuals(theta):
        x = eq.m @ _rotations(theta[3:])[0].T + eq.tau[:, None] * theta[:3]
        n = eq.sw[:, None] * eq.d
        return np.einsum("ij,ij->i", x - eq.p, n), n, np.ones(len(x), bool)

    if len(eq.m) < len(cols):
        lever = max(1.0, float(np.linalg.norm(eq.m, axis=1).max()))
        jac = _jacobian(eq.m, eq.sw[:, None] * eq.d, np.zeros(6), cols, eq.tau)
        free = _undetermined(jac, names, lever)
        raise InputError(
            f"--align datums: {len(eq.m)} constraints for {len(cols)} degrees of freedom ({','.join(names)}): "
            f"the datums do not determine {', '.join(free)}; {hint}",
            source,
        )
    theta, r, it, ok, _, jac = _gauss_newton(eq.m, residuals, names, "datums", hint, source, eq.tau)
    return theta, r, it, ok, jac


def _per_datum(eq: _Rows, r: np.ndarray, count: int) -> np.ndarray:
    """Each datum's residual, mm: the root sum of squares of its (unweighted) equations."""
    out = np.zeros(count)
    np.add.at(out, eq.owner, (r / eq.sw) ** 2)
    return np.sqrt(out)


def _refuse_contradiction(datums, eq: _Rows, res: np.ndarray, names, source) -> None:
    """Refuse an over-determined alignment that leaves a datum beyond its tolerance, naming the
    datum that contradicts the others: the one without which the others agree within theirs (the
    one with the largest residual relative to its tolerance when none does)."""
    tol = np.array([dt.tolerance for dt in datums])
    if (res <= tol).all():
        return
    worst = int(np.argmax(res / tol))
    culprit, agree = None, np.inf
    for j in range(len(datums)):
        keep = np.ones(len(datums), bool)
        keep[j] = False
        sub = eq.take(keep)
        try:
            _, r_sub, *_ = _solve_datums(sub, names, source)
        except InputError:
            continue  # the others alone do not fix the frame
        others = _per_datum(sub, r_sub, len(datums))[keep]
        if (others <= tol[keep]).all() and others.max(initial=0.0) < agree:
            culprit, agree = j, float(others.max(initial=0.0))
    over = ", ".join(
        f"{datums[k].name!r} {res[k]:.4g} mm (tolerance {tol[k]:g})" for k in np.argsort(-res / tol) if res[k] > tol[k]
    )
    j = worst if culprit is None else culprit
    dt = datums[j]
    if culprit is not None:
        msg = (
            f"--align datums: datum {dt.name!r} contradicts the others (without it they agree within {agree:.3g} mm): "
            f"the least-squares alignment leaves {over} from the nominal; check its measurement and nominal, "
            "or give it a lower weight and a wider tolerance"
        )
    else:
        msg = (
            f"--align datums: the datums contradict each other: the least-squares alignment leaves {over} from the "
            "nominal, and leaving out any one datum does not reconcile the rest"
        )
    raise InputError(msg, source, dt.line)
