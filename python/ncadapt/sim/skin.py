"""A virtual skin-milling testbed: the panel of Wu et al.'s experiment, deterministic for a seed.

Panel: 1500 × 1200 × 3 mm, Al 7050 (E = 71.7 GPa, ν = 0.33); two 300 × 200 mm pockets centred at
(450, 600) and (1050, 600), roughed 1 mm deep (T_s = 2.0 mm plus a seeded smooth thickness
variation of ±0.02 mm), finished a_g = 0.5 mm to the target T_g = 1.5 mm. Cutter Ø20, 2 flutes,
f_z = 0.09375 mm at 8000 rpm: feed v = 1500 mm/min = 25 mm/s.

Equations:

- mean axial force over a slot (φ from 0 to π, h = f_z sin φ, N_t teeth, per revolution):
  F(a_p) = N_t a_p (K_ac f_z / π + K_ae / 2), K_ac = 642.5 N/mm², K_ae = 128.29 N/mm (the paper's
  coefficients) — 83.3 N at a_p = 0.5 mm;
- the pocket floor as a plate clamped at the pocket walls (Kirchhoff; Timoshenko and
  Woinowsky-Krieger, Theory of Plates and Shells, Table 35: centre deflection of a clamped
  rectangular plate under a central load w = α P b²/D, α = 0.00703 for a/b = 1.5), one-term
  Rayleigh–Ritz shape φ = sin²(πξ) sin²(πη) (ξ, η ∈ [0, 1] across the pocket), so the point
  compliance at (x, y) is C = α b² φ² / D(t), D = E t³ / (12(1 − ν²));
- the wall thins as it is cut: t = T_s − θ a_p with θ = 0.2 (most of the floor around the tool is
  either uncut or already finished) — this makes f(a_p) nonlinear;
- the support head in parallel: f(a_p) = F C / (1 + k_sup C). k_sup is calibrated so that the
  uncompensated error at the pocket centre is the paper's largest, f(a_g) = 0.24 mm
  (:func:`support_stiffness`: k_sup = F(a_g)/0.24 − 1/C_centre, about 233 N/mm);
- real depth a_r = a_p − f(a_p), thickness T = T_s − a_r, error δ = T − T_g;
- the gauge: its 7 mm spot trails the tool and averages the thickness just cut over 7 mm of path;
  seeded normal noise σ; the limit filter drops readings above 10 mm or more than 0.3 mm from T_g;
- dead time τ (30–60 ms): a W1 command lands v·τ after the reading it came from. The compensator
  steps on every fresh reading — one whose spot lies wholly on material cut after the last
  command landed — so readings come every 7 mm + v·τ of path.

Toolpath: in each pocket a zig-zag along x, x ∈ [−140, 140] mm, 15 lines 12.5 mm apart
(y ∈ [−87.5, 87.5]) about the pocket's centre, sampled every 0.25 mm. The compensator starts
fresh (a_p = a_g) in each pocket.

The 13 checkpoints (pocket-local x, y in mm): pocket 1 — the centre, the four points halfway to
the corners (±75, ±50) and (±100, 0); pocket 2 — the centre, (±75, ±50) and (100, 0). The error at
a checkpoint is the true (noise-free) thickness error where the path passes over it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..processes import skin as ps

E = 71.7e3  # N/mm²
NU = 0.33
T_INITIAL = 2.0  # mm after roughing
T_TARGET = 1.5
A_G = T_INITIAL - T_TARGET
K_AC = 642.5  # N/mm²
K_AE = 128.29  # N/mm
F_Z = 0.09375  # mm/tooth
TEETH = 2
FEED = 25.0  # mm/s
ALPHA = 0.00703  # clamped rectangular plate, a/b = 1.5
THETA = 0.01
F_CENTRE = 0.24  # mm: the paper's largest uncompensated error
POCKET = (300.0, 200.0)
POCKETS = ((450.0, 600.0), (1050.0, 600.0))
SPOT = 7.0  # mm
GAUGE_MAX = 10.0
GAUGE_BAND = 0.3
STEP = 0.25  # mm of path per sample
CHECKPOINTS = (
    (0, 0.0, 0.0), (0, 75, 50), (0, -75, 50), (0, 75, -50), (0, -75, -50), (0, 100, 0), (0, -100, 0),
    (1, 0.0, 0.0), (1, 75, 50), (1, -75, 50), (1, 75, -50), (1, -75, -50), (1, 100, 0),
)


def force(a_p):
    """Mean axial force, N."""
    return TEETH * np.asarray(a_p, float) * (K_AC * F_Z / math.pi + K_AE / 2)


def rigidity(t):
    return E * np.asarray(t, float) ** 3 / (12 * (1 - NU * NU))


def shape(lx, ly):
    """φ² at pocket-local (x, y): 1 at the centre, 0 at the walls."""
    a, b = POCKET
    xi = np.clip(np.asarray(lx, float) / a + 0.5, 0, 1)
    eta = np.clip(np.asarray(ly, float) / b + 0.5, 0, 1)
    return (np.sin(np.pi * xi) ** 2 * np.sin(np.pi * eta) ** 2) ** 2


def plate_compliance(lx, ly, t):
    return ALPHA * POCKET[1] ** 2 * shape(lx, ly) / rigidity(t)


def support_stiffness() -> float:
    """k_sup so that f(a_g) = 0.24 mm at the pocket centre."""
    c = plate_compliance(0.0, 0.0, T_INITIAL - THETA * A_G)
    return float(force(A_G) / F_CENTRE - 1 / c)


K_SUP = support_stiffness()


def deflection(lx, ly, a_p, t_s=T_INITIAL):
    """f(a_p) at pocket-local (x, y), mm."""
    c = plate_compliance(lx, ly, t_s - THETA * np.asarray(a_p, float))
    return force(a_p) * c / (1 + K_SUP * c)


def error(lx, ly, a_p, t_s=T_INITIAL):
    """δ = T − T_g after cutting with programmed depth a_p."""
    a_r = a_p - deflection(lx, ly, a_p, t_s)
    return t_s - a_r - T_TARGET


def thickness_variation(seed: int):
    """A smooth seeded variation of the roughed thickness, ±0.02 mm at most."""
    rng = np.random.default_rng(seed + 7919)
    k = rng.uniform(0.5, 2.0, (3, 2)) * 2 * np.pi / np.array([1500.0, 1200.0])
    ph = rng.uniform(0, 2 * np.pi, 3)
    amp = rng.uniform(-1, 1, 3)
    amp *= 0.02 / np.abs(amp).sum()
    return lambda x, y: sum(amp[i] * np.sin(k[i, 0] * x + k[i, 1] * y + ph[i]) for i in range(3))


def toolpath(pocket: int):
    """Pocket-local (x, y) samples of the zig-zag, every STEP mm."""
    xs = np.arange(-140.0, 140.0 + 1e-9, STEP)
    lines = []
    for j, y in enumerate(np.arange(-87.5, 87.5 + 1e-9, 12.5)):
        x = xs if j % 2 == 0 else xs[::-1]
        lines.append(np.column_stack([x, np.full_like(x, y)]))
    return np.concatenate(lines)


# ------------------------------------------------------------------------------ the paper's protocol
def protocol(method: str, compensations: int = 2) -> dict:
    """Noise-free, at each checkpoint: a pass with a_p = a_g, then ``compensations`` compensated
    passes, each a fresh cut from T_s (the paper's finite-element protocol)."""
    rows = []
    for pocket, x, y in CHECKPOINTS:
        comp = compensator(method, 0.0)
        a = A_G
        deltas = [float(error(x, y, a))]
        for _ in range(compensations):
            a = comp.step(deltas[-1])
            deltas.append(float(error(x, y, a)))
        rows.append({"pocket": pocket + 1, "x": x, "y": y, "errors": deltas})
    last = np.array([abs(r["errors"][-1]) for r in rows])
    return {"method": method, "compensations": compensations, "max_abs_error": float(last.max()),
            "checkpoints": rows}


# ------------------------------------------------------------------------------ real time along the path
@dataclass
class Gauge:
    """The ultrasonic gauge: spot mean over the last SPOT mm, noise, limit filter."""

    noise: float
    rng: np.random.Generator
    rejected: int = 0

    def read(self, thickness_history):
        n = max(1, int(round(SPOT / STEP)))
        t = float(np.mean(thickness_history[-n:]))
        if self.noise:
            t += float(self.rng.normal(0, self.noise))
        if t > GAUGE_MAX or abs(t - T_TARGET) > GAUGE_BAND:
            self.rejected += 1
            return None
        return t


@dataclass
class Run:
    method: str
    noise: float
    latency_ms: float
    seed: int
    checkpoints: list = field(default_factory=list)
    fallbacks: int = 0
    rejected: int = 0
    steps: int = 0
    path_errors: list = field(default_factory=list)  # per pocket: the true error along the path

    def as_dict(self) -> dict:
        e = np.abs([c["error"] for c in self.checkpoints])
        return {"method": self.method, "noise": self.noise, "latency_ms": self.latency_ms, "seed": self.seed,
                "max_abs_error": float(e.max()), "min_abs_error": float(e.min()), "mean_abs_error": float(e.mean()),
                "checkpoints": self.checkpoints, "fallbacks": self.fallbacks, "rejected_readings": self.rejected,
                "compensator_steps": self.steps}


class Machine:
    """The machine side of the loop for one pocket: it cuts with the W1 offset in force and
    produces a reading every ``update`` mm. The loop runner (:mod:`ncadapt.loop`) drives it, or
    a controller (the OPC UA server in the tests) wraps it."""

    def __init__(self, pocket: int, *, noise: float, latency_ms: float, rng, t_var):
        self.pocket = pocket
        self.path = toolpath(pocket)
        cx, cy = POCKETS[pocket]
        self.t_s = T_INITIAL + t_var(self.path[:, 0] + cx, self.path[:, 1] + cy)
        self.lag = int(round(FEED * latency_ms / 1000.0 / STEP))
        self.update = int(round(SPOT / STEP)) + self.lag
        self.gauge = Gauge(noise, rng)
        self.i = 0
        self.a_cmd = A_G  # the programmed depth in force
        self.pending = None  # (sample index it lands at, depth)
        self.thickness = np.full(len(self.path), np.nan)

    @property
    def done(self) -> bool:
        return self.i >= len(self.path)

    def command(self, depth: float) -> None:
        """A new programmed depth (a_g + W1 offset); it lands ``lag`` samples later."""
        self.pending = (self.i + self.lag, float(depth))

    def advance(self):
        """Cut up to the next fresh reading; return the measured thickness (None: rejected or
        the path ended)."""
        start = self.i
        end = min(self.i + self.update, len(self.path))
        while self.i < end:
            if self.pending is not None and self.i >= self.pending[0]:
                self.a_cmd = self.pending[1]
                self.pending = None
            x, y = self.path[self.i]
            self.thickness[self.i] = self.t_s[self.i] - (self.a_cmd - deflection(x, y, self.a_cmd, self.t_s[self.i]))
            self.i += 1
        if end - start < self.update:  # the path ended: no full spot of fresh material
            return None
        return self.gauge.read(self.thickness[:end])


def machines(*, noise: float = 0.005, latency_ms: float = 45.0, seed: int = 1) -> list:
    """The machine of each pocket for a seed (one generator shared in pocket order)."""
    rng = np.random.default_rng(seed)
    t_var = thickness_variation(seed)
    return [Machine(k, noise=noise, latency_ms=latency_ms, rng=rng, t_var=t_var) for k in range(len(POCKETS))]


def compensator(method: str, noise: float = 0.005):
    """A fresh compensator as the testbed uses it (None for ``none``)."""
    if method == "none":
        return None
    return ps.make(method, A_G, **({} if method == "mirror" else {"noise": noise}))


def result(method: str, ms: list, comps: list, *, noise: float, latency_ms: float, seed: int) -> Run:
    """Errors at the checkpoints of machined pockets."""
    out = Run(method, noise, latency_ms, seed)
    for m, comp in zip(ms, comps):
        if comp is not None:
            out.fallbacks += comp.fallbacks
            out.steps += comp.steps
        out.rejected += m.gauge.rejected
        err = m.thickness - T_TARGET
        out.path_errors.append(err)
        cx, cy = POCKETS[m.pocket]
        for p, x, y in CHECKPOINTS:
            if p == m.pocket:
                k = int(np.argmin(np.hypot(m.path[:, 0] - x, m.path[:, 1] - y)))
                out.checkpoints.append({"pocket": p + 1, "x": float(cx + x), "y": float(cy + y), "error": float(err[k])})
    return out


def run(method: str = "kalman", *, noise: float = 0.005, latency_ms: float = 45.0, seed: int = 1) -> Run:
    """Finish both pockets along the toolpath with a compensator (``none``: without), in process."""
    from .. import loop as lp

    ms = machines(noise=noise, latency_ms=latency_ms, seed=seed)
    comps = []
    for m in ms:
        comps.append(compensator(method, max(noise, 1e-4)))
        lp.run_in_process(m, comps[-1])
    return result(method, ms, comps, noise=noise, latency_ms=latency_ms, seed=seed)


# ------------------------------------------------------------------------------ offline mode
def finishing_program(pocket: int = 0, depth: float = A_G) -> str:
    """G-code (mm, absolute, XY plane) that finishes a pocket along :func:`toolpath` at
    Z = −``depth`` below the roughed floor (Z = 0), in panel coordinates."""
    cx, cy = POCKETS[pocket]
    rpm = FEED * 60 / (F_Z * TEETH)
    out = [f"(ncadapt skin testbed: finish pocket {pocket + 1} to Z-{depth:g}, zig-zag along X)",
           "G21 G90 G17 G94", f"S{rpm:.0f} M3", "G0 Z5.000"]
    xs = (-140.0, 140.0)
    for j, y in enumerate(np.arange(-87.5, 87.5 + 1e-9, 12.5)):
        x0, x1 = xs if j % 2 == 0 else xs[::-1]
        if j == 0:
            out += [f"G0 X{cx + x0:.3f} Y{cy + y:.3f}", f"G1 Z{-depth:.3f} F300"]
        else:
            out.append(f"G1 Y{cy + y:.3f}")
        out.append(f"G1 X{cx + x1:.3f} F{FEED * 60:.0f}")
    out += ["G0 Z5.000", "M5", "M2"]
    return "\n".join(out) + "\n"


def thickness_map(depth: float, *, pocket: int = 0, spacing: float = 10.0, noise: float = 0.005, seed: int = 1):
    """Thickness after a pass of programmed depth ``depth`` without compensation, gauged on a grid
    over the pocket (panel coordinates, mm): columns x, y, thickness as an (n, 3) array."""
    rng = np.random.default_rng(seed)
    t_var = thickness_variation(seed)
    a, b = POCKET
    lx, ly = np.meshgrid(np.arange(-a / 2, a / 2 + 1e-9, spacing), np.arange(-b / 2, b / 2 + 1e-9, spacing))
    lx, ly = lx.ravel(), ly.ravel()
    cx, cy = POCKETS[pocket]
    t_s = T_INITIAL + t_var(lx + cx, ly + cy)
    t = t_s - (depth - deflection(lx, ly, depth, t_s)) + rng.normal(0, noise, lx.shape)
    return np.column_stack([lx + cx, ly + cy, t])
