"""Separating the systematic part of a deviation pattern from measurement noise.

Bilateral filter on scattered points (Tomasi & Manduchi 1998, as the freeform method uses it):

    s'(u) = Σ_{p ∈ N(u)} W_c(|p − u|) W_s(|s(u) − s(p)|) s(p)  /  Σ_{p ∈ N(u)} W_c(|p − u|) W_s(|s(u) − s(p)|)
    W_c(d) = exp(−d² / 2σ_c²),  W_s(d) = exp(−d² / 2σ_s²),  N(u) = points within r = 2σ_c of u.

Smoothing spline with MATLAB csaps' parameter p ∈ [0, 1] (p = 0: least-squares straight line,
p = 1: interpolating natural cubic spline): it minimises p Σ (y_i − f(x_i))² + (1 − p) ∫ f''² dx.
On a grid the 1-D smoother (de Boor, "A Practical Guide to Splines", ch. XIV, the algorithm csaps
implements) is applied along each axis in turn. Scattered points get a thin-plate smoothing spline
with the same weighting: smoothing λ = (1 − p) / p (MATLAB tpaps' convention) through
:class:`scipy.interpolate.RBFInterpolator`.
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
    """Thin-plate smoothing spline (λ = (1 − p) / p) of scattered ``values`` at their points."""
    from scipy.interpolate import RBFInterpolator

    if not 0 < p <= 1:
        raise ValueError(f"p must be in (0, 1] for scattered points, got {p}")
    pts = np.asarray(points, dtype=float)
    v = np.asarray(values, dtype=float).ravel()
    if len(v) < 4:
        raise InputError(f"a thin-plate spline needs at least 4 points, got {len(v)}")
    neighbors = None if len(v) <= 3000 else 100
    f = RBFInterpolator(pts, v, kernel="thin_plate_spline", smoothing=(1 - p) / p, neighbors=neighbors)
    return f(pts)
