"""Run LinuxCNC's standalone interpreter ``rs274`` and read its canonical motion.

``rs274 -g IN OUT`` prints one canonical call per line, such as
``STRAIGHT_FEED(10.0000, 2.0000, 3.0000, 0.0000, 0.0000, 0.0000)``, with lengths in the units
last set by ``USE_LENGTH_UNITS`` and 4 decimals, in the program's coordinates; the offsets of the
work system and of G92/G52 come as ``SET_G5X_OFFSET``/``SET_G92_OFFSET`` calls. :func:`canonical`
turns that into millimetres on the machine (program coordinates plus both offsets, which rs274
starts at zero).
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

RS274 = shutil.which("rs274")
_CALL = re.compile(r"^\s*\d+\s+N\S*\s+(\w+)\((.*)\)\s*$")
#: (first, second, normal) axis of each canonical plane
_PLANES = {"CANON_PLANE_XY": (0, 1, 2), "CANON_PLANE_XZ": (2, 0, 1), "CANON_PLANE_YZ": (1, 2, 0)}


@dataclass
class Canon:
    """Canonical motion: kinds ('traverse', 'feed', 'arc', 'probe') and end points (n, 6) X Y Z A B C in
    mm/deg (a probing move's end is its target: rs274 has no probe to trip)."""

    kinds: list[str]
    ends: np.ndarray
    #: for arcs: (rotation, centre first, centre second, plane name); None otherwise
    arcs: list
    #: largest rounding of a printed length in mm (0.00005 printed units)
    resolution_mm: float
    error: str | None
    #: per move: cutter radius compensation was on (or the move is the one after G40, which
    #: leaves the offset path)
    comp: list = field(default_factory=list)
    #: per move: the feed rate rs274 set before it (SET_FEED_RATE, in the program's units per
    #: minute; under G93 the move's length times its F)
    rates: list = field(default_factory=list)
    #: spline moves (G5, G5.1: ``NURBS_FEED``), of which rs274 prints no point: the moves after
    #: one do not start where the move before it ended
    splines: int = 0
    #: per move: the offsets in force (G5x plus G92/G52, mm and degrees), which its end includes
    offsets: list = field(default_factory=list)


def canonical(path: str | Path, timeout: float = 60, tools: str | Path | None = None) -> Canon:
    """Run ``rs274 -g`` (with ``-t tools`` when given) on ``path`` and parse the motion it prints.

    rs274 maps its tool table at ``$HOME/.tool.mmap``, truncating it first, so two runs at once
    would overwrite it or kill each other with SIGBUS: each run gets a HOME of its own.
    """
    out = Path(str(path) + ".canon")
    cmd = [RS274] + (["-t", str(tools)] if tools is not None else []) + ["-g", str(path), str(out)]
    with tempfile.TemporaryDirectory(prefix="rs274-home-") as home:
        proc = subprocess.run(
            cmd,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=timeout,
            errors="replace",
            env={**os.environ, "HOME": home},
        )
    text = out.read_text(errors="replace") if out.exists() else ""
    out.unlink(missing_ok=True)
    scale = 25.4  # rs274 without an ini file works in inches until the program says otherwise
    plane = "CANON_PLANE_XY"
    g5x, g92 = np.zeros(6), np.zeros(6)
    # the XY rotation of the work system (G10 L2 R): LinuxCNC adds the G92 offset to a
    # programmed point, turns it about the work system's origin, then adds that origin
    # (emccanon's rotate_and_offset_pos)
    cos, sin = 1.0, 0.0

    def place(p):
        p = p + g92
        p[0], p[1] = cos * p[0] - sin * p[1], sin * p[0] + cos * p[1]
        return p + g5x

    def lengths(v):
        return np.array([v[0] * scale, v[1] * scale, v[2] * scale, v[3], v[4], v[5]])

    kinds, ends, arcs, comp, rates, offsets = [], [], [], [], [], []
    res, rate, splines = 0.0, 0.0, 0
    comp_on = leaving = False
    for line in text.splitlines():
        m = _CALL.match(line)
        if not m:
            continue
        name, args = m.group(1), m.group(2)
        if name == "COMMENT" and "cutter radius compensation" in args:
            comp_on, leaving = " on " in args + " ", comp_on
            continue
        if name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "STRAIGHT_PROBE", "ARC_FEED"):
            comp.append(comp_on or leaving)
            rates.append(rate)
            offsets.append(g5x + g92)
            leaving = False
        if name == "NURBS_FEED":
            splines += 1
        if name == "SET_FEED_RATE":
            rate = float(args)
        elif name == "USE_LENGTH_UNITS":
            scale = 25.4 if "INCHES" in args else (10.0 if "CM" in args else 1.0)
        elif name == "SELECT_PLANE":
            plane = args.strip()
        elif name == "SET_G5X_OFFSET":
            g5x = lengths([float(a) for a in args.split(",")[1:7]])
        elif name == "SET_G92_OFFSET":
            g92 = lengths([float(a) for a in args.split(",")[:6]])
        elif name == "SET_XY_ROTATION":
            th = math.radians(float(args))
            cos, sin = math.cos(th), math.sin(th)
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "STRAIGHT_PROBE"):
            v = [float(a) for a in args.split(",")]
            ends.append(list(place(lengths(v))))
            kinds.append({"STRAIGHT_TRAVERSE": "traverse", "STRAIGHT_FEED": "feed"}.get(name, "probe"))
            arcs.append(None)
            res = max(res, 0.00005 * scale)
        elif name == "ARC_FEED":
            v = [float(a) for a in args.split(",")]
            a1, a2, an = _PLANES[plane]
            e = np.zeros(6)
            e[a1], e[a2], e[an] = v[0] * scale, v[1] * scale, v[5] * scale
            e[3:6] = v[6:9]
            if sin != 0.0 and plane != "CANON_PLANE_XY":
                raise ValueError("an arc outside the XY plane under an XY rotation")
            c = np.zeros(6)
            c[a1], c[a2] = v[2] * scale, v[3] * scale
            ends.append(list(place(e)))
            kinds.append("arc")
            c = place(c)
            arcs.append((int(v[4]), c[a1], c[a2], plane))
            res = max(res, 0.00005 * scale)
    err = None
    if (
        proc.returncode != 0
        or "error" in proc.stderr.lower()
        or "executing" in proc.stderr
        and len(proc.stderr.splitlines()) > 1
    ):
        tail = [ln for ln in proc.stderr.splitlines() if ln.strip() and ln.strip() != "executing"]
        err = "\n".join(tail[-3:]) or f"exit {proc.returncode}"
    return Canon(kinds, np.asarray(ends, dtype=float).reshape(-1, 6), arcs, res, err, comp, rates, splines, offsets)


class Move:
    """One canonical move of rs274: a straight line or an arc (helix, turns) from the previous end."""

    def __init__(self, kind: str, start: np.ndarray, end: np.ndarray, arc, res: float = 0.0):
        self.kind, self.start, self.end = kind, start, end
        self.arc = arc
        if arc is not None:
            rot, c1, c2, plane = arc
            self.axes = _PLANES[plane]
            a1, a2, an = self.axes
            self.c = np.array([c1, c2])
            self.dir = 1 if rot > 0 else -1
            self.turns = abs(rot)
            s, e = start[[a1, a2]] - self.c, end[[a1, a2]] - self.c
            self.rs, self.re = float(np.hypot(*s)), float(np.hypot(*e))
            self.ts = math.atan2(s[1], s[0])
            base = ((math.atan2(e[1], e[0]) - self.ts) * self.dir) % (2 * math.pi)
            # start and end alike to the printed resolution `res` (the start may have been printed
            # in other units): a full circle
            if np.abs(start[[a1, a2]] - end[[a1, a2]]).max() <= 2 * res + 1e-9:
                base = 2 * math.pi
            self.sweep = base + 2 * math.pi * (self.turns - 1)

    def at(self, t: np.ndarray) -> np.ndarray:
        """XYZ at fractions t of the move."""
        t = np.asarray(t, dtype=float)
        a, b = self.start[:3], self.end[:3]
        if self.arc is None:
            return a + t[:, None] * (b - a)
        a1, a2, an = self.axes
        th = self.ts + self.dir * self.sweep * t
        r = self.rs + t * (self.re - self.rs)
        out = np.empty((len(t), 3))
        out[:, a1] = self.c[0] + r * np.cos(th)
        out[:, a2] = self.c[1] + r * np.sin(th)
        out[:, an] = a[an] + t * (b[an] - a[an])
        return out

    def locate(self, p: np.ndarray, t_from: float = 0.0) -> tuple[float, float]:
        """(largest coordinate difference, fraction t) between p and the nearest point of the move;
        on an arc, of the first turn at or after fraction t_from that comes within 1 µm of the
        nearest (a full circle or P turns pass the same angle more than once)."""
        a, b = self.start[:3], self.end[:3]
        if self.arc is None:
            ab = b - a
            L2 = float(ab @ ab)
            t = 0.0 if L2 == 0 else float(np.clip((p - a) @ ab / L2, 0, 1))
            return float(np.abs(a + t * ab - p).max()), t
        a1, a2, _ = self.axes
        d = p[[a1, a2]] - self.c
        ang = ((math.atan2(d[1], d[0]) - self.ts) * self.dir) % (2 * math.pi)
        t = np.clip((ang + 2 * math.pi * np.arange(-1, self.turns + 1)) / self.sweep, 0, 1)
        # the nearest point of the helix near each angle: on a steep helix the angle of p, taken
        # about rs274's rounded centre, is a poor guess of where along the normal axis it is
        t = self._nearest(p, t)
        dist = np.abs(self.at(t) - p).max(axis=1)
        ok = (t >= t_from - 1e-6) & (dist <= dist.min() + 1e-3)
        i = int(np.flatnonzero(ok)[0]) if ok.any() else int(np.argmin(dist))
        return float(dist[i]), float(t[i])

    def _nearest(self, p: np.ndarray, t0: np.ndarray, w: float = 0.15) -> np.ndarray:
        """Fractions of the points of the move nearest to p within each t0 ± w (a grid, refined)."""
        t = np.asarray(t0, dtype=float)
        k = np.linspace(-1, 1, 41)
        for _ in range(5):
            grid = np.clip(t[:, None] + w * k[None, :], 0, 1)
            d2 = np.sum((self.at(grid.ravel()) - p) ** 2, axis=1).reshape(grid.shape)
            t = grid[np.arange(len(t)), np.argmin(d2, axis=1)]
            w /= 20
        return t

    def dist(self, p: np.ndarray) -> float:
        return self.locate(p)[0]

    def dense(self, step=0.25, sagitta=1e-4) -> np.ndarray:
        """XYZ along the move, close enough that the polyline stays within `sagitta` of it."""
        if self.arc is None:
            n = int(np.ceil(np.linalg.norm(self.end[:3] - self.start[:3]) / step))
        else:
            r = max(self.rs, self.re, 1e-6)
            dth = 2 * math.acos(max(-1.0, 1 - sagitta / r))
            n = int(np.ceil(self.sweep / dth))
        return self.at(np.linspace(0, 1, min(max(n, 1), 200000) + 1))


def moves(canon: Canon) -> list[Move]:
    out = []
    prev = np.zeros(6)  # rs274 starts at the origin
    for kind, end, arc in zip(canon.kinds, canon.ends, canon.arcs):
        out.append(Move(kind, prev, end, arc, canon.resolution_mm))
        prev = end
    return out
