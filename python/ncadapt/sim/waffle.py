"""A virtual SVO machine milling the waffle grid of a cylindrical shell, deterministic for a seed.

Shell: outer diameter D = 1500 mm, 4 rows × 24 cells (15° pitch, rows 120 mm apart); web target
T_ref = 2.0 mm; semi-finishing allowance b = 0.3 mm. Cutter R = 10 mm. Each cell is finished
along a zig-zag: 11 lines along B (±5° about the cell's centre, 0.1° = 1.31 mm apart) stepped
8 mm in Z, at 2000 mm/min (Δt = 0.039 s per sample). The web thickness is evaluated at the path's
samples (a 11 × 101 map per cell); cells are machined row by row.

The back wall's deviation along the depth axis (into the material positive), mm:
V(B, Z) = A₂ cos(2B + φ₂) + A₃ cos(3B + φ₃) + Σ_welds h·exp(−½((s − s_w)/25)²) + c·(Z/Z_max)²
with s = B·πD/360 the arc length, A₂ ~ U(0.5, 1.0), A₃ ~ U(0.2, 0.5), two longitudinal welds
h ~ U(0.2, 0.4) mm at random B, a bow c ~ U(−0.2, 0.2) mm (ovality and lobes of a rolled shell,
weld sag: orders of magnitude of the shape errors the paper's tracking compensates).

Web-thickness error of a finished cell, T − T_ref (mm) — the paper's two groups, from the
testbed's own physics (issue 21 item 11: not the corrector's formulas):

- group I, a pattern inside the cell:
  - the copying chain (:func:`copying_chain`): the stylus in a gap of g = 0.03 mm drags the
    transducer, and the tracking drive follows it as a *second-order* system (3.5 Hz, ζ = 0.8); the
    tool's axis is at the depth y = w + K (w the chain's output along the zig-zag, K the program's
    correction);
  - the spindle tilt as geometry (:func:`cell_error`): the cutter's face is a flat disc of radius
    R = 10 mm perpendicular to the spindle; a point of the web ends at the deepest face that
    covered it — the maximum of y over the tool positions within R, on its own line and the lines
    8 mm away — so T − T_ref = V − max y. On a wall sloping along B this is the paper's −R·|tan α|;
    the wall's slope along Z (the bow) also thins the web through the neighbouring lines, which the
    paper's formula ignores;
  - the cutter's deflection near the ribs: +0.04·exp(−d/8 mm) (d: distance to the pocket's edge
    along B or Z), the same in every cell;
- group II, a drift with the cell's place: temperature, 0.08 mm·(n / N_cells − ½) with n the
  machining order (the machine set up on the shell's middle cell); the rows next to the end
  flanges (stiffer) +0.02 mm, the middle rows −0.02 mm;
- machining noise σ = 4 µm; the ultrasonic thickness map adds σ = 8 µm; the tracking
  pre-measurement (one-way along B, every 2 mm of Z over the row, 0.25° steps) σ = 3 µm.

The corrector (``ncadapt.processes.waffle``) models the tilt as −R·|tan α| from segment fits along
B and the copying chain as a play with a *first-order* drive fitted to a pair of signals; the
testbed shows what that still achieves on this physics.

Strategies: ``none``; ``disturbance`` (K_dist from the pre-measurement: the tilt from its segment
fits, N = 10, plus the copying system's error predicted along the cell's zig-zag with the gap and
drive estimated by :func:`ncadapt.processes.waffle.estimate_backlash` from the pair of signals of
:func:`backlash_pair`, which come from the testbed's chain);
``self-tuning`` (K_fb from a semi-finishing pass smoothed along B with a Gaussian of σ = 2
samples, band T_ref ± 0.03 mm, the finished maps smoothed the same way before the band check); ``combined`` (both; the semi-finishing pass carries K_dist).
A retuned cell is semi-finished then finished; ``retunes`` counts every semi-finishing pass,
the first cell's included.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..processes import waffle as pw

D = 1500.0
ROWS, CELLS = 4, 24
PITCH = 360.0 / CELLS
ROW_PITCH = 120.0
T_REF = 2.0
ALLOWANCE = 0.3
BAND = 0.03
R_TOOL = 10.0
HALF_B = 5.0  # deg: the path's half-width along B
STEP_B = 0.1
Z_LINES = np.arange(-40.0, 40.0 + 1e-9, 8.0)
FEED = 2000.0 / 60.0  # mm/s
GAP = 0.03  # mm, the stylus's gap in the copying chain
DRIVE_HZ = 3.5  # natural frequency of the tracking drive, Hz (second order)
DRIVE_ZETA = 0.8  # its damping ratio
TAU = 1.0 / (2 * math.pi * DRIVE_HZ) * 2 * DRIVE_ZETA  # s: the first-order lag with the same delay (2ζ/ω_n)
RIB = 0.04
DRIFT = 0.08
FLANGE = 0.02
NOISE_CUT, NOISE_UT, NOISE_TRACK = 0.004, 0.008, 0.003
SEGMENT = 10
STRATEGIES = ("none", "disturbance", "self-tuning", "combined")
MM_PER_DEG = math.pi * D / 360.0


@dataclass
class Shell:
    """The back wall of a seeded shell."""

    seed: int
    a2: float
    a3: float
    p2: float
    p3: float
    welds: list
    bow: float

    @classmethod
    def make(cls, seed: int) -> Shell:
        rng = np.random.default_rng(seed)
        return cls(
            seed,
            rng.uniform(0.5, 1.0),
            rng.uniform(0.2, 0.5),
            rng.uniform(0, 2 * np.pi),
            rng.uniform(0, 2 * np.pi),
            [(rng.uniform(0, 360), rng.uniform(0.2, 0.4)) for _ in range(2)],
            rng.uniform(-0.2, 0.2),
        )

    def v(self, b, z):
        b = np.asarray(b, float)
        r = np.radians(b)
        zmax = ROWS * ROW_PITCH / 2
        out = (
            self.a2 * np.cos(2 * r + self.p2)
            + self.a3 * np.cos(3 * r + self.p3)
            + self.bow * (np.asarray(z) / zmax) ** 2
        )
        for bw, h in self.welds:
            ds = ((b - bw + 180) % 360 - 180) * MM_PER_DEG
            out = out + h * np.exp(-0.5 * (ds / 25.0) ** 2)
        return out

    def slope(self, b, z):
        """∂V/∂s (dimensionless)."""
        b = np.asarray(b, float)
        r = np.radians(b)
        d = (-2 * self.a2 * np.sin(2 * r + self.p2) - 3 * self.a3 * np.sin(3 * r + self.p3)) / (D / 2)
        for bw, h in self.welds:
            ds = ((b - bw + 180) % 360 - 180) * MM_PER_DEG
            d = d - h * ds / 25.0**2 * np.exp(-0.5 * (ds / 25.0) ** 2)
        return d + 0 * np.asarray(z)


def cell_path():
    """Local (u in deg, w in mm) samples of the zig-zag, line by line (lines, samples)."""
    u = np.arange(-HALF_B, HALF_B + 1e-9, STEP_B)
    uu = np.array([u if k % 2 == 0 else u[::-1] for k in range(len(Z_LINES))])
    ww = np.repeat(Z_LINES[:, None], len(u), axis=1)
    return uu, ww


def cell_centre(row: int, cell: int) -> tuple[float, float]:
    return cell * PITCH + PITCH / 2, (row - (ROWS - 1) / 2) * ROW_PITCH


def premeasurement(shell: Shell, rng):
    """The tracking pre-measurement [B, Z, V]: one-way along B at every 2 mm of Z, 0.25° steps."""
    b = np.arange(0.0, 360.0, 0.25)
    zs = np.arange(-ROWS * ROW_PITCH / 2 + 10, ROWS * ROW_PITCH / 2 - 10 + 1e-9, 2.0)
    bb, zz = np.meshgrid(b, zs)
    bb, zz = bb.ravel(), zz.ravel()
    return bb, zz, shell.v(bb, zz) + rng.normal(0, NOISE_TRACK, bb.shape)


def rib_pattern(uu, ww):
    d = np.minimum((HALF_B - np.abs(uu)) * MM_PER_DEG, Z_LINES.max() - np.abs(ww)) + R_TOOL
    return RIB * np.exp(-d / 8.0)


@dataclass
class Result:
    strategy: str
    seed: int
    maps: np.ndarray  # (rows, cells, lines, samples) finished thickness error, mm
    before: np.ndarray  # the same without correction (same seed)
    retuned: np.ndarray  # (rows, cells) bool: semi-finished first
    backlash: dict = field(default_factory=dict)

    def out_of_tolerance(self, tolerance: float = BAND) -> np.ndarray:
        """(rows, cells) int: the points of each finished cell with |T − T_ref| > ``tolerance``."""
        return (np.abs(self.maps) > tolerance).sum(axis=(2, 3))

    def as_dict(self, tolerance: float = BAND) -> dict:
        e = self.maps
        out = self.out_of_tolerance(tolerance)
        cells = [
            {
                "row": int(r + 1),
                "cell": int(c + 1),
                "B": cell_centre(r, c)[0],
                "Z": cell_centre(r, c)[1],
                "rms_error": float(np.sqrt(np.mean(e[r, c] ** 2))),
                "max_abs_error": float(np.abs(e[r, c]).max()),
                "points_out_of_tolerance": int(out[r, c]),
                "retuned": bool(self.retuned[r, c]),
            }
            for r in range(e.shape[0])
            for c in range(e.shape[1])
        ]
        return {
            "strategy": self.strategy,
            "seed": self.seed,
            "rms_error": float(np.sqrt(np.mean(e**2))),
            "max_abs_error": float(np.abs(e).max()),
            "retunes": int(self.retuned.sum()),
            "cells_total": int(self.retuned.size),
            "rms_error_uncorrected": float(np.sqrt(np.mean(self.before**2))),
            "tolerance": tolerance,
            "cells_out_of_tolerance": int((out > 0).sum()),
            "points_out_of_tolerance": int(out.sum()),
            "points_total": int(e.size),
            "backlash": self.backlash,
            "cells": cells,
        }


def simulate(strategy: str = "combined", seed: int = 1, *, on_cell=None) -> Result:
    """Mill the shell's 96 cells with a strategy; ``on_cell(done, total)`` after each cell."""
    if strategy not in STRATEGIES:
        raise ValueError(f"strategy must be one of {', '.join(STRATEGIES)}, got {strategy!r}")
    from scipy.ndimage import gaussian_filter1d

    shell = Shell.make(seed)
    uu, ww = cell_path()
    dt = STEP_B * MM_PER_DEG / FEED
    use_dist = strategy in ("disturbance", "combined")
    use_fb = strategy in ("self-tuning", "combined")
    k_field = v_field = None
    backlash = {}
    if use_dist:
        b, z, v = premeasurement(shell, np.random.default_rng([seed, 3]))
        t = pw.tilt(b, z, v, tool_radius=R_TOOL, diameter=D, segment=SEGMENT)
        k_field = pw.DepthField(b, z, t.correction, diameter=D, outside="clamp")
        v_field = pw.DepthField(b, z, v, diameter=D, outside="clamp")
        est = pw.estimate_backlash(*backlash_pair(seed))
        backlash = est.as_dict()
    tuner = pw.SelfTuning(T_REF, ALLOWANCE, T_REF - BAND, T_REF + BAND)
    shape = (ROWS, CELLS) + uu.shape
    maps, before = np.empty(shape), np.empty(shape)
    retuned = np.zeros((ROWS, CELLS), bool)
    n_total = ROWS * CELLS
    for r in range(ROWS):
        for c in range(CELLS):
            bc, zc = cell_centre(r, c)
            bb, zz = bc + uu, zc + ww
            # separate streams: the cut's noise is the same whatever the strategy
            cut_rng, gauge_rng = np.random.default_rng([seed, 1, r, c]), np.random.default_rng([seed, 2, r, c])
            order = r * CELLS + c
            w = copying_chain(shell.v(bb, zz).ravel(), dt).reshape(uu.shape)
            base = cell_error(shell, r, c, w=w)  # the error of an uncorrected pass
            k_dist = 0.0
            if use_dist:
                k_dist = k_field.values(bb.ravel(), zz.ravel()).reshape(uu.shape)
                # the copying system's error predicted along this cell's zig-zag from the
                # pre-measured wall and the estimated gap and drive
                v_pre = v_field.values(bb.ravel(), zz.ravel())
                k_dist = k_dist + pw.copying_error(v_pre, est.gap, est.tau, dt).reshape(uu.shape)
            k = k_dist
            if use_fb:
                if tuner.needs_semi_finish:
                    # semi-finishing pass with allowance b (carrying K_dist), gauged
                    semi = (
                        T_REF
                        + ALLOWANCE
                        + cell_error(shell, r, c, k=k_dist, w=w)
                        + gauge_rng.normal(0, NOISE_CUT, uu.shape)
                    )
                    gauged = semi + gauge_rng.normal(0, NOISE_UT, uu.shape)
                    tuner.tune(gaussian_filter1d(gauged, 2.0, axis=1, mode="nearest"))
                    retuned[r, c] = True
                k = k + tuner.k_fb
            noise = cut_rng.normal(0, NOISE_CUT, uu.shape)
            before[r, c] = base + noise
            maps[r, c] = (base if np.isscalar(k) and k == 0 else cell_error(shell, r, c, k=k, w=w)) + noise
            if use_fb:
                gauged = T_REF + maps[r, c] + gauge_rng.normal(0, NOISE_UT, uu.shape)
                tuner.finished(gaussian_filter1d(gauged, 2.0, axis=1, mode="nearest"))
            if on_cell is not None:
                on_cell(order + 1, n_total)
    return Result(strategy, seed, maps, before, retuned, backlash)


def copying_chain(v, dt: float) -> np.ndarray:
    """The copying chain's output along a path — the testbed's own model, not the corrector's:
    the stylus sits in a gap of width GAP and drags the transducer only while it presses on one
    side of the gap; the tracking drive follows the transducer as a second-order system
    (ω_n = 2π·DRIVE_HZ, ζ = DRIVE_ZETA, exact zero-order-hold discretisation), starting at rest on
    the first sample. The corrector fits a play and a *first-order* drive to it
    (:func:`ncadapt.processes.waffle.estimate_backlash`)."""
    from scipy.signal import cont2discrete, lfilter, lfiltic

    v = np.asarray(v, float)
    x = np.empty_like(v)
    pos, half = v[0], GAP / 2
    for i, vi in enumerate(v):  # the stylus in its gap
        if vi - pos > half:
            pos = vi - half
        elif pos - vi > half:
            pos = vi + half
        x[i] = pos
    wn = 2 * math.pi * DRIVE_HZ
    num, den, _ = cont2discrete(([wn * wn], [1.0, 2 * DRIVE_ZETA * wn, wn * wn]), dt, method="zoh")
    num = np.ravel(num)
    zi = lfiltic(num, den, np.full(3, x[0]), np.full(3, x[0]))
    return lfilter(num, den, x, zi=zi)[0]


def _neighbourhoods():
    """For each line of the zig-zag, the tool positions whose face (radius R) covers a point:
    (line offset, half-width along the line in samples) — the own line R/Δs, lines Δz away
    √(R² − Δz²)/Δs (none beyond R); fractional, the path being continuous between samples."""
    ds = STEP_B * MM_PER_DEG
    dz = float(Z_LINES[1] - Z_LINES[0])
    out = []
    k = 0
    while k * dz < R_TOOL:
        half = math.sqrt(R_TOOL**2 - (k * dz) ** 2) / ds
        out += [(k, half)] if k == 0 else [(k, half), (-k, half)]
        k += 1
    return out


def _shift(a: np.ndarray, n: int) -> np.ndarray:
    """a[:, j + n] at j (−inf beyond the line's ends)."""
    out = np.full(a.shape, -np.inf)
    if n >= 0:
        out[:, : a.shape[1] - n] = a[:, n:]
    else:
        out[:, -n:] = a[:, : a.shape[1] + n]
    return out


def _sweep_max(yb: np.ndarray, half: float) -> np.ndarray:
    """The maximum of a piecewise-linear profile (rows sampled evenly) over ±``half`` samples
    about each sample: the samples inside, and the profile interpolated at the window's two ends
    (a linear piece's maximum is at a sample or an end)."""
    from scipy.ndimage import maximum_filter1d

    n = int(math.floor(half + 1e-12))
    out = maximum_filter1d(yb, size=2 * n + 1, axis=1, mode="constant", cval=-np.inf)
    f = half - n
    if f > 1e-12:
        for sgn in (1, -1):
            a, b = _shift(yb, sgn * n), _shift(yb, sgn * (n + 1))
            ok = np.isfinite(b)  # then a is finite too
            end = np.full(yb.shape, -np.inf)
            end[ok] = a[ok] + f * (b[ok] - a[ok])
            out = np.maximum(out, end)
    return out


def cell_error(shell: Shell, row: int, cell: int, k=None, w=None) -> np.ndarray:
    """The web-thickness error T − T_ref a pass leaves in a cell (0-based row and cell), without
    noise: (lines, samples) along the cell's zig-zag, mm. ``k`` (same shape, mm, into the
    material) is the correction the program adds to the depth axis; ``w`` the copying chain's
    output along the zig-zag (computed when not given).

    The geometry, not the corrector's formula: the tool's axis follows the zig-zag at the depth
    y = w + k (the copying chain tracking the back wall V, plus the correction); its face is a flat
    disc of radius R perpendicular to the spindle, so a point P of the web ends at the deepest face
    that covered it, floor(P) = max of y over the tool positions within R of P — on its own line
    and the neighbouring lines 8 mm away — and T − T_ref = V(P) − floor(P). On a wall sloping by
    tan α along B this leaves the paper's −R·|tan α|; a slope along Z (the bow) also thins the web
    through the neighbouring lines, which the paper's formula does not see. Group I's cutter
    deflection near the ribs and group II's drift are added (see the module's docstring)."""
    uu, ww = cell_path()
    bc, zc = cell_centre(row, cell)
    bb, zz = bc + uu, zc + ww
    dt = STEP_B * MM_PER_DEG / FEED
    v = shell.v(bb, zz)
    if w is None:
        w = copying_chain(v.ravel(), dt).reshape(uu.shape)
    y = w + (0.0 if k is None else np.asarray(k, float))
    order = np.argsort(uu, axis=1, kind="stable")  # each line in the order of B
    yb = np.take_along_axis(y, order, axis=1)
    floor = np.full(yb.shape, -np.inf)
    lines = len(Z_LINES)
    for dk, half in _neighbourhoods():
        m = _sweep_max(yb, half)
        lo, hi = max(0, -dk), min(lines, lines - dk)
        floor[lo:hi] = np.maximum(floor[lo:hi], m[lo + dk : hi + dk])
    floor_path = np.empty_like(floor)
    np.put_along_axis(floor_path, order, floor, axis=1)
    order_n = row * CELLS + cell
    drift = DRIFT * (order_n / (ROWS * CELLS) - 0.5) + (FLANGE if row in (0, ROWS - 1) else -FLANGE)
    return v - floor_path + rib_pattern(uu, ww) + drift


def program_depth(program, row: int, cell: int, depth: float = 8.0) -> np.ndarray:
    """The depth axis Y a program commands along a cell's zig-zag, at the testbed's samples
    ((lines, samples), mm): the program's feed blocks at cutting depth (Y > ``depth``/2) on each
    line's Z, Y linear in B between their ends (the machine interpolates B and Y together)."""
    from .. import nc

    bl = nc.read(program).blocks
    end = bl.end
    feed = (bl.motion == 1) & np.isfinite(end[:, 1]) & np.isfinite(end[:, 2]) & np.isfinite(end[:, 4])
    feed &= end[:, 1] > depth / 2
    uu, ww = cell_path()
    bc, zc = cell_centre(row, cell)
    out = np.empty(uu.shape)
    for k, w in enumerate(Z_LINES):
        on = feed & (np.abs(end[:, 2] - (zc + w)) < 1e-6)
        if on.sum() < 2:
            raise ValueError(f"the program does not cut the line Z = {zc + w:g} mm of row {row + 1} cell {cell + 1}")
        bs, ys = end[on, 4], end[on, 1]
        order = np.argsort(bs, kind="stable")
        bs, ys = bs[order], ys[order]
        if not (bs[0] <= bc + uu[k].min() + 1e-9 and bs[-1] >= bc + uu[k].max() - 1e-9):
            raise ValueError(f"the program does not cover the line Z = {zc + w:g} mm across the cell")
        out[k] = np.interp(bc + uu[k], bs, ys)
    return out


def machine_program(program, seed: int, row: int = 0, cell: int = 0, *, depth: float = 8.0) -> np.ndarray:
    """Cut a cell (0-based row and cell) of the seeded shell with a program (a path or text file in
    the form of :func:`cell_program`, corrected or not) and return the web thickness T at the
    zig-zag's samples ((lines, samples), mm): T = T_ref + (the uncorrected pass's error) −
    the error of a pass whose correction is Y − ``depth`` (:func:`cell_error`, the face swept over
    the wall) + machining noise, Y the depth the program commands (:func:`program_depth`).
    ``depth`` is the finishing depth of the uncorrected program; a semi-finishing program at
    ``depth`` − b leaves b more."""
    shell = Shell.make(seed)
    y = program_depth(program, row, cell, depth)
    noise = np.random.default_rng([seed, 1, row, cell]).normal(0, NOISE_CUT, y.shape)
    return T_REF + cell_error(shell, row, cell, k=y - depth) + noise


def gauge_map(thickness: np.ndarray, seed: int, row: int = 0, cell: int = 0, *, step: int = 5):
    """The ultrasonic thickness map of a machined cell: every ``step``-th sample along B of every
    line (0.5° at the default), with σ = 8 µm; (n, 3) rows of B (deg), Z (mm), thickness (mm)."""
    uu, ww = cell_path()
    bc, zc = cell_centre(row, cell)
    rng = np.random.default_rng([seed, 5, row, cell])
    rows = []
    for k in range(len(Z_LINES)):
        order = np.argsort(uu[k])
        for j in order[::step]:
            rows.append((bc + uu[k, j], zc + ww[k, j], thickness[k, j] + rng.normal(0, NOISE_UT)))
    return np.asarray(rows)


def backlash_pair(seed: int = 1, noise: float = 0.002):
    """The pair of signals of section 3 for the first cell: the ideal V along the cell's zig-zag
    (from the one-way pre-measurement) and V recorded while machining it; and Δt."""
    shell = Shell.make(seed)
    rng = np.random.default_rng(seed + 2)
    uu, ww = cell_path()
    bc, zc = cell_centre(0, 0)
    # a cell where the wall slopes: start at the steepest part of the ovality
    v_ideal = shell.v(bc + uu, zc + ww).ravel()
    dt = STEP_B * MM_PER_DEG / FEED
    measured = copying_chain(v_ideal, dt) + rng.normal(0, noise, v_ideal.shape)
    return v_ideal, measured, dt


def shell_map(maps: np.ndarray):
    """The shell's thickness-error map as one image over B × Z (rows of Z, columns of B) with
    the extents (B0, B1, Z0, Z1)."""
    rows, cells, lines, samples = maps.shape
    uu, _ = cell_path()
    img = np.full((rows * lines, cells * samples), np.nan)
    for r in range(rows):
        for c in range(cells):
            m = maps[r, c].copy()
            m[1::2] = m[1::2, ::-1]  # the zig-zag's odd lines run backwards
            img[r * lines : (r + 1) * lines, c * samples : (c + 1) * samples] = m
    z0 = cell_centre(0, 0)[1] + Z_LINES[0]
    z1 = cell_centre(rows - 1, 0)[1] + Z_LINES[-1]
    return img, (0.0, 360.0, z0, z1)


def cell_program(row: int = 0, cell: int = 0, depth: float = 8.0, step: float = 0.5) -> str:
    """G-code finishing one cell along the zig-zag, as a post-processor writes it for an SVO
    machine: B (deg) rotary, Z along the shell, Y the depth along the spindle (larger: deeper),
    reference points every ``step`` degrees."""
    bc, zc = cell_centre(row, cell)
    u = np.arange(-HALF_B, HALF_B + 1e-9, step)
    out = [
        f"(ncadapt waffle testbed: finish row {row + 1} cell {cell + 1}, zig-zag along B)",
        "G21 G90 G94 G17",
        "S6000 M3",
        "G0 X0.000 Y0.000",
        f"G0 B{bc + u[0]:.3f} Z{zc + Z_LINES[0]:.3f}",
        f"G1 Y{depth:.3f} F300",
    ]
    for k, w in enumerate(Z_LINES):
        line = u if k % 2 == 0 else u[::-1]
        if k:
            out.append(f"G1 Z{zc + w:.3f}")
        out += [f"G1 B{bc + x:.3f} F{FEED * 60:.0f}" for x in line[1:]]
    out += ["G0 Y0.000", "M5", "M2"]
    return "\n".join(out) + "\n"
