"""Run LinuxCNC's standalone interpreter ``rs274`` and read its canonical motion.

``rs274 -g IN OUT`` prints one canonical call per line, such as
``STRAIGHT_FEED(10.0000, 2.0000, 3.0000, 0.0000, 0.0000, 0.0000)``, with lengths in the units
last set by ``USE_LENGTH_UNITS`` and 4 decimals. :func:`canonical` turns that into millimetres.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

RS274 = shutil.which("rs274")
_CALL = re.compile(r"^\s*\d+\s+N\S*\s+(\w+)\((.*)\)\s*$")
#: (first, second, normal) axis of each canonical plane
_PLANES = {"CANON_PLANE_XY": (0, 1, 2), "CANON_PLANE_XZ": (2, 0, 1), "CANON_PLANE_YZ": (1, 2, 0)}


@dataclass
class Canon:
    """Canonical motion: kinds ('traverse', 'feed', 'arc') and end points (n, 6) X Y Z A B C in mm/deg."""

    kinds: list[str]
    ends: np.ndarray
    #: for arcs: (rotation, centre first, centre second, plane name); None otherwise
    arcs: list
    #: largest rounding of a printed length in mm (0.00005 printed units)
    resolution_mm: float
    error: str | None


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
    kinds, ends, arcs = [], [], []
    res = 0.0
    for line in text.splitlines():
        m = _CALL.match(line)
        if not m:
            continue
        name, args = m.group(1), m.group(2)
        if name == "USE_LENGTH_UNITS":
            scale = 25.4 if "INCHES" in args else (10.0 if "CM" in args else 1.0)
        elif name == "SELECT_PLANE":
            plane = args.strip()
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            v = [float(a) for a in args.split(",")]
            ends.append([v[0] * scale, v[1] * scale, v[2] * scale, v[3], v[4], v[5]])
            kinds.append("traverse" if name == "STRAIGHT_TRAVERSE" else "feed")
            arcs.append(None)
            res = max(res, 0.00005 * scale)
        elif name == "ARC_FEED":
            v = [float(a) for a in args.split(",")]
            a1, a2, an = _PLANES[plane]
            e = [0.0] * 6
            e[a1], e[a2], e[an] = v[0] * scale, v[1] * scale, v[5] * scale
            e[3:6] = v[6:9]
            ends.append(e)
            kinds.append("arc")
            arcs.append((int(v[4]), v[2] * scale, v[3] * scale, plane))
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
    return Canon(kinds, np.asarray(ends, dtype=float).reshape(-1, 6), arcs, res, err)
