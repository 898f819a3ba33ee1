"""A virtual lathe: turning a slender shaft with a given program on the model of
:mod:`ncadapt.processes.turning`, revolution by revolution (the paper's 6 × 6 system with the
previous revolution's axial deflections), with optional seeded scatter of the cutting pressure ρ
and of the stiffness (one factor per run, normal with the given relative σ, plus a slow drift of ρ
along the cut, ±σ/2, as tool wear would give).

The program is read as the planner writes it: G0/G1 lines with X (diameter under G7, radius under
G8), Z (Z0 at the tailstock centre, the chuck at Z−L), F (mm/rev under G95) and S (rpm under G97;
G96 is constant surface speed: rpm = 1000·V/(π·d), capped by D). The diameter left at each
revolution is 2·(X₁ + x₁ + y₁) with X₁ the programmed radius.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..processes import turning as tu

_WORD = re.compile(r"([A-Z])\s*([-+]?\d*\.?\d+)")


@dataclass
class Profile:
    x3: np.ndarray  # mm from the tailstock centre
    diameter: np.ndarray  # mm
    deflection: np.ndarray  # mm, radial
    time_s: float
    target: float  # mm: the shaft's diameter after the cut, D − 2 t_p

    @property
    def error_max(self) -> float:
        return float(np.max(np.abs(self.diameter - self.target)))

    def as_dict(self) -> dict:
        return {"diameter_target": self.target, "diameter_error_max": self.error_max,
                "diameter_variation": float(np.ptp(self.diameter)), "diameter_min": float(self.diameter.min()),
                "diameter_max": float(self.diameter.max()), "machining_time_s": self.time_s,
                "profile": [{"x3": float(a), "diameter": float(d)} for a, d in zip(self.x3[::10], self.diameter[::10])]}


def read_program(path) -> list[tuple[float, float, float, float]]:
    """The cutting moves of a lathe program: (z_start, z_end, radius at the end, feed mm/rev,
    rpm) per G1 block, in mm; refuses what it cannot follow, naming the line."""
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror}", str(path)) from None
    diam, css, cap = True, False, math.inf
    motion, x, z, f, s = None, None, None, None, None
    moves = []
    for ln, raw in enumerate(text.splitlines(), 1):
        line = re.sub(r"\(.*?\)|;.*", "", raw).upper()
        words = _WORD.findall(line)
        x_new, z_new = x, z
        for letter, val in words:
            v = float(val)
            if letter == "G":
                g = round(v, 1)
                if g in (0, 1):
                    motion = int(g)
                elif g in (2, 3):
                    raise InputError("arcs are not simulated on the virtual lathe", str(path), ln, 1)
                elif g == 7:
                    diam = True
                elif g == 8:
                    diam = False
                elif g == 96:
                    css = True
                elif g == 97:
                    css = False
                elif g == 94:
                    raise InputError("feed per minute (G94): the virtual lathe needs G95", str(path), ln, 1)
            elif letter == "X":
                x_new = v / 2 if diam else v
            elif letter == "Z":
                z_new = v
            elif letter == "F":
                f = v
            elif letter == "S":
                s = v
            elif letter == "D":
                cap = v
        if motion == 1 and (x_new != x or z_new != z) and x is not None and z is not None:
            if f is None or s is None:
                raise InputError("a cut before F and S are set", str(path), ln, 1)
            rpm = min(1000 * s / (math.pi * 2 * max(x_new, 1e-6)), cap) if css else s
            moves.append((z, z_new, x, x_new, f, rpm))
        x, z = x_new, z_new
    return moves


def simulate(cfg: tu.Config, program_path, *, rho_sigma: float = 0.0, stiffness_sigma: float = 0.0,
             seed: int = 1) -> Profile:
    rng = np.random.default_rng(seed)
    rs = 1 + rho_sigma * rng.normal() if rho_sigma else 1.0
    ks = 1 + stiffness_sigma * rng.normal() if stiffness_sigma else 1.0
    drift = rho_sigma * rng.uniform(-0.5, 0.5) if rho_sigma else 0.0
    m = tu.Model(cfg, rho_scale=rs, stiffness_scale=ks)
    cuts = [c for c in read_program(program_path) if c[1] < c[0]]  # towards the chuck
    if not cuts:
        raise InputError("no cut along the shaft (G1 towards negative Z)", str(program_path))
    L = cfg.length * 1e3
    xs, dia, dfl = [], [], []
    prev, t = 0.0, 0.0
    first = True
    for z0, z1, r0, r1, f, n in cuts:
        a = -z0
        while a < -z1 - 1e-9:
            frac = (a + z0) / (z0 - z1)
            r_prog = r0 + frac * (r1 - r0)
            m.rho_scale = rs * (1 + drift * (a / L - 0.5) * 2)
            x = m.solve_revolution(a * 1e-3, f * 1e-3, n, prev)
            if first:
                for _ in range(50):
                    x = m.solve_revolution(a * 1e-3, f * 1e-3, n, x[2] + x[5])
                first = False
            prev = x[2] + x[5]
            d = (x[0] + x[3]) * 1e3
            xs.append(a)
            dfl.append(d)
            dia.append(2 * (r_prog + d))
            t += 60.0 / n
            a += f
    return Profile(np.array(xs), np.array(dia), np.array(dfl), t, (cfg.diameter - 2 * cfg.depth) * 1e3)
