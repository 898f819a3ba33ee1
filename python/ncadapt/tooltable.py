"""Tool tables for cutter radius compensation: LinuxCNC's format.

A LinuxCNC tool table holds a line per tool, its words in any order after ``T``::

    T1 P1 D0.25 Z0.511 ;1/4 end mill
    T3 P3 X0 Z1.2 D6.0 I0 J0 Q0 ;6 mm

``T`` is the tool number, ``D`` its diameter (0 when left out, as LinuxCNC reads it), the other
words (pocket, offsets, a lathe tool's angles and orientation) are read over; ``;`` starts a
comment. The numbers are in the machine's units, which the table does not say: the caller gives
them (``units``). Fanuc and Haas controls hold the same figure in their diameter offset
registers (``D01`` …): write them as ``T<register> D<diameter>``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from .constants import MM_PER_INCH
from .errors import InputError

#: The units a tool table may be in.
UNITS = ("mm", "inch")
#: Widest tool diameter read, mm: larger numbers are a unit or typing mistake.
MAX_DIAMETER = 1000.0

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")


def read(path: str | os.PathLike, units: str) -> dict[int, float]:
    """The tool diameters (mm) of a LinuxCNC tool table, by tool number.

    Parameters
    ----------
    path : path
        The table file.
    units : {"mm", "inch"}
        The units its numbers are in (LinuxCNC: the machine's linear units).

    Returns
    -------
    dict of int to float
        Tool number → diameter, mm (negative as written: LinuxCNC then compensates on the other
        side).

    Raises
    ------
    InputError
        Naming the file and line: a line that is not ``T<n>`` followed by words, a tool number
        given twice, a D word that is not a finite number within ±:data:`MAX_DIAMETER` mm.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "tool.tbl"
    >>> _ = p.write_text("T1 P1 D0.25 ;quarter inch\\nT2 P2 Z1.5\\n")
    >>> read(p, "inch")
    {1: 6.35, 2: 0.0}
    """
    if units not in UNITS:
        raise ValueError(f'Parameter "units" must be one of {", ".join(UNITS)}; got {units!r}')
    scale = MM_PER_INCH if units == "inch" else 1.0
    src = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise InputError(f"cannot read the tool table: {e.strerror or e}", src) from None
    tools: dict[int, float] = {}
    lines: dict[int, int] = {}
    for k, raw in enumerate(text.splitlines(), 1):
        body = raw.split(";", 1)[0].strip()
        if not body:
            continue
        words = _WORD.findall(body)
        if not words or _WORD.sub("", body).strip() or words[0][0].upper() != "T":
            raise InputError(f"expected a tool line (T<number> P… D… ;comment), got {body[:60]!r}", src, k)
        got: dict[str, float] = {}
        for letter, value in words:
            letter = letter.upper()
            if letter in got:
                raise InputError(f"two {letter} words in one tool line", src, k)
            got[letter] = float(value)
        t = got["T"]
        if t < 0 or t != int(t):
            raise InputError(f"tool number T{t:g} is not a whole number >= 0", src, k)
        n = int(t)
        if n in tools:
            raise InputError(f"tool {n} is given twice (first at line {lines[n]})", src, k)
        d = got.get("D", 0.0) * scale
        if not abs(d) <= MAX_DIAMETER:
            raise InputError(f"tool {n}: diameter {d:g} mm is beyond ±{MAX_DIAMETER:g} mm; check the units", src, k)
        tools[n], lines[n] = round(d, 12), k
    return tools
