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

Under G91 U is written as an increment, as the axes are. Every piece is written with its motion
code (stock Marlin reads no modal motion), and G0, which extrudes as G1 does in Marlin, is
corrected as a feed and written as G0. A rewritten ``G92`` keeps its E.

Copied as written (no X Y Z motion): ``G4`` (``P`` milliseconds or ``S`` seconds), ``G10``/``G11``
(firmware retract), ``T`` tool numbers, a ``G5`` without words (a Bézier to where the head is), and
the M codes of :data:`COPIED_M` (temperatures, fans, motors, limits, messages, progress, FABtotum's
head and laser). ``G28`` and ``G29`` (homing, bed probing) are copied, and the axes they move are
unknown after them until a move names them (E stays known). Refused at their line: ``G5`` with
words (Bézier moves), any other G or M code (a printer's own codes may move the head), a second code
on a line, ``P`` on an arc, lower-case words, an E with more than 8 decimals, a U V W A B C word,
a checksum (``*``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from decimal import Decimal

import numpy as np

from . import rewrite
from .errors import InputError

#: M codes copied as written: they move no axis. Some are FABtotum's (FABlin firmware, a Marlin
#: derivative; stock Marlin ignores them), read in FABlin's ``Marlin_main.cpp``: M728 "Raspberry Pi
#: alive" (the ambient light and the beeper); M793 S… the installed head (``setup_addon``: its
#: heaters, sensors and working mode, FFF, milling or laser; no axis moves and no offset changes);
#: M60, M61 and M62 the laser's power (M60 at once, M61 once the moves before have finished, M62 off).
COPIED_M = frozenset(
    {0, 1, 3, 4, 5, 7, 8, 9, 17, 18, 60, 61, 62, 73, 82, 83, 84, 104, 105, 106, 107, 109, 110, 114}
    | {115, 117, 118, 140, 141, 149, 155, 190, 191, 201, 203, 204, 205, 207, 208, 209, 220, 221, 300}
    | {302, 400, 728, 793, 900}
)
_WORD = re.compile(r"([A-Za-z])[ \t]*([-+]?(?:\d+\.?\d*|\.\d+))?")
#: Most decimals an E word may have: the engine writes at most 8, and E must come back exact.
_MAX_DECIMALS = 8
#: The straight program's first line, before the program's own.
_PREAMBLE = "G0 U0"


@dataclass(frozen=True)
class Translation:
    """A Marlin program as straight RS274NGC: ``data`` (a preamble ``G0 U0``, then one line per
    line of the program, each with its marker; ``straight`` their texts), ``source``, and for each
    line of the program how its E is written (``relative``), whether its axes are relative (G91:
    U is then written as an increment, ``incremental``), the U value of E = 0 (``base``), U at
    its start (``start``), its motion code (``code``: G0 G1 G2 G3, or None) and, on a G92 line,
    its E word (``g92_e``)."""

    data: bytes
    source: bytes = field(repr=False)
    relative: list[bool] = field(repr=False)
    incremental: list[bool] = field(repr=False)
    base: list[Decimal] = field(repr=False)
    start: list[Decimal] = field(repr=False)
    code: list[str | None] = field(repr=False)
    g92_e: list[str | None] = field(repr=False)
    straight: list[str] = field(repr=False)

    @property
    def lines(self) -> np.ndarray:
        """The 1-based line of each straight line: the preamble's is 1, then one to one."""
        return np.r_[1, np.arange(1, len(self.straight), dtype=np.int64)]

    @property
    def blocks_run(self) -> int:
        """The blocks the program ran: each of its lines once (the preamble is not the program's)."""
        return len(self.straight) - 1


def _dec(text: str) -> Decimal:
    return Decimal(text if text not in ("", "+", "-", ".") else "0")


def _text(v: Decimal) -> str:
    t = format(v, "f")
    if "." in t:
        t = t.rstrip("0").rstrip(".")
    return "0" if t in ("-0", "") else t


def translate(data: bytes, name: str = "<program>") -> Translation:
    """The straight RS274NGC program of a Marlin program (see the module's text)."""
    text = rewrite.program_text(data)
    out: list[str] = []
    relative: list[bool] = []
    incremental: list[bool] = []
    bases: list[Decimal] = []
    starts: list[Decimal] = []
    codes: list[str | None] = []
    g92s: list[str | None] = []
    e_rel = xyz_rel = False
    base = Decimal(0)  # U where E reads 0
    u = Decimal(0)  # U now (E = u - base)
    for n, raw in enumerate(rewrite.split_lines(text), 1):
        relative.append(e_rel)
        incremental.append(xyz_rel)
        bases.append(base)
        starts.append(u)
        codes.append(None)
        g92s.append(None)
        code = raw.split(";", 1)[0]
        if "*" in code:
            raise InputError("a checksum (*): a host's line, not a program's", name, n, code.index("*") + 1)
        words = [(m.group(1), m.group(2), m.start()) for m in _WORD.finditer(code)]
        if not words:
            if code.strip():
                raise InputError(f"'{code.strip()[:12]}' is not read", name, n, len(code) - len(code.lstrip()) + 1)
            out.append("")
            continue
        letter, num, at = words[0]
        if letter == "M":  # its parameters, free text for some (M117), are the firmware's
            m = int(num) if num and re.fullmatch(r"\d+", num) else None
            if m == 420:
                raise InputError(
                    "M420 turns on the printer's own bed levelling, which would add to the correction: take it out "
                    "(or level with the printer and not with ncadapt)",
                    name,
                    n,
                    at + 1,
                )
            if m is None or m not in COPIED_M:
                raise InputError(
                    f"M{num} is not a code ncadapt copies (it may move the head or change how moves run)",
                    name,
                    n,
                    at + 1,
                )
            e_rel = {82: False, 83: True}.get(m, e_rel)
            out.append("")
            continue
        bad = re.search(r"[^A-Z0-9 \t.+\-]", code)
        if bad:
            what = "a lower-case word (Marlin reads capitals)" if bad.group().isalpha() else f"'{bad.group()}'"
            raise InputError(f"{what} is not read", name, n, bad.start() + 1)
        if letter == "N":
            raise InputError("line numbers (N) are a host's, not a program's", name, n, at + 1)
        if letter == "T":
            out.append("")
            continue
        if letter != "G" or num is None:
            raise InputError(f"'{letter}{num or ''}' begins a line: not read", name, n, at + 1)
        g = float(num)
        rest = words[1:]
        for w, v, a in rest:
            if w in "GMTN":
                raise InputError(f"{w}{v or ''} after {letter}{num}: Marlin reads one code a line", name, n, a + 1)
            if w in "UVWABC":
                raise InputError(f"{w}: an axis a printer does not have (E is the extruder)", name, n, a + 1)
            if v is None and (g not in (28, 29) or w == "E"):
                raise InputError(f"{w} without a number", name, n, a + 1)
            if w == "E" and len(v.split(".", 1)[1] if "." in v else "") > _MAX_DECIMALS:
                raise InputError(
                    f"E{v}: more than {_MAX_DECIMALS} decimals are not written back exactly", name, n, a + 1
                )
        if g in (0, 1, 2, 3):
            if g in (2, 3) and any(w == "P" for w, _, _ in rest):
                raise InputError(
                    "P on an arc: Marlin counts its turns by its own setting (ARC_P_CIRCLES)", name, n, at + 1
                )
            kept = []
            for w, v, _ in rest:
                if w == "E":
                    e = _dec(v)
                    new = u + e if e_rel else base + e
                    kept.append(f"U{_text(new - u if xyz_rel else new)}")
                    u = new
                else:
                    kept.append(f"{w}{v}")
            # G0 moves and extrudes as G1 does in Marlin: the engine corrects it as a feed
            out.append(" ".join(["G1" if g == 0 else f"G{int(g)}", *kept]))
            codes[-1] = f"G{int(g)}"
        elif g == 92:
            kept = []
            for w, v, _ in rest:
                if w == "E":
                    base = u - _dec(v)  # E reads v here
                    g92s[-1] = f"E{v}"
                else:
                    kept.append(f"{w}{v}")
            out.append(" ".join(["G92", *kept]) if kept else "")
        elif g in (90, 91):
            e_rel = xyz_rel = g == 91
            out.append(f"G{int(g)}")
        elif g in (20, 21, 17, 18, 19):
            out.append(f"G{int(g)}")
        elif g in (28, 29):
            # homing or probing: the axes it moves end where the machine puts them; E stays
            named = [w for w, _, _ in rest if w in "XYZ"] if g == 28 else []
            out.append("G53 G0 " + " ".join(f"{a}0" for a in (named or ["X", "Y", "Z"])))
        elif g in (4, 10, 11):
            out.append("")
        elif g == 5 and not rest:
            # a G5 without words moves nowhere: a Bézier from where the head is to where it is (a
            # firmware built without BEZIER_CURVE_SUPPORT ignores it)
            out.append("")
        elif g == 5:
            raise InputError("G5 (a Bézier move) is not followed", name, n, at + 1)
        else:
            raise InputError(f"G{num} is not read", name, n, at + 1)
    # the preamble: U (E's carrier) starts known, so that the first extruding move can be cut
    out.insert(0, _PREAMBLE)
    return Translation(rewrite.mark(out), data, relative, incremental, bases, starts, codes, g92s, out)


_U = re.compile(r"U([-+]?(?:\d+\.?\d*|\.\d+))")


def assemble(tr: Translation, corrected: bytes) -> tuple[bytes, int]:
    """The Marlin program of the engine's ``corrected`` straight program, and how many lines were
    rewritten: each line whose move changed is written as the corrected pieces (U turned back into
    E, each piece with its motion code, the line's comment after the first), every other line as
    written."""
    groups = rewrite.groups(corrected, len(tr.straight))
    changed = rewrite.changed(groups, tr.straight)
    if changed[0]:
        raise RuntimeError(f"the engine changed the preamble: {groups[0]}")
    groups, changed = groups[1:], changed[1:]
    if not any(changed):
        return tr.source, 0
    repl = {}
    for i, (body, _) in enumerate(rewrite.lines_of(tr.source)):
        if not changed[i]:
            continue
        comment = body[body.index(";") :] if ";" in body else ""
        texts = _to_e(groups[i], tr.relative[i], tr.incremental[i], tr.base[i], tr.start[i])
        texts = _with_codes(texts, tr.code[i])
        if tr.g92_e[i]:
            texts[0] = f"{texts[0]} {tr.g92_e[i]}"
        if comment:
            texts[0] = f"{texts[0]} {comment}"
        repl[i] = texts
    return rewrite.splice(tr.source, repl), len(repl)


def _with_codes(lines: list[str], code: str | None) -> list[str]:
    """Each piece with its motion code (stock Marlin reads no modal motion: a line without G is
    ignored), G0 as the program wrote it."""
    out, last = [], None
    for t in lines:
        m = re.match(r"G0*([0-3])(?![\d.])", t)
        if m:
            last = f"G{m.group(1)}"
            t = t[m.end() :].lstrip()
        written = "G0" if code == "G0" and last == "G1" else last
        out.append(f"{written} {t}" if written and t else (written or t))
    return out


def _to_e(lines: list[str], relative: bool, incremental: bool, base: Decimal, start: Decimal) -> list[str]:
    """The engine's lines for one move with their U words written as E: under M83 the difference
    from the U before, under M82 the U less the value U has where E reads 0 (under G91 each U
    written is an increment)."""
    prev = start
    out = []
    for line in lines:

        def to_e(m: re.Match[str]) -> str:
            nonlocal prev
            u = prev + Decimal(m.group(1)) if incremental else Decimal(m.group(1))
            e = u - prev if relative else u - base
            prev = u
            return "E" + _text(e)  # exact: decimal arithmetic on the written numbers

        out.append(_U.sub(to_e, line.strip()))
    return out
