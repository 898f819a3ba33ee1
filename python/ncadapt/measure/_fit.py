"""Least-squares geometric elements fitted to measured points: plane, line, circle, cylinder, sphere.

Each fit minimises the sum of the squared distances of the points from the element (the geometric,
or orthogonal, least squares of coordinate metrology):

- plane: through the centroid c, normal the right singular vector of the centred points with the
  smallest singular value (closed form);
- line: through c along the singular vector with the largest singular value (closed form);
- circle: the plane fit, then in that plane the circle minimising Σ (|q_i − q0| − r)², started
  from the algebraic fit |q|² = 2 q·q0 + k (Kåsa) and refined by Gauss–Newton;
- sphere: Σ (|p_i − p0| − r)², started from the algebraic fit and refined by Gauss–Newton;
- cylinder: Σ (|(p_i − x0) × a| − r)² over the axis (x0, a) and r, Gauss–Newton with the data moved
  at each iteration so that the axis is the z axis through the origin (then the derivatives are
  those of the reference below), started from the nominal axis and the points' principal
  directions, the lowest residual kept.

Reference: A. B. Forbes, "Least-squares best-fit geometric elements", NPL Report DITC 140/89,
National Physical Laboratory, 1989 (revised 1991) — the parameterisations and Jacobians used here.

A fit is refused (:class:`~ncadapt.errors.InputError` without a location; the caller adds it) with
too few points for the element or when the points do not determine it: collinear points for a
plane or circle, coincident points for a line, coplanar points for a sphere, points that do not fix
a cylinder's axis — its Jacobian's scaled columns rank deficient below ``DEGENERATE``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

#: The elements, and the fewest points that determine each.
MIN_POINTS = {"plane": 3, "line": 2, "circle": 3, "cylinder": 5, "sphere": 4}

#: Relative singular value below which the points do not determine the element: a spread across
#: the element 1e-6 of the spread along it (1 nm across 1 mm) is a line, not a plane.
DEGENERATE = 1e-6
#: Gauss–Newton stops when a step changes no parameter by more than this share of the points'
#: size (1e-12 of 100 mm is 0.1 pm, far below any measurement).
STEP_REL = 1e-12
#: Gauss–Newton iterations of a fit before refusing it as not converged.
MAX_FIT_ITERATIONS = 100


@dataclass(frozen=True)
class FeatureFit:
    """A geometric element fitted to measured points (in the points' frame).

    Attributes
    ----------
    kind : str
        ``"plane"``, ``"line"``, ``"circle"``, ``"cylinder"`` or ``"sphere"``.
    centre : (3,) float, mm
        The plane's and the line's centroid of the points, the circle's and the sphere's centre,
        the point of the cylinder's axis nearest the points' centroid.
    direction : (3,) float
        Unit vector: the plane's normal, the line's direction, the normal of the circle's plane,
        the cylinder's axis; zeros for a sphere. Its sign is arbitrary.
    radius : float, mm
        The circle's, cylinder's or sphere's radius; 0 for a plane or a line.
    residuals : (n,) float, mm
        Each point's distance from the element: signed along the normal (plane), from the line
        (line, ≥ 0), radial in the circle's plane (circle), radial (cylinder, sphere; > 0 outside).
    extent : float, mm
        The farthest point from ``centre`` across the normal (plane), along the line (line) or
        along the axis (cylinder); the radius for a circle or a sphere. It is the lever that turns
        a tilt into a distance.
    """

    kind: str
    centre: np.ndarray
    direction: np.ndarray
    radius: float
    residuals: np.ndarray
    extent: float

    @property
    def form_rms(self) -> float:
        """Root mean square of ``residuals``, mm."""
        return float(np.sqrt(np.mean(self.residuals**2)))

    @property
    def form_max(self) -> float:
        """Largest ``|residuals|``, mm."""
        return float(np.abs(self.residuals).max())


def fit_feature(kind: str, points, axis=None) -> FeatureFit:
    """The least-squares ``kind`` element through ``points``.

    Parameters
    ----------
    kind : str
        One of ``MIN_POINTS``: ``"plane"``, ``"line"``, ``"circle"``, ``"cylinder"``, ``"sphere"``.
    points : (n, 3) float, mm
        The measured points, at least ``MIN_POINTS[kind]``.
    axis : (3,) float, optional
        A cylinder's expected axis direction: one of the starts of its fit (the points' principal
        directions are the others).

    Returns
    -------
    FeatureFit

    Raises
    ------
    InputError
        Too few points, or points that do not determine the element (the message says why).

    Examples
    --------
    >>> t = np.radians([0, 90, 200, 300])
    >>> f = fit_feature("circle", np.column_stack([3 + 5 * np.cos(t), -1 + 5 * np.sin(t), np.full(4, 2.0)]))
    >>> np.round(f.centre, 9) + 0.0, round(f.radius, 9)
    (array([ 3., -1.,  2.]), 5.0)
    """
    p = np.asarray(points, float).reshape(-1, 3)
    if kind not in MIN_POINTS:
        raise InputError(f"a feature is one of {', '.join(MIN_POINTS)}, got {kind!r}")
    if len(p) < MIN_POINTS[kind]:
        raise InputError(f"a {kind} needs at least {MIN_POINTS[kind]} points, got {len(p)}")
    if not np.isfinite(p).all():
        raise InputError(f"the {kind}'s points must be finite")
    if kind == "cylinder":
        return _cylinder(p, axis)
    return {"plane": _plane, "line": _line, "circle": _circle, "sphere": _sphere}[kind](p)


def _svd(p: np.ndarray):
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c, full_matrices=False)
    if len(s) < 3:
        s = np.concatenate([s, np.zeros(3 - len(s))])
    return c, s, vt


def _plane(p: np.ndarray) -> FeatureFit:
    c, s, vt = _svd(p)
    if s[0] == 0 or s[1] <= DEGENERATE * s[0]:
        raise InputError("the plane's points lie on one line (or one point): they do not determine a plane")
    n = vt[2]
    d = p - c
    r = d @ n
    across = d - np.outer(r, n)
    return FeatureFit("plane", c, n, 0.0, r, float(np.linalg.norm(across, axis=1).max()))


def _line(p: np.ndarray) -> FeatureFit:
    c, s, vt = _svd(p)
    if s[0] <= DEGENERATE * max(1.0, float(np.abs(p).max())):
        raise InputError("the line's points coincide: they do not determine a line")
    u = vt[0]
    d = p - c
    along = d @ u
    r = np.linalg.norm(d - np.outer(along, u), axis=1)
    return FeatureFit("line", c, u, 0.0, r, float(np.abs(along).max()))


def _gauss_newton(residual_jacobian, x, scale: float, what: str, lever=None):
    """Minimise Σ r² from ``x``: ``residual_jacobian(x)`` returns (r, J, x_update) where
    ``x_update(step)`` gives the next parameters (a fit may re-base them). The columns of J times
    ``lever`` (default 1: every parameter in mm; an angle's column is divided by the points' size,
    a change per mm of motion of the farthest point) are refused as rank deficient below
    ``DEGENERATE``. Returns (x, r, J)."""
    for _ in range(MAX_FIT_ITERATIONS):
        r, jac, update = residual_jacobian(x)
        scaled = jac if lever is None else jac * lever
        sv = np.linalg.svd(scaled, compute_uv=False)
        if sv[0] == 0 or sv[-1] < DEGENERATE * sv[0]:
            raise InputError(f"the points do not determine the {what}")
        norms = np.linalg.norm(jac, axis=0)
        step = np.linalg.lstsq(jac / norms, -r, rcond=None)[0] / norms
        cost = float(r @ r)
        for _ in range(40):
            x_new = update(step)
            r_new = residual_jacobian(x_new)[0]
            if float(r_new @ r_new) <= cost * (1 + 1e-12) + 1e-300:
                break
            step = step / 2
        x = x_new
        if np.abs(step).max() <= STEP_REL * scale:
            r, jac, _ = residual_jacobian(x)
            return x, r, jac
    raise InputError(f"the {what} fit did not converge in {MAX_FIT_ITERATIONS} iterations")


def _basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors that make (e1, e2, n) a right-handed orthonormal frame."""
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def _circle(p: np.ndarray) -> FeatureFit:
    plane = _plane(p)
    c, n = plane.centre, plane.direction
    e1, e2 = _basis(n)
    q = np.column_stack([(p - c) @ e1, (p - c) @ e2])
    scale = max(1.0, float(np.abs(q).max()))
    # algebraic start (Kåsa): |q|² = 2 q·q0 + k, r² = k + |q0|²
    a = np.column_stack([2 * q, np.ones(len(q))])
    sol = np.linalg.lstsq(a, (q**2).sum(axis=1), rcond=None)[0]
    x0 = np.array([sol[0], sol[1], np.sqrt(max(sol[2] + sol[0] ** 2 + sol[1] ** 2, 0.0))])

    def rj(x):
        d = q - x[:2]
        rho = np.linalg.norm(d, axis=1)
        if (rho == 0).any():
            raise InputError("a point of the circle is at its centre: the points do not determine the circle")
        jac = np.column_stack([-d / rho[:, None], -np.ones(len(q))])
        return rho - x[2], jac, lambda s: x + s

    x, r, _ = _gauss_newton(rj, x0, scale, "circle")
    if x[2] <= 0:
        raise InputError("the points do not determine the circle")
    centre = c + x[0] * e1 + x[1] * e2
    return FeatureFit("circle", centre, n, float(x[2]), r, float(x[2]))


def _sphere(p: np.ndarray) -> FeatureFit:
    _, s, _ = _svd(p)
    if s[0] == 0 or s[2] <= DEGENERATE * s[0]:
        raise InputError("the sphere's points lie in one plane: they do not determine a sphere")
    scale = max(1.0, float(np.abs(p - p.mean(axis=0)).max()))
    c0 = p.mean(axis=0)
    q = p - c0
    a = np.column_stack([2 * q, np.ones(len(q))])
    sol = np.linalg.lstsq(a, (q**2).sum(axis=1), rcond=None)[0]
    x0 = np.concatenate([sol[:3], [np.sqrt(max(sol[3] + sol[:3] @ sol[:3], 0.0))]])

    def rj(x):
        d = q - x[:3]
        rho = np.linalg.norm(d, axis=1)
        if (rho == 0).any():
            raise InputError("a point of the sphere is at its centre: the points do not determine the sphere")
        return rho - x[3], np.column_stack([-d / rho[:, None], -np.ones(len(q))]), lambda s: x + s

    x, r, _ = _gauss_newton(rj, x0, scale, "sphere")
    if x[3] <= 0:
        raise InputError("the points do not determine the sphere")
    return FeatureFit("sphere", c0 + x[:3], np.zeros(3), float(x[3]), r, float(x[3]))


def _cylinder(p: np.ndarray, axis=None) -> FeatureFit:
    c0 = p.mean(axis=0)
    q = p - c0
    scale = max(1.0, float(np.abs(q).max()))
    _, _, vt = np.linalg.svd(q, full_matrices=False)
    starts = list(vt)
    if axis is not None:
        a = np.asarray(axis, float)
        starts.insert(0, a / np.linalg.norm(a))
    best = None
    errors = []
    for a0 in starts:
        try:
            fit = _cylinder_from(q, a0, scale)
        except InputError as e:
            errors.append(e)
            continue
        if best is None or fit[3] @ fit[3] < best[3] @ best[3]:
            best = fit
    if best is None:
        raise errors[0]
    x0, a, r, res = best
    along = (q - x0) @ a
    mid = x0 + along.mean() * a
    extent = float(np.abs(along - along.mean()).max())
    return FeatureFit("cylinder", c0 + mid, a, float(r), res, extent)


def _cylinder_from(q: np.ndarray, a0: np.ndarray, scale: float):
    """Forbes's cylinder fit from the axis through the origin along ``a0``: the state is (x0, a, r)
    with x0 a point of the axis; each iteration moves the data so that x0 is the origin and
    rotates it so that a is z, where the parameters (x, y, α, β, r) of the axis
    (x, y, 0) + λ (α, β, 1) and the radius have the Jacobian of NPL DITC 140/89 §4.3."""
    x = (np.zeros(3), a0 / np.linalg.norm(a0), 0.0)
    rho0 = np.linalg.norm(q - np.outer(q @ x[1], x[1]), axis=1)
    x = (x[0], x[1], float(rho0.mean()))

    def rj(state):
        x0, a, r = state
        e1, e2 = _basis(a)
        rot = np.vstack([e1, e2, a])  # rows: the frame in which a is z
        d = (q - x0) @ rot.T
        rho = np.hypot(d[:, 0], d[:, 1])
        if (rho == 0).any():
            raise InputError("a point of the cylinder is on its axis: the points do not determine the cylinder")
        ux, uy = d[:, 0] / rho, d[:, 1] / rho
        jac = np.column_stack([-ux, -uy, -ux * d[:, 2], -uy * d[:, 2], -np.ones(len(q))])

        def update(s):
            a_new = rot.T @ np.array([s[2], s[3], 1.0])
            a_new /= np.linalg.norm(a_new)
            x_new = x0 + rot.T @ np.array([s[0], s[1], 0.0])
            # keep the axis point nearest the data's centroid (the origin of q)
            x_new = x_new - (x_new @ a_new) * a_new
            return (x_new, a_new, r + s[4])

        return rho - r, jac, update

    lever = np.array([1.0, 1.0, 1.0 / scale, 1.0 / scale, 1.0])
    x_fit, res, _ = _gauss_newton(rj, x, scale, "cylinder", lever)
    if x_fit[2] <= 0:
        raise InputError("the points do not determine the cylinder")
    return x_fit[0], x_fit[1], x_fit[2], res
