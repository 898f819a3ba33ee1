"""A virtual skin-milling testbed: the panel of Wu et al.'s experiment, deterministic for a seed.

Panel: 1500 × 1200 × 3 mm, Al 7050 (E = 71.7 GPa, ν = 0.33); two 300 × 200 mm pockets centred at
(450, 600) and (1050, 600), roughed 1 mm deep (T_s = 2.0 mm plus a seeded smooth thickness
variation of ±0.02 mm), finished a_g = 0.5 mm to the target T_g = 1.5 mm. Cutter Ø20, 2 flutes,
f_z = 0.09375 mm at 8000 rpm (assumed: the paper's table of finishing parameters is not in its
text): feed v = 1500 mm/min = 25 mm/s.

Equations:

- mean axial force over a slot (φ from 0 to π, h = f_z sin φ, N_t teeth, per revolution):
  F(a_p) = N_t a_p (K_ac f_z / π + K_ae / 2), K_ac = 642.5 N/mm², K_ae = 128.29 N/mm (the paper's
  coefficients) — 83.3 N at a_p = 0.5 mm;
- the pocket floor as a Kirchhoff plate clamped at the pocket walls (the 3 mm rim is 8× stiffer),
  D ∇⁴w = q with D = E t³ / (12(1 − ν²)), solved by finite differences on a 5 mm grid
  (:func:`plate_green`: the 13-point biharmonic stencil, clamped edges by mirrored ghost nodes,
  the inverse operator is the Green's function). The tests hold it to Timoshenko and
  Woinowsky-Krieger, Theory of Plates and Shells, Table 35 (clamped, central load: α = 0.00560
  square … 0.00722 at b/a = 2; uniform load 0.00126 … 0.00254) and, with simply supported edges,
  to Navier's double series off the diagonal. At the centre α = 0.00710;
- the cutting force as a moving point load at the tool axis, and the floating support head on the
  opposite face as six constant point forces P_s = 12.5 N (the paper: 0.05 MPa of air, measured
  with a Kistler 9272; a piston of 250 mm²) on a ring about the tool axis, one every 60° from +x
  (:func:`support_points`; a support beyond the pocket presses on the rim and does nothing).
  Constant forces, not springs: they shift the deflection and leave its slope alone. The
  deflection under the tool, f = (F(a_r) α(x; x) − P_s Σ α(x; x + s_i)) b²/D(t);
- the force follows the chip really cut (the paper iterates its finite-element model because the
  force and the error are coupled): a_r = a_p − f(a_r), with the wall thinned to
  t = T_s − θ a_r (:func:`real_depth`, closed form in a_r); the error δ = a_g − a_r, thickness
  T = T_s − a_r;
- calibrated, both to the paper's finite-element protocol at the pocket centre (point 7): the
  ring radius r_s = 56.8 mm (:func:`support_radius`) so that the mirror leaves 32.2 µm after the
  second compensation, and θ = 0.031 so that the secant leaves 0.213 µm. Not calibrated and not
  met: the uncompensated error at the centre is 0.142 mm here, the paper's 0.24 mm (its model is the
  whole curved panel on 16 clamps; with the chip-coupled force no support ring gives more than the
  bare plate's 0.236 mm with this slope). The largest error is at the centre, as in the paper's
  finite-element results; the corners' is the smallest (the paper's lower-right one is its
  smallest because of the panel's clamps, which a pocket model does not see);
- the gauge: its 7 mm spot is centred on the tool path (as in the paper: "the measuring position
  lies at the centre of the tool path"), its back half on the floor just cut, its front half
  under the cutter being cut at the depth in force; seeded normal noise σ; the limit filter drops
  readings above 10 mm or more than 0.3 mm from T_g;
- dead time τ (30–60 ms): a W1 command lands v·τ after the reading it came from. The compensator
  steps on every fresh reading — one whose spot lies wholly on material cut after the last
  command landed — so readings come every 3.5 mm + v·τ of path (4.6 mm at 45 ms).

Toolpath: in each pocket a zig-zag along x, x ∈ [−140, 140] mm, 15 lines 12.5 mm apart
(y ∈ [−87.5, 87.5]) about the pocket's centre, sampled every 0.25 mm. The compensator starts
fresh (a_p = a_g) in each pocket.

The 13 checkpoints of each pocket (:data:`POINTS`, pocket-local x, y in mm; the paper's figure 8
is not in its text, so the layout is assumed): five at y = +50 (x = −100, −50, 0, 50, 100), three
at y = 0 (x = −100, 0, 100; point 7 the centre), five at y = −50, numbered row by row from the
upper left. The error at a checkpoint is the true (noise-free) thickness error where the path
passes over it.
"""

from __future__ import annotations

import functools
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
PLATE_GRID = 5.0  # mm, the finite-difference grid of the pocket floor
THETA = 0.031  # calibrated: the paper's finite-element secant, 0.213 µm after the second compensation
MIRROR_FE = 0.0322  # mm: the paper's finite-element mirror after the second compensation
SUPPORTS = 6  # the floating support head's supports
SUPPORT_PRESSURE = 0.05  # MPa, constant
SUPPORT_FORCE = 12.5  # N per support, constant (the paper's Kistler 9272 measurement)
POCKET = (300.0, 200.0)
POCKETS = ((450.0, 600.0), (1050.0, 600.0))
SPOT = 7.0  # mm, the gauge spot
GAUGE_MAX = 10.0
GAUGE_BAND = 0.3
STEP = 0.25  # mm of path per sample
#: the 13 checkpoints of a pocket (pocket-local x, y in mm), numbered 1–13 row by row from the
#: upper left: five at y = +50, three at y = 0 (point 7 the centre), five at y = −50
POINTS = (
    tuple((x, 50.0) for x in (-100.0, -50.0, 0.0, 50.0, 100.0))
    + ((-100.0, 0.0), (0.0, 0.0), (100.0, 0.0))
    + tuple((x, -50.0) for x in (-100.0, -50.0, 0.0, 50.0, 100.0))
)
CENTRE_POINT = 7
#: (pocket index, x, y) of every checkpoint: the 13 of pocket 1, then the 13 of pocket 2
CHECKPOINTS = tuple((p, x, y) for p in range(2) for x, y in POINTS)


def force(a_p):
    """Mean axial force, N."""
    return TEETH * np.asarray(a_p, float) * (K_AC * F_Z / math.pi + K_AE / 2)


def rigidity(t):
    return E * np.asarray(t, float) ** 3 / (12 * (1 - NU * NU))


def plate_green(a: float, b: float, h: float, edges: str = "clamped"):
    """Green's function of a rectangular Kirchhoff plate by finite differences.

    D ∇⁴w = q on an a × b plate, a grid of spacing ``h``; the interior nodes are the unknowns, w = 0
    on the edges, and through a ghost node mirrored about the edge either a zero slope
    (``edges="clamped"``: w_ghost = w_inner, the one-dimensional fourth difference has 7 instead of
    6 on its first and last diagonal) or a zero moment (``"simple"``: w_ghost = −w_inner, 5);
    ∇⁴ = δ⁴x + 2 δ²x δ²y + δ⁴y (the 13-point stencil). A load P at a node is q = P/h² there, so the
    deflection at every node under a unit load at every node is the inverse operator over h².

    Returns the node coordinates x (across a) and y (across b), both centred with the edges
    included, and the dimensionless influence coefficients α[i, j, k, l] = w(x_i, y_j) D / (P b²)
    for P at (x_k, y_l) (0 on the edges) — Timoshenko and Woinowsky-Krieger's α when both points
    are the centre.
    """
    import scipy.sparse as sp

    if edges not in ("clamped", "simple"):
        raise ValueError(f'edges must be "clamped" or "simple", got {edges!r}')
    corner = 7.0 if edges == "clamped" else 5.0
    nx, ny = int(round(a / h)) - 1, int(round(b / h)) - 1

    def ops(n):
        e = np.ones(n)
        d2 = sp.diags([e[:-1], -2 * e, e[:-1]], [-1, 0, 1]) / h**2
        d4 = sp.diags([e[:-2], -4 * e[:-1], 6 * e, -4 * e[:-1], e[:-2]], [-2, -1, 0, 1, 2]).tolil()
        d4[0, 0] = d4[-1, -1] = corner
        return d2.tocsr(), d4.tocsr() / h**4

    d2x, d4x = ops(nx)
    d2y, d4y = ops(ny)
    k = sp.kron(d4x, sp.identity(ny)) + 2 * sp.kron(d2x, d2y) + sp.kron(sp.identity(nx), d4y)
    green = np.zeros((nx + 2, ny + 2, nx + 2, ny + 2))
    green[1:-1, 1:-1, 1:-1, 1:-1] = (np.linalg.inv(k.toarray()) / (h * b) ** 2).reshape(nx, ny, nx, ny)
    return np.linspace(-a / 2, a / 2, nx + 2), np.linspace(-b / 2, b / 2, ny + 2), green


def plate_coefficients(a: float, b: float, h: float, edges: str = "clamped"):
    """Point-load compliance of a rectangular plate by finite differences (:func:`plate_green`):
    the node coordinates x and y and the coefficient α = w D / (P b²) under the load, at every node
    (the diagonal of the Green's function; 0 on the edges)."""
    x, y, green = plate_green(a, b, h, edges)
    n = len(x) * len(y)
    return x, y, np.diagonal(green.reshape(n, n)).reshape(len(x), len(y)).copy()


@functools.lru_cache(maxsize=1)
def _plate():
    from scipy.interpolate import RegularGridInterpolator

    x, y, green = plate_green(*POCKET, PLATE_GRID, "clamped")
    n = len(x) * len(y)
    diag = np.diagonal(green.reshape(n, n)).reshape(len(x), len(y))
    return RegularGridInterpolator((x, y), diag, bounds_error=False, fill_value=0.0), green.reshape(n, n), x, y


def _weights(px, py):
    """Bilinear weights of pocket-local points on the plate's grid: flat node indices (n, 4) and
    weights (n, 4); a point outside the pocket (on the rib) has weight 0."""
    _, _, x, y = _plate()
    h = x[1] - x[0]
    fx, fy = (px - x[0]) / h, (py - y[0]) / h
    i = np.clip(np.floor(fx).astype(int), 0, len(x) - 2)
    j = np.clip(np.floor(fy).astype(int), 0, len(y) - 2)
    u, v = fx - i, fy - j
    idx = np.stack([i * len(y) + j, (i + 1) * len(y) + j, i * len(y) + j + 1, (i + 1) * len(y) + j + 1], -1)
    w = np.stack([(1 - u) * (1 - v), u * (1 - v), (1 - u) * v, u * v], -1)
    w[(fx < 0) | (fx > len(x) - 1) | (fy < 0) | (fy > len(y) - 1)] = 0.0
    return idx, w


def influence(lx, ly, sx, sy):
    """α(x, y; ξ, η) = w(x, y) D / (P b²) of the clamped pocket floor: the deflection at
    pocket-local (``lx``, ``ly``) under a point load at (``sx``, ``sy``), mm; the load spread to its
    cell's four nodes and the deflection read between them (bilinear); 0 when either point is
    outside the pocket."""
    lx, ly, sx, sy = np.broadcast_arrays(*(np.asarray(v, float) for v in (lx, ly, sx, sy)))
    green = _plate()[1]
    i, w = _weights(lx.ravel(), ly.ravel())
    k, v = _weights(sx.ravel(), sy.ravel())
    g = green[i[:, :, None], k[:, None, :]]
    return np.einsum("na,nb,nab->n", w, v, g).reshape(lx.shape)


def alpha(lx, ly):
    """The clamped pocket floor's point-load coefficient α(x, y) = w D / (P b²) under a load at
    pocket-local (x, y), mm (bilinear between the finite-difference nodes; 0 outside the pocket)."""
    lx, ly = np.broadcast_arrays(np.asarray(lx, float), np.asarray(ly, float))
    return _plate()[0](np.column_stack([lx.ravel(), ly.ravel()])).reshape(lx.shape)


def support_points(radius: float):
    """Pocket-local offsets (6, 2) of the supports from the tool axis, mm: a ring of ``radius``,
    one support every 60° from +x."""
    ang = np.deg2rad(60.0 * np.arange(SUPPORTS))
    return radius * np.column_stack([np.cos(ang), np.sin(ang)])


def support_alpha(lx, ly, radius: float | None = None):
    """Σ α(x, y; x + s_i) over the six supports about the tool axis at pocket-local (x, y): the
    deflection under the tool per unit support force, in units of b²/D (a support off the pocket
    presses on the rib and contributes nothing)."""
    r = support_radius() if radius is None else radius
    lx, ly = np.broadcast_arrays(np.asarray(lx, float), np.asarray(ly, float))
    return sum(influence(lx, ly, lx + sx, ly + sy) for sx, sy in support_points(r))


def compliance(coefficient, t):
    """Point compliance C = α b² / D(t) of the pocket floor, mm/N."""
    return coefficient * POCKET[1] ** 2 / rigidity(t)


def real_depth(coefficient, support, a_p, t_s=T_INITIAL):
    """The depth a_r the cutter really removes with programmed depth ``a_p``, mm, where the plate's
    coefficient under the tool is ``coefficient`` and the supports' summed one ``support``.

    The force follows the chip really cut, F(a_r), and the wall, thinned to t = T_s − θ a_r, gives
    way by f = (F(a_r) α − P_s Σα_s) b²/D(t) (the six supports' constant forces push it back
    towards the cutter); a_r = a_p − f. With F = K a linear this is
    a_r = (a_p + P_s Σα_s b²/D) / (1 + K α b²/D), solved with D(t) from the previous iterate (θ is
    small: three rounds leave < 1e-12 mm). A programmed depth short of the surface (a_p < 0, the
    offline re-cut) cuts only if the supports push the wall that far: a_r ≥ 0."""
    k = float(force(1.0))
    a_p = np.asarray(a_p, float)
    a_r = np.maximum(a_p, 0.0)
    for _ in range(4):
        c = compliance(1.0, t_s - THETA * a_r)
        a_r = np.maximum((a_p + SUPPORT_FORCE * np.asarray(support) * c) / (1 + k * np.asarray(coefficient) * c), 0.0)
    return a_r


@functools.lru_cache(maxsize=1)
def support_radius() -> float:
    """The radius of the supports' ring, mm, calibrated so that the paper's finite-element protocol
    with the error mirror leaves its 32.2 µm after the second compensation at the pocket centre."""
    from scipy.optimize import brentq

    def mirror(r):
        s = support_alpha(0.0, 0.0, r)
        a, d = A_G, 0.0
        for _ in range(3):
            a += d
            d = A_G - float(real_depth(alpha(0.0, 0.0), s, a))
        return d - MIRROR_FE

    return float(brentq(mirror, 5.0, 95.0))


def deflection(lx, ly, a_p, t_s=T_INITIAL):
    """f(a_p) = a_p − a_r at pocket-local (x, y), mm."""
    return deflection_at(alpha(lx, ly), support_alpha(lx, ly), a_p, t_s)


def deflection_at(coefficient, support, a_p, t_s=T_INITIAL):
    """f(a_p) = a_p − a_r, mm (:func:`real_depth`)."""
    return np.asarray(a_p, float) - real_depth(coefficient, support, a_p, t_s)


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


def _line_x():
    return np.arange(-140.0, 140.0 + 1e-9, STEP)


def _line_y():
    """Pocket-local y of the zig-zag's lines."""
    return np.arange(-87.5, 87.5 + 1e-9, 12.5)


def line_samples() -> int:
    """Samples per line of the zig-zag."""
    return len(_line_x())


def toolpath(pocket: int):
    """Pocket-local (x, y) samples of the zig-zag, every STEP mm."""
    xs = _line_x()
    lines = []
    for j, y in enumerate(_line_y()):
        x = xs if j % 2 == 0 else xs[::-1]
        lines.append(np.column_stack([x, np.full_like(x, y)]))
    return np.concatenate(lines)


def spiral_path():
    """Pocket-local (x, y) samples, every STEP mm, of a spiral out from the centre: the centre
    line y = 0, x ∈ [−50, 50] mm, then rings 12.5 mm apart (half-sizes 50 + 12.5k by 12.5k,
    k = 1 … 7), each entered from the previous by a 12.5 mm step outward along +x and run
    anticlockwise (N, W, S, E, N) back to its start."""
    corners = [(-50.0, 0.0), (50.0, 0.0)]
    for k in range(1, 8):
        a, b = 50.0 + 12.5 * k, 12.5 * k
        corners += [(a, 0.0), (a, b), (-a, b), (-a, -b), (a, -b), (a, 0.0)]
    out = [np.array(corners[0])]
    for p0, p1 in zip(corners[:-1], corners[1:]):
        p0, p1 = np.array(p0), np.array(p1)
        n = int(round(np.linalg.norm(p1 - p0) / STEP))
        out += [p0 + (p1 - p0) * t for t in np.arange(1, n + 1) / n]
    return np.array(out)


def readable(path: np.ndarray) -> np.ndarray:
    """(n,) bool: the samples where a reading can be taken — the gauge's spot lies on one straight
    piece of the path (SPOT/2 from every turn)."""
    d = np.diff(path, axis=0)
    turn = np.zeros(len(path), bool)
    turn[1:-1] = np.abs(d[1:, 0] * d[:-1, 1] - d[1:, 1] * d[:-1, 0]) > 1e-9
    turn[[0, -1]] = True
    h = int(round(SPOT / 2 / STEP))
    idx = np.flatnonzero(turn)
    near = np.zeros(len(path), bool)
    for i in idx:
        near[max(0, i - h) : i + h] = True
    return ~near


@dataclass(frozen=True)
class Variant:
    """A testbed condition beyond the paper's (issue 21 item 3).

    ``feed`` (mm/s) with the spindle speed scaled so f_z and the force stay the paper's;
    ``latency_ms`` replaces the run's dead time when given; ``gauge_hz`` a fixed-rate gauge (a
    reading every 1/f s whether or not it reflects the latest command, drawn per seed from the
    range); ``path`` ``"zigzag"`` or ``"spiral"``; ``servo_ms`` the time constant of the W1 axis
    as a first-order servo (0: it moves at once when the command lands)."""

    name: str
    feed: float = FEED
    latency_ms: float | None = None
    gauge_hz: tuple | None = None
    path: str = "zigzag"
    servo_ms: float = 0.0


#: the paper's condition and the variants the default compensator must hold on
VARIANTS = {
    "paper": Variant("paper"),
    "fixed-rate": Variant("fixed-rate", gauge_hz=(20.0, 25.0)),
    "spiral": Variant("spiral", path="spiral"),
    "fast": Variant("fast", feed=100.0, latency_ms=60.0),
    "servo": Variant("servo", servo_ms=30.0),
}


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
        point = POINTS.index((x, y)) + 1
        rows.append({"pocket": pocket + 1, "point": point, "x": x, "y": y, "errors": deltas})
    last = np.array([abs(r["errors"][-1]) for r in rows])
    return {"method": method, "compensations": compensations, "max_abs_error": float(last.max()), "checkpoints": rows}


# ------------------------------------------------------------------------------ real time along the path
@dataclass
class Gauge:
    """The ultrasonic gauge: the mean thickness over its spot, noise, the limit filter."""

    noise: float
    rng: np.random.Generator
    rejected: int = 0

    def read(self, spot):
        """A reading of the mean thickness over the spot's points."""
        t = float(np.mean(spot))
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
    max_abs_w1: float = 0.0  # mm, the largest W1 command
    clamped: int = 0  # commands the interlocks bounded

    def as_dict(self) -> dict:
        e = np.abs([c["error"] for c in self.checkpoints])
        return {
            "method": self.method,
            "noise": self.noise,
            "latency_ms": self.latency_ms,
            "seed": self.seed,
            "max_abs_error": float(e.max()),
            "min_abs_error": float(e.min()),
            "mean_abs_error": float(e.mean()),
            "checkpoints": self.checkpoints,
            "fallbacks": self.fallbacks,
            "rejected_readings": self.rejected,
            "compensator_steps": self.steps,
            "max_abs_w1": self.max_abs_w1,
            "clamped": self.clamped,
        }


class Machine:
    """The machine side of the loop for one pocket: it cuts with the W1 offset in force and stops
    at the next fresh reading. The loop runner (:mod:`ncadapt.loop`) drives it, or a controller
    (the OPC UA server in the tests) wraps it.

    The floor at a path sample takes the real depth in force when the tool axis passes it; the
    gauge spot is centred on the tool axis, its back half on the floor just cut, its front half
    under the cutter, being cut at the depth in force (with the deflection at the axis). A reading
    is fresh when the back half was cut after the latest command landed, SPOT/2 + v·τ of path
    after the reading that caused it."""

    def __init__(self, pocket: int, *, noise: float, latency_ms: float, rng, t_var, variant: Variant | None = None):
        v = variant or VARIANTS["paper"]
        self.variant = v
        self.pocket = pocket
        self.path = spiral_path() if v.path == "spiral" else toolpath(pocket)
        cx, cy = POCKETS[pocket]
        self.t_s = T_INITIAL + t_var(self.path[:, 0] + cx, self.path[:, 1] + cy)
        self.alpha = alpha(self.path[:, 0], self.path[:, 1])
        self.support = support_alpha(self.path[:, 0], self.path[:, 1])
        self.readable = readable(self.path)
        latency = v.latency_ms if v.latency_ms is not None else latency_ms
        self.lag = int(round(v.feed * latency / 1000.0 / STEP))
        self.half_spot = int(round(SPOT / 2 / STEP))
        self.period = None  # samples between readings of a fixed-rate gauge
        if v.gauge_hz is not None:
            hz = float(rng.uniform(*v.gauge_hz))
            self.period = max(1, int(round(v.feed / hz / STEP)))
        dt = STEP / v.feed  # s per sample
        self.servo = 1.0 - math.exp(-dt / (v.servo_ms / 1000.0)) if v.servo_ms > 0 else 1.0
        self.gauge = Gauge(noise, rng)
        self.i = 0
        self.a_cmd = A_G  # the programmed depth commanded to the axis
        self.a_eff = A_G  # the depth in force (the servo's output)
        self.pending: list = []  # (sample index it lands at, depth), in order
        self.landed = 0  # the sample at which the latest command landed
        self.last_read = -(10**9)
        self.thickness = np.full(len(self.path), np.nan)

    @property
    def done(self) -> bool:
        return self.i >= len(self.path)

    def command(self, depth: float) -> None:
        """A new programmed depth (a_g + W1 offset); it lands ``lag`` samples later."""
        self.pending.append((self.i + self.lag, float(depth)))

    def _cut(self, at: int, points) -> np.ndarray:
        """Thickness of ``points`` cut with the depth in force and the tool axis at sample ``at``."""
        f = deflection_at(self.alpha[at], self.support[at], self.a_eff, self.t_s[at])
        return self.t_s[points] - (self.a_eff - f)

    def advance(self):
        """Cut up to the next reading — the next fresh one (the paper's gauge), or the next of a
        fixed-rate gauge; return the measured thickness (None: rejected, or the path ended)."""
        h = self.half_spot
        while self.i < len(self.path):
            i = self.i
            while self.pending and i >= self.pending[0][0]:
                self.a_cmd, self.landed = self.pending.pop(0)[1], i
            self.a_eff += self.servo * (self.a_cmd - self.a_eff)
            self.thickness[i] = self._cut(i, i)
            self.i += 1
            if not (h <= i < len(self.path) - h and self.readable[i]):
                continue
            if self.period is not None:
                due = i - self.last_read >= self.period
            else:
                due = not self.pending and i - h >= self.landed
            if due:
                self.last_read = i
                ahead = self._cut(i, np.arange(i + 1, i + h + 1))
                return self.gauge.read(np.concatenate([self.thickness[i - h : i + 1], ahead]))
        return None


def machines(*, noise: float = 0.005, latency_ms: float = 45.0, seed: int = 1, variant: str = "paper") -> list:
    """The machine of each pocket for a seed (one generator shared in pocket order)."""
    rng = np.random.default_rng(seed)
    t_var = thickness_variation(seed)
    v = VARIANTS[variant]
    return [
        Machine(k, noise=noise, latency_ms=latency_ms, rng=rng, t_var=t_var, variant=v) for k in range(len(POCKETS))
    ]


def compensator(method: str, noise: float = 0.005):
    """A fresh compensator as the testbed uses it (None for ``none``)."""
    if method == "none":
        return None
    return ps.make(method, A_G, noise=noise)


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
                out.checkpoints.append(
                    {
                        "pocket": p + 1,
                        "point": POINTS.index((x, y)) + 1,
                        "x": float(cx + x),
                        "y": float(cy + y),
                        "error": float(err[k]),
                    }
                )
    return out


def run(
    method: str = "kalman",
    *,
    noise: float = 0.005,
    latency_ms: float = 45.0,
    seed: int = 1,
    on_progress=None,
    variant: str = "paper",
) -> Run:
    """Finish both pockets along the toolpath with a compensator (``none``: without), in process,
    behind the loop's interlocks with their defaults (:class:`ncadapt.processes.skin.Interlocks`);
    if they stop the loop, the pocket is finished with W1 held. ``on_progress(done, total)`` gets
    the path samples cut so far."""
    from .. import loop as lp

    ms = machines(noise=noise, latency_ms=latency_ms, seed=seed, variant=variant)
    comps, guards = [], []
    total = sum(len(m.path) for m in ms)
    for k, m in enumerate(ms):
        comps.append(compensator(method, max(noise, 1e-4)))
        guards.append(ps.Interlocks(T_TARGET, A_G))
        before = sum(len(p.path) for p in ms[:k])
        step = None if on_progress is None else (lambda n, t, w, _m=m, _b=before: on_progress(_b + _m.i, total))
        try:
            link = lp.MachineLink(m, A_G)
            lp.run(link, link, comps[-1], T_TARGET, guard=guards[-1], on_step=step)
        except ps.LoopStopped:
            while not m.done:
                m.advance()
        if on_progress is not None:
            on_progress(before + len(m.path), total)
    out = result(method, ms, comps, noise=noise, latency_ms=latency_ms, seed=seed)
    out.max_abs_w1 = max(g.max_abs_w1 for g in guards)
    out.clamped = sum(g.clamped for g in guards)
    return out


# ------------------------------------------------------------------------------ offline mode
def finishing_program(pocket: int = 0, depth: float = A_G) -> str:
    """G-code (mm, absolute, XY plane) that finishes a pocket along :func:`toolpath` at
    Z = −``depth`` below the roughed floor (Z = 0), in panel coordinates."""
    cx, cy = POCKETS[pocket]
    rpm = FEED * 60 / (F_Z * TEETH)
    out = [
        f"(ncadapt skin testbed: finish pocket {pocket + 1} to Z-{depth:g}, zig-zag along X)",
        "G21 G90 G17 G94",
        f"S{rpm:.0f} M3",
        "G0 Z5.000",
    ]
    xs = (-140.0, 140.0)
    for j, y in enumerate(_line_y()):
        x0, x1 = xs if j % 2 == 0 else xs[::-1]
        if j == 0:
            out += [f"G0 X{cx + x0:.3f} Y{cy + y:.3f}", f"G1 Z{-depth:.3f} F300"]
        else:
            out.append(f"G1 Y{cy + y:.3f}")
        out.append(f"G1 X{cx + x1:.3f} F{FEED * 60:.0f}")
    out += ["G0 Z5.000", "M5", "M2"]
    return "\n".join(out) + "\n"


def recut(lx, ly, t_now, depth, t_s=T_INITIAL):
    """The wall thickness after a pass programmed ``depth`` (mm below the roughed floor, Z = −depth)
    over a floor already cut to thickness ``t_now`` (pocket-local x, y; the roughed thickness
    ``t_s``): the cutter's programmed engagement is a = depth − (T_s − t_now) (negative when it
    passes short of the floor), the wall, now t_now thick, gives way under the chip it really cuts
    and the supports push it back (:func:`real_depth`, 0 when they do not bring it to the cutter).
    The testbed's own law for the offline rounds (no compensator formula in it)."""
    lx, ly, t_now, depth, t_s = np.broadcast_arrays(*(np.asarray(v, float) for v in (lx, ly, t_now, depth, t_s)))
    return t_now - real_depth(alpha(lx, ly), support_alpha(lx, ly), depth - (t_s - t_now), t_now)


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
