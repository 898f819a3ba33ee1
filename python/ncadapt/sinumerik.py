"""Read a Sinumerik 840D program: run it as the control does and write the motion it makes as
straight RS274NGC, which the engine corrects; then write the corrected program back in
Sinumerik's syntax (:func:`translate`, :func:`assemble`).

What is read (Siemens, *SINUMERIK 840D sl Programming Manual, Fundamentals* and *Job Planning*):

- blocks with ``N`` numbers and ``LABEL:`` labels, ``;`` comments, upper or lower case;
- ``G0 G1 G2 G3`` with ``X Y Z A B C`` (literals or ``X=expr``), ``=AC(…)``/``=IC(…)`` per word,
  arcs by centre (``I J K``, incremental or ``=AC(…)``; a ``K`` in a G17 arc, the centre's
  coordinate along the helix axis, does not change the arc), by radius (``CR=``, negative for more
  than 180°), through an intermediate point (``CIP`` with ``I1= J1= K1=``, in the active plane), or
  tangent to the path before it (``CT``);
- ``G17 G18 G19``, ``G90 G91``, ``G70 G71 G700 G710`` (inch / metric), ``G54``–``G57`` (before the
  first move), ``G53``/``G153``/``SUPA`` (machine coordinates for the block: kept, not corrected),
  ``G40``, ``G4 F``/``G4 S`` (dwell), ``G94 G95 G96 G97``, ``F S T D M`` words;
- subprograms ``NAME(args)``, ``NAME``, ``L123`` in a file ``NAME.SPF`` (or the control's own name
  ``_N_NAME_SPF``), searched as the control searches: beside the program first, then in the
  subprogram folders given (``subprograms``, in order); ``PROC`` with INT, REAL, BOOL parameters
  by value, ``SAVE``; ended by ``RET``, ``M17`` or their end;
- drilling cycles ``CYCLE81(RTP, RFP, SDIS, DP, DPR)``, ``CYCLE82(…, DTB)`` and ``CYCLE83(…)``
  (deep-hole drilling, along Z) at the position reached (G17 G90), run as G81/G82 from the
  retraction plane;
- frames ``TRANS``/``ATRANS`` (translations), ``ROT``/``AROT`` about Z (``Z…``, or ``RPL=`` in
  G17: each move's X Y, and an arc's I J, turned in the straight program and turned back when it
  is written); ``ROT``, ``SCALE``, ``MIRROR`` without axes reset the frame; scaling and mirroring
  with axes are refused;
- R parameters (``R1``, ``R[expr]``; one read before the program sets it is refused: its value is
  the machine's), ``DEF INT|REAL|BOOL`` variables, ``DEF STRING[n]`` ones (texts, never read as
  numbers), assignments, expressions (``+ - * / DIV MOD``,
  comparisons, ``AND OR XOR NOT``, ``B_AND B_OR B_XOR B_NOT`` on whole numbers, ``SIN COS TAN ASIN ACOS ATAN2`` in degrees, ``SQRT ABS POT
  TRUNC ROUND MINVAL MAXVAL LN EXP``), ``IF/ELSE/ENDIF``, ``WHILE/ENDWHILE``, ``FOR … TO …/ENDFOR``,
  ``REPEAT/UNTIL``, ``LOOP/ENDLOOP``, ``GOTOF/GOTOB/GOTO/GOTOC`` to a label or block number,
  ``IF … GOTOF``, ``CASE(…) OF … DEFAULT …``;
- copied as written, without an effect on the path: ``MSG(…)``, ``SETAL(…)`` (an alarm: the output stops where the input does), ``T="name"``, ``G9 G60 G64 G641
  G642 G643 G644 G645 G601 G602 G603``, ``SOFT BRISK DRIVE FFWON FFWOF CFC CFTCP CFIN STOPRE``,
  ``G340 G341 G450 G451 DIAMOF``, ``ADIS= ADISPOS= LIMS=``, ``TURN=0``;
- ``M30 M2 M17 RET`` end the program.

Refused at their line (:class:`~ncadapt.InputError`), because the path they make is not
followed: calls of subprograms found in none of those folders (or twice in one) and of other
cycles (``CYCLE84(…)``),
``MCALL``, a program that is itself a ``PROC``, ``VAR`` parameters,
splines and polynomials (``ASPLINE BSPLINE CSPLINE POLY``), a ``CT`` whose direction is not known
or along its chord, ``TURN=`` more
than 0, polar coordinates (``AP= RP= G110 G111 G112``), ``AR=``, threads and tapping, cutter
compensation ``G41``/``G42``, rotations about X or Y (and arcs in G18/G19 under a rotation about
Z), scaling and mirroring, ``DIAMON``, system variables
(``$…``), other axes, a change of work system after a move, an arc without a centre or radius,
a CIP moving the axis normal to its plane, an incremental value on an axis whose frame changed
since its last absolute value (setting data SD42440 decides whether the change is travelled), a
jump into a FOR loop, an axis written twice in a block, a loop that runs more than
:data:`MAX_BLOCKS` blocks.

The straight program (:attr:`Translation.data`) has one line per thing the program did, each
ending in a marker ``;@k`` naming its :class:`Item`; the engine keeps the markers, so its output
says which corrected lines belong to which original line (:func:`assemble`).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import rewrite
from .constants import COORD_MAX, MM_PER_INCH
from .errors import InputError

#: Most blocks a program may run: a loop that runs more is taken as one that does not end.
MAX_BLOCKS = 2_000_000
#: Deepest subprogram nesting followed.
MAX_DEPTH = 12
#: The largest INT (Siemens: 32-bit signed).
INT_MAX = 2**31 - 1

_AXES = ("X", "Y", "Z", "A", "B", "C")
_LINEAR = ("X", "Y", "Z")
#: Plane: (first axis, second axis, their centre letters).
_PLANES = {17: ("X", "Y", "I", "J"), 18: ("Z", "X", "K", "I"), 19: ("Y", "Z", "J", "K")}
#: G codes copied without an effect on the path (exact stop, continuous path, SAR plane, corners).
_COPY_G = {9, 60, 64, 641, 642, 643, 644, 645, 601, 602, 603, 340, 341, 450, 451}
#: Predefined procedures that move nothing, copied with their arguments: a message on the
#: screen, an alarm set (which stops the program as the control's alarm reaction says: the
#: output stops where the input does).
_COPIED_CALLS = ("MSG", "SETAL")
_COPY_WORDS = {"SOFT", "BRISK", "DRIVE", "FFWON", "FFWOF", "CFC", "CFTCP", "CFIN", "STOPRE", "DIAMOF"}
_COPY_ASSIGN = {"ADIS", "ADISPOS", "LIMS"}
#: The drilling cycles read (Siemens standard cycles).
_CYCLES = ("CYCLE81", "CYCLE82", "CYCLE83")
_FRAMES = {"TRANS", "ATRANS", "ROT", "AROT", "SCALE", "ASCALE", "MIRROR", "AMIRROR"}
_REFUSED_WORDS = {
    "MCALL": "a modal cycle call (MCALL)",
    "ASPLINE": "spline interpolation",
    "BSPLINE": "spline interpolation",
    "CSPLINE": "spline interpolation",
    "POLY": "polynomial interpolation",
    "DIAMON": "diameter programming (DIAMON)",
    "DIAM90": "diameter programming (DIAM90)",
    "TRAORI": "a 5-axis transformation",
    "TRANSMIT": "a transformation",
    "TRACYL": "a transformation",
}
_REFUSED_G = {
    33: "a thread (G33)",
    34: "a thread (G34)",
    35: "a thread (G35)",
    331: "tapping (G331)",
    332: "tapping (G332)",
    63: "tapping (G63)",
    # (its F words are not carried into the straight program, where each piece needs its own)
    93: "inverse-time feed (G93) in a Sinumerik program",
    41: "cutter radius compensation (G41) in a Sinumerik program",
    42: "cutter radius compensation (G42) in a Sinumerik program",
    110: "polar coordinates (G110)",
    111: "polar coordinates (G111)",
    112: "polar coordinates (G112)",
    25: "a working-area limit (G25)",
    26: "a working-area limit (G26)",
    74: "a reference point approach (G74)",
    75: "a fixed point approach (G75)",
    147: "a smooth approach (SAR)",
    148: "a smooth retract (SAR)",
    247: "a smooth approach (SAR)",
    248: "a smooth retract (SAR)",
    347: "a smooth approach (SAR)",
    348: "a smooth retract (SAR)",
}
_PASS_G = {17, 18, 19, 90, 91, 40, 94, 95, 96, 97, 54, 55, 56, 57}
_UNITS = {70: 20, 700: 20, 71: 21, 710: 21}
_OPENERS = {
    "IF": ("ELSE", "ENDIF"),
    "WHILE": ("ENDWHILE",),
    "FOR": ("ENDFOR",),
    "REPEAT": ("UNTIL",),
    "LOOP": ("ENDLOOP",),
}
_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:EX[-+]?\d+)?)|(?P<name>[A-Z_$][A-Z0-9_$]*)|(?P<str>\"[^\"]*\")"
    r"|(?P<op>==|<>|<=|>=|<<|[-+*/()<>=,\[\]:]))"
)
_FUNCS = {
    "SIN": lambda x: math.sin(math.radians(x)),
    "COS": lambda x: math.cos(math.radians(x)),
    "TAN": lambda x: math.tan(math.radians(x)),
    "ASIN": lambda x: math.degrees(math.asin(x)),
    "ACOS": lambda x: math.degrees(math.acos(x)),
    "ATAN2": lambda y, x: math.degrees(math.atan2(y, x)),
    "SQRT": math.sqrt,
    "ABS": abs,
    "POT": lambda x: x * x,
    "TRUNC": lambda x: float(math.trunc(x)),
    "ROUND": rewrite.round_half_away,
    "MINVAL": min,
    "MAXVAL": max,
    "LN": math.log,
    "EXP": math.exp,
}
# binary operators by priority, lowest first (Siemens, Job Planning, "Priority of the operations":
# the comparisons come last, after the logic, so ``A > 1 AND B`` compares ``A`` with ``1 AND B``)
_LEVELS = (
    ("==", "<>", "<", ">", "<=", ">="),
    ("OR",),
    ("XOR",),
    ("AND",),
    ("B_OR",),
    ("B_XOR",),
    ("B_AND",),
    ("+", "-"),
    ("*", "/", "DIV", "MOD"),
)
#: Comparisons test relative equality (Siemens, "Precision correction on comparison errors"):
#: two values within this fraction of the larger are equal.
RELATIVE_EQUAL = 1e-12


_Error = rewrite.LineError


@dataclass
class Item:
    """One line of the straight program: ``line`` the 0-based original line it comes from,
    ``kind`` ``motion`` (a move; its words ``spans`` in the original line are what a correction
    rewrites) or ``state`` (modal settings, a dwell, an end), ``rs`` its RS274NGC text, ``sn`` its
    Sinumerik text for an expanded program (for a move: None, the corrected RS274 text is
    written), ``mode`` the Sinumerik motion mode in effect for a move (``G0``…``G3``, ``CIP``) and
    ``machine`` the word that puts a move in machine coordinates (``SUPA``, ``G53``, ``G153``)."""

    line: int
    kind: str
    rs: str
    sn: str | None = None
    spans: tuple[tuple[int, int], ...] = ()
    mode: str | None = None
    machine: str | None = None
    #: a drilling cycle's call: (name, its arguments' values (None where left out), their spans
    #: in the original line, the safety clearance)
    cycle: tuple | None = None
    #: the subprogram (in another file) it comes from, called at ``line``; None in the program
    sub: str | None = None
    #: a move whose block names its motion code
    explicit: bool = False
    #: a move under G91, and the axes whose frame changed since their last absolute value before
    #: it (an incremental word the correction adds on one of them is not the program's to write)
    incremental: bool = False
    shifted: frozenset = frozenset()
    #: ``push``/``pop``: a subprogram's call and return (``pop_save``: one with SAVE)
    mark: str | None = None
    #: the frame's rotation about Z (degrees) the move is made in: its straight words are turned
    #: by it, and turned back when it is written
    rot: float = 0.0


@dataclass(frozen=True)
class Translation:
    """A Sinumerik program as straight RS274NGC: ``data`` (bytes, one :class:`Item` a line),
    ``items``, ``lines`` (n,) the 1-based original line of each, ``runs`` how many times each
    original line ran, ``blocks_run`` the blocks the program ran (its flow lines included)."""

    data: bytes
    items: list[Item]
    lines: np.ndarray
    runs: np.ndarray
    blocks_run: int
    source: bytes = field(repr=False, default=b"")
    #: the subprograms the program called, by name: the file each was read from
    subprograms: dict[str, str] = field(default_factory=dict)


# ----------------------------------------------------------------------------------- expressions
#: What :meth:`_Tokens.peek` gives past the last token.
_END = ("end", "", -1, -1)


class _Tokens:
    """The tokens of a line's code (upper case outside strings), with their columns."""

    def __init__(self, code: str):
        self.toks: list[tuple[str, str, int, int]] = []  # (kind, text, start, end)
        k = 0
        while k < len(code):
            if code[k].isspace():
                k += 1
                continue
            m = _TOKEN.match(code, k)
            if not m or m.end() == k:
                raise _Error(f"cannot read '{code[k : k + 12]}'", k + 1)
            kind = m.lastgroup or "op"
            self.toks.append((kind, m.group(kind), m.start(kind), m.end()))
            k = m.end()
        self.i = 0

    def peek(self, n: int = 0) -> tuple[str, str, int, int]:
        """The token ``n`` ahead, or :data:`_END` past the last."""
        j = self.i + n
        return self.toks[j] if j < len(self.toks) else _END

    def take(self, text: str) -> bool:
        t = self.peek()
        if t[0] in ("op", "name") and t[1] == text:
            self.i += 1
            return True
        return False

    def need(self, text: str) -> None:
        if not self.take(text):
            raise _Error(f"expected '{text}'", self.col())

    def col(self) -> int:
        t = self.peek()
        return t[2] + 1 if t[0] != "end" else (self.toks[-1][3] + 1 if self.toks else 1)


def _number(text: str) -> float:
    return float(text.replace("EX", "E"))


class _Machine:
    """The program's variables: R parameters and ``DEF`` variables (name → [type, value])."""

    def __init__(self):
        self.r: dict[int, float] = {}
        self.vars: dict[str, list] = {}

    def get(self, name: str, col: int) -> float:
        v = self.vars.get(name)
        if v is None:
            if name.startswith("$"):
                raise _Error(f"{name} is a system variable: its value is the machine's", col)
            raise _Error(f"'{name}' is not defined (DEF) in the program", col)
        if v[0] == "STRING":
            raise _Error(f"{name} is a STRING: read as a number, its value is the control's conversion", col)
        return v[1]

    def get_r(self, k: float, col: int) -> float:
        if not math.isfinite(k) or k != int(k) or k < 0:
            raise _Error(f"R{k} is not an R parameter", col)
        if int(k) not in self.r:
            raise _Error(f"R{int(k)} is read before the program sets it: its value is the machine's", col)
        return self.r[int(k)]

    def set(self, target: tuple, v: float, col: int) -> None:
        if target[0] == "R":
            if not math.isfinite(target[1]) or target[1] != int(target[1]) or target[1] < 0:
                raise _Error(f"R[{target[1]:g}] is not an R parameter", col)
            if not math.isfinite(v):
                raise _Error(f"R{int(target[1])}: the value is out of range", col)
            self.r[int(target[1])] = v
            return
        var = self.vars.get(target[1])
        if var is None:
            raise _Error(f"'{target[1]}' is not defined (DEF) in the program", col)
        if not math.isfinite(v):
            raise _Error(f"{target[1]}: the value is out of range", col)
        if var[0] == "INT":
            v = rewrite.round_half_away(v)
            if abs(v) > INT_MAX:
                raise _Error(f"{target[1]} = {v:g}: beyond an INT's range (±{INT_MAX})", col)
        elif var[0] == "BOOL":
            v = float(v != 0.0)
        var[1] = v


def _expr(t: _Tokens, m: _Machine, level: int = 0) -> float:
    if level == len(_LEVELS):
        return _unary(t, m)
    a = _expr(t, m, level + 1)
    while True:
        tok = t.peek()
        if tok[0] in ("end", "str") or tok[1] not in _LEVELS[level]:
            return a
        col = t.col()
        t.i += 1
        b = _expr(t, m, level + 1)
        a = _binary(tok[1], a, b, col)


def _binary(op: str, a: float, b: float, col: int) -> float:
    try:
        v = _operate(op, a, b, col)
    except (OverflowError, ValueError):
        v = math.nan
    if not math.isfinite(v):
        raise _Error(f"{a:g} {op} {b:g}: out of range", col)
    return v


def _operate(op: str, a: float, b: float, col: int) -> float:
    if op in ("/", "DIV", "MOD") and b == 0.0:
        raise _Error("division by zero", col)
    if op.startswith("B_"):
        x, y = _bits(a, op, col), _bits(b, op, col)
        return float({"B_AND": x & y, "B_OR": x | y, "B_XOR": x ^ y}[op])
    match op:
        case "+":
            return a + b
        case "-":
            return a - b
        case "*":
            return a * b
        case "/":
            return a / b
        case "DIV":
            return float(math.trunc(a / b))
        case "MOD":
            return math.fmod(a, b)
        case "==" | "<>" | "<" | ">" | "<=" | ">=":
            same = abs(a - b) <= RELATIVE_EQUAL * max(abs(a), abs(b))
            return float(
                {"==": same, "<>": not same, "<": a < b and not same, ">": a > b and not same}.get(
                    op, same or (a < b if op == "<=" else a > b)
                )
            )
        case "AND":
            return float(a != 0.0 and b != 0.0)
        case "XOR":
            return float((a != 0.0) != (b != 0.0))
    return float(a != 0.0 or b != 0.0)


def _bits(v: float, op: str, col: int) -> int:
    """A bit operator's operand: a whole number (an INT's value); the rounding of a REAL one is
    the control's, not read."""
    if v != math.trunc(v) or abs(v) >= 2.0**31:
        raise _Error(f"{op} of {v:g}: the bit operators are read for whole numbers (INT) only", col)
    return int(v)


def _unary(t: _Tokens, m: _Machine) -> float:
    tok = t.peek()
    if tok[0] == "end":
        raise _Error("expected a value", t.col())
    kind, text, col = tok[0], tok[1], tok[2] + 1
    if t.take("-"):
        return -_unary(t, m)
    if t.take("+"):
        return _unary(t, m)
    if t.take("NOT"):
        return float(_unary(t, m) == 0.0)
    if t.take("B_NOT"):
        return float(~_bits(_unary(t, m), "B_NOT", col))
    if t.take("("):
        v = _expr(t, m)
        t.need(")")
        return v
    t.i += 1
    if kind == "num":
        return _number(text)
    if kind != "name":
        raise _Error(f"expected a value, found '{text}'", col)
    if text in ("TRUE", "FALSE"):
        return float(text == "TRUE")
    if text in _FUNCS:
        t.need("(")
        args = [_expr(t, m)]
        while t.take(","):
            args.append(_expr(t, m))
        t.need(")")
        try:
            return float(_FUNCS[text](*args))  # type: ignore[operator]
        except (ValueError, TypeError, OverflowError):
            raise _Error(f"{text} of {', '.join(f'{a:g}' for a in args)} has no value", col) from None
    r = _r_index(text, t, m, col)
    if r is not None:
        return m.get_r(r, col)
    return m.get(text, col)


def _r_index(text: str, t: _Tokens, m: _Machine, col: int) -> float | None:
    """The index of an R parameter named by ``text`` (``R12``, or ``R`` followed by ``[expr]``)."""
    if re.fullmatch(r"R\d+", text):
        return float(text[1:])
    if text == "R" and t.take("["):
        k = _expr(t, m)
        t.need("]")
        return k
    return None


# ----------------------------------------------------------------------------------- the program
@dataclass
class _Line:
    code: str  # upper case outside strings, comment removed, N number and label removed
    code_at: int  # column of `code` in the raw line
    label: str | None
    number: int | None
    keyword: str | None  # a flow keyword, DEF, GOTO…, PROC, EXTERN, or None


def _split(raw: str) -> tuple[str, int]:
    """A line's code (comment removed, upper case outside strings) and where it starts."""
    out, k, quoted = [], 0, False
    while k < len(raw):
        c = raw[k]
        if c == '"':
            quoted = not quoted
        elif c == ";" and not quoted:
            break
        up = c.upper()
        out.append(c if quoted or len(up) != 1 else up)
        k += 1
    return "".join(out), 0


def _read(text: str, src: str) -> list[_Line]:
    lines = []
    for n, raw in enumerate(rewrite.split_lines(text), 1):
        code, at = _split(raw)
        number, label = None, None
        m = re.match(r"\s*N(\d+)\b\s*", code)
        if m:
            number, at = int(m.group(1)), m.end()
        m = re.match(r"\s*([A-Z_][A-Z0-9_]*):(?!=)\s*", code[at:])
        if m:
            label, at = m.group(1), at + m.end()
        body = code[at:]
        stripped = body.strip()
        if stripped.startswith("/"):
            raise InputError("a skipped block (/): whether it runs is the machine's setting", src, n, at + 1)
        kw = re.match(
            r"(IF|ELSE|ENDIF|WHILE|ENDWHILE|FOR|ENDFOR|REPEAT|UNTIL|LOOP|ENDLOOP|DEF|GOTOF|GOTOB|GOTOC|GOTO"
            r"|PROC|EXTERN|RET|DEFINE|SAVE|CASE)\b",
            stripped,
        )
        lines.append(_Line(body, at, label, number, kw.group(1) if kw else None))
    return lines


def _match(lines: list[_Line], src: str) -> dict[int, tuple[int, ...]]:
    """For each flow opener and middle, the lines of its ELSE / end (IF → (ELSE, ENDIF) …)."""
    stack: list[tuple[str, int, list[int]]] = []
    out: dict[int, tuple[int, ...]] = {}
    for i, ln in enumerate(lines):
        kw = ln.keyword
        if kw == "IF" and re.search(r"\bGOTO[FBC]?\b", ln.code):
            continue  # IF … GOTOF label: one line
        if kw in _OPENERS:
            stack.append((kw, i, []))
        elif kw in ("ELSE", "ENDIF", "ENDWHILE", "ENDFOR", "UNTIL", "ENDLOOP"):
            if not stack or kw not in _OPENERS[stack[-1][0]]:
                raise InputError(f"{kw} without its opening statement", src, i + 1, ln.code_at + 1)
            opener, at, mids = stack[-1]
            if kw == "ELSE":
                if mids:
                    raise InputError("a second ELSE", src, i + 1, ln.code_at + 1)
                mids.append(i)
                continue
            stack.pop()
            els = mids[0] if mids else -1
            out[at] = (els, i)
            if els >= 0:
                out[els] = (els, i)
            out[i] = (at,)
    if stack:
        kw, at, _ = stack[-1]
        raise InputError(f"{kw} without its end", src, at + 1)
    return out


def _targets(lines: list[_Line]) -> dict[str, list[int]]:
    """Where a jump may land: the lines of each label and block number (``N90``), in order."""
    out: dict[str, list[int]] = {}
    for j, ln in enumerate(lines):
        keys = {ln.label, None if ln.number is None else f"N{ln.number}"} - {None}
        for key in keys:
            out.setdefault(key, []).append(j)  # type: ignore[arg-type]
    return out


#: The motion modes a machine may start a program in (``translate``'s ``start_motion``; None: not
#: stated, and a move before the program states one is refused).
START_MOTIONS = (None, "G0", "G1")


@dataclass
class _State:
    """What the control holds between blocks, as far as the path goes."""

    mode: str | None = None  # group 1: G0 G1 G2 G3 CIP; at the start the machine's (machine data)
    plane: int = 17
    absolute: bool = True
    inch: bool | None = None
    moved: bool = False
    wcs: int | None = None
    trans: dict = field(default_factory=lambda: dict.fromkeys(_AXES, 0.0))
    rot: float = 0.0  # the programmable frame's rotation about Z, degrees, after its translation
    pos: dict = field(default_factory=lambda: dict.fromkeys(_AXES))  # program coordinates; None unknown
    #: a drilling cycle ran since the last move (the straight program's G80 left no motion mode)
    after_cycle: bool = False
    #: the direction the last move ended in (X Y Z), for CT; None when not known
    tangent: tuple[float, float, float] | None = None
    #: axes whose frame changed since their last absolute value: an incremental value there may
    #: or may not travel the change (setting data SD42440 $SC_FRAME_OFFSET_INCR_PROG)
    shifted: set = field(default_factory=set)


_fmt = rewrite.number


@dataclass
class _Block:
    """The words of one block, gathered before it runs."""

    axes: dict = field(default_factory=dict)  # letter → (value, "AC"/"IC"/"", span)
    arc: dict = field(default_factory=dict)  # I J K I1 J1 K1 CR → (value, how, span)
    motion: tuple[str, tuple[int, int]] | None = None
    pre: list = field(default_factory=list)  # (rs, sn) before the move
    post: list = field(default_factory=list)  # (rs, sn) after it
    machine: str | None = None
    frame: str | None = None
    dwell: bool = False
    end: bool = False
    end_code: int = 0
    call: str | None = None  # an L123 subprogram call
    rpl: float | None = None  # ROT/AROT RPL=: a rotation in the plane

    def put(self, name: str, v: float, how: str, col: int, span: tuple[int, int]) -> None:
        if not math.isfinite(v):
            raise _Error(f"{name}: the value is out of range", col)
        into = self.axes if name in _AXES else self.arc
        if name in into:
            raise _Error(f"{name} is written twice in the block", col)
        into[name] = (v, how, span)

    def set_motion(self, code: str, span: tuple[int, int], col: int) -> None:
        if self.motion is not None:
            raise _Error("two motion codes in one block", col)
        self.motion = (code, span)


class _Run:
    def __init__(self, lines: list[_Line], src: str, folders: list[Path]):
        self.lines, self.src = lines, src
        #: where a called subprogram is looked for, in order; and the files read, by name
        self.folders = folders
        self.read: dict[str, str] = {}
        #: each subprogram file read: its lines, their flow and jump targets (read once a run)
        self.files: dict[str, tuple[list[_Line], dict, dict]] = {}
        #: the calls of subprograms in other files: (the caller's lines, name, flow, jump targets and FOR
        #: ends, the line to return to, its variables, what SAVE restores, the subprogram's name)
        self.calls: list[tuple] = []
        self.flow = _match(lines, src)
        self.m = _Machine()
        self.s = _State()
        self.items: list[Item] = []
        self.runs = np.zeros(len(lines), dtype=np.int64)
        self.targets = _targets(lines)
        self.for_end: dict[int, float] = {}

    # --- flow
    def step(self, i: int) -> int | None:
        ln = self.lines[i]
        if not self.calls:
            self.runs[i] += 1
        kw = ln.keyword
        t = _Tokens(ln.code)
        if kw is None:
            return self.block(t, i)
        t.i = 1
        if kw == "IF":
            cond = _expr(t, self.m)
            if t.peek()[1].startswith("GOTO"):
                return self.goto(t, i) if cond != 0.0 else i + 1
            self.end(t)
            if cond != 0.0:
                return i + 1
            els, end = self.flow[i]
            return (els if els >= 0 else end) + 1
        if kw == "ELSE":
            return self.flow[i][1] + 1
        if kw in ("ENDIF", "REPEAT", "LOOP"):
            self.end(t)
            return i + 1
        if kw == "WHILE":
            cond = _expr(t, self.m)
            self.end(t)
            return i + 1 if cond != 0.0 else self.flow[i][1] + 1
        if kw == "ENDWHILE":
            return self.flow[i][0]
        if kw == "ENDLOOP":
            return self.flow[i][0] + 1
        if kw == "UNTIL":
            cond = _expr(t, self.m)
            self.end(t)
            return i + 1 if cond != 0.0 else self.flow[i][0] + 1
        if kw == "FOR":
            target = self.target(t)
            t.need("=")
            start = _expr(t, self.m)
            t.need("TO")
            stop = _expr(t, self.m)
            self.end(t)
            self.m.set(target, start, ln.code_at + 1)
            self.for_end[i] = stop
            return i + 1 if self.value(target) <= stop else self.flow[i][1] + 1
        if kw == "ENDFOR":
            at = self.flow[i][0]
            if at not in self.for_end:
                raise _Error("ENDFOR reached without its FOR: a jump into a loop (the control refuses it)", 1)
            ft = _Tokens(self.lines[at].code)
            ft.i = 1
            target = self.target(ft)
            self.m.set(target, self.value(target) + 1.0, ln.code_at + 1)
            return at + 1 if self.value(target) <= self.for_end[at] else i + 1
        if kw == "DEF":
            self.define(t)
            return i + 1
        if kw.startswith("GOTO"):
            t.i = 0
            return self.goto(t, i)
        if kw == "CASE":
            return self.case(t, i)
        if kw == "RET":
            return self.leave() if self.calls else None
        if kw == "PROC":
            raise _Error(
                "a subprogram (PROC): its parameters come from the program that calls it; correct that one "
                "(which reads it)",
                1,
            )
        if kw == "EXTERN":
            return i + 1  # a declaration: the call reads the subprogram
        raise _Error(f"{kw} is not read", 1)

    def end(self, t: _Tokens) -> None:
        if t.peek()[0] != "end":
            raise _Error(f"unexpected '{t.peek()[1]}'", t.col())

    def target(self, t: _Tokens) -> tuple:
        tok = t.peek()
        if tok[0] != "name":
            raise _Error("expected a variable", t.col())
        t.i += 1
        r = _r_index(tok[1], t, self.m, tok[2] + 1)
        return ("R", r) if r is not None else ("V", tok[1])

    def value(self, target: tuple) -> float:
        return self.m.r.get(int(target[1]), 0.0) if target[0] == "R" else self.m.vars[target[1]][1]

    def define(self, t: _Tokens) -> None:
        tok = t.peek()
        kind = tok[1]
        if kind not in ("INT", "REAL", "BOOL", "STRING"):
            raise _Error(f"DEF {kind}: only INT, REAL, BOOL and STRING variables are read", t.col())
        t.i += 1
        if kind == "STRING":
            # STRING[n]: its length; its values are kept, never read as numbers (MSG, names)
            if not t.take("["):
                raise _Error("DEF STRING without its length [n]", t.col())
            _expr(t, self.m)
            t.need("]")
            while True:
                name = t.peek()
                if name[0] != "name":
                    raise _Error("expected a variable name", t.col())
                t.i += 1
                self.m.vars[name[1]] = ["STRING", ""]
                if t.take("="):
                    self.string(name[1], t, name[2] + 1)
                if not t.take(","):
                    break
            self.end(t)
            return
        while True:
            name = t.peek()
            if name[0] != "name":
                raise _Error("expected a variable name", t.col())
            t.i += 1
            if t.peek()[1] == "[":
                raise _Error("arrays are not read", t.col())
            self.m.vars[name[1]] = [kind, 0.0]
            if t.take("="):
                self.m.set(("V", name[1]), _expr(t, self.m), name[2] + 1)
            if not t.take(","):
                break
        self.end(t)

    def goto(self, t: _Tokens, i: int, alone: bool = True) -> int:
        """The line a GOTOF/GOTOB/GOTO/GOTOC at the tokens' position jumps to (a label, a block
        number ``N90`` or ``90``); with ``alone`` nothing may follow it."""
        kw = t.peek()[1]
        t.i += 1
        tok = t.peek()
        if tok[0] == "end":
            raise _Error(f"{kw} without a destination", t.col())
        t.i += 1
        dest = "N" + tok[1] if tok[0] == "num" else tok[1]
        if dest == "N" and t.peek()[0] == "num":
            dest = "N" + t.peek()[1]
            t.i += 1
        if alone:
            self.end(t)
        found = self.targets.get(f"N{int(dest[1:])}" if dest[1:].isdigit() and dest[0] == "N" else dest, [])
        fwd = [j for j in found if j > i]
        back = [j for j in found if j <= i]
        if kw == "GOTOF":
            found = fwd[:1]
        elif kw == "GOTOB":
            found = back[-1:]
        else:
            found = fwd[:1] or back[-1:]
        if not found:
            if kw == "GOTOC":
                return i + 1
            raise _Error(f"{kw} {dest}: no such label", tok[2] + 1)
        return found[0]

    def case(self, t: _Tokens, i: int) -> int:
        """``CASE(expr) OF c1 GOTOF L1 c2 GOTOF L2 … DEFAULT GOTOF L``: the jump of the first
        constant equal to the value, else the DEFAULT's, else the next line."""
        t.need("(")
        v = _expr(t, self.m)
        t.need(")")
        t.need("OF")
        chosen = None
        while t.peek()[0] != "end":
            if t.take("DEFAULT"):
                const = None
            else:
                const = _unary(t, self.m)
            if not t.peek()[1].startswith("GOTO"):
                raise _Error("CASE: expected GOTOF, GOTOB, GOTO or GOTOC", t.col())
            dest = self.goto(t, i, alone=False)
            if chosen is None and (const is None or _binary("==", v, const, t.col()) != 0.0):
                chosen = dest
        return i + 1 if chosen is None else chosen

    # --- a block of words
    def block(self, t: _Tokens, i: int) -> int | None:
        ln = self.lines[i]
        at = ln.code_at
        b = _Block()
        while t.peek()[0] != "end":
            kind, text, c0, c1 = t.peek()
            col = at + c0 + 1
            if kind != "name":
                raise _Error(f"unexpected '{text}'", col)
            nxt = t.peek(1)
            if nxt[1] == "=":
                t.i += 2
                self.assignment(text, t, col, c0, b)
                continue
            if nxt[1] == "(":
                if text in _CYCLES:
                    return self.drill(text, t, i)
                if text not in _COPIED_CALLS:
                    return self.enter(text, t, i, col)
                t.i += 2
                depth = 1
                while depth and t.peek()[0] != "end":
                    depth += {"(": 1, ")": -1}.get(t.peek()[1], 0) if t.peek()[0] == "op" else 0
                    t.i += 1
                if depth:
                    raise _Error(f"{text}( without its )", col)
                b.pre.append(("", ln.code[c0 : t.toks[t.i - 1][3]]))
                continue
            t.i += 1
            lit = re.fullmatch(r"([A-Z])(\d+)", text)
            if lit:  # X10, G1, M30: a letter and a number written together (X10.5: and a fraction)
                letter, num, end_at = lit.group(1), lit.group(2), c1
                if nxt[0] == "num" and nxt[2] == c1 and nxt[1].startswith("."):
                    num, end_at = num + nxt[1], nxt[3]
                    t.i += 1
                self.word(letter, _number(num), num, col, (c0, end_at), b)
                continue
            if len(text) == 1 and nxt[2] == c1 and nxt[0] == "num":
                t.i += 1  # X.5
                self.word(text, _number(nxt[1]), nxt[1], col, (c0, nxt[3]), b)
                continue
            num_tok = t.peek(1)
            if (
                len(text) == 1
                and nxt[1] in ("-", "+")
                and nxt[2] == c1
                and num_tok[0] == "num"
                and num_tok[2] == nxt[3]
            ):
                t.i += 2
                v = _number(num_tok[1]) * (-1.0 if nxt[1] == "-" else 1.0)
                self.word(text, v, nxt[1] + num_tok[1], col, (c0, num_tok[3]), b)
                continue
            if text in ("CIP", "CT"):
                b.set_motion(text, (c0, c1), col)
            elif text == "SUPA":
                b.machine = text
            elif text in _FRAMES:
                if b.frame is not None:
                    raise _Error(
                        f"{b.frame} and {text} in one block: each frame instruction is a block of its own", col
                    )
                b.frame = text
            elif text in _COPY_WORDS:
                b.pre.append(("", text))
            elif text in _REFUSED_WORDS:
                raise _Error(f"{_REFUSED_WORDS[text]} is not followed", col)
            elif text.startswith("$"):
                raise _Error(f"{text} is a system variable: what it does is the machine's", col)
            elif text in self.m.vars:
                raise _Error(f"'{text}' without a value", col)
            elif re.fullmatch(r"[A-Z_][A-Z0-9_]{2,}", text) and not re.fullmatch(r"[A-Z]\d+[A-Z].*", text):
                t.i -= 1
                return self.enter(text, t, i, col)
            else:
                raise _Error(f"'{text}' is not read", col)
        if b.frame is not None:
            return self.set_frame(b, i)
        if b.rpl is not None:
            raise _Error("RPL= without ROT or AROT", at + 1)
        if b.dwell:
            self.dwell(b, i)
            return i + 1
        if b.motion is not None:
            self.s.mode = b.motion[0]
        # the words that set things come before the move, the program's stops and end after it
        for rs, sn in b.pre:
            self.items.append(Item(i, "state", rs, sn))
        if b.axes or b.arc:
            self.move(i, b)
        elif b.motion is not None:
            if b.motion[0] in ("G2", "G3", "CIP", "CT"):
                raise _Error(f"{b.motion[0]} without an end point", at + b.motion[1][0] + 1)
            # a motion code alone: the engine may bring the tool to the corrected height there
            span = (at + b.motion[1][0], at + b.motion[1][1])
            self.items.append(Item(i, "motion", b.motion[0], None, (span,), b.motion[0], explicit=True, rot=self.s.rot))
            self.s.after_cycle = False
        elif b.machine is not None:
            raise _Error(f"{b.machine} without a move", at + 1)
        for rs, sn in b.post:
            self.items.append(Item(i, "state", rs, sn))
        if b.call is not None:
            if b.axes or b.arc or b.motion or b.pre or b.post:
                raise _Error(f"{b.call} with other words: a subprogram is called in a block of its own", at + 1)
            t.i = len(t.toks)
            return self.enter(b.call, None, i, at + 1)
        if b.end and self.calls:
            if b.end_code != 17:
                raise _Error(
                    f"M{b.end_code} in a subprogram: whether it returns or ends the program is machine data; end "
                    "it with M17 or RET",
                    at + 1,
                )
            return self.leave()
        return None if b.end else i + 1

    def drill(self, name: str, t: _Tokens, i: int) -> int:
        """``CYCLE81(RTP, RFP, SDIS, DP, DPR)`` (and CYCLE82 with DTB, a dwell at the bottom) at the
        position reached: a rapid to the reference plane plus the safety clearance, a feed to the
        final depth (DP, or DPR below the reference plane), a rapid to the retraction plane (Siemens,
        *Cycles*, "CYCLE81 drilling, centering"). Written for the engine as a canned cycle from the
        retraction plane: ``G0 Z<RTP>``, ``G98 G81 R<RFP+SDIS> Z<DP>`` (G82 with P), ``G80``.
        ``CYCLE83(RTP, RFP, SDIS, DP, DPR, FDEP, FDPR, DAM, DTB, DTS, FRF, VARI, _AXN, _MDEP, _VRT,
        _DTD, _DIS1)``, deep-hole drilling, pecks down the same line (each infeed, retract and
        re-approach on the hole's axis between RTP and DP): the engine is given it as the G81 of
        that line, which the correction moves as a whole; its absolute first depth FDEP moves
        with RFP and DP, its relative values (FDPR, DAM, the distances) stay."""
        ln, s = self.lines[i], self.s
        col = ln.code_at + t.peek()[2] + 1
        if t.i != 0:
            raise _Error(f"{name} with other words before it: a cycle is called in a block of its own", col)
        t.i += 2
        args: list[float | None] = []
        spans: list[tuple[int, int] | None] = []
        while True:
            tok = t.peek()
            if tok[1] in (",", ")") and tok[0] == "op":
                args.append(None)
                spans.append(None)
            else:
                a0 = tok[2]
                args.append(_expr(t, self.m))
                spans.append((ln.code_at + a0, ln.code_at + t.toks[t.i - 1][3]))
            if t.take(")"):
                break
            t.need(",")
        self.end(t)
        n_args = {"CYCLE81": 5, "CYCLE82": 6, "CYCLE83": 17}[name]
        if len(args) > n_args:
            raise _Error(f"{name} takes {n_args} arguments; {len(args)} given", col)
        args += [None] * (n_args - len(args))
        spans += [None] * (n_args - len(spans))
        rtp, rfp, sdis, dp, dpr = args[:5]
        if rtp is None or rfp is None:
            raise _Error(f"{name} without its retraction plane (RTP) or reference plane (RFP)", col)
        sdis = sdis or 0.0
        if dpr is not None and dp is not None and abs((rfp - abs(dpr)) - dp) > 1e-9:
            raise _Error(f"{name}: DP {dp:g} and DPR {dpr:g} give different depths", col)
        if dpr is None and dp is None:
            raise _Error(f"{name} without a final depth (DP or DPR)", col)
        depth = rfp - abs(dpr) if dpr is not None else dp
        if s.plane != 17 or not s.absolute:
            raise _Error(f"{name} in G{s.plane}{'' if s.absolute else ' G91'}: cycles are read in G17 G90", col)
        if s.pos["X"] is None or s.pos["Y"] is None:
            raise _Error(f"{name} at a position that is not known here", col)
        if rtp < rfp + sdis:
            raise _Error(f"{name}: the retraction plane {rtp:g} is below the safety plane {rfp + sdis:g}", col)
        if depth >= rfp + sdis:  # type: ignore[operator]
            raise _Error(f"{name}: the final depth {depth:g} is not below the safety plane", col)
        code = "G81"
        extra = ""
        if name == "CYCLE83":
            fdep, fdpr, axn = args[5], args[6], args[12]
            if axn not in (None, 0.0, 3.0):
                raise _Error(f"{name} with _AXN={axn:g}: only drilling along Z (in G17) is read", col)
            if fdep is not None and fdpr is not None and abs((rfp - abs(fdpr)) - fdep) > 1e-9:
                raise _Error(f"{name}: FDEP {fdep:g} and FDPR {fdpr:g} give different first depths", col)
            if args[11] not in (None, 0.0, 1.0):
                raise _Error(
                    f"{name}: VARI={args[11]:g} is not a machining type (0 chip breaking, 1 swarf removal)", col
                )
        elif name == "CYCLE82":
            dtb = args[5] or 0.0
            if dtb < 0:
                raise _Error(f"{name}: a dwell in spindle turns (DTB < 0) is not read", col)
            code, extra = "G82", f" P{_fmt(dtb)}"
        self.items.append(Item(i, "state", f"G0 Z{_fmt(rtp)}", ""))
        self.items.append(
            Item(
                i,
                "motion",
                f"G98 {code} R{_fmt(rfp + sdis)} Z{_fmt(depth)}{extra}",  # type: ignore[arg-type]
                None,
                (),
                s.mode,
                None,
                (name, tuple(args), tuple(spans), sdis),
            )
        )
        self.items.append(Item(i, "state", "G80", ""))
        # the cycle gives back the caller's motion mode (a standard cycle is a SAVE subprogram);
        # G80 leaves none in the straight program, so the next move there names it
        s.pos["Z"], s.tangent, s.moved, s.after_cycle = rtp, None, True, True
        return i + 1

    def enter(self, name: str, t: _Tokens | None, i: int, col: int) -> int:
        """Call subprogram ``name`` (``NAME(args)``, ``NAME``, ``L123``): the file :meth:`find`
        finds, its ``PROC`` parameters given the arguments (by value; 0 where left
        out), its own variables, R parameters shared. Returns its first line's index."""
        if t is not None:
            if t.i != 0:
                raise _Error(f"{name} with other words before it: a subprogram is called in a block of its own", col)
            t.i = 1
        path = self.find(name, col)
        args: list[float | None] = []
        if t is not None and t.take("("):
            while not t.take(")"):
                args.append(None if t.peek()[1] in (",", ")") else _expr(t, self.m))
                if t.peek()[1] != ")":
                    t.need(",")
        if t is not None:
            self.end(t)
        if len(self.calls) >= MAX_DEPTH:
            raise _Error(f"subprograms nested deeper than {MAX_DEPTH}", col)
        self.read.setdefault(name, str(path))
        if str(path) not in self.files:
            lines = _read(rewrite.program_text(path.read_bytes()), str(path))
            self.files[str(path)] = (lines, _match(lines, str(path)), _targets(lines))
        lines, flow, targets = self.files[str(path)]
        proc = next((k for k, ln in enumerate(lines) if ln.keyword == "PROC"), None)
        params, save = self.proc(lines[proc], name, str(path), proc) if proc is not None else ([], False)
        if len(args) > len(params):
            raise _Error(f"{name} takes {len(params)} argument(s); {len(args)} given", col)
        local: dict[str, list] = {}
        caller = self.m.vars
        self.m.vars = local
        for k, (typ, pname) in enumerate(params):
            local[pname] = [typ, 0.0]
            v = args[k] if k < len(args) else None
            if v is not None:
                self.m.set(("V", pname), v, col)
        snapshot = (
            (self.s.mode, self.s.plane, self.s.absolute, self.s.inch, (dict(self.s.trans), self.s.rot))
            if save
            else None
        )
        self.calls.append((self.lines, self.src, self.flow, self.targets, self.for_end, i + 1, caller, snapshot, name))
        self.items.append(Item(i, "state", "", "", sub=name, mark="push"))
        self.lines, self.src, self.flow, self.targets = lines, str(path), flow, targets
        self.for_end = {}
        return 0 if proc is None else proc + 1

    def find(self, name: str, col: int) -> Path:
        """The file of subprogram ``name``: ``NAME.SPF`` or ``_N_NAME_SPF`` (any case) in the first
        folder that holds one; two such files in that folder are refused (which the control takes is
        not known), and so is a name in none."""
        if name in self.read:  # (found before in this run)
            return Path(self.read[name])
        names = {f"{name}.SPF", f"_N_{name}_SPF"}
        for folder in self.folders:
            found = sorted(p for p in folder.iterdir() if p.name.upper() in names and p.is_file())
            if len(found) > 1:
                raise _Error(f"{name}: {' and '.join(map(str, found))} both hold it; which one runs is not known", col)
            if found:
                return found[0]
        if re.match(r"(CYCLE|POCKET|SLOT|HOLES|LONGHOLE)\d", name) or not self.folders:
            raise self.call(name, col)
        raise _Error(
            f"{name} calls a subprogram, and neither {name}.SPF nor _N_{name}_SPF is in "
            f"{', '.join(map(str, self.folders))} (a subprogram elsewhere, or a cycle, is not read: the motion it "
            "makes is not known; --subprograms DIR names a folder to search)",
            col,
        )

    def proc(self, ln: _Line, name: str, src: str, at: int) -> tuple[list[tuple[str, str]], bool]:
        """A PROC line's parameters (type, name) and whether it has SAVE."""
        t = _Tokens(ln.code)
        t.i = 1
        try:
            if t.peek()[1] != name:
                raise _Error(f"the file holds PROC {t.peek()[1]}, not {name}", t.col())
            t.i += 1
            params = []
            if t.take("("):
                while not t.take(")"):
                    if t.peek()[1] == "VAR":
                        raise _Error("a VAR parameter (by reference) is not read", t.col())
                    typ = t.peek()[1]
                    if typ not in ("INT", "REAL", "BOOL"):
                        raise _Error(f"a parameter of type {typ}: only INT, REAL and BOOL are read", t.col())
                    t.i += 1
                    pname = t.peek()
                    if pname[0] != "name" or t.peek(1)[1] in ("[", "="):
                        raise _Error("expected a parameter's name (arrays and defaults are not read)", t.col())
                    params.append((typ, pname[1]))
                    t.i += 1
                    if t.peek()[1] != ")":
                        t.need(",")
            save = False
            while t.peek()[0] != "end":
                word = t.peek()[1]
                if word == "SAVE":
                    save = True
                elif word not in ("DISPLOF", "DISPLON", "SBLOF", "SBLON", "ACTBLOCNO"):
                    raise _Error(f"PROC attribute {word} is not read", t.col())
                t.i += 1
        except _Error as e:
            raise InputError(e.message, src, at + 1, ln.code_at + e.col) from None
        return params, save

    def leave(self) -> int:
        """Return from a subprogram (RET, M17, its end): the caller's line after the call; with
        SAVE, the caller's motion mode, plane and G90/G91 again."""
        lines, src, flow, targets, for_end, back, caller, snapshot, name = self.calls.pop()
        if snapshot is not None:
            mode, plane, absolute, inch, trans = snapshot
            if trans != (self.s.trans, self.s.rot) or inch != self.s.inch:
                raise _Error(
                    f"{name} (SAVE) changes a frame or the units: what the control gives back is not followed", 1
                )
            self.s.mode, self.s.plane, self.s.absolute = mode, plane, absolute
            self.items.append(Item(0, "state", f"G{plane}", f"G{plane}"))
            self.items.append(Item(0, "state", "G90" if absolute else "G91", "G90" if absolute else "G91"))
            self.s.after_cycle = mode is not None  # the next move names the mode given back
        self.items.append(Item(0, "state", "", "", mark="pop_save" if snapshot is not None else "pop"))
        self.lines, self.src, self.flow, self.targets, self.for_end = lines, src, flow, targets, for_end
        self.m.vars = caller
        return back

    def call(self, name: str, col: int) -> _Error:
        what = "a cycle" if re.match(r"(CYCLE|POCKET|SLOT|HOLES|LONGHOLE)", name) else "a subprogram"
        return _Error(f"{name} calls {what} that is not read: the motion it makes is not known", col)

    def assignment(self, name: str, t: _Tokens, col: int, c0: int, b: _Block) -> None:
        if name in _AXES or name in ("I", "J", "K", "I1", "J1", "K1", "CR"):
            how = ""
            tok, nxt = t.peek(), t.peek(1)
            if tok[1] in ("AC", "IC") and nxt[1] == "(":
                how = tok[1]
                t.i += 2
                v = _expr(t, self.m)
                t.need(")")
            elif tok[1] in ("DC", "ACP", "ACN", "CAC", "CIC", "CACP", "CACN"):
                raise _Error(f"{name}={tok[1]}(…): rotary positioning is not followed", col)
            else:
                v = _expr(t, self.m)
            b.put(name, v, how, col, (c0, t.toks[t.i - 1][3]))
            return
        if name == "RPL":
            if b.rpl is not None:
                raise _Error("RPL is written twice in the block", col)
            b.rpl = _expr(t, self.m)
            return
        if name in ("F", "S"):
            v = _expr(t, self.m)
            b.pre.append((f"{name}{_fmt(v)}", f"{name}{_fmt(v)}"))
            return
        if name == "T":
            tok = t.peek()
            if tok[0] == "str":
                t.i += 1
                b.pre.append(("", f"T={tok[1]}"))
            else:
                b.pre.append(("", f"T{_fmt(_expr(t, self.m))}"))
            return
        if name in _COPY_ASSIGN or name == "TURN":
            v = _expr(t, self.m)
            if name == "TURN" and v != 0.0:
                raise _Error("TURN= (helix turns) is not followed", col)
            b.pre.append(("", f"{name}={_fmt(v)}"))
            return
        if name in ("AP", "RP", "AR"):
            what = "an arc by its angle" if name == "AR" else "polar coordinates"
            raise _Error(f"{name}= ({what}) is not followed", col)
        r = re.fullmatch(r"R(\d+)", name)
        if not r and self.m.vars.get(name, [None])[0] == "STRING":
            self.string(name, t, col)
            return
        if not r and name not in self.m.vars:
            if name.startswith("$"):
                raise _Error(f"{name} is a system variable: setting it is the machine's", col)
            raise _Error(f"'{name}' is not defined (DEF) in the program", col)
        self.m.set(("R", float(r.group(1))) if r else ("V", name), _expr(t, self.m), col)

    def string(self, name: str, t: _Tokens, col: int) -> None:
        """A STRING variable set to a literal or to another STRING's value (``<<`` and the string
        functions are not read)."""
        tok = t.peek()
        if tok[0] == "str":
            value = tok[1]
        elif tok[0] == "name" and self.m.vars.get(tok[1], [None])[0] == "STRING":
            value = self.m.vars[tok[1]][1]
        else:
            raise _Error(f"{name} is a STRING: only a text in quotes or another STRING is read as its value", col)
        t.i += 1
        if t.peek()[0] != "end" and t.peek()[1] != ",":
            raise _Error(f"{name} = … {t.peek()[1]}: string operations are not read", t.col())
        self.m.vars[name][1] = value

    def word(self, letter: str, v: float, text: str, col: int, span: tuple[int, int], b: _Block) -> None:
        if letter in _AXES or letter in "IJK":
            b.put(letter, v, "", col, span)
            return
        if letter == "G":
            self.g(v, text, col, span, b)
        elif letter == "M":
            m = int(v)
            if v != m:
                raise _Error(f"M{text} is not read", col)
            if m in (2, 17, 30):
                b.post.append(("M2", f"M{m}") if not self.calls else ("", ""))
                b.end, b.end_code = True, m
            elif m in (0, 1):
                b.post.append((f"M{m}", f"M{m}"))
            else:
                b.pre.append((f"M{m}", f"M{m}") if m in (3, 4, 5, 7, 8, 9) else ("", f"M{text}"))
        elif letter in ("F", "S"):
            b.pre.append((f"{letter}{text}", f"{letter}{text}"))
        elif letter in ("T", "D"):
            b.pre.append(("", f"{letter}{text}"))
        elif letter == "L":
            b.call = f"L{text}"
        else:
            raise _Error(f"{letter}{text} is not read", col)

    def g(self, v: float, text: str, col: int, span: tuple[int, int], b: _Block) -> None:
        g = int(v)
        if v != g:
            raise _Error(f"G{text} is not read", col)
        s = self.s
        if g in (0, 1, 2, 3):
            b.set_motion(f"G{g}", span, col)
        elif g == 4:
            b.dwell = True
        elif g in (53, 153):
            b.machine = f"G{g}"
        elif g in _COPY_G:
            b.pre.append(("", f"G{g}"))
        elif g in _UNITS:
            inch = g in (70, 700)
            if inch != bool(s.inch):
                # the position and the frame stay where they are: their numbers change unit
                k = 1.0 / MM_PER_INCH if inch else MM_PER_INCH
                s.pos = {a: (v * k if v is not None and a in _LINEAR else v) for a, v in s.pos.items()}
                s.trans = {a: (v * k if a in _LINEAR else v) for a, v in s.trans.items()}
            s.inch = inch
            b.pre.append((f"G{_UNITS[g]}", f"G{g}"))
        elif g in (54, 55, 56, 57, 500):
            if s.moved and s.wcs != g:
                raise _Error(f"G{g} changes the work system after a move: a field is in one system's coordinates", col)
            s.wcs = g
            s.pos = dict.fromkeys(_AXES)
            s.shifted |= set(_AXES)
            b.pre.append((f"G{g}" if g != 500 else "", f"G{g}"))
        elif g in _PASS_G:
            if g in (17, 18, 19):
                s.plane = g
            if g in (90, 91):
                s.absolute = g == 90
            b.pre.append((f"G{g}", f"G{g}"))
        elif g in _REFUSED_G:
            raise _Error(f"{_REFUSED_G[g]} is not followed", col)
        else:
            raise _Error(f"G{g} is not read", col)

    # --- what a block does
    def value_of(self, name: str, v: float, how: str, col: int) -> tuple[float, float | None]:
        """An axis word's value as the RS274 program writes it (absolute under G90, incremental
        under G91) and the absolute program coordinate it gives (None when not known)."""
        s = self.s
        p = s.pos[name]
        inc = how == "IC" or (how == "" and not s.absolute)
        if inc and name in s.shifted:
            raise _Error(
                f"{name} incremental after a change of frame or work system: whether the control travels the change "
                "is its setting (SD42440 $SC_FRAME_OFFSET_INCR_PROG); write the first move after it absolute",
                col,
            )
        if not inc:
            s.shifted.discard(name)
        if inc == (not s.absolute):  # written in the mode in effect
            return v, (v if s.absolute else (None if p is None else p + v))
        if p is None:
            raise _Error(f"{name}={how}(…) needs the position of {name}, which is not known here", col)
        absolute = p + v if inc else v
        return (absolute if s.absolute else absolute - p), absolute

    def move(self, i: int, b: _Block) -> None:
        s, mode = self.s, self.s.mode
        col0 = self.lines[i].code_at + 1
        if mode is None:
            raise _Error(
                "a move before any G0, G1, G2, G3 or CIP: the motion mode a program starts in is machine data "
                "($MC_GCODE_RESET_VALUES: G1 in Siemens' setting, which the machine's maker may change); write G0 "
                "or G1 before the first move, or state the machine's with --start-motion",
                col0,
            )
        at = self.lines[i].code_at
        spans = tuple(sp for _, _, sp in list(b.axes.values()) + list(b.arc.values()))
        if b.motion is not None:
            spans += (b.motion[1],)
        spans = tuple(sorted((at + s0, at + s1) for s0, s1 in spans))
        if b.machine is not None:
            if mode not in ("G0", "G1") or b.arc:
                raise _Error(f"{b.machine} with {mode}: only straight moves are read in machine coordinates", col0)
            if any(how == "IC" for _, how, _ in b.axes.values()) or not s.absolute:
                raise _Error(f"{b.machine} with incremental values is not read", col0)
            moves = " ".join(f"{a}{_fmt(v)}" for a, (v, _, _) in b.axes.items())
            self.items.append(Item(i, "motion", f"G53 {mode} {moves}", None, (), mode, b.machine))
            for a in b.axes:
                s.pos[a] = None
            if s.rot != 0.0 and {"X", "Y"} & set(b.axes):  # each frame coordinate is both machine axes'
                s.pos["X"] = s.pos["Y"] = None
            s.tangent = None
            return
        shifted_before = frozenset(s.shifted)
        written, ends = {}, {}
        for a, (v, how, sp) in b.axes.items():
            written[a], ends[a] = self.value_of(a, v, how, self.lines[i].code_at + sp[0] + 1)
        tail: list[str] = []
        if mode in ("G0", "G1"):
            if b.arc:
                raise _Error(f"{', '.join(b.arc)} in a straight move ({mode}) is not read", col0)
            words = [b.motion[0]] if b.motion is not None else ([mode] if s.after_cycle else [])
            start = [s.pos[a] for a in _LINEAR]
            end = [ends.get(a, p) for a, p in zip(_LINEAR, start, strict=True)]
            if any(v is None for v in start + end):
                s.tangent = None
            elif any(e != q for e, q in zip(end, start, strict=True)):
                s.tangent = (end[0] - start[0], end[1] - start[1], end[2] - start[2])  # type: ignore[operator]
        else:
            code, tail = self.circle(mode, ends, b.arc, col0)
            words = [code]
        if s.rot != 0.0 and ("X" in written or "Y" in written or tail):
            written, tail = self.turned(mode, written, ends, tail, col0)
        words += [f"{a}{_fmt(v)}" for a, v in written.items()] + tail
        s.moved, s.after_cycle = True, False
        s.pos.update(ends)
        self.items.append(
            Item(
                i,
                "motion",
                " ".join(words),
                None,
                spans,
                mode,
                None,
                explicit=b.motion is not None,
                incremental=not s.absolute,
                shifted=shifted_before,
                rot=s.rot,
            )
        )

    def turned(self, mode: str, written: dict, ends: dict, tail: list[str], col: int) -> tuple[dict, list[str]]:
        """A move's straight words under a rotation about Z: X and Y (both) and an arc's I J
        turned into the unrotated frame (G52's)."""
        s = self.s
        if mode not in ("G0", "G1") and s.plane != 17:
            raise _Error(f"an arc in G{s.plane} under a rotation about Z: its plane turns out of G{s.plane}", col)
        if s.absolute:
            x, y = ends.get("X", s.pos["X"]), ends.get("Y", s.pos["Y"])
            if x is None or y is None:
                raise _Error("a move under a rotation needs the position of X and Y, which is not known here", col)
        else:
            x, y = written.get("X", 0.0), written.get("Y", 0.0)
        x, y = _turn(x, y, s.rot)
        out = {"X": x, "Y": y} | {a: v for a, v in written.items() if a not in ("X", "Y")}
        centre = dict((w[0], float(w[1:])) for w in tail if w[0] in "IJ")
        if centre:
            i, j = _turn(centre.get("I", 0.0), centre.get("J", 0.0), s.rot)
            tail = [f"I{_fmt(i)}", f"J{_fmt(j)}"] + [w for w in tail if w[0] not in "IJ"]
        return out, tail

    def circle(self, mode: str, ends: dict, arc: dict, col: int) -> tuple[str, list[str]]:
        """The arc's direction (``G2``/``G3``) and its centre (incremental) or radius words."""
        s = self.s
        a1, a2, c1, c2 = _PLANES[s.plane]
        if mode not in ("CIP", "CT") and "CR" not in arc and c1 not in arc and c2 not in arc:
            raise _Error(f"{mode} without a centre ({c1}, {c2}) or a radius (CR=)", col)
        start = (s.pos[a1], s.pos[a2])
        if start[0] is None or start[1] is None:
            raise _Error(f"an arc ({mode}) from a position that is not known here", col)
        end = (ends.get(a1, start[0]), ends.get(a2, start[1]))
        if any(e is None for e in end):
            raise _Error(f"an arc ({mode}) to a position that is not known here", col)
        if mode == "CT":
            if arc:
                raise _Error(f"CT with {', '.join(sorted(arc))}: a tangential arc takes its end point only", col)
            t = s.tangent
            tx, ty = (t[_LINEAR.index(a1)], t[_LINEAR.index(a2)]) if t is not None else (0.0, 0.0)
            norm = math.hypot(tx, ty)
            if norm == 0.0:
                raise _Error(
                    f"CT after a move whose direction in the plane G{s.plane} is not known here (a first move, a "
                    "move along the plane's normal, a machine-coordinate move)",
                    col,
                )
            nx, ny = -ty / norm, tx / norm  # the left of the direction
            dx, dy = end[0] - start[0], end[1] - start[1]
            dn = dx * nx + dy * ny
            if abs(dn) <= 1e-9 * max(math.hypot(dx, dy), 1.0):
                raise _Error("CT along the direction it starts in: a straight line, not an arc", col)
            r = (dx * dx + dy * dy) / (2.0 * dn)  # signed: left of the direction when positive
            ux, uy = r * nx, r * ny
            code = "G3" if dn > 0 else "G2"
            self._end_tangent(code, start, end, (ux, uy), a1, a2)
            return code, [f"{c1}{_fmt(ux)}", f"{c2}{_fmt(uy)}"]
        if mode == "CIP":
            normal = next(a for a in _LINEAR if a not in (a1, a2))
            if normal in ends and (s.pos[normal] is None or ends[normal] != s.pos[normal]):
                raise _Error(
                    f"CIP moving {normal}: a circle through three points in space, off the plane G{s.plane}, is not "
                    "followed",
                    col,
                )
            names = (c1 + "1", c2 + "1")
            extra = set(arc) - set(names)
            if extra:
                raise _Error(
                    f"CIP with {', '.join(sorted(extra))}: only an intermediate point in the active plane "
                    f"(G{s.plane}) is read",
                    col,
                )
            mid = []
            for k, c in enumerate(names):
                if c not in arc:
                    raise _Error(f"CIP without {c}= (its intermediate point)", col)
                v, how, _ = arc[c]
                inc = how == "IC" or (how == "" and not s.absolute)
                mid.append(start[k] + v if inc else v)
            bx, by = mid[0] - start[0], mid[1] - start[1]
            cx, cy = end[0] - start[0], end[1] - start[1]
            cross = bx * cy - by * cx
            scale = max(math.hypot(bx, by), math.hypot(cx, cy))
            if abs(cross) <= 1e-9 * scale * scale:
                raise _Error("CIP through three points on a line, or back to its start: no circle", col)
            bb, cc = bx * bx + by * by, cx * cx + cy * cy
            ux, uy = (cy * bb - by * cc) / (2 * cross), (bx * cc - cx * bb) / (2 * cross)
            code = "G3" if cross > 0 else "G2"
            self._end_tangent(code, start, end, (ux, uy), a1, a2)
            return code, [f"{c1}{_fmt(ux)}", f"{c2}{_fmt(uy)}"]
        other = set(arc) - {"CR", "I", "J", "K"}
        if other:
            raise _Error(f"{', '.join(sorted(other))} in a {mode} arc is not read", col)
        given = [c for c in (c1, c2) if c in arc]
        if "CR" in arc:
            if given:
                raise _Error(f"{mode} with both CR= and a centre", col)
            r, how, _ = arc["CR"]
            if how:
                raise _Error(f"CR={how}(…) is not read", col)
            if end == start:
                raise _Error(f"{mode} CR= with its end at its start: no circle", col)
            half = math.hypot(end[0] - start[0], end[1] - start[1]) / 2.0
            if half <= abs(r):
                # the centre: off the chord's middle, left of it for G3 with CR > 0 (and G2 with CR < 0)
                h = math.sqrt(r * r - half * half) * (1.0 if (mode == "G3") == (r > 0) else -1.0)
                cx, cy = (end[0] - start[0]) / (2 * half), (end[1] - start[1]) / (2 * half)
                off = (half * cx - h * cy, half * cy + h * cx)
                self._end_tangent(mode, start, end, off, a1, a2)
            else:
                s.tangent = None
            return mode, [f"R{_fmt(r)}"]
        centre = []
        for k, c in enumerate((c1, c2)):
            v, how, _ = arc.get(c, (0.0, "", None))
            inc = how != "AC"  # I J K are incremental unless AC: G90 does not change them
            centre.append(v if inc else v - start[k])
        self._end_tangent(mode, start, end, (centre[0], centre[1]), a1, a2)
        return mode, [f"{c1}{_fmt(centre[0])}", f"{c2}{_fmt(centre[1])}"]

    def _end_tangent(self, code: str, start, end, off, a1: str, a2: str) -> None:
        """The direction an arc ends in (in its plane), from its centre ``start + off``."""
        rx, ry = end[0] - start[0] - off[0], end[1] - start[1] - off[1]
        tx, ty = (-ry, rx) if code == "G3" else (ry, -rx)
        t = [0.0, 0.0, 0.0]
        t[_LINEAR.index(a1)], t[_LINEAR.index(a2)] = tx, ty
        self.s.tangent = (t[0], t[1], t[2])

    def dwell(self, b: _Block, i: int) -> None:
        times = [p for p in b.pre if p[1][:1] in ("F", "S")]
        if b.axes or b.arc or len(times) != 1 or len(b.pre) != 1 or b.post or b.motion:
            raise _Error("G4 with other words than one F (seconds) or S (spindle turns)", self.lines[i].code_at + 1)
        rs, sn = times[0]
        self.items.append(Item(i, "state", f"G4 P{sn[1:]}" if sn.startswith("F") else "", f"G4 {sn}"))

    def set_frame(self, b: _Block, i: int) -> int:
        """TRANS/ATRANS (translations) and ROT/AROT about Z (``ROT Z…``, ``ROT RPL=…`` in G17):
        TRANS and ROT replace the programmable frame, ATRANS and AROT add to it in the frame in
        force (an ATRANS after a rotation moves along the turned axes). The straight program
        holds the translation as G52 and each move's X Y turned by the rotation."""
        col = self.lines[i].code_at + 1
        kind, axes, s = b.frame or "TRANS", b.axes, self.s
        if b.motion is not None or b.pre or b.post or b.arc or b.machine:
            raise _Error(f"{kind} with other words: a frame is programmed in a block of its own", col)
        if b.rpl is not None and kind not in ("ROT", "AROT"):
            raise _Error(f"RPL= with {kind}: a rotation in the plane is programmed with ROT or AROT", col)
        if kind in ("ROT", "SCALE", "MIRROR") and not axes and b.rpl is None:
            kind = "TRANS"  # without axes they take the whole programmable frame away
        new, rot = dict.fromkeys(_AXES, 0.0) if kind in ("TRANS", "ROT") else dict(s.trans), s.rot
        if kind in ("ROT", "AROT"):
            if b.rpl is not None and axes:
                raise _Error(f"{kind} with RPL= and axes", col)
            if b.rpl is None and not axes:
                raise _Error(f"{kind} without an angle", col)
            if b.rpl is None and (set(axes) != {"Z"} or axes["Z"][1]):
                other = ", ".join(a for a in axes if a != "Z") or f"Z={axes['Z'][1]}(…)"
                raise _Error(f"{kind} {other}: only a rotation about Z is followed (the plane would tilt)", col)
            if b.rpl is not None and s.plane != 17:
                raise _Error(f"{kind} RPL= in G{s.plane}: only a rotation about Z (in G17) is followed", col)
            angle = b.rpl if b.rpl is not None else axes["Z"][0]
            rot = angle if kind == "ROT" else rot + angle
            if not (math.isfinite(rot) and abs(rot) <= 1e6):
                raise _Error(f"{kind}: the angle {rot:g} is out of range", col)
        elif kind in ("TRANS", "ATRANS"):
            if kind == "TRANS":
                rot = 0.0
            step = {}
            for a, (v, how, _) in axes.items():
                if how or a not in _LINEAR:
                    raise _Error(
                        f"{kind} {a}{'=' + how + '(…)' if how else ''} is not read: translations of X, Y, Z are", col
                    )
                step[a] = v
            if kind == "ATRANS":  # along the axes of the frame in force
                step["X"], step["Y"] = _turn(step.get("X", 0.0), step.get("Y", 0.0), s.rot)
            for a, v in step.items():
                new[a] += v
                if not abs(new[a]) <= COORD_MAX:
                    raise _Error(f"{kind}: the translation of {a} ({new[a]:g}) is out of range", col)
        else:
            raise _Error(f"{kind} ({'a rotation' if 'ROT' in kind else 'scaling or mirroring'}) is not followed", col)
        # the position in the new frame: the same place
        base: dict[str, float | None] = {a: None if s.pos[a] is None else s.pos[a] + s.trans[a] for a in _AXES}
        if s.pos["X"] is not None and s.pos["Y"] is not None:
            dx, dy = _turn(s.pos["X"], s.pos["Y"], s.rot)
            base["X"], base["Y"] = dx + s.trans["X"], dy + s.trans["Y"]
        # the axes whose frame changed (SD42440): under a rotation a frame axis is both machine
        # axes, so X and Y change together
        turned = rot != s.rot or (
            (rot != 0.0 or s.rot != 0.0) and any(abs(new[a] - s.trans[a]) > 1e-9 for a in ("X", "Y"))
        )
        for a in _AXES:
            if abs(new[a] - s.trans[a]) > 1e-9 or (turned and a in ("X", "Y")):
                s.shifted.add(a)
            here = base[a]
            if here is not None:
                s.pos[a] = here - new[a]
        if s.pos["X"] is not None and s.pos["Y"] is not None:
            s.pos["X"], s.pos["Y"] = _turn(s.pos["X"], s.pos["Y"], -rot)
        elif rot != 0.0 or s.rot != 0.0:
            s.pos["X"] = s.pos["Y"] = None  # one of them not known: turned, neither is
        if s.tangent is not None and rot != s.rot:  # (kept in the frame's coordinates)
            tx, ty = _turn(s.tangent[0], s.tangent[1], s.rot - rot)
            s.tangent = (tx, ty, s.tangent[2])
        s.trans, s.rot = new, rot
        words = " ".join(f"{a}{_fmt(new[a])}" for a in _LINEAR)
        given = "".join(f" {a}{_fmt(v)}" for a, (v, _, _) in axes.items())
        sn = (b.frame or kind) + (given if b.rpl is None else f" RPL={_fmt(b.rpl)}")
        self.items.append(Item(i, "state", f"G52 {words}", sn))
        return i + 1


def _turn(x: float, y: float, degrees: float) -> tuple[float, float]:
    """(x, y) turned about the origin by ``degrees`` (counter-clockwise seen from +Z)."""
    if degrees == 0.0:
        return x, y
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return c * x - s * y, s * x + c * y


def translate(
    data: bytes,
    name: str = "<program>",
    subprograms: Sequence[str | os.PathLike] = (),
    start_motion: str | None = None,
) -> Translation:
    """The straight RS274NGC program a Sinumerik program runs (see the module's text). A called
    subprogram is looked for beside the program (when ``name`` is its file), then in each folder
    of ``subprograms``. ``start_motion`` (``"G0"`` or ``"G1"``): the motion mode the machine
    starts a program in, which its machine data sets ($MC_GCODE_RESET_VALUES); without it a move
    before the program states one is refused."""
    if start_motion not in START_MOTIONS:
        raise ValueError(f"start_motion must be one of {START_MOTIONS}, not {start_motion!r}")
    text = rewrite.program_text(data)
    lines = _read(text, name)
    path = Path(name) if name and not name.startswith("<") else None
    folders = [path.parent] if path is not None and path.is_file() else []
    for d in map(Path, subprograms):
        if not d.is_dir():
            raise InputError(f"subprogram folder {d} is not a folder", str(d))
        folders.append(d)
    run = _Run(lines, name, folders)
    run.s.mode = start_motion
    i, blocks = 0, 0
    while True:
        if i >= len(run.lines) and not run.calls:
            break
        blocks += 1
        if blocks > MAX_BLOCKS:
            raise InputError(
                f"the program runs more than {MAX_BLOCKS:,} blocks: a loop that does not end?", run.src, i + 1
            )
        top = run.calls[0] if run.calls else None
        n0 = len(run.items)
        try:
            nxt = run.step(i) if i < len(run.lines) else run.leave()  # a subprogram's end returns as RET
        except _Error as e:
            raise InputError(e.message, run.src, i + 1, e.col) from None
        if top is not None:  # the items a subprogram makes belong to the program's line that calls it
            for it in run.items[n0:]:
                it.line, it.sub = top[5] - 1, top[8]
        if nxt is None:
            break
        i = nxt
    first = next((k for k, it in enumerate(run.items) if it.kind == "motion"), None)
    if start_motion is not None and first is not None:
        # the mode the machine starts in, just before the straight program's first move (after
        # the words its block sets first, such as F: rs274 refuses a G1 without a feed rate)
        run.items.insert(first, Item(run.items[first].line, "state", start_motion, ""))
    if any(it.rs.startswith("G52 ") for it in run.items):
        # the programmable frame is empty when a program starts (the control deletes it at reset
        # and at the end of a program): the engine follows the translations (the program's or a
        # subprogram's) from there (before anything else: after a motion code, the engine takes
        # G52 for an offset the machine may have moved under)
        run.items.insert(0, Item(0, "state", "G52 X0 Y0 Z0", ""))
    return Translation(
        rewrite.mark([it.rs for it in run.items]),
        run.items,
        np.asarray([it.line + 1 for it in run.items], dtype=np.int64),
        run.runs,
        blocks,
        data,
        run.read,
    )


# ----------------------------------------------------------------------------------- writing back
_RADIUS = re.compile(r"(?<![A-Z_=])R(?=[-+]?[.\d])")
#: The words that stop the program or end it, after the block's motion.
_STOPS = re.compile(r"(?<![A-Z0-9_.])M0*(?:0|1|2|17|30)(?![\d.])", re.I)
_MOTION = re.compile(r"(?<![A-Z_0-9.])G0*([0-3])(?![\d.])|\b(CIP|CT)\b")
#: A word of the straight program (the engine's output): its letter and its number.
_WORD = re.compile(r"(?<![A-Z0-9.])([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")


class NeedsExpand(Exception):
    """A corrected line runs more than once with different corrections, or is in a subprogram
    (``sub``, called at ``line``): only the program written straight (``expand``) holds them.
    ``line`` (1-based), ``runs``."""

    def __init__(self, line: int, runs: int, sub: str | None = None):
        super().__init__(line, runs, sub)
        self.line, self.runs, self.sub = line, runs, sub


def _sinumerik(rs: str) -> str:
    """An RS274 line the engine wrote, in Sinumerik's words (its radius ``R`` is ``CR=``)."""
    return _RADIUS.sub("CR=", rs)


def _last_mode(text: str, mode: str | None) -> str | None:
    for m in _MOTION.finditer(re.sub(r'"[^"]*"', '""', text)):
        mode = f"G{m.group(1)}" if m.group(1) else m.group(2)
    return mode


def assemble(tr: Translation, corrected: bytes, expand: bool = False) -> tuple[bytes, int, str]:
    """The Sinumerik program the engine's ``corrected`` straight program makes, and how many of
    its lines were written, and how (``as it is``, ``in place``, ``straight``): the program as
    written when nothing changed; otherwise each line
    whose move changed rewritten in place (its other words, its comment and every other line
    kept as written). When a changed move is on a line that runs more than once (a loop, a
    jump back), the program is written straight with ``expand`` (one line per block run), and
    :class:`NeedsExpand` is raised without it."""
    groups = rewrite.groups(corrected, len(tr.items))
    changed = rewrite.changed(groups, [it.rs for it in tr.items])
    if any(it.rot for it in tr.items):
        groups = _unturned(tr, groups)
    for k in map(int, np.flatnonzero(changed)):
        it = tr.items[k]
        if it.kind == "state" and it.rs.startswith("G0 Z") and k + 1 < len(tr.items) and tr.items[k + 1].cycle:
            raise Unwritable(
                it.line + 1,
                "the rapid to a drilling cycle's retraction plane was corrected (--rapids): "
                "the cycle's own retraction is not",
            )
        if it.kind != "motion" or it.machine is not None:
            raise RuntimeError(f"the engine changed line {it.line + 1}, which is not a move it corrects: {groups[k]}")
        if it.cycle is not None:
            _cycle_values(it, groups[k])  # refuses what a call cannot say
        if it.incremental and it.shifted:
            named = {a for t in groups[k] for a, _ in _WORD.findall(t.split(";")[0]) if a in "XYZ"}
            if named & it.shifted:
                raise Unwritable(
                    it.line + 1,
                    f"the correction writes an incremental {', '.join(sorted(named & it.shifted))} after a change of "
                    "frame or work system: whether the control travels the change is its setting (SD42440)",
                )
    if not any(changed):
        return tr.source, 0, "as it is"
    looped = [k for k in map(int, np.flatnonzero(changed)) if tr.runs[tr.items[k].line] > 1 or tr.items[k].sub]
    if looped and not expand:
        it = tr.items[looped[0]]
        raise NeedsExpand(it.line + 1, int(tr.runs[it.line]), it.sub)
    if looped:
        out = []
        for g, it in zip(groups, tr.items, strict=True):
            if it.machine is not None:
                out.append(it.rs.replace("G53", it.machine, 1))
            elif it.cycle is not None:
                values = _cycle_values(it, g)
                out.append(f"{it.cycle[0]}({', '.join('' if v is None else _fmt(v) for v in values)})")
            elif it.kind == "motion":
                out += [_sinumerik(t) for t in g]
            elif it.sn:
                out.append(it.sn)
        return "".join(t + "\n" for t in out).encode("utf-8", "surrogateescape"), len(out), "straight"
    redo: dict[int, int] = {tr.items[k].line: int(k) for k in np.flatnonzero(changed)}  # original line → item
    # A CT arc starts in the direction the move before it ends in: after a rewritten move (cut in
    # pieces, or moved) that direction is not the program's, so a CT is written as its arc.
    after_redo = False
    for k, it in enumerate(tr.items):
        if it.kind != "motion":
            continue
        if it.line not in redo and it.mode == "CT" and after_redo:
            if tr.runs[it.line] > 1 or it.sub:
                raise NeedsExpand(it.line + 1, int(tr.runs[it.line]), it.sub)
            redo[it.line] = k
        after_redo = it.line in redo
    src = rewrite.lines_of(tr.source)
    rewritten = {j: _rewrite(src[j][0], tr.items[k], groups[k]) for j, k in redo.items()}
    # The motion mode each line is read in, in the order the program runs: a line left as written
    # after a rewritten one that left another mode in force (a CIP written as G2 or as pieces) gets
    # its own mode written, the same on every run.
    own = [_last_mode(_code(body), None) for body, _ in src]
    need: dict[int, set[str]] = {}
    mode: str | None = None
    at_calls: list[str | None] = []
    for it in tr.items:
        j = it.line
        if it.mark == "push":
            at_calls.append(mode)
            continue
        if it.mark in ("pop", "pop_save"):
            given_back = at_calls.pop()
            if it.mark == "pop_save":  # SAVE: the control gives back the mode the call found
                mode = given_back
            continue
        if it.sub is not None:  # a subprogram's moves run as written, in the mode they find
            if it.kind == "motion" and it.mode is not None and it.cycle is None:
                if not it.explicit and mode is not None and mode != it.mode:
                    raise NeedsExpand(j + 1, int(tr.runs[j]), it.sub)
                mode = it.mode
        elif j in rewritten:
            for t in rewritten[j]:
                mode = _last_mode(_code(t), mode)
        elif own[j] is not None:
            mode = own[j]
        elif it.kind == "motion" and it.mode is not None and it.cycle is None:
            if mode is not None and mode != it.mode:
                need.setdefault(j, set()).add(it.mode)
            mode = it.mode
    repl = dict(rewritten)
    for j, modes in need.items():
        if len(modes) > 1:
            raise NeedsExpand(j + 1, int(tr.runs[j]))
        body = src[j][0]
        at = _code_start(body)
        repl[j] = [body[:at] + next(iter(modes)) + " " + body[at:]]
    return rewrite.splice(tr.source, repl), len(rewritten), "in place"


def _unturned(tr: Translation, groups: list[list[str]]) -> list[list[str]]:
    """``groups`` with the lines of the moves made under a rotation about Z written in the
    frame's own coordinates: X Y (an absolute line's missing one from where the straight
    program is) and I J turned back. The straight program is followed line by line for that."""
    pos: dict[str, float | None] = {"X": 0.0, "Y": 0.0}  # the straight program's, from G52's origin
    off = {"X": 0.0, "Y": 0.0}
    absolute, inch = True, False
    out = []
    for g, it in zip(groups, tr.items, strict=True):
        new = []
        for line in g:
            code = line.split(";")[0]
            words = _WORD.findall(code)
            gs = {float(v) for a, v in words if a == "G"}
            absolute = False if 91 in gs else True if 90 in gs else absolute
            k = 1.0 / MM_PER_INCH if 20 in gs and not inch else MM_PER_INCH if 21 in gs and inch else 1.0
            if k != 1.0:  # a change of units: the straight program's numbers are the new unit's
                pos = {a: None if v is None else v * k for a, v in pos.items()}
                off = {a: v * k for a, v in off.items()}
            inch = True if 20 in gs else False if 21 in gs else inch
            named = {a: float(v) for a, v in words if a in "XYIJ"}
            if 52 in gs:
                for a in off:
                    v = named.get(a, 0.0)
                    p = pos[a]
                    pos[a] = None if p is None else p + off[a] - v
                    off[a] = v
                new.append(line)
                continue
            if 53 in gs or 28 in gs or 30 in gs:
                for a in ("X", "Y"):
                    if a in named or 53 not in gs:
                        pos[a] = None
                new.append(line)
                continue
            p0 = dict(pos)
            for a in ("X", "Y"):
                if a in named:
                    pos[a] = named[a] if absolute else (None if p0[a] is None else p0[a] + named[a])  # type: ignore[operator]
            if it.rot == 0.0 or it.kind != "motion" or not ({"X", "Y", "I", "J"} & set(named)):
                new.append(line)
                continue
            if absolute:
                if pos["X"] is None or pos["Y"] is None:
                    raise Unwritable(it.line + 1, "a move under a rotation from a position the program does not tell")
                x, y = _turn(pos["X"], pos["Y"], -it.rot)
            else:
                x, y = _turn(named.get("X", 0.0), named.get("Y", 0.0), -it.rot)
            turned = {"X": x, "Y": y}
            if not absolute:  # an increment of nothing is not written (its axis may not take one)
                turned = {a: v for a, v in turned.items() if abs(v) > 1e-9} or {"X": 0.0}
            if "I" in named or "J" in named:
                turned["I"], turned["J"] = _turn(named.get("I", 0.0), named.get("J", 0.0), -it.rot)
            # the frame's words where the straight program's were: X Y at the first of them, I J likewise
            text, done = [], set()
            last = 0
            for m in _WORD.finditer(code):
                a = m.group(1)
                if a not in "XYIJ":
                    continue
                text.append(code[last : m.start()])
                pair = ("X", "Y") if a in "XY" else ("I", "J")
                if pair[0] not in done:
                    text.append(" ".join(f"{b}{_fmt(turned[b])}" for b in pair if b in turned))
                    done.add(pair[0])
                last = m.end()
            text.append(code[last:])
            new.append(re.sub(r"[ \t]{2,}", " ", "".join(text)).strip() + line[len(code) :])
        out.append(new)
    return out


def _code(line: str) -> str:
    """A line without its comment, upper case outside strings."""
    return _split(line)[0]


def _code_start(line: str) -> int:
    """Where a line's words start, after its N number and label."""
    code = _code(line)
    at = 0
    m = re.match(r"\s*N\d+(?![\d.])\s*", code)
    if m:
        at = m.end()
    m = re.match(r"\s*[A-Z_][A-Z0-9_]*:(?!=)\s*", code[at:])
    if m:
        at += m.end()
    return at + (len(code[at:]) - len(code[at:].lstrip()))


class Unwritable(Exception):
    """A corrected block that the program's own syntax cannot say (a drilling cycle's hole moved
    in X or Y): ``line`` (1-based), ``message``."""

    def __init__(self, line: int, message: str):
        super().__init__(line, message)
        self.line, self.message = line, message


def _cycle_values(it: Item, group: list[str]) -> list[float | None]:
    """A drilling cycle's arguments after the correction: the engine's cycle block (R and Z moved
    by the field) as the reference plane (R less the safety clearance) and the final depth; the
    relative depth DPR, the retraction plane and the rest as written."""
    name, args, _, sdis = it.cycle  # type: ignore[misc]
    if len(group) != 1:
        raise Unwritable(
            it.line + 1, f"{name}: the correction wrote its hole as moves (--expand-cycles); a call cannot hold them"
        )
    words = dict(_WORD.findall(group[0].split(";")[0]))
    if "X" in words or "Y" in words:
        raise Unwritable(
            it.line + 1,
            f"{name}: the field moves the hole in X or Y, and the call drills where the "
            "tool stands: move the position before it",
        )
    r, z = float(words["R"]), float(words["Z"])
    if r > args[0]:
        raise Unwritable(
            it.line + 1,
            f"{name}: the field raises the safety plane to {r:g}, above the retraction "
            f"plane {args[0]:g}, where the cycle retracts: raise RTP",
        )
    values = list(args)
    values[1] = r - sdis
    if values[3] is not None:
        values[3] = z
    if name == "CYCLE83" and values[5] is not None:  # the first depth, absolute: moved with the hole
        values[5] = args[5] + (values[1] - args[1])
    return values


def _comment_at(text: str) -> int:
    """Where a line's comment starts (a ';' outside strings), or its length."""
    quoted = False
    for k, c in enumerate(text):
        if c == '"':
            quoted = not quoted
        elif c == ";" and not quoted:
            return k
    return len(text)


def _take_stops(text: str) -> tuple[str, list[str]]:
    """``text`` without the words that stop or end the program (outside strings and the
    comment), and those words."""
    end = _comment_at(text)
    parts = re.split(r'("[^"]*")', text[:end])  # strings at the odd places
    stops: list[str] = []
    for k in range(0, len(parts), 2):
        stops += [w.strip() for w in _STOPS.findall(parts[k])]
        if stops:
            parts[k] = re.sub(r"[ \t]{2,}", " ", _STOPS.sub("", parts[k]))
    return "".join(parts) + text[end:], stops


def _rewrite(body: str, it: Item, group: list[str]) -> list[str]:
    """The original line ``body`` with its move's words replaced by the engine's first line, and
    the lines the engine added after it (a drilling cycle: its reference plane and depth)."""
    if it.cycle is not None:
        values, spans = _cycle_values(it, group), it.cycle[2]
        out, at = [], 0
        for k in (1, 3, 5) if it.cycle[0] == "CYCLE83" else (1, 3):
            v = values[k]
            if spans[k] is not None and v is not None:
                out += [body[at : spans[k][0]], _fmt(v)]
                at = spans[k][1]
        return ["".join(out) + body[at:]]
    first = _sinumerik(group[0]).strip()
    keep, at = [], 0
    for s0, s1 in it.spans:
        keep.append(body[at:s0])
        at = s1
    keep.append(body[at:])
    head = keep[0]
    rest = " ".join(piece.strip() for piece in keep[1:] if piece.strip())
    stops: list[str] = []
    if len(group) > 1:
        # a stop or the program's end acts after the block's motion: it goes to the last piece
        head, before = _take_stops(head)
        rest, after = _take_stops(rest)
        stops = before + after
        rest = rest.strip()
    sep = "" if not head.lstrip(rewrite.BOM) or head.endswith((" ", "\t")) else " "
    line = head + sep + first + (" " + rest if rest else "")
    tail = [_sinumerik(t).strip() for t in group[1:]]
    if stops:
        tail[-1] += " " + " ".join(stops)
    return [line, *tail]
