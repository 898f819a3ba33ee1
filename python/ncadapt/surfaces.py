"""Parametric surfaces: bicubic B-spline surfaces Q(u, v) = (x, y, z), their normals and curvature.

A :class:`Surface` interpolates a grid of points over (u, v) with one bicubic spline per coordinate
(:class:`scipy.interpolate.RectBivariateSpline`, s = 0); its knots and coefficients are a B-spline
surface that :mod:`ncadapt.cad` writes as STEP or IGES unchanged.

Mean curvature (the sign follows the normal Q_u × Q_v):

    H = (A |Q_v|² − 2 B Q_u·Q_v + C |Q_u|²) / (2 |Q_u × Q_v|³),
    A = (Q_u × Q_v)·Q_uu,  B = (Q_u × Q_v)·Q_uv,  C = (Q_u × Q_v)·Q_vv.

:class:`Frame` places a part that is a height field over some plane in (u, v, w): w along the
measured normals' mean direction, (u, v) in the plane across it.

Also here: :func:`extrapolate_border`, the cubic extrapolation of values known inside a region of a
(u, v) grid into the rest of the grid (the unmeasured border strip of a part).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import RectBivariateSpline

from .errors import InputError


@dataclass(frozen=True)
class Surface:
    """A bicubic B-spline surface through a grid of points ``grid`` (nu, nv, 3) at ``u`` × ``v``."""

    u: np.ndarray
    v: np.ndarray
    grid: np.ndarray
    # the three coordinate splines, made from the grid
    _s: list = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        u, v, g = np.asarray(self.u, float), np.asarray(self.v, float), np.asarray(self.grid, float)
        if g.shape != (len(u), len(v), 3):
            raise ValueError(f"grid must be ({len(u)}, {len(v)}, 3), got {g.shape}")
        if len(u) < 4 or len(v) < 4:
            raise ValueError("a bicubic surface needs at least 4 x 4 grid points")
        if not (np.all(np.diff(u) > 0) and np.all(np.diff(v) > 0)):
            raise ValueError("u and v must increase strictly")
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "v", v)
        object.__setattr__(self, "grid", g)
        object.__setattr__(self, "_s", [RectBivariateSpline(u, v, g[:, :, k], kx=3, ky=3, s=0) for k in range(3)])

    @classmethod
    def from_function(cls, f, u_range, v_range, nu: int = 41, nv: int = 41) -> Surface:
        """Interpolate ``f(u, v) -> (x, y, z)`` (vectorised) on an nu × nv grid."""
        u = np.linspace(u_range[0], u_range[1], nu)
        v = np.linspace(v_range[0], v_range[1], nv)
        U, V = np.meshgrid(u, v, indexing="ij")
        return cls(u, v, np.stack(f(U, V), axis=-1))

    @classmethod
    def height(cls, f, x_range, y_range, nx: int = 41, ny: int = 41) -> Surface:
        """A height field z = f(x, y), parametrised by u = x, v = y."""
        return cls.from_function(lambda x, y: (x, y, f(x, y)), x_range, y_range, nx, ny)

    # ------------------------------------------------------------------------------ evaluation
    def _ev(self, u, v, du=0, dv=0) -> np.ndarray:
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        return np.stack([s.ev(u, v, dx=du, dy=dv) for s in self._s], axis=-1)

    def point(self, u, v) -> np.ndarray:
        """Q(u, v), shape (..., 3)."""
        return self._ev(u, v)

    def derivatives(self, u, v):
        """Q_u, Q_v, Q_uu, Q_uv, Q_vv."""
        return (
            self._ev(u, v, 1, 0),
            self._ev(u, v, 0, 1),
            self._ev(u, v, 2, 0),
            self._ev(u, v, 1, 1),
            self._ev(u, v, 0, 2),
        )

    def normal(self, u, v) -> np.ndarray:
        """Unit normal Q_u × Q_v / |Q_u × Q_v|."""
        qu, qv = self._ev(u, v, 1, 0), self._ev(u, v, 0, 1)
        n = np.cross(qu, qv)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def mean_curvature(self, u, v) -> np.ndarray:
        """H at (u, v) (1/mm); positive where the surface bends towards its normal."""
        qu, qv, quu, quv, qvv = self.derivatives(u, v)
        n = np.cross(qu, qv)
        a = (n * quu).sum(-1)
        b = (n * quv).sum(-1)
        c = (n * qvv).sum(-1)
        num = a * (qv * qv).sum(-1) - 2 * b * (qu * qv).sum(-1) + c * (qu * qu).sum(-1)
        return num / (2 * np.linalg.norm(n, axis=-1) ** 3)

    def bspline(self):
        """(knots_u, knots_v, control points (nu_c, nv_c, 3)) of the bicubic B-spline surface."""
        # the full knot vectors (get_knots() drops the repeated end knots)
        tck = [s.tck for s in self._s]
        tu, tv = tck[0][0], tck[0][1]
        ncu, ncv = len(tu) - 4, len(tv) - 4
        ctrl = np.stack([t[2].reshape(ncu, ncv) for t in tck], axis=-1)
        return tu, tv, ctrl

    def with_grid(self, grid) -> Surface:
        """The same parametrisation through other grid points (a compensated surface)."""
        return Surface(self.u, self.v, grid)


# a normal further than this from the frame's w axis makes the part not a height field over (u, v)
MAX_TILT_DEG = 80.0
# a mean normal this close to a machine axis takes the axis as w (a measured grid stays a grid)
AXIS_SNAP_DEG = 10.0


@dataclass(frozen=True)
class Frame:
    """Right-handed orthonormal axes (rows ``eu``, ``ev``, ``ew``) through the origin.

    (u, v, w) = (p·e_u, p·e_v, p·e_w). :meth:`fit` takes w from the outward normals of measured
    points: their mean direction, or the machine axis (±x, ±y, ±z) nearest to it when it is within
    :data:`AXIS_SNAP_DEG` — then (u, v) are two machine coordinates and a measured grid stays a
    grid. Every normal must be within :data:`MAX_TILT_DEG` of w. e_u is the machine axis least
    parallel to w (x before y before z on ties) made orthogonal to w, and e_v = e_w × e_u: a part
    seen from +z has (u, v) = (x, y), a wall seen from +x has (u, v) = (y, z).
    """

    axes: np.ndarray  # (3, 3) rows e_u, e_v, e_w

    @classmethod
    def along(cls, w) -> Frame:
        w = np.asarray(w, float)
        w = w / np.linalg.norm(w)
        k = int(np.argmin(np.abs(w)))
        u = np.eye(3)[k] - w[k] * w
        u /= np.linalg.norm(u)
        return cls(np.array([u, np.cross(w, u), w]))

    @classmethod
    def fit(cls, normals, source: str | None = None) -> Frame:
        n = np.asarray(normals, float)
        m = n.sum(axis=0)
        if np.linalg.norm(m) < 1e-9 * max(len(n), 1):
            raise InputError(
                "the normals cancel out: the part is not a height field over one plane; "
                "measure and compensate it in patches",
                source,
            )
        m /= np.linalg.norm(m)
        k = int(np.argmax(np.abs(m)))
        w = m if abs(m[k]) < np.cos(np.radians(AXIS_SNAP_DEG)) else np.sign(m[k]) * np.eye(3)[k]
        worst = float(np.min(n @ w))
        if worst <= np.cos(np.radians(MAX_TILT_DEG)):
            deg = float(np.degrees(np.arccos(np.clip(worst, -1, 1))))
            raise InputError(
                f"a normal is {deg:.0f}° from the viewing direction (more than {MAX_TILT_DEG:.0f}°): the "
                "part is not a height field over one plane; measure and compensate it in patches",
                source,
            )
        return cls.along(w)

    @property
    def names(self) -> tuple[str, str]:
        """Axis names of (u, v) for plots: "x", "-z" … when along a machine axis, else "u", "v"."""
        out = []
        for e, other in zip(self.axes[:2], ("u", "v")):
            k = int(np.argmax(np.abs(e)))
            out.append(("-" if e[k] < 0 else "") + "xyz"[k] if abs(abs(e[k]) - 1) < 1e-12 else other)
        return out[0], out[1]

    def uv(self, points) -> np.ndarray:
        """(n, 2) coordinates across w."""
        return np.asarray(points, float) @ self.axes[:2].T

    def w(self, points) -> np.ndarray:
        return np.asarray(points, float) @ self.axes[2]

    def local(self, points) -> np.ndarray:
        """(n, 3) frame coordinates (u, v, w) of world points."""
        return np.asarray(points, float) @ self.axes.T

    def to_world(self, u, v, w) -> np.ndarray:
        """Points (…, 3) from frame coordinates."""
        return np.stack([u, v, w], axis=-1) @ self.axes


def extrapolate_border(u, v, values, known, *, fit_points: int = 12, mode: str = "cubic") -> np.ndarray:
    """Fill the grid cells outside ``known`` by cubic extrapolation (``mode="hold"``: with the
    nearest known cell's value instead).

    ``values`` (nu, nv) are valid where ``known`` is True, a region that is convex along every grid
    row and column (the measured area of a part). Each row is extended by a least-squares cubic
    through its known values nearest each end (``fit_points``, or half the row's known values if
    more), then each column likewise; cells that neither reaches keep the nearest filled value.
    Extrapolated values are held within the known values' range widened by a quarter of its span
    on each side: a cubic through noisy data can run away a few cells out, and a compensation must
    not invent errors larger than any it measured.
    """
    out = np.array(values, dtype=float)
    have = np.array(known, dtype=bool)
    out[~have] = np.nan
    if mode == "hold":  # every unknown cell takes the value of the nearest known one
        from scipy.ndimage import distance_transform_edt

        _, (ii, jj) = distance_transform_edt(~have, return_indices=True)
        return out[ii, jj]
    if mode != "cubic":
        raise ValueError(f"mode must be 'cubic' or 'hold', got {mode!r}")
    lo_v, hi_v = float(np.min(out[have])), float(np.max(out[have]))
    pad = 0.25 * (hi_v - lo_v)
    lo_v, hi_v = lo_v - pad, hi_v + pad

    def line_fill(coord, vals, ok):
        idx = np.flatnonzero(ok)
        if len(idx) < 4:
            return vals, ok
        vals = vals.copy()
        m = max(fit_points, len(idx) // 2)
        lo, hi = idx[:m], idx[-m:]
        for sel, side in ((lo, coord < coord[idx[0]]), (hi, coord > coord[idx[-1]])):
            if side.any():
                c = np.polyfit(coord[sel], vals[sel], 3)
                vals[side] = np.clip(np.polyval(c, coord[side]), lo_v, hi_v)
        return vals, np.isfinite(vals)

    for i in range(out.shape[0]):
        out[i], _ = line_fill(v, out[i], have[i])
    have = np.isfinite(out)
    for j in range(out.shape[1]):
        out[:, j], _ = line_fill(u, out[:, j], have[:, j])
    if np.isnan(out).any():
        from scipy.ndimage import distance_transform_edt

        miss = np.isnan(out)
        _, (ii, jj) = distance_transform_edt(miss, return_indices=True)
        out[miss] = out[ii[miss], jj[miss]]
    return out
