"""Separating the systematic part of a deviation pattern from measurement noise.

Bilateral filter on scattered points (Tomasi & Manduchi 1998, as the freeform method uses it):

    s'(u) = Σ_{p ∈ N(u)} W_c(|p − u|) W_s(|s(u) − s(p)|) s(p)  /  Σ_{p ∈ N(u)} W_c(|p − u|) W_s(|s(u) − s(p)|)
    W_c(d) = exp(−d² / 2σ_c²),  W_s(d) = exp(−d² / 2σ_s²),  N(u) = points within r = 2σ_c of u.

Smoothing spline with MATLAB csaps' parameter p ∈ [0, 1] (p = 0: least-squares straight line,
p = 1: interpolating natural cubic spline): it minimises p Σ (y_i − f(x_i))² + (1 − p) ∫ f''² dx.
On a grid the 1-D smoother (de Boor, "A Practical Guide to Splines", ch. XIV, the algorithm csaps
implements) is applied along each axis in turn (csaps on gridded data): with λ = (1 − p)/p and K
the natural spline's roughness matrix its result is (I + λK_u)⁻¹ ⊗ (I + λK_v)⁻¹ y, the minimiser of
‖y − F‖² + λFᵀ(K_u ⊗ I + I ⊗ K_v)F + λ²Fᵀ(K_u ⊗ K_v)F. Scattered points get that same functional
on a node grid spaced like the points (:func:`smoothing_spline`), so one p means one thing: points
on a grid given to either smoother give the same surface (tests/test_freeform_stats.py).

The default p is csaps' automatic choice, p·trace(A) = (1 − p)·trace(B) in its linear system,
which for sites h apart is p = 1 / (1 + h³ / 9) (:func:`csaps_auto_p`).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from .errors import InputError
from .neighbours import pairs_within


def bilateral(points, values, sigma_c: float, sigma_s: float, radius: float | None = None) -> np.ndarray:
    """Bilateral filter of ``values`` at scattered ``points`` (n, d); lengths in the points' units.

    ``radius`` defaults to 2 σ_c. Neighbour pairs come from a KD-tree, so time and memory grow with
    the number of pairs (about 16 bytes each), not n².
    """
    p = np.asarray(points, dtype=float)
    s = np.asarray(values, dtype=float).ravel()
    if p.ndim != 2 or len(p) != len(s):
        raise ValueError(f"points must be (n, d) with n = {len(s)}, got {p.shape}")
    if not (sigma_c > 0 and sigma_s > 0):
        raise ValueError(f"sigma_c and sigma_s must be > 0, got {sigma_c}, {sigma_s}")
    r = 2.0 * sigma_c if radius is None else float(radius)
    # every pair closer than r once (i < j), from the KD-tree as an array; each counts both ways
    pairs = pairs_within(cKDTree(p), r, "the bilateral filter's radius 2 sigma_c =")
    i, j = pairs[:, 0], pairs[:, 1]
    # distances divided by the sigmas before squaring: no overflow for any positive sigma
    dc = np.sqrt(((p[i] - p[j]) ** 2).sum(axis=1)) / sigma_c
    ds = np.abs(s[i] - s[j]) / sigma_s
    with np.errstate(over="ignore"):  # a distance of many sigmas weighs exp(-inf) = 0
        w = np.exp(-0.5 * (dc * dc + ds * ds))
    n = len(s)
    # the point itself has weight 1
    num = s + np.bincount(i, weights=w * s[j], minlength=n) + np.bincount(j, weights=w * s[i], minlength=n)
    den = 1.0 + np.bincount(i, weights=w, minlength=n) + np.bincount(j, weights=w, minlength=n)
    return num / den


def csaps_auto_p(h: float) -> float:
    """csaps' automatic smoothing parameter for sites ``h`` apart: 1 / (1 + trace(R) / (6 trace(QᵀQ)))
    with R = tridiag(h, 4h, h) and Qᵀ the second differences / h, whose traces are 4h and 6/h² per
    interior site: 1 / (1 + h³ / 9)."""
    return 1.0 / (1.0 + h**3 / 9.0)


def _csaps_1d_operator(x: np.ndarray, p: float) -> np.ndarray:
    """The matrix S with S y = the p-smoothing spline of (x, y) at x (de Boor's algorithm)."""
    n = len(x)
    if n < 3:
        return np.eye(n)
    h = np.diff(x)
    if not (h > 0).all():
        raise ValueError("sites must increase strictly")
    r = sparse.diags([h[1:-1], 2 * (h[1:] + h[:-1]), h[1:-1]], [-1, 0, 1], shape=(n - 2, n - 2))
    hi = 1.0 / h
    qt = sparse.diags([hi[:-1], -(hi[:-1] + hi[1:]), hi[1:]], [0, 1, 2], shape=(n - 2, n))
    a = (6 * (1 - p) * (qt @ qt.T) + p * r).tocsc()
    # u = a⁻¹ Qᵀ y; smoothed y = y − 6(1 − p) Q u
    qt_dense = qt.toarray()
    u = spsolve(a, qt_dense) if n > 3 else np.linalg.solve(a.toarray(), qt_dense)
    u = np.asarray(u).reshape(n - 2, n)
    return np.eye(n) - 6 * (1 - p) * (qt_dense.T @ u)


def smoothing_spline_grid(axes, values, p: float) -> np.ndarray:
    """Smoothing spline (csaps' p) of gridded ``values`` at its own grid sites.

    ``axes`` is a sequence of 1-D site arrays, one per dimension of ``values``.
    """
    if not 0 <= p <= 1:
        raise ValueError(f"p must be in [0, 1], got {p}")
    out = np.asarray(values, dtype=float)
    if out.ndim != len(axes):
        raise ValueError(f"{len(axes)} axes for a {out.ndim}-d grid")
    for k, x in enumerate(axes):
        x = np.asarray(x, dtype=float)
        if len(x) != out.shape[k]:
            raise ValueError(f"axis {k} has {len(x)} sites, the grid {out.shape[k]}")
        s = _csaps_1d_operator(x, p)
        out = np.moveaxis(np.tensordot(s, np.moveaxis(out, k, 0), axes=(1, 0)), 0, k)
    return out


def effective_spacing(points) -> float:
    """The spacing s of a square grid holding as many points over the same area (mm, like the points).

    The area is the points' convex hull grown by s/2 all round (area A + perimeter P · s/2 + s²), so
    n s² = A + P s/2 + s²; a full n_x × n_y grid h apart gives back h exactly.
    """
    from scipy.spatial import ConvexHull

    p = np.asarray(points, dtype=float)[:, :2]
    n = len(p)
    if n < 4:
        raise InputError(f"an area needs at least 4 points, got {n}")
    hull = ConvexHull(p)
    a, perimeter = hull.volume, hull.area  # in 2-D scipy calls the area "volume", the perimeter "area"
    return float((perimeter / 2 + np.sqrt(perimeter**2 / 4 + 4 * (n - 1) * a)) / (2 * (n - 1)))


class _Axis:
    """One axis of the node grid: sites x and the natural-spline roughness K = 6 Q r⁻¹ Qᵀ in parts."""

    def __init__(self, x: np.ndarray):
        from scipy.sparse.linalg import splu

        self.x = x
        n = len(x)
        h = np.diff(x)
        hi = 1.0 / h
        self.qt = sparse.diags([hi[:-1], -(hi[:-1] + hi[1:]), hi[1:]], [0, 1, 2], shape=(n - 2, n)).tocsr()
        r = sparse.diags([h[1:-1], 2 * (h[1:] + h[:-1]), h[1:-1]], [-1, 0, 1], shape=(n - 2, n - 2))
        self.r = splu(r.tocsc())

    def roughness(self, v: np.ndarray) -> np.ndarray:
        """K v along the first axis of v: the ∫ f''² form of the natural spline through v."""
        return 6 * (self.qt.T @ self.r.solve(np.asarray(self.qt @ v)))


def _along(op, v: np.ndarray, axis: int) -> np.ndarray:
    """op applied along ``axis`` of a 2-D array."""
    return op(v) if axis == 0 else op(v.T).T


def smoothing_spline(points, values, p: float) -> np.ndarray:
    """The grid smoothing spline's functional (csaps' p) fitted to scattered ``values`` at their points.

    Points (n, 2) scattered over an area get the tensor-product smoothing spline of the grid
    smoother: on a node grid spaced like the points (:func:`effective_spacing` s, nodes g_u, g_v
    apart over the points' bounding box) the node values F minimise

        ‖y − B F‖² + α Fᵀ(K_u ⊗ I)F + β Fᵀ(I ⊗ K_v)F + αβ Fᵀ(K_u ⊗ K_v)F,   α = λ g_v / s, β = λ g_u / s,

    with λ = (1 − p)/p, B the bilinear interpolation of the nodes at the points and K the natural
    cubic spline's roughness along each node axis (∫ f''² = Fᵀ K F). On a grid (B = I, g = s) this
    is (I + λK_u) ⊗ (I + λK_v) F = y, whose solution is csaps' gridded smoother S_u ⊗ S_v
    (:func:`smoothing_spline_grid`) exactly; elsewhere the weights keep the balance of the data
    term (n ≈ area / s²) against the roughness per unit area, so one p smooths scattered points as
    it smooths a grid of the same density. Solved by conjugate gradients preconditioned by the grid
    smoother itself (exact in one step on a grid). Returns the fitted surface at the points.
    """
    from scipy.sparse.linalg import LinearOperator, cg

    if not 0 < p < 1:
        raise ValueError(f"p must be in (0, 1) for scattered points, got {p}")
    pts = np.asarray(points, dtype=float)
    v = np.asarray(values, dtype=float).ravel()
    if pts.ndim != 2 or pts.shape[1] < 2 or len(pts) != len(v):
        raise ValueError(f"points must be (n, 2) with n = {len(v)}, got {pts.shape}")
    if not np.isfinite(v).all():
        raise InputError("the values to smooth must be finite")
    s = effective_spacing(pts)
    axes, loc = [], []
    for k in range(2):
        lo, hi = pts[:, k].min(), pts[:, k].max()
        m = max(4, int(round((hi - lo) / s)) + 1)
        x = np.linspace(lo, hi, m)
        i = np.clip(np.searchsorted(x, pts[:, k], side="right") - 1, 0, m - 2)
        t = (pts[:, k] - x[i]) / (x[i + 1] - x[i])
        axes.append(_Axis(x))
        loc.append((i, t))
    nu, nv = len(axes[0].x), len(axes[1].x)
    gu, gv = np.diff(axes[0].x[:2])[0], np.diff(axes[1].x[:2])[0]
    lam = (1 - p) / p
    alpha, beta = lam * gv / s, lam * gu / s
    (iu, tu), (iv, tv) = loc
    rows = np.repeat(np.arange(len(v)), 4)
    cols = np.column_stack([iu * nv + iv, iu * nv + iv + 1, (iu + 1) * nv + iv, (iu + 1) * nv + iv + 1]).ravel()
    w = np.column_stack([(1 - tu) * (1 - tv), (1 - tu) * tv, tu * (1 - tv), tu * tv]).ravel()
    b = sparse.csr_matrix((w, (rows, cols)), shape=(len(v), nu * nv))
    btb = (b.T @ b).tocsr()
    su = _csaps_1d_operator(axes[0].x, 1 / (1 + alpha))
    sv = _csaps_1d_operator(axes[1].x, 1 / (1 + beta))

    def penalised(f):  # (I + αK_u) ⊗ (I + βK_v) f − f
        g = f.reshape(nu, nv)
        g = g + alpha * axes[0].roughness(g)
        g = g + beta * _along(axes[1].roughness, g, 1)
        return g.ravel() - f

    def system(f):
        f = np.asarray(f).ravel()
        return btb @ f + penalised(f)

    def precondition(r):  # the grid smoother: ((I + αK_u) ⊗ (I + βK_v))⁻¹
        return (su @ np.asarray(r).reshape(nu, nv) @ sv.T).ravel()

    n = nu * nv
    rhs = b.T @ v
    scale = np.linalg.norm(rhs) or 1.0
    f, info = cg(
        LinearOperator((n, n), system, dtype=float),
        rhs / scale,
        rtol=1e-8,
        atol=0.0,
        maxiter=20_000,
        M=LinearOperator((n, n), precondition, dtype=float),
    )
    if info != 0:
        raise InputError(f"the scattered smoothing spline did not converge ({info} iterations); smooth more")
    return b @ f * scale
