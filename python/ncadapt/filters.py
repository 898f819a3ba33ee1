"""Separating the systematic part of a deviation pattern from measurement noise.

Bilateral filter on scattered points (Tomasi & Manduchi 1998, as the freeform method uses it):

    s'(u) = Σ_{p ∈ N(u)} W_c(|p − u|) W_s(|s(u) − s(p)|) s(p)  /  Σ_{p ∈ N(u)} W_c(|p − u|) W_s(|s(u) − s(p)|)
    W_c(d) = exp(−d² / 2σ_c²),  W_s(d) = exp(−d² / 2σ_s²),  N(u) = points within r = 2σ_c of u.

Smoothing spline with MATLAB csaps' parameter p ∈ [0, 1] (p = 0: least-squares straight line,
p = 1: interpolating natural cubic spline): it minimises p Σ (y_i − f(x_i))² + (1 − p) ∫ f''² dx.
On a grid the 1-D smoother (de Boor, "A Practical Guide to Splines", ch. XIV, the algorithm csaps
implements) is applied along each axis in turn (csaps on gridded data). Scattered points get the
thin-plate smoothing spline of the same weighting, p Σ (y_i − f(x_i))² + (1 − p) J(f) with the
thin-plate energy J = ∫∫ f_xx² + 2 f_xy² + f_yy²: scipy's :class:`~scipy.interpolate.RBFInterpolator`
with the kernel r² log r minimises Σ (y_i − f(x_i))² + λ cᵀKc and J(f) = 8π cᵀKc for that kernel
(its Green's function is r² log r / 8π; Wahba 1990, ch. 2), so λ = 8π (1 − p) / p. The two are
different functionals (a tensor product of 1-D splines, a thin plate), so one p smooths alike but
not identically: on grid points both leave residuals within about a third of each other
(tests/test_freeform_stats.py).

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


def smoothing_spline(points, values, p: float) -> np.ndarray:
    """Thin-plate smoothing spline (λ = 8π (1 − p) / p, see the module docstring) of scattered
    ``values`` at their points."""
    from scipy.interpolate import RBFInterpolator

    if not 0 < p <= 1:
        raise ValueError(f"p must be in (0, 1] for scattered points, got {p}")
    pts = np.asarray(points, dtype=float)
    v = np.asarray(values, dtype=float).ravel()
    if len(v) < 4:
        raise InputError(f"a thin-plate spline needs at least 4 points, got {len(v)}")
    neighbors = None if len(v) <= 3000 else 100
    f = RBFInterpolator(pts, v, kernel="thin_plate_spline", smoothing=8 * np.pi * (1 - p) / p, neighbors=neighbors)
    return f(pts)
