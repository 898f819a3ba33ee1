"""Freeform surfaces: compensation from coordinate measurements (V. A. Pechenin, "Technique of
compensating errors in machining of parts with sculptured surfaces", Vestnik of Samara University
15(4), 2016, DOI 10.18287/2541-7533-2016-15-4-252-264).

measure → :func:`analyze` (deviations; Moran's I and the offset test: is it systematic?) → :func:`decompose`
(bilateral filter or smoothing spline: systematic + random, noise diagnostics) → :func:`compensate`
(the systematic part on the part's surface grid, carried into the unmeasured border;
the mirrored surface P_c = P − dF·n; a correction field −dF·n for the NC program).

The part is a height field over some plane: :class:`~ncadapt.surfaces.Frame` puts w along the
measured normals (the nearest machine axis when every normal is within 80° of it, else their mean)
and a measured point is placed by its nominal (u, v) across w — (x, y) for a part seen from +z,
(y, z) for a wall seen from +x. Moran's I, the filters and the surface grid all work in (u, v). Ball-end programs: the tool tip at a contact point P with normal
n is at P + R n − R ẑ, so the NC field is given at those tip positions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .. import filters, stats
from ..errors import InputError
from ..fields import ScatteredField
from ..measure import Measurements
from ..surfaces import Frame, Surface, extrapolate_border

FILTERS = ("bilateral", "spline")
# fewest points each step needs
MIN_POINTS = 10
# how the systematic error is carried into the unmeasured border of the surface grid: "hold" (the
# nearest measured value) or "cubic" (the paper's cubic extrapolation). On the testbed (2 error
# models x 3 seeds, the 5 mm unmeasured border) "hold" leaves 7.5 µm RMS there on average (7.4-7.8),
# "cubic" 7.9 µm (7.5-8.6); inside, both 2.2 µm (docs/freeform.md)
BORDERS = ("hold", "cubic")
BORDER = "hold"
# most nodes of the surface grid (its arrays, normals and field: some 0.5 GB at this size)
MAX_GRID_NODES = 4_000_000


@dataclass(frozen=True)
class Analysis:
    """The gate: Moran's I (a spatial pattern) and the offset test (a uniform part), each at α/2,
    and their verdict."""

    n_points: int
    moran: stats.Moran
    deviation: dict
    offset: stats.Offset
    verdict: stats.Verdict

    @property
    def systematic(self) -> bool:
        return self.verdict.systematic

    def as_dict(self) -> dict:
        return {
            "n_points": self.n_points,
            "moran": self.moran.as_dict(),
            "deviation": self.deviation,
            "offset": self.offset.as_dict(),
            "verdict": self.verdict.as_dict(),
        }


def spacing(points) -> float:
    """Median distance from a point to its nearest neighbour (in x, y)."""
    p = np.asarray(points, float)[:, :2]
    d, _ = cKDTree(p).query(p, k=2)
    return float(np.median(d[:, 1]))


def noise_level(points, values) -> float:
    """A robust estimate of the noise std: the median absolute difference between nearest
    neighbours, / (0.6745 √2) (it is the noise of a difference of two independent readings)."""
    p = np.asarray(points, float)[:, :2]
    _, j = cKDTree(p).query(p, k=2)
    d = np.asarray(values)[j[:, 1]] - np.asarray(values)
    return float(np.median(np.abs(d)) / (0.6745 * np.sqrt(2)))


def require_area(uv, source: str | None = None) -> float:
    """Refuse points in (u, v) that lie along one line (a single scan line, a row of points): a
    surface, a triangulation or a thin-plate spline over them is undetermined across the line.
    Returns their :func:`spacing`, which the check measures against."""
    q = np.asarray(uv, float)[:, :2]
    c = q - q.mean(axis=0)
    across = np.linalg.svd(c, full_matrices=False)[2][-1]
    width = float(np.abs(c @ across).max()) if len(q) else 0.0
    h = spacing(q)
    if width < 0.5 * h:
        raise InputError(
            f"the {len(q)} measured points lie along one line (all within half their spacing of it): "
            "a surface needs points over an area",
            source,
        )
    return h


def frame_of(meas: Measurements, frame: Frame | None = None) -> Frame:
    """``frame``, or the one :meth:`Frame.fit` chooses from the measured normals."""
    return frame if frame is not None else Frame.fit(meas.normal, meas.source)


def analyze(
    meas: Measurements, *, frame: Frame | None = None, progress=None, alpha: float = 0.05, **moran_options
) -> Analysis:
    """Deviation statistics, Moran's I of the deviations over (u, v) (options of
    :func:`ncadapt.stats.moran`; ``progress(done, total)`` follows its all-pairs weights) and the
    offset test; the verdict at ``alpha`` (each test at α/2)."""
    meas.require(MIN_POINTS, "the analysis")
    m = stats.moran(
        frame_of(meas, frame).uv(meas.nominal), meas.deviation, progress=progress, alpha=alpha / 2, **moran_options
    )
    o = stats.offset(meas.deviation)
    return Analysis(len(meas), m, stats.summary(meas.deviation), o, stats.verdict(m, o, alpha))


@dataclass(frozen=True)
class Decomposition:
    """Systematic + random parts; ``noise`` checks the random part (``noise.passed``: no systematic
    error left); ``auto`` ({"passed", "setting"}) when the setting was searched (``auto=True``)."""

    systematic: np.ndarray
    random: np.ndarray
    method: str
    parameters: dict
    noise: stats.Noise
    auto: dict | None = None

    def as_dict(self) -> dict:
        d = {
            "method": self.method,
            "parameters": self.parameters,
            "systematic": {
                "rms": float(np.sqrt((self.systematic**2).mean())),
                "max_abs": float(np.abs(self.systematic).max()),
            },
            "random": {
                "std": self.noise.std,
                "pearson_p": self.noise.pearson_p,
                "student_p": self.noise.student_p,
                "moran_z": self.noise.moran_z,
                "moran_p": self.noise.moran_p,
                "passed": self.noise.passed,
            },
        }
        if self.auto is not None:
            d["auto"] = self.auto
        return d


def _on_grid(points):
    """(xs, ys, order) when the points form a full rectangular grid, else None."""
    x = np.round(points[:, 0], 6)
    y = np.round(points[:, 1], 6)
    xs, ys = np.unique(x), np.unique(y)
    if len(xs) * len(ys) != len(points) or len(xs) < 4 or len(ys) < 4:
        return None
    ix = np.searchsorted(xs, x)
    iy = np.searchsorted(ys, y)
    flat = ix * len(ys) + iy
    if len(np.unique(flat)) != len(points):
        return None
    return xs, ys, flat


def _filter(method, xy, e, par):
    if method == "bilateral":
        return filters.bilateral(xy, e, par["sigma_c"], par["sigma_s"])
    grid = _on_grid(xy)
    if grid is not None:
        xs, ys, flat = grid
        g = np.empty(len(xs) * len(ys))
        g[flat] = e
        return filters.smoothing_spline_grid((xs, ys), g.reshape(len(xs), len(ys)), par["p"]).ravel()[flat]
    return filters.smoothing_spline(xy, e, par["p"])


def decompose(
    meas: Measurements,
    method: str = "bilateral",
    *,
    sigma_c: float | None = None,
    sigma_s: float | None = None,
    p: float | None = None,
    auto: bool = False,
    frame: Frame | None = None,
    **moran_options,
) -> Decomposition:
    """Split the deviations into a systematic part and random noise.

    ``bilateral``: σ_c defaults to 1.5 × the point spacing, σ_s to 3 × the estimated noise std.
    ``spline``: p defaults to csaps' automatic choice for sites h apart, 1 / (1 + h³ / 9)
    (:func:`ncadapt.filters.csaps_auto_p`), h the spacing of a square grid of the points' density
    (:func:`ncadapt.filters.effective_spacing`: a grid's own spacing; 0.3655 on a 2.5 mm grid).
    ``auto``: the smoothest setting (largest σ_c, or smallest p) of a ladder whose random part
    passes the residual check (:attr:`ncadapt.stats.Noise.passed`: no significantly positive
    Moran's I or lag-1 correlation left, one-sided, at the analysis' ``alpha``). When no setting
    passes, the default setting is used and ``auto["passed"]`` is False: the caller must say so.
    """
    if method not in FILTERS:
        raise ValueError(f"filter must be one of {FILTERS}, got {method!r}")
    meas.require(MIN_POINTS, "the decomposition")
    xy = frame_of(meas, frame).uv(meas.nominal)
    if method == "spline":
        require_area(xy, meas.source)
    e = meas.deviation
    h = spacing(xy)
    sig = max(noise_level(xy, e), 1e-6)
    if method == "bilateral":
        base = {"sigma_c": sigma_c or 1.5 * h, "sigma_s": sigma_s or 3 * sig}
        ladder = [dict(base, sigma_c=h * f) for f in (4.0, 3.0, 2.5, 2.0, 1.5, 1.0, 0.75)] if auto else [base]
    else:
        p0 = p if p is not None else filters.csaps_auto_p(filters.effective_spacing(xy))
        ladder = [{"p": q} for q in (1e-4, 1e-3, 1e-2, 0.05, 0.1, 0.3, 0.6, 0.9)] if auto else [{"p": p0}]

    def split(par):
        s = _filter(method, xy, e, par)
        r = e - s
        if np.ptp(r) == 0:
            raise InputError(
                f"the {method} filter with {', '.join(f'{k} {v:g}' for k, v in par.items())} keeps every "
                "deviation as systematic (nothing is left as noise); smooth more",
                meas.source,
            )
        return s, r, par, stats.noise(xy, r, **moran_options)

    chosen = next((c for c in map(split, ladder) if c[3].passed), None) if auto else split(ladder[0])
    found = chosen is not None
    if not found:  # no rung passes: the default setting, flagged
        chosen = split(base if method == "bilateral" else {"p": p0})
    assert chosen is not None
    s, r, par, nz = chosen
    params = {k: float(v) for k, v in par.items()}
    return Decomposition(
        s,
        r,
        method,
        params | {"auto": auto, "noise_estimate": sig},
        nz,
        {"passed": found, "setting": params} if auto else None,
    )


@dataclass(frozen=True)
class Compensation:
    """The systematic error on the part's surface grid and what is made from it."""

    surface: Surface
    df_grid: np.ndarray  # (nu, nv) mm, extrapolated into the border
    measured_region: np.ndarray  # (nu, nv) bool: inside the measured area
    compensated: Surface  # P_c = P − dF n
    points_compensated: np.ndarray  # (n, 3) the measured points' nominals moved by −dF n
    frame: Frame  # the (u, v) of the surface grid

    def field(self, tool_radius: float = 0.0, outside: str = "error") -> FramedField:
        """The NC correction field: −dF·n at the tool-tip positions of a ball-end tool of radius R
        (its axis along z), interpolated over the frame's (u, v): the tips of a wall seen from +x
        are spread over (y, z). ``outside`` (error|clamp|extrapolate): tool positions beyond the
        surface grid — the measured area, or ``--extent``."""
        s = self.surface
        U, V = np.meshgrid(s.u, s.v, indexing="ij")
        p = s.point(U, V).reshape(-1, 3)
        n = s.normal(U, V).reshape(-1, 3)
        tip = p + tool_radius * n - tool_radius * np.array([0.0, 0.0, 1.0])
        return FramedField(
            self.frame,
            ScatteredField(
                self.frame.local(tip), -self.df_grid.reshape(-1, 1) * n, outside=outside, source="compensation"
            ),
        )


class FramedField:
    """A field over a frame's (u, v): world points are put in frame coordinates (u, v, w) before
    ``inner`` (a field over their first two) is evaluated; displacements stay in world axes."""

    def __init__(self, frame: Frame, inner: ScatteredField):
        self.frame, self.inner = frame, inner
        self.outside = inner.outside
        # the world (x, y) box the clearance check of `correct` uses: only for a part seen along z
        self.bounds = inner.bounds if np.allclose(np.abs(frame.axes[2]), [0, 0, 1]) else None

    def __call__(self, points) -> np.ndarray:
        return self.inner(self.frame.local(np.asarray(points, float)))

    def __repr__(self):
        return f"FramedField({self.frame.names}, {self.inner!r})"


def compensate(
    surface: Surface, meas: Measurements, systematic, *, frame: Frame | None = None, border: str = BORDER
) -> Compensation:
    """Carry the systematic part onto the surface grid, extrapolate it and mirror the surface.

    The surface's (u, v) must be the frame's (u, v) of the measured points (as
    :func:`fit_height_surface` makes it with the same frame)."""
    from scipy.interpolate import LinearNDInterpolator

    sysv = np.asarray(systematic, float)
    frame = frame_of(meas, frame)
    xy = frame.uv(meas.nominal)
    U, V = np.meshgrid(surface.u, surface.v, indexing="ij")
    grid = _on_grid(xy)
    if grid is not None:
        # a measured grid: bilinear on it (a triangulation of a regular grid is degenerate and slow:
        # 30 s for 100,000 points); both are linear between the measured values, equal at them
        from scipy.interpolate import RegularGridInterpolator

        xs, ys, flat = grid
        g = np.empty(len(xs) * len(ys))
        g[flat] = sysv
        inside = RegularGridInterpolator((xs, ys), g.reshape(len(xs), len(ys)), bounds_error=False, fill_value=np.nan)(
            np.stack([U, V], axis=-1)
        )
    else:
        inside = LinearNDInterpolator(xy, sysv)(U, V)
    known = np.isfinite(inside)
    if known.sum() < 16:
        raise InputError("the measured points cover fewer than 16 nodes of the surface grid", meas.source)
    df = extrapolate_border(surface.u, surface.v, np.where(known, inside, 0.0), known, mode=border)
    n = surface.normal(U, V)
    comp = surface.with_grid(surface.grid - df[..., None] * n)
    pc = meas.nominal - sysv[:, None] * meas.normal
    return Compensation(surface, df, known, comp, pc, frame)


@dataclass(frozen=True)
class Extrapolation:
    """Where a surface fitted through the measured nominal points reaches beyond them: there its
    nominal is invented (extrapolated), not measured."""

    max_distance: float  # mm in (u, v): the farthest surface-grid node from the points' convex hull
    area_fraction: float  # the share of the grid's nodes outside the hull
    outside: np.ndarray  # (nu, nv) bool
    u: np.ndarray  # the grid's axes, mm
    v: np.ndarray

    def as_dict(self) -> dict:
        return {"max_distance": self.max_distance, "area_fraction": self.area_fraction}


def nominal_extrapolation(surface: Surface, points, frame: Frame | None = None) -> Extrapolation:
    """How far the surface grid reaches beyond the convex hull of ``points`` in (u, v)."""
    from scipy.spatial import ConvexHull

    frame = frame or Frame(np.eye(3))
    uv = frame.uv(points)
    hull = ConvexHull(uv)
    U, V = np.meshgrid(surface.u, surface.v, indexing="ij")
    q = np.column_stack([U.ravel(), V.ravel()])
    # outside a half-plane of the hull by more than rounding (nodes on its edges are measured area)
    tol = 1e-9 * max(1.0, float(np.abs(uv).max()))
    out = ((q @ hull.equations[:, :2].T + hull.equations[:, 2]) > tol).any(axis=1)
    dist = 0.0
    if out.any():
        a, b = uv[hull.simplices[:, 0]], uv[hull.simplices[:, 1]]  # the hull's edges
        ab = b - a
        for chunk in np.array_split(q[out], max(1, int(out.sum()) // 4096 + 1)):
            t = np.clip(np.einsum("pej,ej->pe", chunk[:, None, :] - a[None], ab) / np.einsum("ej,ej->e", ab, ab), 0, 1)
            d = np.linalg.norm(chunk[:, None, :] - (a[None] + t[..., None] * ab[None]), axis=2).min(axis=1)
            dist = max(dist, float(d.max()))
    return Extrapolation(dist, float(out.mean()), out.reshape(U.shape), surface.u, surface.v)


def fit_height_surface(points, extent=None, step: float | None = None, frame: Frame | None = None) -> Surface:
    """A surface w(u, v) through nominal points, parametrised by the frame's (u, v) (default
    (x, y)); a full grid is interpolated as it is, scattered points through a cubic triangulation,
    the border beyond them extrapolated. ``extent`` (u0, u1, v0, v1) widens it to the part's edges."""
    frame = frame or Frame(np.eye(3))
    q = np.asarray(points, float)
    p = np.column_stack([frame.uv(q), frame.w(q)])
    grid = _on_grid(p)
    if grid is not None and extent is None:
        xs, ys, flat = grid
        z = np.empty(len(xs) * len(ys))
        z[flat] = p[:, 2]
        Z = z.reshape(len(xs), len(ys))
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        return Surface(xs, ys, frame.to_world(X, Y, Z))
    from scipy.interpolate import CloughTocher2DInterpolator

    measured_spacing = require_area(p)  # refuses a single scan line whatever the step
    h = step or measured_spacing
    x0, x1, y0, y1 = extent or (p[:, 0].min(), p[:, 0].max(), p[:, 1].min(), p[:, 1].max())
    what = "the extent" if extent else "the measured area"
    area = f"{what} u {x0:g} … {x1:g}, v {y0:g} … {y1:g} mm"
    if min(x1 - x0, y1 - y0) < h:
        raise InputError(f"{area} is narrower than the point spacing {h:.4g} mm: no surface to fit")
    nu, nv = (max(4, int(round(span / h)) + 1) for span in (x1 - x0, y1 - y0))
    if nu * nv > MAX_GRID_NODES:
        raise InputError(
            f"{area} at the point spacing {h:.4g} mm needs a surface grid of {nu:,} x {nv:,} nodes, "
            f"more than {MAX_GRID_NODES:,}; "
            + ("give a smaller extent" if extent else "check the coordinates or give the part's extent")
        )
    xs = np.linspace(x0, x1, nu)
    ys = np.linspace(y0, y1, nv)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    zi = CloughTocher2DInterpolator(p[:, :2], p[:, 2])(X, Y)
    known = np.isfinite(zi)
    if known.sum() < 16:
        raise InputError(
            f"the measured points cover {known.sum()} nodes of the surface grid over {area}, fewer "
            "than 16: the extent must overlap the measured area"
        )
    Z = extrapolate_border(xs, ys, np.where(known, zi, 0.0), known)
    return Surface(xs, ys, frame.to_world(X, Y, Z))
