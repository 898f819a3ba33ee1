"""A virtual lathe: turning a slender shaft between chuck and tailstock with a given program,
revolution by revolution — a model of its own, not the planner's closed form.

Physics per revolution (SI inside; the configuration of :mod:`ncadapt.processes.turning` gives the
shaft, the supports, the tool and ρ(V)):

- the depth of cut is taken from the **programmed** radius, the paper's eq. 5:
  t = r_s − X₁ − (x₁ + y₁), r_s the radius of the stock at the tool (the bar, or the surface a
  previous cut left), X₁ the programmed radius interpolated along the block;
- contact check (the paper, after eq. 5): t ≤ 0 means no contact — no force, the surface is left as
  it was, and the run reports where;
- the chip area is the exact one of a sharp tool with plan angles φ, φ₁ (not the linearised one):
  S t − ζ S² where t ≥ 2ζS (eq. 4), t²/(4ζ) where the depth is smaller than the trailing triangle;
- the feed per revolution is the path of the tool tip over the revolution, eq. 5's
  S_p = S + a(prev) − a with a = x₃ + y₃ the axial deflection (the previous revolution's is kept);
- the force F₀ = ρ(V)·area along λ deflects the tool (c^(X) x = λF₀) and the workpiece
  (c^(Y)(x3) y = λF₀, the beam on elastic supports); the scalar equation F₀ = ρ·area(F₀) is solved
  exactly each revolution (a safeguarded Newton iteration; the area falls as F₀ grows, so the root
  is unique);
- ρ(V) with the cutting speed V = π·(2 r_s)·n on the stock's diameter, as the paper's table;
- the revolution's surface is r = X₁ + x₁ + y₁ (eq. 1) where there is contact.

Optional seeded scatter: the cutting pressure ρ and the stiffness each get one log-normal factor
per run, exp(σ·N(0, 1)) (always positive), and ρ a slow linear drift along the cut of ±σ/2 (tool
wear). σ is at most 0.5.

The program is read as its controller reads it (``dialect``: LinuxCNC, Fanuc lathe in G-code system
A — diameter programming, G99, G50 S — or Sinumerik — DIAMON/DIAMOF, G95, LIMS=). For LinuxCNC:
G0/G1 with X (diameter under G7, radius under G8; one of them must be set), Z (Z0 at the tailstock centre, the chuck face at Z−L), F in
mm/rev under G95 and S (rpm under G97; under G96 the surface speed in m/min, rpm = 1000·V/(π·d) at
the tool's diameter d, capped by the G96 D word, which must be given). Refused at their line: feed
per minute (G94; G98, Fanuc's feed per minute, and G99), F ≤ 0 or over 5 mm/rev, inch (G20),
incremental (G91), arcs, threading and cycles, Z beyond the chuck face or the tailstock centre on a
cut, a rapid into the stock, a cut towards the tailstock.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from .._io import read_text
from ..errors import InputError
from ..processes import turning as tu

_WORD = re.compile(r"([A-Z])\s*([-+]?\d*\.?\d+)")
FEED_MAX = 5.0  # mm/rev: far beyond any turning insert's feed
RPM_MAX = 100_000.0
REVOLUTIONS_MAX = 2_000_000  # revolutions of cutting a program may ask the virtual lathe for
SIGMA_MAX = 0.5
GRID = 0.05  # mm: the stock surface is kept on this grid along the shaft


@dataclass
class Move:
    line: int
    z0: float  # mm
    z1: float
    r0: float  # programmed radius at the start, mm
    r1: float
    feed: float  # mm/rev
    speed: float  # rpm under G97, m/min under G96
    css: bool
    cap: float  # rpm limit under G96


@dataclass
class Profile:
    x3: np.ndarray  # mm from the tailstock centre: the stock grid's points the cuts passed
    diameter: np.ndarray  # mm, the surface left there after the whole program
    deflection: np.ndarray  # mm, radial, of the last revolution there (0 without contact)
    time_s: float
    target: float  # mm: the shaft's diameter after the cut, D − 2 t_p
    no_contact: list = field(default_factory=list)  # (x3 from, x3 to, revolutions), mm
    revolutions: int = 0

    @property
    def error_max(self) -> float:
        """max |D − D_target|, mm."""
        return float(np.max(np.abs(self.diameter - self.target)))

    @property
    def variation(self) -> float:
        """max D − min D, mm."""
        return float(np.ptp(self.diameter))

    def as_dict(self) -> dict:
        return {
            "measure": "diameter, mm (error: max |D - D_target|; variation: max D - min D)",
            "diameter_target": self.target,
            "diameter_error_max": self.error_max,
            "diameter_variation": self.variation,
            "diameter_min": float(self.diameter.min()),
            "diameter_max": float(self.diameter.max()),
            "machining_time_s": self.time_s,
            "revolutions": self.revolutions,
            "no_contact": [{"x3_from": a, "x3_to": b, "revolutions": n} for a, b, n in self.no_contact],
            "profile": [{"x3": float(a), "diameter": float(d)} for a, d in zip(self.x3[::10], self.diameter[::10])],
        }


_KNOWN_G = {
    "linuxcnc": {0, 1, 4, 7, 8, 17, 18, 19, 21, 40, 43, 49, 54, 55, 56, 57, 58, 59, 61, 64, 80, 90, 95, 96, 97},
    "fanuc": {0, 1, 4, 18, 21, 40, 50, 54, 55, 56, 57, 58, 59, 80, 96, 97, 99},
    "sinumerik": {0, 1, 4, 17, 18, 19, 40, 54, 55, 56, 57, 60, 64, 71, 90, 95, 96, 97, 500},
}
_SINUMERIK_WORD = re.compile(r"\b(LIMS\s*=\s*([-+]?\d*\.?\d+)|DIAMON|DIAMOF|DIAM90)\b")


def read_program(path, length: float | None = None, dialect: str = "linuxcnc") -> list[Move]:
    """The feed moves of a lathe program (see the module) with their lines, mm; ``length`` (mm)
    bounds Z: a move beyond the chuck face (Z < −length) is refused. ``dialect``: how the program
    is read — ``linuxcnc`` (G7/G8, G95, G96 D), ``fanuc`` (lathe, G-code system A: diameter
    programming, G99 feed per revolution, G50 S spindle limit, T0101) or ``sinumerik`` (DIAMON/
    DIAMOF, G95, LIMS=, T1 D1)."""
    if dialect not in _KNOWN_G:
        raise ValueError(f"dialect must be one of {', '.join(_KNOWN_G)}, got {dialect!r}")
    path = str(path)
    text = read_text(path)
    fanuc, sinu = dialect == "fanuc", dialect == "sinumerik"
    diam, css, cap, per_rev = (True if fanuc else None), False, math.inf, False
    motion, x, z, f, s = None, None, None, None, None
    known = _KNOWN_G[dialect]
    moves = []
    for ln, raw in enumerate(text.splitlines(), 1):
        line = re.sub(r"\(.*?\)|;.*", "", raw).upper()
        if line.strip() == "%":
            continue
        if sinu:
            for mt in _SINUMERIK_WORD.finditer(line):
                word = mt.group(1)
                if word == "DIAMON":
                    diam = True
                elif word == "DIAMOF":
                    diam = False
                elif word == "DIAM90":
                    raise InputError("DIAM90 is not simulated; use DIAMON or DIAMOF", path, ln, mt.start() + 1)
                else:
                    v = float(mt.group(2))
                    if not 0 < v <= RPM_MAX:
                        raise InputError(
                            f"LIMS={mt.group(2)} must be > 0 and at most {RPM_MAX:g} rpm", path, ln, mt.start() + 1
                        )
                    cap = v
            line = _SINUMERIK_WORD.sub(" ", line)
            if "=" in line:
                raise InputError(
                    "an assignment (NAME=…) is not simulated on the virtual lathe", path, ln, line.find("=") + 1
                )
        x_new, z_new, xw = x, z, None
        g50 = False
        for mt in _WORD.finditer(line):
            letter, val, col = mt.group(1), mt.group(2), mt.start() + 1
            v = float(val)
            if not math.isfinite(v):
                raise InputError(f"{letter} must be finite", path, ln, col)
            if letter == "G":
                g = round(v, 1)
                if g in (2, 3):
                    raise InputError("arcs are not simulated on the virtual lathe", path, ln, col)
                if g == 94 and not fanuc:
                    raise InputError(
                        "feed per minute (G94): the virtual lathe needs feed per revolution (G95)", path, ln, col
                    )
                if g == 98 and fanuc:
                    raise InputError(
                        "feed per minute (G98): the virtual lathe needs feed per revolution (G99 on a Fanuc lathe)",
                        path,
                        ln,
                        col,
                    )
                if g in (98, 99) and not fanuc:
                    raise InputError(
                        f"G{g:g}: feed per {'minute' if g == 98 else 'revolution'} on a Fanuc lathe "
                        f"(G-code system A), not in {dialect}; read as --dialect fanuc, or use G95 "
                        "feed per revolution",
                        path,
                        ln,
                        col,
                    )
                if g == 20 or (sinu and g == 70):
                    raise InputError(f"inch units (G{g:g}): the virtual lathe reads millimetre programs", path, ln, col)
                if g == 91:
                    raise InputError("incremental distances (G91) are not simulated; use G90", path, ln, col)
                if g not in known:
                    raise InputError(f"G{g:g} is not simulated on the virtual lathe ({dialect})", path, ln, col)
                if g in (0, 1):
                    motion = int(g)
                elif g == 7:
                    diam = True
                elif g == 8:
                    diam = False
                elif g == 96:
                    css = True
                elif g == 97:
                    css = False
                elif g in (95, 99):
                    per_rev = True
                elif g == 50:
                    g50 = True
            elif letter == "X":
                xw = (v, col)
            elif letter == "Z":
                z_new = v
            elif letter in ("U", "W") and fanuc:
                raise InputError(f"incremental {letter} words are not simulated; use X and Z", path, ln, col)
            elif letter == "F":
                if not 0 < v <= FEED_MAX:
                    raise InputError(f"feed F{val} mm/rev must be > 0 and at most {FEED_MAX:g} mm/rev", path, ln, col)
                f = v
            elif letter == "S":
                if not 0 < v <= RPM_MAX:
                    raise InputError(f"S{val} must be > 0 and at most {RPM_MAX:g}", path, ln, col)
                if g50:
                    cap = v  # Fanuc: G50 S is the spindle limit
                else:
                    s = v
            elif letter == "D" and dialect == "linuxcnc":
                if not v > 0:
                    raise InputError(f"the G96 speed limit D{val} must be > 0 rpm", path, ln, col)
                cap = v
        if g50 and (xw is not None or z_new != z):
            raise InputError("G50 with X or Z sets the coordinate system: not simulated", path, ln, 1)
        if xw is not None:
            if diam is None:
                raise InputError(
                    "an X word before G7 (diameter) or G8 (radius) mode is set"
                    if not sinu
                    else "an X word before DIAMON (diameter) or DIAMOF (radius) is set",
                    path,
                    ln,
                    xw[1],
                )
            x_new = xw[0] / 2 if diam else xw[0]
            if x_new < 0:
                raise InputError(f"X{xw[0]:g} is below the axis", path, ln, xw[1])
        if length is not None and z_new is not None and z_new < -length - 1e-9:
            raise InputError(f"Z{z_new:g} is beyond the chuck face (Z{-length:g})", path, ln, line.find("Z") + 1 or 1)
        moved = x_new != x or z_new != z
        if motion == 1 and moved and x is not None and z is not None:
            if not per_rev:
                raise InputError(f"a cut before feed per revolution ({'G99' if fanuc else 'G95'}) is set", path, ln, 1)
            if f is None or s is None:
                raise InputError("a cut before F and S are set", path, ln, 1)
            if css and not math.isfinite(cap):
                raise InputError(
                    "G96 without a spindle-speed limit ("
                    + {"linuxcnc": "D", "fanuc": "G50 S", "sinumerik": "LIMS="}[dialect]
                    + "): the speed would grow without bound near the "
                    "axis",
                    path,
                    ln,
                    1,
                )
            moves.append(Move(ln, z, z_new, x, x_new, f, s, css, cap))
        elif motion == 0 and moved and x_new is not None and z_new is not None:  # a rapid: checked, not cut
            moves.append(
                Move(ln, z_new if z is None else z, z_new, x_new if x is None else x, x_new, 0.0, 0.0, False, math.inf)
            )
        x, z = x_new, z_new
    return moves


def _area(s: float, t: float, zeta: float) -> tuple[float, float, float]:
    """Chip area of a sharp tool and its derivatives (∂/∂S, ∂/∂t), SI."""
    if t <= 0 or s <= 0:
        return 0.0, 0.0, 0.0
    if t >= 2 * zeta * s:
        return s * t - zeta * s * s, t - 2 * zeta * s, s
    return t * t / (4 * zeta), 0.0, t / (2 * zeta)


def _force(rho, g, g3, s, a_prev, t0, zeta) -> float:
    """F₀ solving F₀ = ρ·area(S + a_prev − g₃F₀, t₀ − gF₀) (safeguarded Newton), N."""
    hi = rho * _area(s + a_prev, t0, zeta)[0]
    if hi <= 0:
        return 0.0
    lo, F = 0.0, 0.0
    for _ in range(100):
        a, da_s, da_t = _area(s + a_prev - g3 * F, t0 - g * F, zeta)
        h = F - rho * a
        if h > 0:
            hi = min(hi, F)
        else:
            lo = max(lo, F)
        dh = 1 + rho * (g3 * da_s + g * da_t)
        nxt = F - h / dh
        if not lo <= nxt <= hi:
            nxt = 0.5 * (lo + hi)
        if abs(nxt - F) <= 1e-13 * max(1.0, abs(F)):
            return nxt
        F = nxt
    return F


def simulate(
    cfg: tu.Config,
    program_path,
    *,
    rho_sigma: float = 0.0,
    stiffness_sigma: float = 0.0,
    seed: int = 1,
    progress=None,
    dialect: str = "linuxcnc",
    entry_transient: bool = True,
) -> Profile:
    """Turn the shaft of ``cfg`` with the program (see the module); ``progress(fraction)`` is
    called as the revolutions go by.

    ``entry_transient=False`` turns a lathe without it, to measure what it costs: the revolution
    that enters the stock after a revolution without contact cuts as if the axial deflection of
    the revolution before were already its own (S_p = S, the steady state the planner assumes)
    instead of 0."""
    for name, v in (("rho_sigma", rho_sigma), ("stiffness_sigma", stiffness_sigma)):
        if not (math.isfinite(v) and 0 <= v <= SIGMA_MAX):
            raise InputError(f"{name} must be within 0 … {SIGMA_MAX:g}, got {v!r}")
    rng = np.random.default_rng(seed)
    rs = math.exp(rho_sigma * rng.normal()) if rho_sigma else 1.0
    ks = math.exp(stiffness_sigma * rng.normal()) if stiffness_sigma else 1.0
    drift = rho_sigma * rng.uniform(-0.5, 0.5) if rho_sigma else 0.0
    m = tu.Model(cfg, stiffness_scale=ks)
    L = cfg.length * 1e3
    moves = read_program(program_path, L, dialect)
    src = str(program_path)
    grid = np.arange(0.0, L + GRID / 2, GRID)  # x3, mm
    stock = np.full(len(grid), cfg.diameter / 2 * 1e3)  # radius, mm

    def stock_at(a):
        return float(np.interp(a, grid, stock))

    # checks and the work up front
    revs_total = 0
    for mv in moves:
        a0, a1 = -mv.z0, -mv.z1
        if mv.feed == 0:
            continue
        if a1 > a0 + 1e-12:
            revs_total += math.ceil((a1 - a0) / mv.feed)
            if a0 < -1e-9 and min(mv.r0, mv.r1) < cfg.diameter / 2 * 1e3:
                raise InputError(f"a cut from Z{mv.z0:g}, beyond the tailstock centre (Z0)", src, mv.line, 1)
        elif a1 < a0 - 1e-12 and min(mv.r0, mv.r1) < max(stock_at(a0), stock_at(a1)) - 1e-6:
            raise InputError("a cut towards the tailstock (+Z) is not simulated on the virtual lathe", src, mv.line, 1)
    if not any(-mv.z1 > -mv.z0 + 1e-12 and mv.feed > 0 for mv in moves):
        raise InputError("no cut along the shaft (G1 towards negative Z)", src)
    if revs_total > REVOLUTIONS_MAX:
        raise InputError(
            f"the program asks for {revs_total:,} revolutions of cutting; the virtual lathe turns at "
            f"most {REVOLUTIONS_MAX:,} (a feed too small?)",
            src,
        )

    zeta = m.zeta
    lam = cfg.lam
    s_tool = m.s_tool
    covered = np.zeros(len(grid), bool)
    defl = np.zeros(len(grid))  # mm, the last revolution's radial deflection there
    t, done = 0.0, 0
    a_cur, a_prev = -1.0, 0.0  # where the next revolution starts; the last axial deflection, m
    no_contact: list = []
    nc_run = None
    for mv in moves:
        a0, a1 = -mv.z0, -mv.z1
        if mv.feed == 0:  # a rapid must end clear of the stock as it is now
            if 0 <= a1 <= L and mv.r1 < stock_at(a1) - 1e-6:
                raise InputError(
                    f"a rapid move (G0) into the stock: radius {mv.r1:.4f} mm at Z{mv.z1:g} inside "
                    f"the work (radius {stock_at(a1):.4f} mm there)",
                    src,
                    mv.line,
                    1,
                )
            continue
        n_const = mv.speed if not mv.css else None
        if a1 <= a0 + 1e-12:  # a radial move (plunge or retract): time only
            dr = abs(mv.r1 - mv.r0)
            n = n_const if n_const else min(1000 * mv.speed / (math.pi * 2 * max(min(mv.r0, mv.r1), 1e-6)), mv.cap)
            t += dr / mv.feed * 60.0 / n
            continue
        # the revolutions go on from where the last block left them (a block ends mid-revolution)
        start = a_cur if a0 - 1e-9 <= a_cur < a1 else a0
        k = max(1, math.ceil((a1 - start) / mv.feed - 1e-9))
        pos = start + mv.feed * np.arange(k)
        a_cur = float(start + mv.feed * k)
        frac = (pos - a0) / (a1 - a0)
        r_prog = mv.r0 + frac * (mv.r1 - mv.r0)
        comp = s_tool[None] + m.workpiece_compliance(pos * 1e-3)
        gs, g3s = comp[:, 0, :] @ lam, comp[:, 2, :] @ lam
        for j in range(k):
            a, rp = float(pos[j]), float(r_prog[j])
            n = n_const if n_const else min(1000 * mv.speed / (math.pi * 2 * max(rp, 1e-6)), mv.cap)
            lo_i, hi_i = np.searchsorted(grid, [a - 1e-9, min(a + mv.feed, a1) - 1e-9])
            hi_i = max(hi_i, lo_i + 1)
            rsk = float(stock[lo_i:hi_i].max())  # the material ahead of the tool this revolution
            v = math.pi * 2 * rsk * 1e-3 * n  # m/min on the stock's diameter
            rho = float(np.interp(v, cfg.rho_speed, cfg.rho)) * rs * (1 + drift * (a / L - 0.5) * 2)
            t0 = (rsk - rp) * 1e-3
            F = _force(rho, float(gs[j]), float(g3s[j]), mv.feed * 1e-3, a_prev, t0, zeta) if t0 > 0 else 0.0
            if F > 0 and a_prev == 0.0 and not entry_transient:  # the steady state: a_prev = g₃F₀ (fixed point)
                for _ in range(200):
                    nxt = _force(rho, float(gs[j]), float(g3s[j]), mv.feed * 1e-3, float(g3s[j]) * F, t0, zeta)
                    if abs(nxt - F) <= 1e-12 * F:
                        break
                    F = nxt
                F = nxt
            w = float(gs[j]) * F * 1e3  # mm
            a_prev = float(g3s[j]) * F  # no contact: 0, the next contact is an entry
            covered[lo_i:hi_i] = True
            defl[lo_i:hi_i] = w
            if F > 0:
                stock[lo_i:hi_i] = np.minimum(stock[lo_i:hi_i], rp + w)
                if nc_run is not None:
                    no_contact.append(tuple(nc_run))
                    nc_run = None
            else:
                nc_run = [nc_run[0], a, nc_run[2] + 1] if nc_run else [a, a, 1]
            t += 60.0 / n
            done += 1
            if progress is not None and done % 2000 == 0:
                progress(done / revs_total)
        if nc_run is not None:
            no_contact.append(tuple(nc_run))
            nc_run = None
    x_cut = grid[covered]
    return Profile(
        x_cut,
        2 * stock[covered],
        defl[covered],
        t,
        (cfg.diameter - 2 * cfg.depth) * 1e3,
        [(float(a), float(b), int(c)) for a, b, c in no_contact],
        done,
    )
