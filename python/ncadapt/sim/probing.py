"""A virtual touch probe: runs a LinuxCNC probing program (as :mod:`ncadapt.probing` writes it)
against a machined z-map and writes the log the controller would write.

The machine:

- ``G0`` moves go where they are told (the program keeps them clear of the part).
- A ``G38.2`` move carries the stylus ball (radius r, its centre the controlled point) from where
  it is towards the target and stops at contact: the first t along the move where some point of
  the z-map (bilinear, sampled every h/4) lies inside the ball. Found by stepping 0.2 mm and
 bisecting to 1e-6 mm. The trip position is the contact position plus the travel during the
  trigger delay (delay × feed, along the move) plus normal noise along the move (seeded).
- No contact before the target: LinuxCNC's error "G38.2 probe move finished without tripping";
  the program stops (:class:`ProbeFailure`, carrying the log written so far).
- ``(PROBEOPEN f)`` logs every probe move as ``x y z a b c u v w`` (``%f``), ``(LOG,#5061 #5062
  #5063)`` writes the last trip position (with ``(LOGOPEN,f)``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .freeform import ZMap

__all__ = ["ProbeFailure", "ProbeRun", "run"]

_WORD = re.compile(r"([A-Z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


class ProbeFailure(RuntimeError):
    """A probe move ended without contact; ``log`` is what was logged before."""

    def __init__(self, line: int, log: str):
        self.line = line
        self.log = log
        super().__init__(f"line {line}: G38.2 probe move finished without tripping")


@dataclass(frozen=True)
class ProbeRun:
    """The log text and the trip positions (n, 3) of every probe move, mm."""

    log: str
    trips: np.ndarray


def _ball_offsets(radius: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    k = int(np.ceil(radius / h))
    o = np.arange(-k, k + 1) * h
    dx, dy = np.meshgrid(o, o, indexing="ij")
    inside = dx**2 + dy**2 <= radius * radius
    dx, dy = dx[inside], dy[inside]
    return np.column_stack([dx, dy]), np.sqrt(np.maximum(radius * radius - dx**2 - dy**2, 0.0))


def _gap(zmap: ZMap, c: np.ndarray, offs: np.ndarray, cap: np.ndarray) -> np.ndarray:
    """For ball centres c (m, 3): min over the ball's footprint of (lower ball surface − material);
    ≤ 0 means the ball is in contact. Beyond the z-map there is no material."""
    x = c[:, None, 0] + offs[None, :, 0]
    y = c[:, None, 1] + offs[None, :, 1]
    fi = (x - zmap.x0) / zmap.h
    fj = (y - zmap.y0) / zmap.h
    nx, ny = zmap.z.shape
    z = ndimage.map_coordinates(zmap.z, [fi.ravel(), fj.ravel()], order=1, mode="nearest").reshape(x.shape)
    off = (fi < 0) | (fi > nx - 1) | (fj < 0) | (fj > ny - 1)
    g = (c[:, None, 2] - cap[None, :]) - z
    g[off] = np.inf
    return g.min(axis=1)


def _contact(zmap, start, end, offs, cap, step=0.2):
    d = end - start
    length = float(np.linalg.norm(d))
    if length == 0:
        return None
    u = d / length
    ts = np.append(np.arange(0.0, length, step), length)
    g = _gap(zmap, start + ts[:, None] * u, offs, cap)
    hit = np.flatnonzero(g <= 0)
    if not len(hit):
        return None
    k = int(hit[0])
    if k == 0:
        return start.copy()  # already touching where the move starts
    lo, hi = ts[k - 1], ts[k]
    while hi - lo > 1e-6:
        mid = (lo + hi) / 2
        if _gap(zmap, (start + mid * u)[None], offs, cap)[0] <= 0:
            hi = mid
        else:
            lo = mid
    return start + hi * u


def run(
    program: str, zmap: ZMap, *, stylus_radius: float, noise: float = 0.0, trigger_delay: float = 0.0, seed: int = 0
) -> ProbeRun:
    """Run a LinuxCNC probing program written by :mod:`ncadapt.probing` (G0, G38.2, G90/G91,
    PROBEOPEN/LOGOPEN/LOG comments) on ``zmap``. ``noise`` mm (standard deviation along the move),
    ``trigger_delay`` s."""
    rng = np.random.default_rng(seed)
    offs, cap = _ball_offsets(stylus_radius, zmap.h / 4) if stylus_radius > 0 else (np.zeros((1, 2)), np.zeros(1))
    pos = np.array([0.0, 0.0, 0.0])
    absolute = True
    feed = 0.0
    logging = None  # "probe" (every move) or "log" (LOG lines)
    log: list[str] = []
    trips: list[np.ndarray] = []
    last = None
    for n, raw in enumerate(program.splitlines(), 1):
        line = raw.strip()
        m = re.match(r"\(PROBEOPEN\s+(\S+)\)", line)
        if m:
            logging = "probe"
            continue
        if re.match(r"\(LOGOPEN,", line):
            logging = "log"
            continue
        if line.startswith("(LOG,"):
            if last is None:
                raise ValueError(f"line {n}: LOG before any probe move")
            log.append(" ".join(f"{v:f}" for v in last))
            continue
        if line.startswith("(") or not line:
            continue
        code = re.sub(r"\([^)]*\)", "", line).upper()
        words = _WORD.findall(code)
        gs = [float(v) for a, v in words if a == "G"]
        axes = {a: float(v) for a, v in words if a in "XYZ"}
        for a, v in words:
            if a == "F":
                feed = float(v)
        if 90.0 in gs:
            absolute = True
        if 91.0 in gs:
            absolute = False
        target = pos.copy()
        for k, a in enumerate("XYZ"):
            if a in axes:
                target[k] = axes[a] if absolute else pos[k] + axes[a]
        if 38.2 in gs:
            c = _contact(zmap, pos, target, offs, cap)
            if c is None:
                raise ProbeFailure(n, "".join(s + "\n" for s in log))
            u = (target - pos) / np.linalg.norm(target - pos)
            trip = c + u * (trigger_delay * feed / 60.0 + (rng.normal(0.0, noise) if noise > 0 else 0.0))
            pos = trip
            last = trip
            trips.append(trip)
            if logging == "probe":
                log.append(" ".join(f"{v:f}" for v in (*trip, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
        elif axes:
            pos = target
    return ProbeRun("".join(s + "\n" for s in log), np.asarray(trips).reshape(-1, 3))
