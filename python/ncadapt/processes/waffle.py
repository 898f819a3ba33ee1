"""Waffle (grid-stiffened) shells milled on tracking machines (Pas, Serkov, "Investigation of the
possibilities of improving the accuracy of waffle-grid machining by software correction",
Siberian Aerospace Journal 23(2), 2022, DOI 10.31772/2712-8970-2022-23-2-321-336).

The shell turns on a rotary table (B, degrees); a copying head tracks the back wall with a sensor
(V, mm) coaxial with the cutter and the CNC moves the tool along the spindle axis (the depth axis,
Y here) so the web left at the bottom of each cell keeps its thickness.

Conventions: the depth axis points into the material (a larger Y cuts deeper, leaves a thinner
web), as in the paper's Y_c = Y_p + K_fb with K_fb = T_pf − T_ref − b; thickness errors are
T − T_ref (positive: too thick).

Spindle tilt (section 1)
------------------------
On a tracking pre-measurement [B, Z, V] the rows are cut into segments of N consecutive points —
from the first row, restarting whenever Z changes (a segment never mixes two passes) — and a
segment's last piece shorter than N/2 joins the previous segment. Each segment is fitted by least
squares V = k·B + t (the paper's closed forms for k and t). The wall's slope under the tool face
is tan α = (360/(πD))·k (k in mm per degree, πD/360 mm of arc per degree), and the paper's error is
E = R·tan α, reported signed.

The sign, derived: the cutter's face is flat and perpendicular to the spindle; the tracking keeps
the face at the planned distance from the back wall at the axis point A₀, so over the face the
distance to an inclined wall varies by ±R·tan α from rim A₁ to rim A₂. As the face sweeps along B,
every point of the web is cut by the whole face and the floor ends where the face came deepest:
the web is left thinner by R·|tan α| whichever way the wall leans (the sign of tan α says which rim,
A₁ or A₂, forms the floor — the paper's |E|). So the web-thickness error of the tilt is −R·|tan α|,
and the disturbance corrector withdraws the tool by that much: K_dist = −R·|tan α| (depth axis into
the material).

Backlash of the copying system (section 3)
------------------------------------------
The chain surface → stylus → transducer → tracking drive has an elastic gap: a play (backlash)
operator of width g, y_k = min(max(y_k−1, x_k − g/2), x_k + g/2), followed by a first-order drive
w_k = w_k−1 + (1 − e^(−Δt/τ))(y_k − w_k−1). In a one-way motion the play only delays the signal by
a constant g/2; at a reversal the output stays flat while the input crosses the gap — the
"shelf" of the paper's figures. :func:`estimate_backlash` fits g (and τ) by least squares to a pair
of signals: the ideal V (from the one-way pre-measurement) and V recorded while machining a zig-zag
cell. The web error the gap leaves is V_ideal − w (:func:`copying_error`); known g and τ predict it
along a planned path from the pre-measured wall, so the disturbance corrector can take it out too
(the paper found it hard to compensate by disturbance correction without such a model).

Combined self-tuning correction (section 4)
-------------------------------------------
K_fb = T_pf − T_ref − b from the smoothed thickness map of a semi-finishing pass with allowance b;
later cells reuse K_fb while every finished thickness stays inside (T_th,min, T_th,max); when a
cell's max ≥ T_th,max **or** min ≤ T_th,min (the paper prints "and", which would never retune on a
one-sided drift), the next cell gets a semi-finishing pass and K_fb is recomputed. The combined
correction is Y_c = Y_p + K_fb + K_dist; in it the semi-finishing pass already carries K_dist, so
K_fb measures what the disturbance corrector left (otherwise the tilt would be corrected twice).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = [
    "segments",
    "fit_segments",
    "Tilt",
    "tilt",
    "read_tracking",
    "read_thickness",
    "DepthField",
    "Sum",
    "feedback_correction",
    "play",
    "drive",
    "copy",
    "copying_error",
    "estimate_backlash",
    "Backlash",
    "SelfTuning",
    "reversal_travels",
    "CellState",
    "plan_cells",
    "Z_TOL",
]


# ------------------------------------------------------------------------------ spindle tilt
#: default tolerance on Z within one pass, mm: rows whose Z differs from the previous row's by
#: no more than this belong to the same pass (encoder jitter of a few tenths of a µm; passes of a
#: pre-measurement are millimetres apart)
Z_TOL = 0.01


def segments(z, n: int, z_tol: float = Z_TOL) -> list[tuple[int, int]]:
    """Index ranges [start, end) of the segments: N consecutive rows from the first, restarting
    where Z changes by more than ``z_tol`` (mm) from one row to the next (a new pass); a last piece
    shorter than N/2 joins the previous segment of its pass."""
    if n < 2:
        raise ValueError(f"a segment needs at least 2 points, got N = {n}")
    if not (math.isfinite(z_tol) and z_tol >= 0):
        raise ValueError(f"z_tol must be a finite number ≥ 0 mm, got {z_tol}")
    z = np.asarray(z, float)
    out: list[tuple[int, int]] = []
    breaks = np.flatnonzero(np.abs(np.diff(z)) > z_tol) + 1
    for a, b in zip(np.r_[0, breaks], np.r_[breaks, len(z)]):
        pass_segs = [(s, min(s + n, b)) for s in range(a, b, n)]
        if len(pass_segs) > 1 and pass_segs[-1][1] - pass_segs[-1][0] < n / 2:
            last = pass_segs.pop()
            pass_segs[-1] = (pass_segs[-1][0], last[1])
        out += pass_segs
    return out


def fit_segments(b, v, segs) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares V = k·B + t on each segment (the paper's closed forms); (k, t) per segment."""
    b, v = np.asarray(b, float), np.asarray(v, float)
    ks, ts = [], []
    for s, e in segs:
        bb, vv, m = b[s:e], v[s:e], e - s
        den = m * np.dot(bb, bb) - bb.sum() ** 2
        if m < 2 or not abs(den) > 1e-12 * max(1.0, m * np.dot(bb, bb)):
            raise ValueError(f"rows {s + 1}-{e}: B does not change, no slope can be fitted")
        k = (m * np.dot(bb, vv) - bb.sum() * vv.sum()) / den
        ks.append(k)
        ts.append((vv.sum() - k * bb.sum()) / m)
    return np.asarray(ks), np.asarray(ts)


@dataclass
class Tilt:
    """Per input row: the row's segment, the wall slope tan α (dimensionless) and the error
    E = R·tan α (mm, signed); the web-thickness error of the tilt is −|E|."""

    b: np.ndarray
    z: np.ndarray
    v: np.ndarray
    segment: np.ndarray
    tan_alpha: np.ndarray
    error: np.ndarray

    @property
    def correction(self) -> np.ndarray:
        """K_dist along the depth axis (into the material): −|E|, which cancels the tilt's
        web-thickness error −|E|."""
        return -np.abs(self.error)

    def as_dict(self) -> dict:
        e = self.error
        return {
            "points": [
                {"B": float(b), "Z": float(z), "tan_alpha": float(t), "error": float(x)}
                for b, z, t, x in zip(self.b, self.z, self.tan_alpha, e)
            ],
            "segments": int(self.segment.max() + 1) if len(self.segment) else 0,
            "max_abs_error": float(np.abs(e).max()) if len(e) else 0.0,
            "rms_error": float(np.sqrt(np.mean(e**2))) if len(e) else 0.0,
        }


def tilt(b, z, v, *, tool_radius: float, diameter: float, segment: int = 10, z_tol: float = Z_TOL) -> Tilt:
    """The spindle-tilt error along a tracking pre-measurement (B in degrees, Z and V in mm)."""
    if not (math.isfinite(tool_radius) and tool_radius > 0) or not (math.isfinite(diameter) and diameter > 0):
        raise ValueError("tool radius and shell diameter must be finite and > 0 mm")
    b, z, v = (np.asarray(a, float).ravel() for a in (b, z, v))
    segs = segments(z, segment, z_tol)
    with np.errstate(over="ignore", invalid="ignore"):
        k, _ = fit_segments(b, v, segs)
    if not np.all(np.isfinite(k)) or not np.all(np.isfinite(tool_radius * 360.0 / (math.pi * diameter) * k)):
        raise ValueError("the wall's slope overflows: B, V or the diameter are out of any machine's range")
    seg = np.empty(len(b), dtype=np.int64)
    for i, (s, e) in enumerate(segs):
        seg[s:e] = i
    tan_a = 360.0 / (math.pi * diameter) * k[seg]
    return Tilt(b, z, v, seg, tan_a, tool_radius * tan_a)


#: physical ranges of the input data: a tracking sensor's travel (V, mm), a shell's length (Z, mm),
#: the rotary axis over many turns (B, degrees), a web's thickness (mm)
V_RANGE = 1000.0
Z_RANGE = 1.0e5
B_RANGE = 1.0e5
THICKNESS_RANGE = 1000.0


def _check_ranges(path, c: dict, lines, ranges: dict) -> None:
    """Every value of column ``name`` within ±``ranges[name][0]`` (``[1]``: its unit; a third item
    True: > 0), or an error at its line."""
    for name, (bound, unit, *pos) in ranges.items():
        a = c[name]
        bad = ~(np.abs(a) <= bound)
        if pos and pos[0]:
            bad |= ~(a > 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            what = f"between 0 and {bound:g}" if pos and pos[0] else f"within ±{bound:g}"
            raise InputError(f"column {name}: {a[i]:g} is not {what} {unit}", str(path), int(lines[i]))


def read_tracking(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A tracking log: CSV with columns B (deg), Z (mm), V (mm)."""
    from .. import fields

    c, lines = fields.read_columns(path, ("b", "z", "v"))
    if len(c["b"]) < 2:
        raise InputError(f"a tracking log needs at least 2 rows, found {len(c['b'])}", str(path))
    _check_ranges(
        path, c, lines, {"b": (B_RANGE, "deg"), "z": (Z_RANGE, "mm"), "v": (V_RANGE, "mm (the sensor's travel)")}
    )
    return c["b"], c["z"], c["v"]


def read_thickness(path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A thickness map: CSV with columns B (deg), Z (mm), thickness (mm); also the line numbers.
    A point measured twice is refused (which of two values is right cannot be told)."""
    from .. import fields

    c, lines = fields.read_columns(path, ("b", "z", "thickness"))
    _check_ranges(
        path, c, lines, {"b": (B_RANGE, "deg"), "z": (Z_RANGE, "mm"), "thickness": (THICKNESS_RANGE, "mm", True)}
    )
    pts = np.column_stack([c["b"], c["z"]])
    _, first, inverse = np.unique(pts, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    rep = np.flatnonzero(first[inverse] != np.arange(len(pts)))
    if len(rep):
        i, j = int(rep[0]), int(first[inverse[rep[0]]])
        raise InputError(
            f"point B={pts[i, 0]:g} Z={pts[i, 1]:g} repeats the point at line {int(lines[j])}", str(path), int(lines[i])
        )
    return c["b"], c["z"], c["thickness"], lines


# ------------------------------------------------------------------------------ corrections as fields
class DepthField:
    """A correction along the depth axis known at points (B, Z), for :meth:`Program.correct`.

    Evaluated at every sampled point with the rotary and axial positions there (the NC engine
    interpolates B along split moves); the displacement is put on the depth axis. Points are
    interpolated linearly over a triangulation of (s, Z), s = B·πD/360 the arc length (so that
    both coordinates are millimetres); outside the measured area the nearest value is held
    (``outside="clamp"``), extended linearly (``"extrapolate"``: from the end segments of a single
    pass, the edge cells of a grid, a thin-plate spline through scattered points) or the program is
    refused (``"error"``).
    """

    uses_axes = True

    def __init__(
        self,
        b,
        z,
        k,
        *,
        diameter: float,
        depth_axis: str = "Y",
        axial_axis: str = "Z",
        rotary_axis: str = "B",
        outside: str = "error",
    ):
        from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator

        axes = "XYZABCUVW"
        for name, a, allowed in (
            ("depth", depth_axis, "XYZUVW"),
            ("axial", axial_axis, "XYZUVW"),
            ("rotary", rotary_axis, "ABC"),
        ):
            if a.upper() not in allowed:
                raise ValueError(f"the {name} axis must be one of {', '.join(allowed)}, got {a!r}")
        if outside not in ("error", "clamp", "extrapolate"):
            raise ValueError(f'outside must be "error", "clamp" or "extrapolate", got {outside!r}')
        # index in XYZABCUVW: a U, V or W depth axis is displaced by the engine as X, Y, Z are
        self.depth = axes.index(depth_axis.upper())
        self.axial = axes.index(axial_axis.upper())
        self.rotary = axes.index(rotary_axis.upper())
        self.scale = math.pi * diameter / 360.0
        self.outside = outside
        self.b, self.z, self.k = (np.asarray(a, float).ravel() for a in (b, z, k))
        pts = np.column_stack([self.b * self.scale, self.z])
        pts, idx = np.unique(pts, axis=0, return_index=True)
        vals = self.k[idx]
        xs, zs = np.unique(pts[:, 0]), np.unique(pts[:, 1])
        self._grid = self._lin = self._1d = None
        if len(xs) == 1 or len(zs) == 1:
            # a single pass (one Z) or a single B: interpolate along the coordinate that varies
            varying = 0 if len(xs) > 1 else 1
            if len(pts) < 2:
                raise ValueError("a depth correction needs at least 2 distinct points")
            order = np.argsort(pts[:, varying])
            self._1d = (varying, pts[order, varying], vals[order])
        elif np.linalg.matrix_rank(pts - pts.mean(axis=0), tol=1e-9 * max(1.0, float(np.abs(pts).max()))) < 2:
            raise ValueError(
                f"the {len(pts)} points lie on one line that is neither one pass (one Z) nor one B: "
                "a depth correction needs points spanning B and Z"
            )
        elif len(pts) == len(xs) * len(zs):
            # a full grid (a pre-measurement along B at regular Z): bilinear, fast for any size
            from scipy.interpolate import RegularGridInterpolator

            grid = np.empty((len(xs), len(zs)))
            grid[np.searchsorted(xs, pts[:, 0]), np.searchsorted(zs, pts[:, 1])] = vals
            self._grid = RegularGridInterpolator((xs, zs), grid, bounds_error=False, fill_value=np.nan)
            self._grid_out = RegularGridInterpolator((xs, zs), grid, bounds_error=False, fill_value=None)
        else:
            self._lin = LinearNDInterpolator(pts, vals)
        self._near = NearestNDInterpolator(pts, vals)
        self._pts, self._vals = pts, vals
        self.bounds = (float(self.b.min()), float(self.b.max()), float(self.z.min()), float(self.z.max()))

    def values(self, b, z) -> np.ndarray:
        q = np.column_stack([np.asarray(b, float) * self.scale, np.asarray(z, float)])
        if self._1d is not None:
            j, xs, vs = self._1d
            out = np.interp(q[:, j], xs, vs, left=np.nan, right=np.nan)
        elif self._grid is not None:
            out = self._grid(q)
        else:
            assert self._lin is not None  # one of the three was built in __init__
            out = self._lin(q)
        bad = ~np.isfinite(out)
        if bad.any():
            if self.outside == "error":
                from ..fields import OutsideError

                raise OutsideError(
                    np.flatnonzero(bad),
                    f"the measured area B {self.bounds[0]:g}..{self.bounds[1]:g} deg, "
                    f"Z {self.bounds[2]:g}..{self.bounds[3]:g} mm",
                )
            out[bad] = self._near(q[bad]) if self.outside == "clamp" else self._extrapolate(q[bad])
        return out

    def _extrapolate(self, q: np.ndarray) -> np.ndarray:
        if self._1d is not None:
            j, xs, vs = self._1d
            t = q[:, j]
            lo = vs[0] + (t - xs[0]) * (vs[1] - vs[0]) / (xs[1] - xs[0])
            hi = vs[-1] + (t - xs[-1]) * (vs[-1] - vs[-2]) / (xs[-1] - xs[-2])
            return np.where(t < xs[0], lo, hi)
        if self._grid is not None:
            return self._grid_out(q)
        from scipy.interpolate import RBFInterpolator

        return RBFInterpolator(self._pts, self._vals, kernel="thin_plate_spline")(q)

    def __call__(self, points, axes=None) -> np.ndarray:
        points = np.asarray(points, float)
        if axes is None:
            raise ValueError("a DepthField needs the rotary axis: use it with Program.correct")
        d = np.zeros((len(points), 3 if self.depth < 3 else 9))
        if len(points):
            d[:, self.depth] = self.values(axes[:, self.rotary], axes[:, self.axial])
        return d


class Sum:
    """The sum of depth corrections (K_dist + K_fb) as one field for :meth:`Program.correct`."""

    uses_axes = True

    def __init__(self, parts):
        self.parts = list(parts)

    def __call__(self, points, axes=None):
        parts = [np.asarray(f(points, axes), float) for f in self.parts]
        # X Y Z (n, 3), or X Y Z A B C U V W (n, 9) when a part displaces U, V or W
        width = max([3] + [p.shape[1] for p in parts])
        out = np.zeros((len(points), width))
        for p in parts:
            out[:, : p.shape[1]] += p
        return out


def feedback_correction(thickness, target: float, allowance: float) -> np.ndarray:
    """K_fb = T_pf − T_ref − b (the paper's eq. 7) from a semi-finished thickness map."""
    return np.asarray(thickness, float) - float(target) - float(allowance)


# ------------------------------------------------------------------------------ backlash
def play(x, g: float, y0: float | None = None) -> np.ndarray:
    """The play (backlash) operator of width g: the output moves only when the input pushes it
    from one side of the gap."""
    x = np.asarray(x, float)
    y = np.empty_like(x)
    h = 0.5 * g
    prev = x[0] if y0 is None else y0
    for i, xi in enumerate(x):
        if xi > prev + h:
            prev = xi - h
        elif xi < prev - h:
            prev = xi + h
        y[i] = prev
    return y


def drive(y, tau: float, dt: float) -> np.ndarray:
    """A first-order drive with time constant τ sampled every Δt (zero-order hold input)."""
    y = np.asarray(y, float)
    if tau <= 0:
        return y.copy()
    a = 1.0 - math.exp(-dt / tau)
    from scipy.signal import lfilter

    w, _ = lfilter([a], [1.0, a - 1.0], y, zi=[(1.0 - a) * y[0]])
    return w


def copy(v_ideal, g: float, tau: float = 0.0, dt: float = 1.0) -> np.ndarray:
    """The copying system's output for an ideal back-wall signal: drive(play(V))."""
    return drive(play(v_ideal, g), tau, dt)


def copying_error(v_ideal, g: float, tau: float = 0.0, dt: float = 1.0) -> np.ndarray:
    """The web-thickness error the copying system leaves along a path, V_ideal − copy(V_ideal)
    (positive: thicker); as a correction along the depth axis it is added as it is."""
    v = np.asarray(v_ideal, float)
    return v - copy(v, g, tau, dt)


@dataclass
class Backlash:
    """The copying system identified from a pair of signals: its gap g, time constant τ, offset,
    the fit's residual and the web-thickness error it leaves."""

    gap: float  # g, mm
    tau: float  # s
    offset: float  # mm: a constant between the two signals
    residual_rms: float  # mm
    web_error: np.ndarray  # V_ideal − w, the web-thickness error the copying system leaves

    def as_dict(self) -> dict:
        return {
            "gap": self.gap,
            "tau": self.tau,
            "offset": self.offset,
            "residual_rms": self.residual_rms,
            "web_error_max_abs": float(np.abs(self.web_error).max()),
        }


def estimate_backlash(v_ideal, v_measured, dt: float = 1.0, *, fit_tau: bool = True) -> Backlash:
    """Least squares for the gap g (and the drive's τ and a constant offset) between the ideal
    signal and the one recorded while machining: min Σ (copy(V_ideal; g, τ) + c − V_meas)²."""
    from scipy.optimize import least_squares

    vi, vm = np.asarray(v_ideal, float), np.asarray(v_measured, float)
    if vi.shape != vm.shape or len(vi) < 4:
        raise ValueError("the two signals must have the same length (at least 4 samples)")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"the sampling period must be > 0 s, got {dt}")
    if not (np.all(np.isfinite(vi)) and np.all(np.isfinite(vm))):
        raise ValueError("the signals must be finite numbers")
    span = float(np.ptp(vi))
    if not span > 0:
        raise ValueError("V_ideal does not change: the gap cannot be identified from a constant signal")
    travels = reversal_travels(vi)
    if not len(travels):
        raise ValueError(
            "V_ideal never reverses: one way, the gap only delays the signal by g/2, which a "
            "constant offset absorbs; record the pair across reversals (a zig-zag cell)"
        )

    def model(p):
        g, tau = abs(p[0]), (abs(p[1]) if fit_tau else 0.0)
        w = copy(vi, g, tau, dt)
        return w, float(np.mean(vm - w))

    def resid(p):
        w, c = model(p)
        return w + c - vm

    best = None
    for g0 in np.linspace(0.0, 0.5 * span, 11)[1:]:  # the play makes the cost piecewise: several starts
        for t0 in (dt, 10 * dt) if fit_tau else (0.0,):
            r = least_squares(resid, [g0, t0], x_scale=[span, dt], diff_step=1e-4)
            if best is None or r.cost < best.cost:
                best = r
    assert best is not None  # the loops ran
    g, tau = abs(best.x[0]), (abs(best.x[1]) if fit_tau else 0.0)
    if not travels.max() > g:
        raise ValueError(
            f"V_ideal reverses by at most {travels.max() * 1000:.3g} µm, not more than the fitted gap "
            f"({g * 1000:.3g} µm): the shelf never ends, so the gap is not identified"
        )
    w, c = model(best.x)
    return Backlash(g, tau, c, float(np.sqrt(np.mean((w + c - vm) ** 2))), vi - (w + c))


def reversal_travels(v) -> np.ndarray:
    """How far the signal travels back after each reversal (mm), before it turns again: the
    reversals are found with a hysteresis of 3σ of the signal's sample-to-sample noise (from the
    median absolute second difference), so noise alone does not make one."""
    v = np.asarray(v, float)
    d2 = np.diff(v, 2)
    sigma = float(np.median(np.abs(d2 - np.median(d2)))) / 0.6745 / math.sqrt(6.0) if len(d2) else 0.0
    h = max(3.0 * sigma, 1e-9 * max(1.0, float(np.abs(v).max())))
    out = []
    direction, ext = 0, v[0]  # the current direction and its extremum
    start = None  # the extremum where the current leg started after a reversal
    for x in v[1:]:
        if direction >= 0 and x > ext:
            ext = x
            direction = 1 if x - v[0] > h or direction else direction
        elif direction <= 0 and x < ext:
            ext = x
            direction = -1 if v[0] - x > h or direction else direction
        if direction == 1 and ext - x > h:  # turned down
            if start is not None:
                out.append(abs(ext - start))
            start, direction, ext = ext, -1, x
        elif direction == -1 and x - ext > h:  # turned up
            if start is not None:
                out.append(abs(ext - start))
            start, direction, ext = ext, 1, x
    if start is not None:
        out.append(abs(ext - start))
    return np.asarray(out)


# ------------------------------------------------------------------------------ self-tuning
class SelfTuning:
    """Cell-to-cell self-tuning: keep K_fb while every finished thickness of a cell stays inside
    (t_min, t_max); retune (semi-finish the next cell, recompute K_fb) when max ≥ t_max or
    min ≤ t_min."""

    def __init__(self, target: float, allowance: float, t_min: float, t_max: float):
        if not t_min < target < t_max:
            raise ValueError(f"the signal band ({t_min}, {t_max}) must contain the target {target}")
        self.target, self.allowance, self.t_min, self.t_max = target, allowance, t_min, t_max
        self.k_fb: np.ndarray | None = None
        self.retunes = 0
        self._retune_next = True

    @property
    def needs_semi_finish(self) -> bool:
        return self._retune_next

    def tune(self, semi_finished_thickness) -> np.ndarray:
        k_fb = feedback_correction(semi_finished_thickness, self.target, self.allowance)
        self.k_fb = k_fb
        self.retunes += 1
        self._retune_next = False
        return k_fb

    def finished(self, thickness) -> bool:
        """Record a finished cell's thickness map; True when the next cell must be retuned."""
        t = np.asarray(thickness, float)
        self._retune_next = bool(t.max() >= self.t_max or t.min() <= self.t_min)
        return self._retune_next


@dataclass(frozen=True)
class CellState:
    """The self-tuning state of one cell (1-based row and cell): ``status`` is ``"finished"`` (a
    finished thickness map was read: ``t_min``, ``t_max`` in mm, ``in_band``), ``"next"`` (the next
    cell to machine) or ``"pending"``; ``semi_finish`` says whether the cell needs (or needed) a
    semi-finishing pass before finishing — True, False, or None while it depends on cells not
    finished yet."""

    row: int
    cell: int
    status: str
    semi_finish: bool | None
    t_min: float | None = None
    t_max: float | None = None
    in_band: bool | None = None
    source: str | None = None

    def as_dict(self) -> dict:
        return {
            "row": self.row,
            "cell": self.cell,
            "status": self.status,
            "semi_finish": self.semi_finish,
            "t_min": self.t_min,
            "t_max": self.t_max,
            "in_band": self.in_band,
            "source": self.source,
        }


def plan_cells(finished: dict, rows: int, cells: int, t_min: float, t_max: float) -> list[CellState]:
    """The self-tuning decision over a shell machined row by row (cell 1 … ``cells`` of row 1, then
    row 2 …), from the finished thickness maps there are: ``finished`` maps (row, cell), 1-based, to
    (thickness array, source name). The first cell is semi-finished; a cell is semi-finished when
    the cell machined before it finished with max ≥ ``t_max`` or min ≤ ``t_min`` (the paper's rule,
    "or"). The maps must be of consecutive cells from the first: a gap is refused (the decision for
    the cell after it would be a guess)."""
    if not t_min < t_max:
        raise ValueError(f"the band's lower end {t_min:g} must be below its upper end {t_max:g}")
    order = [(r, c) for r in range(1, rows + 1) for c in range(1, cells + 1)]
    extra = sorted(set(finished) - set(order))
    if extra:
        raise ValueError(
            f"a finished map of row {extra[0][0]} cell {extra[0][1]} is outside the {rows} x {cells} shell"
        )
    out: list[CellState] = []
    retune, next_seen = True, False
    for r, c in order:
        if (r, c) in finished:
            if next_seen:
                gap = next(s for s in out if s.status == "next")
                raise ValueError(
                    f"row {r} cell {c} is finished but row {gap.row} cell {gap.cell}, machined before "
                    "it, has no finished map"
                )
            t, src = finished[(r, c)]
            t = np.asarray(t, float)
            lo, hi = float(t.min()), float(t.max())
            inside = not (hi >= t_max or lo <= t_min)
            out.append(CellState(r, c, "finished", retune, lo, hi, inside, src))
            retune = not inside
        elif not next_seen:
            out.append(CellState(r, c, "next", retune))
            next_seen = True
        else:
            out.append(CellState(r, c, "pending", None))
    return out
