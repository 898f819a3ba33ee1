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
    meas: Measurements,
    *,
    frame: Frame | None = None,
    coords=None,
    progress=None,
    alpha: float = 0.05,
    **moran_options,
) -> Analysis:
    """Deviation statistics, Moran's I of the deviations over (u, v) (options of
    :func:`ncadapt.stats.moran`; ``progress(done, total)`` follows its all-pairs weights) and the
    offset test; the verdict at ``alpha`` (each test at α/2). ``coords`` (n, d) mm: the points'
    coordinates for Moran's I instead of the frame's (u, v) (a CAD face's own, :func:`face_coordinates`)."""
    meas.require(MIN_POINTS, "the analysis")
    xy = frame_of(meas, frame).uv(meas.nominal) if coords is None else np.asarray(coords, float)
    m = stats.moran(xy, meas.deviation, progress=progress, alpha=alpha / 2, **moran_options)
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
    coords=None,
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
    ``coords`` (n, 2) mm: the points' coordinates instead of the frame's (u, v) (a CAD face's own,
    :func:`face_coordinates`).
    """
    if method not in FILTERS:
        raise ValueError(f"filter must be one of {FILTERS}, got {method!r}")
    meas.require(MIN_POINTS, "the decomposition")
    xy = frame_of(meas, frame).uv(meas.nominal) if coords is None else np.asarray(coords, float)
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
    gain: float = 1.0  # the gain this round's systematic part was taken with (rounds)

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


def _linear_onto(xy, values, U, V) -> np.ndarray:
    """``values`` at scattered ``xy`` interpolated linearly at (U, V); NaN outside their hull."""
    from scipy.interpolate import LinearNDInterpolator

    grid = _on_grid(xy)
    if grid is not None:
        # a measured grid: bilinear on it (a triangulation of a regular grid is degenerate and slow:
        # 30 s for 100,000 points); both are linear between the measured values, equal at them
        from scipy.interpolate import RegularGridInterpolator

        xs, ys, flat = grid
        g = np.empty(len(xs) * len(ys))
        g[flat] = values
        return RegularGridInterpolator((xs, ys), g.reshape(len(xs), len(ys)), bounds_error=False, fill_value=np.nan)(
            np.stack([U, V], axis=-1)
        )
    return LinearNDInterpolator(xy, values)(U, V)


def compensate(
    surface: Surface,
    meas: Measurements,
    systematic,
    *,
    frame: Frame | None = None,
    border: str = BORDER,
    base=None,
    gain: float = 1.0,
) -> Compensation:
    """Carry the systematic part onto the surface grid, extrapolate it and mirror the surface.

    The surface's (u, v) must be the frame's (u, v) of the measured points (as
    :func:`fit_height_surface` makes it with the same frame). A later round
    (:mod:`ncadapt.processes.rounds`): dF = ``base``(u, v) + ``gain`` × the systematic part, ``base``
    the previous round's dF (a callable of the frame's (u, v) in mm, any shape, returning mm)."""
    sysv = np.asarray(systematic, float)
    frame = frame_of(meas, frame)
    xy = frame.uv(meas.nominal)
    U, V = np.meshgrid(surface.u, surface.v, indexing="ij")
    inside = _linear_onto(xy, sysv, U, V)
    known = np.isfinite(inside)
    if known.sum() < 16:
        raise InputError("the measured points cover fewer than 16 nodes of the surface grid", meas.source)
    df = extrapolate_border(surface.u, surface.v, np.where(known, inside, 0.0), known, mode=border)
    at_points = sysv
    if base is not None:
        df = base(U, V) + gain * df
        at_points = base(xy[:, 0], xy[:, 1]) + gain * sysv
    n = surface.normal(U, V)
    comp = surface.with_grid(surface.grid - df[..., None] * n)
    pc = meas.nominal - at_points[:, None] * meas.normal
    return Compensation(surface, df, known, comp, pc, frame, gain if base is not None else 1.0)


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


# ------------------------------------------------------------------------ a CAD part as nominal
# least share of a face's area (its grid nodes inside the trimmed face) that the measured points'
# hull must cover for the face to be compensated: beyond it dF is only carried (hold or cubic)
MIN_COVER = 0.25
# the B-spline rebuilt through the grid must reproduce P − dF·n at the grid cells' centres within
# this, mm (else the grid is refined, up to MAX_FACE_NODES a side)
REBUILD_TOL = 1e-4
# the compensated face in the part must lie −dF from the nominal face along its normal within
# this at the checked points, mm (the 1 µm)
CHECK_TOL = 1e-3
# nodes a side of a face's compensation grid: fewest and most
MIN_FACE_NODES, MAX_FACE_NODES = 8, 400
# points of each face at which the written part is checked against −dF
CHECK_POINTS = 400


def face_scale(face) -> tuple[float, float]:
    """Mean lengths |∂P/∂u|, |∂P/∂v| (mm per unit of u, v) over a face's (u, v) box (chords of a
    17 × 17 grid): the face's (u, v) times these are near millimetres along the surface — exactly
    for a plane or a cylinder, whose lengths are constant."""
    from .. import cad

    u0, u1, v0, v1 = cad.face_uv_bounds(face)
    U, V = np.meshgrid(np.linspace(u0, u1, 17), np.linspace(v0, v1, 17), indexing="ij")
    P = cad.face_evaluate(face, U, V)[0].reshape(17, 17, 3)
    lu = np.linalg.norm(np.diff(P, axis=0), axis=2).sum(axis=0).mean() / (u1 - u0)
    lv = np.linalg.norm(np.diff(P, axis=1), axis=2).sum(axis=1).mean() / (v1 - v0)
    return float(lu), float(lv)


@dataclass(frozen=True)
class FaceCompensation:
    """One face of a CAD part: its points' statistics and decomposition in its own (u, v) scaled
    to mm (``scale``, :func:`face_scale`), and the compensated surface over its whole (u, v) box.

    ``u``, ``v``: the grid axes in the face's parameters; ``df_grid`` (nu, nv) mm the systematic
    error there (inside the measured hull: interpolated linearly; outside: carried by ``border``);
    ``measured_region``, ``in_face`` (nu, nv) bool; ``compensated`` the B-spline surface through
    P − dF·n (the face's (u, v)); ``rebuild_error`` mm its largest distance from P − dF·n at the
    grid cells' centres, dF there the bicubic spline through ``df_grid`` (:meth:`df`).

    A face of a face set (``face_set``, :class:`FaceSet`): ``analysis`` is that of its points in the
    set's (u, v), ``decomposition`` the set's at its points, ``df_grid`` the set's field at the
    nodes, ``measured_region`` the nodes inside the set's measured hull; ``coords`` and ``scale``
    stay the face's own."""

    face: int
    points: np.ndarray  # indices of the face's measurements
    coords: np.ndarray  # (k, 2) mm: their (u, v) times ``scale``
    scale: tuple[float, float]
    analysis: Analysis
    decomposition: Decomposition
    u: np.ndarray
    v: np.ndarray
    df_grid: np.ndarray
    measured_region: np.ndarray
    in_face: np.ndarray
    normal: np.ndarray  # (nu, nv, 3) outward normals of the nominal face
    compensated: Surface
    rebuild_error: float
    border: str
    gain: float = 1.0  # rounds: this round's effective gain on the face's systematic part
    face_set: int | None = None  # the index of the face's set in ``PartCompensation.sets``, None on its own

    def df(self, u, v) -> np.ndarray:
        """dF (mm) at face parameters (u, v): the bicubic spline through ``df_grid``."""
        from scipy.interpolate import RectBivariateSpline

        return RectBivariateSpline(self.u, self.v, self.df_grid, kx=3, ky=3, s=0).ev(u, v)

    @property
    def border_strip(self) -> np.ndarray:
        """(nu, nv) bool: grid nodes on the face outside the measured hull (dF extrapolated there)."""
        return self.in_face & ~self.measured_region

    def as_dict(self) -> dict:
        strip = self.border_strip
        return {
            "face": self.face,
            "n_points": len(self.points),
            "scale": list(self.scale),
            **self.analysis.as_dict(),
            **self.decomposition.as_dict(),
            "grid": [len(self.u), len(self.v)],
            "cover": float((self.measured_region & self.in_face).sum() / self.in_face.sum()),
            "border": {
                "mode": self.border,
                "area_fraction": float(strip.sum() / self.in_face.sum()),
                "max_abs_df": float(np.abs(self.df_grid[strip]).max()) if strip.any() else 0.0,
            },
            "rebuild_error": self.rebuild_error,
        }


@dataclass(frozen=True)
class PartCompensation:
    """The compensated CAD part: ``part`` (an OpenCASCADE shape, valid by ``BRepCheck_Analyzer``)
    with each compensated face replacing the nominal one (``placed`` {face id: face in the part},
    every face);
    ``check_error`` mm: the largest |distance along the normal from the nominal face to the
    compensated one + dF| at ``check_points`` points of the faces; ``max_tolerance`` mm: the
    widest gap an edge of the sewn part covers (an unmoved neighbour's edge against a moved face's)."""

    faces: tuple[FaceCompensation, ...]
    part: object
    placed: dict
    summary: dict
    max_tolerance: float
    check_error: float
    check_points: int
    nominal_faces: dict  # {face id: the nominal face}
    sets: tuple[FaceSet, ...] = ()  # the face sets, decomposed each in one (u, v)

    @property
    def ids(self) -> list[int]:
        return [f.face for f in self.faces]

    def surfaces(self):
        """The compensated faces alone (one compound)."""
        from .. import cad

        return cad.compound([self.placed[i] for i in self.ids])

    def as_dict(self) -> dict:
        return {
            **self.summary,
            "valid": True,
            "max_tolerance": self.max_tolerance,
            "check": {"max_error": self.check_error, "points": self.check_points, "tolerance": CHECK_TOL},
        }

    def field(self, tool_radius: float = 0.0, outside: str = "error") -> FramedField:
        """The NC correction field −dF·n at the tool-tip positions of a ball-end tool of radius R
        (as :meth:`Compensation.field`) over the compensated faces' grid nodes on the faces, in the
        (u, v) of the frame their normals fit (:meth:`~ncadapt.surfaces.Frame.fit`: a part seen
        along one direction)."""
        from .. import cad

        pts, nrm, dfs = [], [], []
        for f in self.faces:
            k = f.in_face
            U, V = np.meshgrid(f.u, f.v, indexing="ij")
            p = cad.face_evaluate(self.nominal_faces[f.face], U[k], V[k])[0]
            pts.append(p)
            nrm.append(f.normal[k])
            dfs.append(f.df_grid[k])
        p, n, df = np.concatenate(pts), np.concatenate(nrm), np.concatenate(dfs)
        frame = Frame.fit(n, "the compensated faces")
        tip = p + tool_radius * n - tool_radius * np.array([0.0, 0.0, 1.0])
        return FramedField(
            frame, ScatteredField(frame.local(tip), -df[:, None] * n, outside=outside, source="compensation")
        )


def compensate_cad(
    proj,
    method: str = "bilateral",
    *,
    sigma_c: float | None = None,
    sigma_s: float | None = None,
    p: float | None = None,
    auto: bool = False,
    border: str = BORDER,
    alpha: float = 0.05,
    previous=None,
    gain: float = 1.0,
    **moran_options,
) -> PartCompensation:
    """Compensate the faces of a CAD part that the measured points fell on
    (:func:`ncadapt.measure.project_on_cad`), each in its own (u, v) or with its face set in the
    set's, and put them in the part.

    For each face on its own: the points' (u, v) scaled to mm (:func:`face_scale`) carry the
    analysis and the decomposition (:func:`analyze`, :func:`decompose`); the systematic part is
    interpolated onto a grid over the face's whole (u, v) box and carried beyond the measured hull
    by ``border`` (:func:`~ncadapt.surfaces.extrapolate_border`: dF is extrapolated, never the
    nominal, which is the face's own surface); the compensated face P_c = P − dF·n is a bicubic
    B-spline through the grid, bounded by the face's own trimming curves, and replaces the face in
    the part (:func:`ncadapt.cad.replace_faces`).

    For a face set (``proj.sets``): the points of all its faces are analysed and decomposed together
    in the (u, v) of the plane the set's normals fit (:func:`face_set_frame`; refused when the set
    is not a height field over it); each face's grid node P takes dF from the set's field at P's
    place in that plane (inside the set's measured hull: interpolated linearly; outside: carried by
    ``border`` over a grid of the plane), so dF is one function of the place across the set's common
    edges. Each face is then rebuilt and checked as a face on its own; its own entry
    (:class:`FaceCompensation`) holds the analysis of its points and the set's decomposition there.

    Refused (:class:`~ncadapt.InputError`, nothing made): a chosen face without points, a face with
    fewer than :data:`MIN_POINTS` points or whose points' hull (its set's, for a face in a set)
    covers less than :data:`MIN_COVER` of it, a face that cannot be rebuilt as one B-spline (a seam
    or a pole) or whose B-spline misses P − dF·n by more than :data:`REBUILD_TOL`, a part not valid
    after the replacement, or a compensated face off −dF by more than :data:`CHECK_TOL` in the part.

    A later round (:mod:`ncadapt.processes.rounds`): ``previous`` {face id: its previous dF, a
    callable of the face's (u, v) returning mm}; on each face dF = previous + ``gain`` × w × the
    systematic part, w the face's (or its set's) :func:`~ncadapt.processes.rounds.damping`.
    """
    from .. import cad

    meas = proj.measurements
    src = proj.nominal
    used = [int(f) for f in np.unique(proj.face)]
    if len(proj.chosen) < len(proj.faces):
        empty = [f for f in proj.chosen if f not in used]
        if empty:
            raise InputError(f"face {empty[0]}: no measured point is nearest to it", src)
    for fid in used:
        n = int((proj.face == fid).sum())
        if n < MIN_POINTS:
            raise InputError(
                f"face {fid}: {n} measured point(s) fell on it, the decomposition needs at least "
                f"{MIN_POINTS}; measure it or leave it out with --face",
                src,
            )
        why = cad.face_rebuild_problem(proj.faces[fid - 1])
        if why:
            raise InputError(f"face {fid} cannot be rebuilt as a compensated B-spline: {why}", src)
    split = dict(method=method, sigma_c=sigma_c, sigma_s=sigma_s, p=p, auto=auto, alpha=alpha, **moran_options)
    sets, fields = [], []
    for ids in proj.sets:
        frame, idx, xy = face_set_points(proj, ids)
        sub = _subset(meas, idx)
        a = analyze(sub, coords=xy, alpha=alpha, **moran_options)
        d = decompose(sub, coords=xy, **split)  # type: ignore[arg-type]
        g = 1.0
        if previous is not None:
            from .rounds import damping

            g = gain * damping(method, xy, d.systematic, d.parameters)
        fs = FaceSet(tuple(ids), frame, idx, xy, a, d, g)
        sets.append(fs)
        fields.append(_set_field(fs, [proj.faces[f - 1] for f in ids], border, src))
    out = []
    for fid in used:
        face = proj.faces[fid - 1]
        idx = np.flatnonzero(proj.face == fid)
        scale = face_scale(face)
        own = proj.uv[idx] * scale
        sub = _subset(meas, idx)
        k = proj.face_set_of(fid)
        if k is None:
            require_area(own, f"{meas.source} (face {fid})")
            a = analyze(sub, coords=own, alpha=alpha, **moran_options)
            d = decompose(sub, coords=own, **split)  # type: ignore[arg-type]
            field, h = _own_field(own, d.systematic, scale, border), spacing(own)
            g = 1.0
            if previous is not None:
                from .rounds import damping

                g = gain * damping(method, own, d.systematic, d.parameters)
        else:
            fs = sets[k]
            at = np.searchsorted(fs.points, idx)  # the face's points among the set's (both in order)
            xy = fs.coords[at]
            a = analyze(sub, coords=xy, alpha=alpha, **moran_options)
            d = _restricted(fs.decomposition, at, xy, alpha=alpha, **moran_options)  # type: ignore[arg-type]
            field, h, g = fields[k], spacing(fs.coords), fs.gain
        base = None
        if previous is not None:
            base = previous.get(fid) or (lambda U, V: np.zeros(np.shape(U)))
        out.append(_face_grid(fid, face, idx, scale, own, a, d, field, h, border, src, base, g, k))
    new = {f.face: cad.face_on_surface(proj.faces[f.face - 1], f.compensated) for f in out}
    before = cad.part_summary(proj.shape)
    tol = 2.0 * max(float(np.abs(f.df_grid).max()) for f in out) + 1e-3
    try:
        part, placed = cad.replace_faces(proj.shape, new, tol)
    except ValueError as e:
        raise InputError(f"the compensated faces could not be put in the part: {e}", src) from None
    after = cad.part_summary(part)
    if not cad.is_valid(part):
        raise InputError("the part is not valid after the faces were replaced (BRepCheck_Analyzer)", src)
    if (after["solids"], after["faces"]) != (before["solids"], before["faces"]) or (
        before["closed"] and not after["closed"]
    ):
        raise InputError(
            f"the part changed its topology when the faces were replaced ({before} before, {after} after)", src
        )
    worst, count = 0.0, 0
    for f in out:
        off, k = _check_face(f, proj.faces[f.face - 1], placed[f.face])
        if off > CHECK_TOL:
            raise InputError(
                f"face {f.face}: in the rebuilt part the compensated face is {off * 1000:.2f} µm off −dF (more "
                f"than {CHECK_TOL * 1000:g} µm)",
                src,
            )
        worst, count = max(worst, off), count + k
    nominal = {f.face: proj.faces[f.face - 1] for f in out}
    return PartCompensation(
        tuple(out), part, placed, after, cad.max_tolerance(part), worst, count, nominal, tuple(sets)
    )


def _subset(meas: Measurements, idx) -> Measurements:
    from dataclasses import replace

    return replace(
        meas,
        nominal=meas.nominal[idx],
        normal=meas.normal[idx],
        deviation=meas.deviation[idx],
        measured=None if meas.measured is None else meas.measured[idx],
        ids=None if meas.ids is None else tuple(meas.ids[i] for i in idx),
        lines=None if meas.lines is None else meas.lines[idx],
    )


def _restricted(d: Decomposition, at, xy, **moran_options) -> Decomposition:
    """A set's decomposition at some of its points (``at``), its random part checked over ``xy``."""
    r = d.random[at]
    return Decomposition(d.systematic[at], r, d.method, d.parameters, stats.noise(xy, r, **moran_options), d.auto)


def _own_field(xy, systematic, scale, border):
    """dF of a face on its own: (measured, carried) callables of its grid (see :func:`_face_grid`)."""

    def measured(U, V, P):  # noqa: ARG001 - the face's own (u, v) place the nodes
        return _linear_onto(xy, systematic, U * scale[0], V * scale[1])

    def carried(u, v, inside, known, P):  # noqa: ARG001
        return extrapolate_border(u, v, np.where(known, inside, 0.0), known, mode=border)

    return measured, carried


def _face_grid(
    fid, face, idx, scale, coords, a, d, field, h, border, src, base=None, gain=1.0, face_set=None
) -> FaceCompensation:
    """The compensation grid of one face, refined until its B-spline reproduces P − dF·n.

    ``field`` (measured, carried): ``measured(U, V, P)`` the systematic part at the grid nodes (face
    parameters U, V; points P (nu, nv, 3)), NaN outside the measured hull; ``carried(u, v, inside,
    known, P)`` dF over the whole grid, ``inside`` where ``known``. ``h`` mm: the points' spacing."""
    from scipy.interpolate import RectBivariateSpline

    from .. import cad

    measured, carried = field
    u0, u1, v0, v1 = cad.face_uv_bounds(face)
    nu, nv = (
        int(np.clip(round(span / h) + 1, MIN_FACE_NODES, MAX_FACE_NODES))
        for span in ((u1 - u0) * scale[0], (v1 - v0) * scale[1])
    )
    while True:
        u, v = np.linspace(u0, u1, nu), np.linspace(v0, v1, nv)
        U, V = np.meshgrid(u, v, indexing="ij")
        P, N, _ = cad.face_evaluate(face, U, V)
        P, N = P.reshape(nu, nv, 3), N.reshape(nu, nv, 3)
        if not np.isfinite(N).all():
            raise InputError(f"face {fid} has points without a normal (a singular point of its surface)", src)
        inside = measured(U, V, P)
        known = np.isfinite(inside)
        in_face = cad.face_inside(face, U, V, edges=True).reshape(nu, nv)
        cover = float((known & in_face).sum() / max(in_face.sum(), 1))
        if cover < MIN_COVER or known.sum() < 16:
            hull = "their hull in its (u, v)" if face_set is None else "the hull of its face set's points"
            raise InputError(
                f"face {fid}: the measured points cover {cover:.0%} of it ({hull}); at least "
                f"{MIN_COVER:.0%} is needed to compensate it",
                src,
            )
        df = carried(u, v, inside, known, P)
        if base is not None:
            df = base(U, V) + gain * df
        surf = Surface(u, v, P - df[..., None] * N)
        # the B-spline against P − dF·n at the cells' centres, dF the spline through the grid
        um, vm = np.meshgrid((u[1:] + u[:-1]) / 2, (v[1:] + v[:-1]) / 2, indexing="ij")
        pm, nm, _ = cad.face_evaluate(face, um, vm)
        dfm = RectBivariateSpline(u, v, df, kx=3, ky=3, s=0).ev(um.ravel(), vm.ravel())
        err = float(np.linalg.norm(surf.point(um.ravel(), vm.ravel()) - (pm - dfm[:, None] * nm), axis=1).max())
        if err <= REBUILD_TOL:
            break
        if max(nu, nv) >= MAX_FACE_NODES:
            raise InputError(
                f"face {fid} cannot be rebuilt faithfully: the B-spline through a {nu} x {nv} grid is "
                f"{err * 1000:.2f} µm off P − dF·n (more than {REBUILD_TOL * 1000:g} µm)",
                src,
            )
        nu, nv = min(2 * nu - 1, MAX_FACE_NODES), min(2 * nv - 1, MAX_FACE_NODES)
    return FaceCompensation(
        fid, idx, coords, scale, a, d, u, v, df, known, in_face, N, surf, err, border, gain, face_set
    )


# ------------------------------------------------------------------------ face sets
# a face of a set may turn its normal this far from the direction the set is seen along, deg: the
# set's plane then shortens lengths on it to no less than cos 45° ≈ 0.71 of theirs along the face (a
# filter's σ_c reaches at most √2 as far along the face as across the plane)
SET_MAX_TILT_DEG = 45.0
# cells a side of the grid each face of a set is sampled on (cell centres) for the set's viewing
# direction (the area-weighted mean normal) and the folding check
SET_SAMPLES = 24
# a line along the viewing direction through a sample of the set that crosses the set's faces again
# farther than this from the sample, mm, shows the set folding over its plane
FOLD_TOL = 1e-3
# most nodes of the grid over a set's plane that carries dF beyond the set's measured hull
MAX_SET_GRID_NODES = 1_000_000


@dataclass(frozen=True)
class FaceSet:
    """Faces of a CAD part analysed and decomposed together in one (u, v): that of the plane their
    normals fit (``frame``, :func:`face_set_frame`).

    ``faces`` their 1-based ids; ``points`` (k,) the indices of their measurements (in order);
    ``coords`` (k, 2) mm those points' (u, v) in ``frame`` (the nominal points projected on its
    plane); ``analysis`` and ``decomposition`` (None from :func:`analyze_face_sets`) over those
    coordinates; ``gain`` this round's effective gain on the set's systematic part (rounds)."""

    faces: tuple[int, ...]
    frame: Frame
    points: np.ndarray
    coords: np.ndarray
    analysis: Analysis
    decomposition: Decomposition | None = None
    gain: float = 1.0

    def as_dict(self) -> dict:
        d = {
            "faces": list(self.faces),
            "n_points": len(self.points),
            "frame": self.frame.axes.tolist(),
            **self.analysis.as_dict(),
        }
        if self.decomposition is not None:
            d |= self.decomposition.as_dict()
        return d


def _set_said(ids) -> str:
    return "face set " + ",".join(map(str, ids))


def face_set_frame(faces: dict, source: str | None = None) -> Frame:
    """The frame whose (u, v) a face set ({face id: face}) is decomposed in: w the area-weighted
    mean of the faces' outward normals (sampled at the centres of a :data:`SET_SAMPLES`² grid of each
    face's (u, v) box, inside the face), or the machine axis nearest to it within
    :data:`~ncadapt.surfaces.AXIS_SNAP_DEG` (:class:`~ncadapt.surfaces.Frame`).

    Refused (:class:`~ncadapt.InputError` naming the faces): the normals cancel out; a normal of a
    face more than :data:`SET_MAX_TILT_DEG` from w; the set folding over the plane — a line along
    w through a sample crosses the set's faces again more than :data:`FOLD_TOL` from it (two
    places of the set over one place of the plane)."""
    from .. import cad
    from ..surfaces import AXIS_SNAP_DEG

    said = _set_said(list(faces))
    pts, nrm, wts, owner = [], [], [], []
    for fid, face in faces.items():
        u0, u1, v0, v1 = cad.face_uv_bounds(face)
        u, v = np.linspace(u0, u1, SET_SAMPLES + 1), np.linspace(v0, v1, SET_SAMPLES + 1)
        C = cad.face_evaluate(face, *np.meshgrid(u, v, indexing="ij"))[0].reshape(len(u), len(v), 3)
        area = 0.5 * np.linalg.norm(np.cross(C[1:, 1:] - C[:-1, :-1], C[:-1, 1:] - C[1:, :-1]), axis=2)
        U, V = np.meshgrid((u[1:] + u[:-1]) / 2, (v[1:] + v[:-1]) / 2, indexing="ij")
        P, N, _ = cad.face_evaluate(face, U, V)
        keep = cad.face_inside(face, U, V) & np.isfinite(N).all(axis=1)
        pts.append(P[keep])
        nrm.append(N[keep])
        wts.append(area.ravel()[keep])
        owner.append(np.full(int(keep.sum()), fid))
    p, n, w8, who = np.concatenate(pts), np.concatenate(nrm), np.concatenate(wts), np.concatenate(owner)
    m = (w8[:, None] * n).sum(axis=0)
    if np.linalg.norm(m) < 1e-9 * max(float(w8.sum()), 1e-12):
        raise InputError(f"{said}: the faces' normals cancel out: the set is not a height field over one plane", source)
    m /= np.linalg.norm(m)
    k = int(np.argmax(np.abs(m)))
    w = m if abs(m[k]) < np.cos(np.radians(AXIS_SNAP_DEG)) else np.sign(m[k]) * np.eye(3)[k]
    tilt = np.degrees(np.arccos(np.clip(n @ w, -1.0, 1.0)))
    if tilt.max() > SET_MAX_TILT_DEG:
        steep = [int(f) for f in faces if (who == f).any() and tilt[who == f].max() > SET_MAX_TILT_DEG]
        worst = int(who[int(np.argmax(tilt))])
        turn = (
            f"face {worst} turn up to {tilt.max():.0f}°"
            if len(steep) == 1
            else f"faces {','.join(map(str, steep))} turn up to {tilt.max():.0f}° (face {worst})"
        )
        raise InputError(
            f"{said}: the normals of {turn} from the direction the set is seen along "
            f"({w[0]:+.3f}, {w[1]:+.3f}, {w[2]:+.3f}), more than {SET_MAX_TILT_DEG:g}°: the set is not a height "
            "field over one plane; decompose its faces in their own (u, v) (leave the steep ones out of the set)",
            source,
        )
    reach = 2.0 * float(np.ptp(p, axis=0).max()) + 1.0
    hits = cad.line_crossings(cad.compound(list(faces.values())), p, w, reach)
    for j, t in enumerate(hits):
        far = t[np.abs(t) > FOLD_TOL]
        if len(far):
            q = p[j] + far[0] * w
            other = min(faces, key=lambda f: float(cad.face_parameters(faces[f], q[None])[1][0]))
            raise InputError(
                f"{said} folds over its plane: the line along the direction it is seen along "
                f"({w[0]:+.3f}, {w[1]:+.3f}, {w[2]:+.3f}) through ({p[j][0]:.3f}, {p[j][1]:.3f}, {p[j][2]:.3f}) on "
                f"face {who[j]} crosses face {other} again {abs(far[0]):.4g} mm away: the set is not a height field "
                "over one plane; split it",
                source,
            )
    return Frame.along(w)


def face_set_points(proj, ids) -> tuple[Frame, np.ndarray, np.ndarray]:
    """(frame, indices (k,), coordinates (k, 2) mm): the frame of a face set of ``proj`` (a
    :class:`~ncadapt.measure.CadProjection`; :func:`face_set_frame`), the indices of the
    measurements on its faces and their nominal points' (u, v) in it. Refused: a face of the set
    that no point fell on; the points along one line (:func:`require_area`)."""
    src = proj.nominal
    for f in ids:
        if not (proj.face == f).any():
            raise InputError(f"{_set_said(ids)}: no measured point fell on face {f}", src)
    frame = face_set_frame({f: proj.faces[f - 1] for f in ids}, src)
    idx = np.flatnonzero(np.isin(proj.face, ids))
    xy = frame.uv(proj.measurements.nominal[idx])
    require_area(xy, f"{proj.measurements.source} ({_set_said(ids)})")
    return frame, idx, xy


def analyze_face_sets(proj, *, alpha: float = 0.05, **moran_options) -> list[FaceSet]:
    """The gate (:func:`analyze`) over each face set of ``proj`` (``proj.sets``) in the set's
    (u, v) (:func:`face_set_points`)."""
    out = []
    for ids in proj.sets:
        frame, idx, xy = face_set_points(proj, ids)
        a = analyze(_subset(proj.measurements, idx), coords=xy, alpha=alpha, **moran_options)
        out.append(FaceSet(tuple(ids), frame, idx, xy, a))
    return out


def _set_field(fs: FaceSet, faces, border: str, src):
    """dF of a face set over its faces: (measured, carried) callables of a face's grid (see
    :func:`_face_grid`), both functions of a node's place P in the set's plane. Beyond the set's
    measured hull the systematic part is carried by ``border`` over a grid of the plane covering
    the faces' (u, v) boxes, at the points' spacing (coarser if it would exceed
    :data:`MAX_SET_GRID_NODES`), and read bilinearly from it."""
    from scipy.interpolate import RegularGridInterpolator

    from .. import cad

    frame, xy, s = fs.frame, fs.coords, fs.decomposition.systematic  # type: ignore[union-attr]
    box = []
    for face in faces:
        u0, u1, v0, v1 = cad.face_uv_bounds(face)
        U, V = np.meshgrid(np.linspace(u0, u1, 33), np.linspace(v0, v1, 33), indexing="ij")
        box.append(frame.uv(cad.face_evaluate(face, U, V)[0]))
    q = np.concatenate([*box, xy])
    lo, hi = q.min(axis=0), q.max(axis=0)
    step = max(spacing(xy), float(np.sqrt(np.prod(hi - lo) / MAX_SET_GRID_NODES)))
    gu, gv = (np.linspace(a, b, max(4, int(np.ceil((b - a) / step)) + 1)) for a, b in zip(lo, hi))
    GU, GV = np.meshgrid(gu, gv, indexing="ij")
    inside = _linear_onto(xy, s, GU, GV)
    known = np.isfinite(inside)
    if known.sum() < 16:
        raise InputError(
            f"{_set_said(fs.faces)}: its measured points cover fewer than 16 nodes of its plane's grid", src
        )
    carry = RegularGridInterpolator(
        (gu, gv), extrapolate_border(gu, gv, np.where(known, inside, 0.0), known, mode=border)
    )

    def measured(U, V, P):  # noqa: ARG001 - the node's place P in the set's plane places it
        c = frame.uv(P.reshape(-1, 3))
        return _linear_onto(xy, s, c[:, 0], c[:, 1]).reshape(np.shape(U))

    def carried(u, v, inside, known, P):  # noqa: ARG001
        c = np.clip(frame.uv(P.reshape(-1, 3)), lo, hi)
        return np.where(known, inside, carry(c).reshape(known.shape))

    return measured, carried


def _check_face(f: FaceCompensation, nominal_face, placed) -> tuple[float, int]:
    """The largest |distance from the nominal face to the compensated face in the part, along the
    nominal normal, + dF| at up to :data:`CHECK_POINTS` points of the face (grid cells' centres)."""
    from .. import cad

    um, vm = np.meshgrid((f.u[1:] + f.u[:-1]) / 2, (f.v[1:] + f.v[:-1]) / 2, indexing="ij")
    um, vm = um.ravel(), vm.ravel()
    keep = cad.face_inside(nominal_face, um, vm)
    um, vm = um[keep], vm[keep]
    step = max(1, len(um) // CHECK_POINTS)
    um, vm = um[::step], vm[::step]
    p, n, _ = cad.face_evaluate(nominal_face, um, vm)
    along, _ = cad.signed_distances(placed, p, n)
    return float(np.abs(along + f.df(um, vm)).max()), len(um)


def part_decomposition(pc: PartCompensation, meas: Measurements, **moran_options) -> Decomposition:
    """The faces' decompositions as one over all the points (in the measurements' order): its
    random part checked over the points' 3-D positions; ``parameters`` those of the face when
    there is one, else the filter and ``by_face`` (see each face's own)."""
    s = np.zeros(len(meas))
    for f in pc.faces:
        s[f.points] = f.decomposition.systematic
    r = meas.deviation - s
    first = pc.faces[0].decomposition
    params = dict(first.parameters) if len(pc.faces) == 1 else {"auto": first.parameters.get("auto", False)}
    nz = stats.noise(meas.nominal, r, **moran_options)
    auto = first.auto if len(pc.faces) == 1 else None
    if len(pc.faces) > 1 and first.auto is not None:
        auto = {"passed": all(f.decomposition.auto["passed"] for f in pc.faces), "setting": "by_face"}  # type: ignore[index]
    return Decomposition(s, r, first.method, params, nz, auto)


def part_moved(pc: PartCompensation, n: int) -> np.ndarray:
    """(n,) mm: what this round's correction removes at each measured point — its face's effective
    gain times the systematic part there (the systematic part itself in a first round); the
    deviation predicted after the correction is the measured one minus this."""
    out = np.zeros(n)
    for f in pc.faces:
        out[f.points] = f.gain * f.decomposition.systematic
    return out


def face_layout(pc: PartCompensation, n: int, gap: float = 5.0) -> np.ndarray:
    """(n, 2) mm: each point's face (u, v) scaled to mm (``coords``), the faces side by side
    along u, ``gap`` mm apart (for plots)."""
    out = np.zeros((n, 2))
    shift = 0.0
    for f in pc.faces:
        xy = f.coords - [f.coords[:, 0].min() - shift, 0.0]
        out[f.points] = xy
        shift = float(xy[:, 0].max()) + gap
    return out
