"""Read a Marlin (3D printer) program: its extruder axis E carried through the correction.

The engine corrects X, Y and Z; E is the filament a move feeds, which a correction must not
change in total but must share out among the pieces a move is cut into. :func:`translate` writes
the program as RS274NGC with E as a continuous absolute U axis (the engine interpolates U along a
move's pieces in proportion to their length, and never displaces it); :func:`assemble` writes
the corrected program back with E as the program had it:

- **M82 (absolute E):** each piece's E is the value interpolated at its end; the last is the
  move's own E;
- **M83 (relative E):** each piece's E is the difference of the interpolated values at its ends;
  the pieces add up to the move's E exactly (decimal arithmetic on the written numbers).

The E mode follows Marlin's firmware (``GcodeSuite::axis_is_relative`` and
``set_relative_mode`` in ``gcode.h``): G90 makes every axis absolute, E included, G91 every axis
relative; M82 and M83 set E alone until the next G90 or G91. ``G92 E…`` sets the E coordinate
(``G92 E0`` restarts it); ``G92`` with X Y Z is the engine's. Lines are read one to one.

Copied as written (no X Y Z motion): ``G4``, ``G10``/``G11`` (firmware retract), ``T`` tool
numbers, and the M codes of :data:`COPIED_M` (temperatures, fans, motors, limits, messages,
progress). ``G28`` and ``G29`` (homing, bed probing) are copied, and the position is unknown after
them until a move names every axis (as after LinuxCNC's G28). Refused at their line: ``G5``
(Bézier moves), any other G or M code (a printer's own codes may move the head), a U V W A B C
word, a checksum (``*``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from decimal import Decimal

import numpy as np

from . import rewrite
from .errors import InputError

#: M codes copied as written: they move no axis.
COPIED_M = frozenset(
    {0, 1, 3, 4, 5, 7, 8, 9, 17, 18, 73, 82, 83, 84, 104, 105, 106, 107, 109, 110, 114, 115, 117, 118}
    | {140, 141, 149, 155, 190, 191, 201, 203, 204, 205, 207, 208, 209, 220, 221, 300, 302, 400, 900}
)
_WORD = re.compile(r"([A-Za-z])[ \t]*([-+]?(?:\d+\.?\d*|\.\d+))?")
#: The straight program's first line, before the program's own.
_PREAMBLE = "G0 U0"


@dataclass(frozen=True)
class Translation:
    """A Marlin program as straight RS274NGC: ``data`` (a preamble ``G0 U0``, then one line per
    line of the program, each with its marker; ``straight`` their texts), ``source``, and for each
    line of the program the E mode at it (``relative``), the U value of E = 0 (``base``) and U at
    its start (``start``)."""

    data: bytes
    source: bytes = field(repr=False)
    relative: list[bool] = field(repr=False)
    base: list[Decimal] = field(repr=False)
    start: list[Decimal] = field(repr=False)
    straight: list[str] = field(repr=False)

    @property
    def lines(self) -> np.ndarray:
        """The 1-based line of each straight line: the preamble's is 1, then one to one."""
        return np.r_[1, np.arange(1, len(self.straight), dtype=np.int64)]


def _dec(text: str) -> Decimal:
    return Decimal(text if text not in ("", "+", "-", ".") else "0")


def _text(v: Decimal) -> str:
    t = format(v, "f")
    if "." in t:
        t = t.rstrip("0").rstrip(".")
    return "0" if t in ("-0", "") else t


def translate(data: bytes, name: str = "<program>") -> Translation:
    """The straight RS274NGC program of a Marlin program (see the module's text)."""
    text = data.decode("utf-8", "surrogateescape")
    out: list[str] = []
    relative, bases, starts = [], [], []
    e_rel = False
    base = Decimal(0)  # U where E reads 0
    u = Decimal(0)  # U now (E = u - base)
    for n, raw in enumerate(text.splitlines(), 1):
        relative.append(e_rel)
        bases.append(base)
        starts.append(u)
        code = raw.split(";", 1)[0]
        if "*" in code:
            raise InputError("a checksum (*): a host's line, not a program's", name, n, code.index("*") + 1)
        words = [(m.group(1).upper(), m.group(2), m.start()) for m in _WORD.finditer(code)]
        bad = re.search(r"[^A-Za-z0-9 \t.+\-]", code) if not (words and words[0][0] == "M") else None
        if bad:
            raise InputError(f"'{bad.group()}' is not read", name, n, bad.start() + 1)
        if not words:
            out.append("")
            continue
        letter, num, at = words[0]
        if letter == "N":
            raise InputError("line numbers (N) are a host's, not a program's", name, n, at + 1)
        code_no = float(num) if num else None
        if letter == "M":
            m = int(code_no) if code_no is not None and code_no == int(code_no) else None
            if m is None or m not in COPIED_M:
                raise InputError(
                    f"M{num} is not a code ncadapt copies (it may move the head or change how moves run)",
                    name,
                    n,
                    at + 1,
                )
            if m == 82:
                e_rel = False
            elif m == 83:
                e_rel = True
            out.append("")
            continue
        if letter == "T":
            out.append("")
            continue
        if letter != "G" or code_no is None:
            raise InputError(f"'{letter}{num or ''}' begins a line: not read", name, n, at + 1)
        g = code_no
        rest = words[1:]
        for w, v, a in rest:
            if w in "UVWABC":
                raise InputError(f"{w}: an axis a printer does not have (E is the extruder)", name, n, a + 1)
            if v is None and not (g in (28, 29) or g == 29.0):
                raise InputError(f"{w} without a number", name, n, a + 1)
        if g in (0, 1, 2, 3):
            kept = []
            for w, v, _ in rest:
                if w == "E":
                    e = _dec(v)
                    u = u + e if e_rel else base + e
                    kept.append(f"U{_text(u)}")
                else:
                    kept.append(f"{w}{v}")
            out.append(" ".join([f"G{int(g)}", *kept]))
        elif g == 92:
            kept = []
            for w, v, _ in rest:
                if w == "E":
                    base = u - _dec(v)  # E reads v here
                else:
                    kept.append(f"{w}{v}")
            out.append(" ".join(["G92", *kept]) if kept else "")
        elif g in (90, 91):
            e_rel = g == 91
            out.append(f"G{int(g)}")
        elif g in (20, 21, 17, 18, 19):
            out.append(f"G{int(g)}")
        elif g in (28, 29):
            out.append("G28")  # homing or probing: where the head ends is the machine's
        elif g in (4, 10, 11):
            out.append("")
        elif g == 5:
            raise InputError("G5 (a Bézier move) is not followed", name, n, at + 1)
        else:
            raise InputError(f"G{num} is not read", name, n, at + 1)
    # the preamble: U (E's carrier) starts known, so that the first extruding move can be cut
    out.insert(0, _PREAMBLE)
    return Translation(rewrite.mark(out), data, relative, bases, starts, out)


_U = re.compile(r"U([-+]?(?:\d+\.?\d*|\.\d+))")


def assemble(tr: Translation, corrected: bytes) -> tuple[bytes, int]:
    """The Marlin program of the engine's ``corrected`` straight program, and how many lines were
    rewritten: each line whose move changed is written as the corrected pieces (U turned back into
    E, the line's comment after the first), every other line as written."""
    groups = rewrite.groups(corrected, len(tr.straight))
    changed = rewrite.changed(groups, tr.straight)
    if changed[0]:
        raise RuntimeError(f"the engine changed the preamble: {groups[0]}")
    groups, changed = groups[1:], changed[1:]
    if not any(changed):
        return tr.source, 0
    out = []
    n = 0
    for i, (body, eol) in enumerate(rewrite.lines_of(tr.source)):
        if not changed[i]:
            out.append(body + eol)
            continue
        n += 1
        comment = body[body.index(";") :] if ";" in body else ""
        texts = _to_e(groups[i], tr.relative[i], tr.base[i], tr.start[i])
        if comment:
            texts[0] = f"{texts[0]} {comment}"
        out += [t + (eol or "\n") for t in texts]
    return "".join(out).encode("utf-8", "surrogateescape"), n


def _to_e(lines: list[str], relative: bool, base: Decimal, start: Decimal) -> list[str]:
    """The engine's lines for one move with their U words written as E: under M83 the difference
    from the U before, under M82 the U less the value U has where E reads 0."""
    prev = start
    out = []
    for line in lines:

        def to_e(m: re.Match[str]) -> str:
            nonlocal prev
            u = Decimal(m.group(1))
            e = u - prev if relative else u - base
            prev = u
            return "E" + _text(e)  # exact: decimal arithmetic on the written numbers

        out.append(_U.sub(to_e, line.strip()))
    return out
