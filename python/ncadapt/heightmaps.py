"""Height maps written by autoleveling senders: grbl ``[PRB:…]`` reports, OpenCNCPilot ``.hmap``,
Candle ``.map``.

Each reader returns a :class:`ncadapt.fields.GridField` (points on a full rectangular grid) or a
:class:`ncadapt.fields.ScatteredField` (any other layout) whose Z displacement is the probed height,
as bCNC, Candle and OpenCNCPilot apply it: the program's Z plus the height at (x, y). Errors name the
file, line and column.

Formats (read from the senders' sources):

- **grbl**: after every G38.x move grbl prints ``[PRB:x,y,z:s]`` (``s`` 1 when the probe touched,
  0 when not), in *machine* coordinates (grbl 1.1 ``report.c``, ``report_probe_parameters``). The
  work position is the machine position minus the work coordinate offset: the last status report's
  ``WCO:x,y,z`` before the line, or — without one — the ``$#`` report's ``[G54:…]`` (or the
  ``G55``…``G59`` a ``[GC:…]`` report names) plus ``[G92:…]`` plus ``[TLO:z]``. A log with neither
  is refused: the map would be in machine coordinates. Sender console logs (UGS, cncjs, bCNC) carry
  the reports with prefixes (time stamps, ``>>``, ``<``): a report is found anywhere on its line.
  Consecutive reports at one (x, y) are touches of one point (a fast and a slow touch): the last
  counts. ``$13=1`` (reports in inches) is refused. The ``$#`` report ends with ``[TLO:…]`` and a
  ``[PRB:…]`` that repeats the last probe (zeros and flag 0 after power-up): a report on the line
  after ``[TLO:…]`` is that one, not a probe move, and is skipped.
- **OpenCNCPilot** (``HeightMap.Save``): ``<heightmap MinX MinY MaxX MaxY SizeX SizeY>`` with one
  ``<point X="i" Y="j">height</point>`` per probed node; node (i, j) is at
  (MinX + i (MaxX − MinX)/(SizeX − 1), MinY + j (MaxY − MinY)/(SizeY − 1)).
- **Candle** (``frmMain::saveHeightMap``, ``.map``): ``x;y;width;height``, ``nx;ny;zbottom;ztop``,
  ``interpolation;stepx;stepy``, then ``ny`` rows of ``nx`` heights separated by ``;``; row i,
  column j is at (x + j width/(nx − 1), y + i height/(ny − 1)).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from ._io import read_text
from .constants import COORD_MAX
from .errors import InputError, cut

__all__ = [
    "read_grbl_log",
    "read_hmap",
    "read_candle_map",
    "read_worded_log",
    "is_grbl_log",
    "is_worded_log",
    "prb_reports",
    "worded_points",
]

#: Most nodes of a height map read (a 1000 x 1000 map is far beyond any autolevel grid).
MAX_NODES = 1_000_000

_PRB = re.compile(r"\[PRB:([^\]]*)\]")
_WCO = re.compile(r"\bWCO:([^|>]*)")
_OFFSET = re.compile(r"\[(G5[4-9]|G92|TLO):([^\]]*)\]")
_GC = re.compile(r"\[GC:([^\]]*)\]")
_INCH = re.compile(r"^\s*\$13\s*=\s*1\b")


def _num(word: str, src: str, line: int, col: int, what: str) -> float:
    try:
        v = float(word)
    except ValueError:
        raise InputError(f"{what}: expected a number, found {cut(word.strip())}", src, line, col) from None
    if not math.isfinite(v):
        raise InputError(f"{what}: value is not finite ({word.strip()})", src, line, col)
    if abs(v) > COORD_MAX:
        raise InputError(f"{what}: {v:g} is beyond ±{COORD_MAX:g} mm, larger than any machine value", src, line, col)
    return v


def _numbers(text: str, src: str, line: int, col: int, what: str) -> list[float]:
    """Comma-separated numbers starting at ``col`` (1-based) of ``line``."""
    out, pos = [], col
    for w in text.split(","):
        out.append(_num(w, src, line, pos, what))
        pos += len(w) + 1
    return out


_WORDED = re.compile(r"^\s*X\s*(\S+?)\s*Y\s*(\S+?)\s*Z\s*(\S+?)\s*$")


def is_worded_log(text: str) -> bool:
    """Whether a log's first line that is not blank is ``X… Y… Z…`` (Fanuc ``DPRNT`` output)."""
    first = next((ln for ln in text.splitlines() if ln.strip()), "")
    return first.lstrip().upper().startswith("X")


def worded_points(path) -> tuple[np.ndarray, np.ndarray]:
    """The ``X… Y… Z…`` lines of a Fanuc ``DPRNT`` log (as the ``fanuc`` probing programs write
    them), in order: (m, 3) mm and their line numbers."""
    path = Path(path)
    src = str(path)
    out, lines = [], []
    for n, line in enumerate(read_text(path).splitlines(), 1):
        if not line.strip():
            continue
        m = _WORDED.match(line.upper())
        if not m:
            raise InputError("expected a line 'X<x> Y<y> Z<z>' (Fanuc DPRNT output)", src, n, 1)
        out.append([_num(m.group(k), src, n, m.start(k) + 1, "probe position") for k in (1, 2, 3)])
        lines.append(n)
    if not out:
        raise InputError("no probe points", src)
    return np.asarray(out), np.asarray(lines, dtype=np.int64)


def read_worded_log(path, method: str = "linear", outside: str = "error"):
    """Read a Fanuc ``DPRNT`` probe log (``X… Y… Z…`` lines) as a field, Z displacement = probed Z."""
    from . import fields

    a, lines = worded_points(path)
    return fields.from_values(
        np.round(a[:, 0], 6),
        np.round(a[:, 1], 6),
        a[:, 2],
        method=method,
        outside=outside,
        source=str(path),
        linenos=lines,
    )


def is_grbl_log(text: str) -> bool:
    """Whether a text holds grbl probe reports."""
    return "[PRB:" in text


def prb_reports(path) -> list[tuple[int, np.ndarray]]:
    """The successful ``[PRB:…]`` reports of a grbl log in work coordinates: (line, (x, y, z))."""
    path = Path(path)
    src = str(path)
    text = read_text(path)
    wco = None  # the last status report's work coordinate offset
    offsets: dict[str, list[float]] = {}
    wcs = "G54"
    out: list[tuple[int, np.ndarray]] = []
    after_tlo = False  # the `$#` report ends [TLO:…] [PRB:…]: that PRB repeats the last probe, or zeros
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        in_report, after_tlo = after_tlo, "[TLO:" in line
        if _INCH.search(line):
            raise InputError("$13=1: grbl reports positions in inches; set $13=0 (mm) and probe again", src, n, 1)
        for m in _WCO.finditer(line):
            v = _numbers(m.group(1).strip(), src, n, m.start(1) + 1, "WCO")
            if len(v) < 3:
                raise InputError(f"WCO needs x,y,z, found {len(v)} number(s)", src, n, m.start(1) + 1)
            wco = np.asarray(v[:3])
        for m in _OFFSET.finditer(line):
            v = _numbers(m.group(2), src, n, m.start(2) + 1, m.group(1))
            need = 1 if m.group(1) == "TLO" else 3
            if len(v) < need:
                raise InputError(f"[{m.group(1)}:…] needs {need} number(s), found {len(v)}", src, n, m.start(2) + 1)
            offsets[m.group(1)] = v
        for m in _GC.finditer(line):
            w = re.search(r"\bG5[4-9]\b", m.group(1))
            if w:
                wcs = w.group(0)
        for m in _PRB.finditer(line):
            if in_report:
                continue  # the `$#` report's line, not a probe move
            body = m.group(1)
            col = m.start(1) + 1
            if ":" not in body:
                raise InputError("a probe report is [PRB:x,y,z:s]; the success flag is missing", src, n, col)
            coords, flag = body.rsplit(":", 1)
            if flag.strip() not in ("0", "1"):
                raise InputError(
                    f"probe report success flag must be 0 or 1, found {cut(flag.strip())}",
                    src,
                    n,
                    col + len(coords) + 1,
                )
            v = _numbers(coords, src, n, col, "probe position")
            if len(v) < 3:
                raise InputError(f"probe report needs x,y,z, found {len(v)} number(s)", src, n, col)
            if flag.strip() == "0":
                raise InputError(
                    "probe report with success flag 0: the probe did not touch (grbl alarm); the map "
                    "is incomplete, probe again",
                    src,
                    n,
                    m.start() + 1,
                )
            if wco is not None:
                off = wco
            elif wcs in offsets:
                off = np.asarray(offsets[wcs][:3]) + np.asarray(offsets.get("G92", [0.0, 0.0, 0.0])[:3])
                off = off + np.array([0.0, 0.0, offsets.get("TLO", [0.0])[0]])
            else:
                raise InputError(
                    "grbl reports probe positions in machine coordinates and the log holds no work offset before "
                    f"this report (a status report with WCO: or the $# report's [{wcs}:…]); send $# before probing "
                    "and keep its output in the log",
                    src,
                    n,
                    m.start() + 1,
                )
            out.append((n, np.asarray(v[:3]) - off))
    return out


def read_grbl_log(path, method: str = "linear", outside: str = "error"):
    """Read the grbl ``[PRB:…]`` reports of a sender's console log or a plain capture as a field
    (Z displacement = the probed work Z); see the module docstring for the rules."""
    from . import fields

    path = Path(path)
    reports = prb_reports(path)
    if not reports:
        raise InputError("no [PRB:x,y,z:1] probe reports", str(path))
    pts: list[np.ndarray] = []
    lines: list[int] = []
    for n, p in reports:
        if pts and np.allclose(pts[-1][:2], p[:2], atol=1e-6, rtol=0):
            pts[-1], lines[-1] = p, n  # a second (slow) touch of the same point
            continue
        pts.append(p)
        lines.append(n)
    a = np.asarray(pts)
    return fields.from_values(
        np.round(a[:, 0], 6),
        np.round(a[:, 1], 6),
        a[:, 2],
        method=method,
        outside=outside,
        source=str(path),
        linenos=np.asarray(lines),
    )


def read_hmap(path, method: str = "linear", outside: str = "error"):
    """Read an OpenCNCPilot ``.hmap`` height map as a :class:`~ncadapt.fields.GridField`."""
    from lxml import etree

    path = Path(path)
    src = str(path)
    read_text(path)  # UTF-8 with a located error
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False)
    try:
        root = etree.parse(src, parser).getroot()
    except OSError as e:
        raise InputError(f"not a readable .hmap (XML) file: {e}", src) from None
    except etree.XMLSyntaxError as e:
        line, col = e.position if e.position else (0, 0)
        msg = re.sub(r",? line \d+, column \d+$", "", e.msg or "")
        raise InputError(f"not well-formed XML (.hmap): {msg}", src, line or 0, col or 0) from None
    if root is None or not isinstance(root.tag, str) or etree.QName(root).localname != "heightmap":
        raise InputError(
            "not an OpenCNCPilot height map: the root element must be <heightmap>",
            src,
            getattr(root, "sourceline", 0) or 0,
        )
    ln = root.sourceline or 0

    def attr(name):
        v = root.get(name)
        if v is None:
            raise InputError(f"<heightmap> has no {name} attribute", src, ln)
        return v

    x0, y0, x1, y1 = (_num(attr(k), src, ln, 0, k) for k in ("MinX", "MinY", "MaxX", "MaxY"))
    sizes = []
    for k in ("SizeX", "SizeY"):
        s = attr(k).strip()
        if not re.fullmatch(r"\d{1,7}", s) or int(s) < 2:
            raise InputError(f"{k} must be a whole number of at least 2, found {cut(s)}", src, ln)
        sizes.append(int(s))
    nx, ny = sizes
    if nx * ny > MAX_NODES:
        raise InputError(f"{nx} x {ny} nodes: more than {MAX_NODES:,}", src, ln)
    if not (x1 > x0 and y1 > y0):
        raise InputError(f"MaxX must exceed MinX and MaxY MinY (got X {x0:g}..{x1:g}, Y {y0:g}..{y1:g})", src, ln)
    z = np.full((ny, nx), np.nan)
    where = np.zeros((ny, nx), dtype=np.int64)
    for el in root:
        if not isinstance(el.tag, str) or etree.QName(el).localname != "point":
            continue
        el_ln = el.sourceline or 0
        idx = []
        for k, size in (("X", nx), ("Y", ny)):
            s = (el.get(k) or "").strip()
            if not re.fullmatch(r"\d{1,7}", s):
                raise InputError(f"point {k} must be a node index (a whole number), found {cut(s)}", src, el_ln)
            if int(s) >= size:
                raise InputError(
                    f"point {k}={s} is beyond the map's Size{k}={size} (indices 0..{size - 1})", src, el_ln
                )
            idx.append(int(s))
        i, j = idx
        if where[j, i]:
            raise InputError(f"node X={i} Y={j} given twice (first at line {where[j, i]})", src, el_ln)
        z[j, i] = _num(el.text or "", src, el_ln, 0, "height")
        where[j, i] = el_ln
    missing = np.argwhere(np.isnan(z))
    if len(missing):
        j, i = missing[0]
        raise InputError(
            f"{len(missing)} of {nx * ny} nodes not probed, e.g. X={i} Y={j}; probe the whole map", src, ln
        )
    xs = x0 + np.arange(nx) * ((x1 - x0) / (nx - 1))
    ys = y0 + np.arange(ny) * ((y1 - y0) / (ny - 1))
    xs[-1], ys[-1] = x1, y1
    if method == "cubic" and (nx < 4 or ny < 4):
        raise InputError(
            f"bicubic interpolation (--interp cubic) needs a grid of at least 4 x 4 points; this one "
            f"has {nx} x {ny}: use --interp linear",
            src,
        )
    return _grid(xs, ys, z, method, outside, src)


def _grid(xs, ys, z, method, outside, src):
    from . import fields

    if np.any(np.diff(xs) <= 0) or np.any(np.diff(ys) <= 0):
        raise InputError(
            "the map's nodes do not have distinct coordinates (its extent is too small for its number of nodes)", src
        )
    return fields.GridField(xs, ys, z, method=method, outside=outside, source=src)


def read_candle_map(path, method: str = "linear", outside: str = "error"):
    """Read a Candle ``.map`` height map as a :class:`~ncadapt.fields.GridField`."""

    path = Path(path)
    src = str(path)
    lines = read_text(path).splitlines()
    rows = [(n, ln) for n, ln in enumerate(lines, 1) if ln.strip()]
    if len(rows) < 3:
        raise InputError(
            "a Candle height map starts with three header lines (x;y;width;height, nx;ny;zbottom;ztop, "
            "interpolation;stepx;stepy)",
            src,
        )

    def fields_of(n, text, count, what):
        parts = text.split(";")
        if len(parts) != count:
            raise InputError(f"{what}: expected {count} values separated by ';', found {len(parts)}", src, n, 1)
        out, col = [], 1
        for p in parts:
            out.append((p, col))
            col += len(p) + 1
        return out

    (n1, l1), (n2, l2), (n3, _) = rows[:3]
    x0, y0, w, h = (
        _num(p, src, n1, c, k) for (p, c), k in zip(fields_of(n1, l1, 4, "border"), ("x", "y", "width", "height"))
    )
    if not (w > 0 and h > 0):
        raise InputError(f"the border's width and height must be positive, found {w:g} and {h:g}", src, n1, 1)
    g = fields_of(n2, l2, 4, "grid")
    counts = []
    for (p, c), k in zip(g[:2], ("nx", "ny")):
        s = p.strip()
        if not re.fullmatch(r"\d{1,7}(\.0*)?", s) or int(float(s)) < 2:
            raise InputError(f"grid {k} must be a whole number of at least 2, found {cut(s)}", src, n2, c)
        counts.append(int(float(s)))
    nx, ny = counts
    if nx * ny > MAX_NODES:
        raise InputError(f"{nx} x {ny} nodes: more than {MAX_NODES:,}", src, n2, 1)
    data = rows[3:]
    if len(data) != ny:
        raise InputError(
            f"the header announces {ny} rows of heights, the file has {len(data)}",
            src,
            data[ny][0] if len(data) > ny else 0,
        )
    z = np.empty((ny, nx))
    for i, (n, text) in enumerate(data):
        for j, (p, c) in enumerate(fields_of(n, text, nx, f"row {i + 1}")):
            if p.strip().lower() in ("nan", ""):
                raise InputError(f"row {i + 1}, column {j + 1}: node not probed; probe the whole map", src, n, c)
            z[i, j] = _num(p, src, n, c, "height")
    xs = x0 + np.arange(nx) * (w / (nx - 1))
    ys = y0 + np.arange(ny) * (h / (ny - 1))
    if method == "cubic" and (nx < 4 or ny < 4):
        raise InputError(
            f"bicubic interpolation (--interp cubic) needs a grid of at least 4 x 4 points; this one "
            f"has {nx} x {ny}: use --interp linear",
            src,
        )
    return _grid(xs, ys, z, method, outside, src)
