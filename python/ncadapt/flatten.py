"""Flatten an RS274NGC program: parameters, expressions and O-word flow evaluated into straight
G-code, as LinuxCNC's interpreter runs them (and, in the Fanuc dialect, M98/M99 subprograms and
Custom Macro B: see :func:`flatten` and :class:`_FanucMachine`).

``ncadapt correct --expand`` corrects the flattened program: every block the program runs, in the
order it runs them, with its words' values computed (``X[2*#1]`` → ``X8``), numbered, named and
global parameters set, ``o… sub/endsub/call/return``, ``if/elseif/else/endif``,
``while/endwhile``, ``do/while``, ``repeat/endrepeat``, ``break`` and ``continue`` followed.
Lines that only set parameters or steer the flow are left out; comments stay with their block.

Refused, at their line (:class:`~ncadapt.InputError`): what only the machine knows (parameters
#5000 and up and LinuxCNC's predefined named parameters such as ``#<_x>`` or ``#<_value>`` before
a ``return`` sets it: positions, offsets, probe results, tool data), a subroutine in another file,
an undefined named parameter, LinuxCNC's errors (division by zero, the square root of a negative
number, an O-word without its match), and a program that runs more than :data:`MAX_BLOCKS` blocks
(a loop that does not end).

The rules are LinuxCNC 2.9's (its documentation, "O Codes" and "Numbered Parameters" /
"Expressions"): parameters set on a line take effect after the line is read, so its other words
see the old values; EQ and NE compare within 0.0001; MOD's result is from 0 up to the divisor's size;
ROUND rounds halves away from zero; FIX and FUP are floor and ceiling; trigonometry in degrees;
#1–#30 are a subroutine's arguments and locals, named parameters without a leading underscore
local to their subroutine.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from . import rewrite
from .errors import InputError
from .rewrite import split_lines

#: Most blocks a flattened program may hold: a loop that runs more is taken as one that does not end.
MAX_BLOCKS = 5_000_000
#: Deepest subroutine nesting (LinuxCNC's is 10).
MAX_DEPTH = 10
#: Numbered parameters the program may use; from #5000 up they hold the machine's state.
MACHINE_PARAMETERS = 5000
#: EQ and NE compare within this (LinuxCNC's TOLERANCE_EQUAL).
TOLERANCE_EQUAL = 0.0001

_FUNCS = {
    "abs": abs,
    "acos": lambda x: math.degrees(math.acos(x)),
    "asin": lambda x: math.degrees(math.asin(x)),
    "cos": lambda x: math.cos(math.radians(x)),
    "sin": lambda x: math.sin(math.radians(x)),
    "tan": lambda x: math.tan(math.radians(x)),
    "exp": math.exp,
    "fix": math.floor,
    "fup": math.ceil,
    "ln": math.log,
    "round": rewrite.round_half_away,
    "sqrt": math.sqrt,
}
# binary operators by precedence, lowest first (LinuxCNC: ** > * / MOD > + - > comparisons > logic)
_LEVELS = [("and", "or", "xor"), ("eq", "ne", "gt", "ge", "lt", "le"), ("+", "-"), ("*", "/", "mod"), ("**",)]
_OPS = sorted({op for lv in _LEVELS for op in lv}, key=len, reverse=True)
# Fanuc Macro B (0i-F operator's manual, "Arithmetic and logic operation"): comparisons only in
# conditions, OR and XOR with + and -, AND with * / MOD; the logic works bit by bit on integers
_FANUC_LEVELS = [("eq", "ne", "gt", "ge", "lt", "le"), ("+", "-", "or", "xor"), ("*", "/", "mod", "and")]
# G codes (× 10) after which the machine's parameters (#5000 up) hold what the machine did: probing
# G38.x, offsets G10, G52, G54-G59.3, G92-G92.3, stored positions G28.1/G30.1, tool lengths G43/G49
_MACHINE_CODES = {
    100,
    382,
    383,
    384,
    385,
    520,
    540,
    550,
    560,
    570,
    580,
    590,
    591,
    592,
    593,
    920,
    921,
    922,
    923,
    281,
    301,
}
_MACHINE_CODES |= {430, 431, 432, 490}
_NUMBER = re.compile(r"[0-9]*\.?[0-9]*")
_LITERAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)")
_KEYWORDS = ("sub", "endsub", "call", "return", "if", "elseif", "else", "endif")
_KEYWORDS += ("while", "endwhile", "do", "repeat", "endrepeat", "break", "continue")


@dataclass(frozen=True)
class Flat:
    """A flattened program: ``data`` the straight G-code (bytes, one block a line), ``lines`` (n,)
    the 1-based line of the original program each of its lines comes from, ``blocks_run`` how many
    blocks the program ran (its flow lines included)."""

    data: bytes
    lines: np.ndarray
    blocks_run: int
    #: (lines of the program,) how many flattened lines each line gave
    runs: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: (lines of the program,) lines whose text cannot be replaced by their flattened block: they
    #: set parameters, or call or end a subprogram
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


_Error = rewrite.LineError


# ----------------------------------------------------------------------------------- reading lines
def _strip(raw: str) -> tuple[str, list[str]]:
    """A line without its comments (lower case, no spaces) and its comments as written."""
    out, comments, k = [], [], 0
    while k < len(raw):
        c = raw[k]
        if c == "(":
            end = raw.find(")", k)
            if end < 0:
                raise _Error("comment not closed", k + 1)
            comments.append(raw[k : end + 1])
            k = end + 1
        elif c == ";":
            comments.append("(" + raw[k + 1 :].strip().replace("(", "[").replace(")", "]") + ")")
            break
        else:
            if not c.isspace():
                out.append(c.lower())
            k += 1
    return "".join(out), comments


class _Parser:
    """Reads the words of one line (without comments, lower case) against the parameters `read`."""

    def __init__(self, text: str, read, fanuc: bool = False):
        self.s, self.k, self.read = text, 0, read
        # LinuxCNC's numbered parameters; Fanuc's variables: #0 (vacant) to the system's
        self.lo, self.hi = (0, 99999) if fanuc else (1, 5602)
        self.fanuc = fanuc
        self.address = False  # reading an NC word's value (not a macro statement)

    def peek(self, n: int = 1) -> str:
        return self.s[self.k : self.k + n]

    def take(self, lit: str) -> bool:
        if self.s.startswith(lit, self.k):
            self.k += len(lit)
            return True
        return False

    def need(self, lit: str) -> None:
        if not self.take(lit):
            raise _Error(f"expected '{lit}'", self.k + 1)

    def number(self) -> float:
        m = _NUMBER.match(self.s, self.k)
        text = m.group(0) if m else ""
        if text in ("", "."):
            raise _Error("expected a number", self.k + 1)
        self.k += len(text)
        return float(text)

    def value(self) -> float:
        """A real value: a number, [expression], #parameter, a function, or a signed one of these."""
        c = self.peek()
        if c == "-":
            self.k += 1
            return -self.value()
        if c == "+":
            self.k += 1
            return self.value()
        if c == "[":
            self.k += 1
            v = self.expr()
            self.need("]")
            return v
        if c == "#":
            return self.read(self.param_ref())
        if c.isalpha():
            m = re.compile(r"[a-z]+").match(self.s, self.k)
            name = m.group(0) if m else ""
            at = self.k
            if name == "atan":
                self.k += 4
                self.need("[")
                a = self.expr()
                self.need("]")
                self.need("/")
                self.need("[")
                b = self.expr()
                self.need("]")
                if self.fanuc and a == 0.0 and b == 0.0:
                    raise _Error("ATAN[0]/[0] has no value", at + 1)
                v = math.degrees(math.atan2(a, b))
                if self.fanuc and v < 0:
                    raise _Error(
                        f"ATAN of {a:g}/{b:g} is {v:g} or {v + 360:g}: the control's parameter (6004#0) decides", at + 1
                    )
                return v
            if name == "exists" and not self.fanuc:
                self.k += 6
                self.need("[")
                ref = self.param_ref()
                self.need("]")
                return 1.0 if self.read(ref, exists=True) else 0.0
            if name in _FUNCS:
                self.k += len(name)
                self.need("[")
                x = self.expr()
                self.need("]")
                if self.fanuc and name in ("fix", "fup"):
                    # Fanuc: FIX drops the fraction, FUP raises it away from zero (FUP[-1.2] = -2)
                    return float(math.trunc(x)) if name == "fix" else math.copysign(math.ceil(abs(x)), x) + 0.0
                if self.fanuc and name == "round" and self.address:
                    raise _Error(
                        "ROUND in an address rounds to the control's least input increment: write the value", at + 1
                    )
                if self.fanuc and name == "tan" and abs(math.cos(math.radians(x))) < 1e-12:
                    raise _Error(f"TAN[{x:g}] has no value", at + 1)
                try:
                    v = float(_FUNCS[name](x))
                except (ValueError, OverflowError):
                    raise _Error(f"{name.upper()}[{x:g}] has no value", at + 1) from None
                if self.fanuc and name == "asin" and v < 0:
                    raise _Error(
                        f"ASIN[{x:g}] is {v:g} or {v + 360:g}: the control's parameter (6004#0) decides", at + 1
                    )
                return v
            raise _Error(f"unknown function or word '{name}' in a value", at + 1)
        return self.number()

    def param_ref(self):
        """The parameter after '#': its number (int) or its name (str, lower case)."""
        self.need("#")
        if self.fanuc and self.peek() == "<":
            raise _Error("named parameters #<…> are LinuxCNC's, not Fanuc's", self.k + 1)
        if self.take("<"):
            end = self.s.find(">", self.k)
            if end < 0:
                raise _Error("named parameter not closed with '>'", self.k + 1)
            name = self.s[self.k : end]
            self.k = end + 1
            return name
        at = self.k
        v = self.read(self.param_ref()) if self.peek() == "#" else self.value()
        if v != int(v) or not self.lo <= v <= self.hi:
            raise _Error(f"parameter number {v:g} is not a whole number from {self.lo} to {self.hi}", at + 1)
        return int(v)

    def expr(self, level: int = 0) -> float:
        levels = _FANUC_LEVELS if self.fanuc else _LEVELS
        if level == len(levels):
            return self.value()
        left = self.expr(level + 1)
        while True:
            op = next((o for o in _OPS if self.s.startswith(o, self.k)), None)
            if op is None or op not in levels[level]:
                return left
            at = self.k
            self.k += len(op)
            right = self.expr(level + 1)
            left = _fanuc_binary(op, left, right, at) if self.fanuc else _binary(op, left, right, at)


def _fanuc_binary(op: str, a: float, b: float, at: int) -> float:
    """Fanuc's operators: EQ and NE exact (its manual: compare ABS[a - b] with a tolerance), AND
    OR XOR bit by bit on whole numbers."""
    if op in ("eq", "ne"):
        return float((a == b) == (op == "eq"))
    if op == "mod" and (a < 0 or b < 0):
        raise _Error(f"{a:g} MOD {b:g}: the sign of a remainder of negative numbers is not followed", at + 1)
    if op in ("and", "or", "xor"):
        if a != int(a) or b != int(b):
            raise _Error(f"{op.upper()} of {a:g} and {b:g}: the control works bit by bit on whole numbers", at + 1)
        x, y = int(a), int(b)
        return float({"and": x & y, "or": x | y, "xor": x ^ y}[op])
    return _binary(op, a, b, at)


def _binary(op: str, a: float, b: float, at: int) -> float:
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if op == "/":
        if b == 0:
            raise _Error("division by zero", at + 1)
        return a / b
    if op == "mod":
        if b == 0:
            raise _Error("MOD by zero", at + 1)
        r = math.fmod(a, b)
        return r + abs(b) if r < 0 else r
    if op == "**":
        try:
            return float(a**b)
        except (ZeroDivisionError, OverflowError):
            raise _Error(f"{a:g} ** {b:g} has no value", at + 1) from None
    if op in ("eq", "ne"):
        same = abs(a - b) < TOLERANCE_EQUAL
        return float(same if op == "eq" else not same)
    if op in ("gt", "ge", "lt", "le"):
        return float({"gt": a > b, "ge": a >= b, "lt": a < b, "le": a <= b}[op])
    x, y = a != 0.0, b != 0.0
    return float({"and": x and y, "or": x or y, "xor": x != y}[op])


def _fmt(v: float, letter: str) -> str:
    return rewrite.number(v, 4 if letter in "gm" else 6)


# ----------------------------------------------------------------------------------- the program
@dataclass
class _Line:
    text: str  # without comments, lower case
    comments: list[str]
    label: str | None = None  # an O-word's label
    keyword: str | None = None
    rest: str = ""  # after the keyword
    number: int | None = None  # its N number (Fanuc's GOTO goes to it)
    deleted: bool = False  # a block-delete line (/): run as executed, written with its /


_FANUC_FLOW = re.compile(r"(?:n(\d+))?(?:(if)(\[.*)|(while)(\[.*)|(goto)(.*)|do(\d+)|end(\d+))?$")


def _read(text: str, src: str, fanuc: bool = False) -> list[_Line]:
    out = []
    for n, raw in enumerate(split_lines(text), 1):
        try:
            body, comments = _strip(raw)
        except _Error as e:
            raise InputError(e.message, src, n, e.col) from None
        deleted = body.startswith("/")
        if deleted:
            body = body[1:]
        line = _Line(body, comments, deleted=deleted)
        if fanuc:
            num = re.match(r"n(\d+)", body)
            if num:
                line.number = int(num.group(1))
            m = _FANUC_FLOW.match(body)
            if m and any(m.group(k) for k in (2, 4, 6, 8, 9)):
                if m.group(2) or m.group(4) or m.group(6):
                    line.keyword = "f" + (m.group(2) or m.group(4) or m.group(6))
                    line.rest = m.group(3) or m.group(5) or m.group(7) or ""
                else:
                    line.keyword, line.label = ("fdo", m.group(8)) if m.group(8) else ("fend", m.group(9))
                out.append(line)
                continue
        prog = re.fullmatch(r"(?:n\d+)?o(\d+)", body)
        if prog:  # a program number (Fanuc's O1234; M98 P1234 calls it)
            line.label, line.keyword = str(int(prog.group(1))), "program"
            out.append(line)
            continue
        m = re.match(r"(?:n\d+)?o(<[^>]*>|\d+)([a-z]+)(.*)$", body)
        if m and body.lstrip("n0123456789").startswith("o"):
            line.label, kw, line.rest = m.group(1), m.group(2), m.group(3)
            key = next((k for k in sorted(_KEYWORDS, key=len, reverse=True) if kw.startswith(k)), None)
            if key is None:
                raise InputError(f"unknown O-word keyword '{kw}'", src, n)
            line.keyword, line.rest = key, kw[len(key) :] + line.rest
        out.append(line)
    return out


def _match(lines: list[_Line], src: str) -> tuple[dict, dict, dict]:
    """The O-word structure: for each flow line, the lines it jumps to; the subroutines by label;
    the programs (O1234, which M98 P1234 calls) by number."""
    jumps: dict[int, dict] = {}
    subs: dict[str, int] = {}
    programs: dict[int, int] = {}
    stack: list[tuple[str, str, int, list[int]]] = []  # (label, kind, line, branch lines)
    loops: list[tuple[str, int]] = []  # Fanuc's open DO m: (m, line)
    for i, ln in enumerate(lines):
        kw, lab = ln.keyword, ln.label
        if kw is None:
            continue

        def fail(msg, i=i):
            raise InputError(msg, src, i + 1)

        if kw in ("fwhile", "fdo"):
            if kw == "fwhile":
                m = re.search(r"do(\d+)$", ln.rest)
                if not m:
                    fail("WHILE […] without DO m")
                lab = m.group(1)
            if not 1 <= int(lab) <= 3:
                fail(f"DO {lab}: the loop numbers are 1, 2 and 3")
            loops.append((lab, i))
            continue
        if kw == "fend":
            if not loops or loops[-1][0] != lab:
                fail(f"END {lab} without its DO {lab}" + (f" (DO {loops[-1][0]} is open)" if loops else ""))
            _, start = loops.pop()
            jumps[start] = {"start": start, "end": i}
            jumps[i] = {"start": start, "end": i}
            continue
        if kw in ("fif", "fgoto"):
            continue

        if kw == "program":
            if int(lab) in programs:
                fail(f"program O{lab} given twice (first at line {programs[int(lab)] + 1})")
            programs[int(lab)] = i
            continue
        if kw == "sub":
            if stack:
                fail(f"o{lab} sub inside o{stack[-1][0]} {stack[-1][1]}")
            if lab in subs:
                fail(f"subroutine o{lab} defined twice (first at line {subs[lab] + 1})")
            stack.append((lab, "sub", i, []))
        elif kw in ("if", "repeat", "do") or (
            kw == "while" and not (stack and stack[-1][0] == lab and stack[-1][1] == "do")
        ):
            stack.append((lab, kw, i, []))
        elif kw in ("elseif", "else"):
            if not stack or stack[-1][:2] != (lab, "if"):
                fail(f"o{lab} {kw} without its o{lab} if")
            stack[-1][3].append(i)
        elif kw in ("break", "continue"):
            loop = next((s for s in reversed(stack) if s[0] == lab and s[1] in ("while", "do", "repeat")), None)
            if loop is None:
                fail(f"o{lab} {kw} outside an o{lab} loop")
            loop[3].append(i)
        elif kw == "return":
            if not any(s[1] == "sub" for s in stack):
                fail(f"o{lab} return outside a subroutine")
            jumps[i] = {}
        elif kw == "call":
            jumps[i] = {}
        else:
            closes = {"endsub": "sub", "endif": "if", "endwhile": "while", "endrepeat": "repeat", "while": "do"}[kw]
            if not stack or stack[-1][:2] != (lab, closes):
                fail(f"o{lab} {kw} without its o{lab} {closes}")
            _, kind, start, branches = stack.pop()
            if kind == "sub":
                subs[lab] = start
                jumps[start] = {"end": i}
                jumps[i] = {}
            elif kind == "if":
                chain = [start] + [b for b in branches if lines[b].keyword in ("elseif", "else")] + [i]
                for a, b in zip(chain, chain[1:]):
                    jumps[a] = {"next": b, "end": i}
                jumps[i] = {}
            else:
                for b in [start, *branches, i]:
                    jumps[b] = {"start": start, "end": i}
    if stack:
        lab, kind, start, _ = stack[-1]
        raise InputError(f"o{lab} {kind} without its end", src, start + 1)
    if loops:
        raise InputError(f"DO {loops[-1][0]} without its END {loops[-1][0]}", src, loops[-1][1] + 1)
    return jumps, subs, programs


class _Machine:
    """Runs the flattened program and holds its parameters."""

    def __init__(self):
        self.numbered = np.zeros(5603)
        self.set_numbered = np.zeros(5603, bool)
        self.globals: dict[str, float] = {}
        self.frames: list[dict[str, float]] = [{}]

    def read(self, ref, exists: bool = False):
        if isinstance(ref, int):
            if exists:
                return True
            if ref >= MACHINE_PARAMETERS and not self.set_numbered[ref]:
                raise _Error(
                    f"parameter #{ref} holds the machine's state (offsets, probe results, tool data), which the "
                    "program does not give"
                )
            return float(self.numbered[ref])
        scope = self.globals if ref.startswith("_") else self.frames[-1]
        if ref in scope:
            return True if exists else scope[ref]
        if exists and ref.startswith("_"):
            # (LinuxCNC's predefined parameters exist, #<_lathe_diameter_mode> on a mill too, and a
            # global one may come from an earlier program or the parameter file)
            raise _Error(
                f"EXISTS[#<{ref}>]: a global parameter the program has not set exists or not as the machine "
                "has it (LinuxCNC predefines many)"
            )
        if exists:
            return False
        if ref.startswith("_"):
            raise _Error(
                f"#<{ref}> is not set by the program: LinuxCNC's predefined parameters hold the machine's state"
            )
        raise _Error(f"named parameter #<{ref}> is not defined")

    def write(self, ref, v: float) -> None:
        if isinstance(ref, int):
            if 5161 <= ref <= 5390 or 5400 <= ref <= 5428:
                raise _Error(
                    f"setting #{ref} changes the machine's state (stored positions, offsets, tool data, the "
                    "position): write the G10, G92 or G43 that does it"
                )
            self.numbered[ref], self.set_numbered[ref] = v, True
        elif ref.startswith("_"):
            self.globals[ref] = v
        else:
            self.frames[-1][ref] = v


#: G65's arguments (argument specification I): the letter's local variable.
FANUC_ARGUMENTS = {"a": 1, "b": 2, "c": 3, "i": 4, "j": 5, "k": 6, "d": 7, "e": 8, "f": 9, "h": 11, "m": 13}
FANUC_ARGUMENTS |= {"q": 17, "r": 18, "s": 19, "t": 20, "u": 21, "v": 22, "w": 23, "x": 24, "y": 25, "z": 26}


class _FanucMachine:
    """Fanuc Macro B's variables: #1-#33 local (a set per G65 call level), #100-#199 and
    #500-#999 common. #0 is vacant, #1000 and up are the system's. A variable read before the
    program sets it is refused: it is vacant (the control leaves a word written with it out, and
    reads it as 0 in a sum), or, from #500, kept on the machine between programs."""

    def __init__(self):
        self.levels: list[dict[int, float]] = [{}]
        self.common: dict[int, float] = {}

    def _store(self, ref, writing: bool) -> dict[int, float]:
        if not isinstance(ref, int):
            raise _Error("named parameters #<…> are LinuxCNC's, not Fanuc's")
        if 1 <= ref <= 33:
            return self.levels[-1]
        if 100 <= ref <= 199 or 500 <= ref <= 999:
            return self.common
        if ref == 0:
            raise _Error(
                "#0 is vacant: it is always empty" if writing else "#0 (vacant): a word written with it is left out"
            )
        raise _Error(f"#{ref} is a system variable (or none): {'setting' if writing else 'its value is'} the machine's")

    def read(self, ref, exists: bool = False):
        if exists:
            raise _Error("EXISTS is LinuxCNC's, not Fanuc's")
        store = self._store(ref, False)
        if ref not in store:
            if ref >= 500:
                raise _Error(f"#{ref} keeps its value on the machine between programs; the program does not set it")
            raise _Error(
                f"#{ref} is read before the program sets it: it is vacant (a word written with it is left out)"
            )
        return store[ref]

    def write(self, ref, v: float) -> None:
        self._store(ref, True)[ref] = v


def flatten(data: bytes, name: str = "<program>", dialect: str = "linuxcnc") -> Flat:
    """The straight G-code that an RS274NGC program runs (see the module's text); in the ``fanuc``
    dialect its M98/M99 subprograms and Custom Macro B (variables, G65, IF/GOTO, WHILE/DO/END).
    Words written as numbers are written as they are; computed values with six decimals (and a
    decimal point in the Fanuc dialect, where a number without one counts least input
    increments).

    Examples
    --------
    >>> prog = b"#1 = 2\\no100 repeat [2]\\nG1 X[#1 * 3] F100 (cut)\\n#1 = [#1 + 1]\\no100 endrepeat\\nM2\\n"
    >>> print(flatten(prog).data.decode())
    G1 X6 F100 (cut)
    G1 X9 F100 (cut)
    M2
    <BLANKLINE>
    """
    if dialect not in ("linuxcnc", "fanuc"):
        raise ValueError(f"flatten reads LinuxCNC's and Fanuc's programs, not {dialect}")
    lines = _read(rewrite.program_text(data), name, dialect == "fanuc")
    run = _Run(lines, *_match(lines, name), fanuc=dialect == "fanuc")
    i, blocks = 0, 0
    while i < len(lines):
        blocks += 1
        if blocks > MAX_BLOCKS:
            raise InputError(
                f"the program runs more than {MAX_BLOCKS:,} blocks: a loop that does not end?", name, i + 1
            )
        try:
            nxt = run.step(i)
        except _Error as e:
            raise InputError(e.message, name, i + 1, e.col) from None
        if nxt is None:
            break
        i = nxt
    if dialect == "fanuc":
        last = next((k for k in range(len(lines) - 1, -1, -1) if lines[k].text or lines[k].comments), None)
        if last is not None and lines[last].text == "%" and run.out[-1:] != ["%"]:
            run.out.append("%")  # the program's end of tape
            run.origin.append(last)
    body = "".join(t + "\n" for t in run.out)
    origin = np.asarray(run.origin, dtype=np.int64)
    fixed = np.zeros(len(lines), dtype=bool)
    fixed[sorted(run.fixed)] = True
    return Flat(
        body.encode("utf-8", "surrogateescape"),
        origin + 1,
        blocks,
        np.bincount(origin, minlength=len(lines)),
        fixed,
    )


class _Run:
    """A program being run: its lines and O-word structure, its parameters (``mac``), the call
    stack, the repeat counters, and the blocks written (``out``, each with the index of the line
    it comes from in ``origin``)."""

    def __init__(self, lines: list[_Line], jumps: dict, subs: dict, programs: dict, *, fanuc: bool):
        self.lines, self.jumps, self.subs, self.programs, self.fanuc = lines, jumps, subs, programs, fanuc
        self.mac: _Machine | _FanucMachine = _FanucMachine() if fanuc else _Machine()
        # the program (its O line's index) each line belongs to, for Fanuc's GOTO
        self.region = np.maximum.accumulate([i if ln.keyword == "program" else 0 for i, ln in enumerate(lines)] or [0])
        # ("o", line to return to, saved #1-#30, loop counters) for an O-word call,
        # ("m98", line to return to, the subprogram's first line, passes left) for M98
        self.calls: list[tuple] = []
        self.counters: dict[int, int] = {}
        self.out: list[str] = []
        self.origin: list[int] = []
        self.fixed: set[int] = set()

    def cond(self, ln: _Line) -> float:
        """The [condition] (or count) after an O-word keyword."""
        p = _Parser(ln.rest, self.mac.read)
        if not p.peek():
            raise _Error(f"o{ln.label} {ln.keyword} needs [a condition]")
        v = p.value()
        if p.peek():
            raise _Error(f"unexpected '{p.s[p.k :]}' after o{ln.label} {ln.keyword}", p.k + 1)
        return v

    def step(self, i: int) -> int | None:
        """Run line i; the next line's index, or None at the program's end."""
        ln, lines, mac, calls, counters = self.lines[i], self.lines, self.mac, self.calls, self.counters
        kw = ln.keyword
        if self.fanuc and kw not in (None, "program"):
            if kw.startswith("f"):
                return self.macro_flow(ln, i)
            raise _Error(f"O-word {kw}: LinuxCNC's flow, not Fanuc's")
        if self.fanuc and re.search(r"g0*6[67](?![\d.])", ln.text):
            raise _Error("G66/G67 modal macro calls are not flattened")
        if kw is None:
            return self.block(ln, i)
        if kw == "program":
            if self.fanuc and not calls and not any(t.startswith("O") for t in self.out):
                # the main program's number (a Fanuc control files the program under it)
                self.out.append(" ".join([f"O{ln.label}", *ln.comments]))
                self.origin.append(i)
            return i + 1  # a program number: where M98 enters, no block
        j = self.jumps.get(i, {})
        if kw == "sub":
            return j["end"] + 1  # a definition: skipped where it stands
        if kw in ("endsub", "return"):
            p = _Parser(ln.rest, mac.read)
            if p.peek():
                mac.globals["_value"] = p.value()
                mac.globals["_value_returned"] = 1.0
            if not calls or calls[-1][0] != "o":
                raise _Error(f"o{ln.label} {kw} outside a call")
            _, back, saved, saved_counters = calls.pop()
            mac.numbered[1:31] = saved
            mac.frames.pop()
            counters.clear()
            counters.update(saved_counters)
            return back
        if kw == "call":
            if ln.label not in self.subs:
                raise _Error(f"subroutine o{ln.label} is not in this file (a subroutine file of the machine's)")
            if len(calls) >= MAX_DEPTH:
                raise _Error(f"subroutines nested deeper than {MAX_DEPTH}")
            p = _Parser(ln.rest, mac.read)
            args = []
            while p.peek():
                if p.peek() != "[":
                    raise _Error("call arguments are [expressions]", p.k + 1)
                args.append(p.value())
            if len(args) > 30:
                raise _Error("more than 30 call arguments")
            calls.append(("o", i + 1, mac.numbered[1:31].copy(), dict(counters)))
            mac.numbered[1:31] = 0.0
            mac.numbered[1 : 1 + len(args)] = args
            mac.frames.append({})
            mac.globals["_value_returned"] = 0.0
            counters.clear()
            return self.subs[ln.label] + 1
        if kw == "if":
            # the first branch whose condition holds (an else's when none does), else past the endif
            k = i
            while lines[k].keyword in ("if", "elseif"):
                if self.cond(lines[k]) != 0.0:
                    return k + 1
                k = self.jumps[k]["next"]
            return k + 1
        if kw in ("elseif", "else"):
            return j["end"] + 1  # reached at the end of the branch taken
        if kw in ("endif", "do"):
            return i + 1
        if kw == "while" and lines[j["start"]].keyword == "do" and j["end"] == i:
            return j["start"] + 1 if self.cond(ln) != 0.0 else i + 1
        if kw == "while":
            return i + 1 if self.cond(ln) != 0.0 else j["end"] + 1
        if kw == "endwhile":
            return j["start"]
        if kw == "repeat":
            counters[i] = int(self.cond(ln))
            return i + 1 if counters[i] > 0 else j["end"] + 1
        if kw == "endrepeat":
            s = j["start"]
            counters[s] = counters.get(s, 0) - 1
            return s + 1 if counters[s] > 0 else i + 1
        if kw == "break":
            return j["end"] + 1
        if kw == "continue":
            start, end = j["start"], j["end"]
            return end if lines[start].keyword in ("repeat", "do") else start
        raise _Error(f"o{ln.label} {kw}: not followed")

    def macro_flow(self, ln: _Line, i: int) -> int:
        """Fanuc Macro B's IF [..] GOTO n, IF [..] THEN #v = .., GOTO n, WHILE [..] DO m, DO m, END m."""
        kw, mac = ln.keyword, self.mac
        if kw in ("fdo", "fend"):
            start = self.jumps[i]["start"]
            if kw == "fdo" or self.lines[start].keyword == "fdo":
                return i + 1 if kw == "fdo" else start + 1
            return start  # END m: the WHILE again
        p = _Parser(ln.rest, mac.read, True)
        if kw == "fgoto":
            return self.goto(p, i)
        if not p.peek() == "[":
            raise _Error(f"{kw[1:].upper()} needs [a condition]", p.k + 1)
        cond = p.value() != 0.0
        if kw == "fwhile":
            return i + 1 if cond else self.jumps[i]["end"] + 1
        if p.take("goto"):
            return self.goto(p, i) if cond else i + 1
        if p.take("then"):
            ref = p.param_ref()
            p.need("=")
            v = p.expr(1)
            if p.peek():
                raise _Error(f"unexpected '{p.s[p.k :]}' after THEN", p.k + 1)
            if cond:
                mac.write(ref, v)
            self.fixed.add(i)
            return i + 1
        raise _Error("IF […] without GOTO or THEN", p.k + 1)

    def goto(self, p: _Parser, i: int) -> int:
        """GOTO n: the block N n of the program the line is in, searched forward, then from the
        program's start."""
        at = p.k
        n = p.value()
        if p.peek():
            raise _Error(f"unexpected '{p.s[p.k :]}' after GOTO", p.k + 1)
        if n != int(n) or n < 0:
            raise _Error(f"GOTO {n:g}: a block number is a whole number", at + 1)
        region = self.region[i]
        found = [j for j, ln in enumerate(self.lines) if ln.number == int(n) and self.region[j] == region]
        if not found:
            raise _Error(f"GOTO {int(n)}: no block N{int(n)} in this program", at + 1)
        later = [j for j in found if j > i]
        dest = (later or found)[0]
        for start, jump in self.jumps.items():
            if self.lines[start].keyword in ("fwhile", "fdo") and start < dest <= jump["end"]:
                if not start <= i <= jump["end"]:
                    raise _Error(f"GOTO {int(n)} into a DO loop (the control refuses a branch into a loop)", at + 1)
        return dest

    def macro(self, words, i: int) -> int:
        """G65 P<program> [L<times>] <arguments>: program O<program> of the file, with a new set of
        local variables holding the arguments (argument specification I: A #1, B #2, C #3, I #4,
        J #5, K #6, D #7 …, Z #26), until its M99."""
        mac = self.mac
        assert isinstance(mac, _FanucMachine)
        got = dict(words)
        letters = [c for c, _ in words]
        if [c for c in letters if c == "g"] != ["g"]:
            raise _Error("G65 with another G code")
        if any(letters.count(c) > 1 for c in "ijk"):
            raise _Error("G65 with I, J, K given more than once (argument specification II): not flattened")
        pv, lv = got.get("p"), got.get("l", 1.0)
        if pv is None or pv != int(pv) or int(pv) not in self.programs:
            raise _Error(f"G65 P{pv if pv is None else f'{pv:g}'}: no such program O… in this file")
        if lv != int(lv) or lv < 1:
            raise _Error(f"G65 L{lv:g}: the times are a whole number >= 1")
        other = [c for c in letters if c not in FANUC_ARGUMENTS and c not in "gpl"]
        if other:
            raise _Error(f"G65 with {other[0].upper()}: not an argument")
        if len(self.calls) >= MAX_DEPTH:
            raise _Error(f"macros nested deeper than {MAX_DEPTH}")
        args = {FANUC_ARGUMENTS[c]: v for c, v in words if c in FANUC_ARGUMENTS}
        start = self.programs[int(pv)] + 1
        self.calls.append(("g65", i + 1, start, int(lv), args))
        mac.levels.append(dict(args))
        self.fixed.add(i)
        return start

    def block(self, ln: _Line, i: int) -> int | None:
        """A block of words and parameter settings: written with its values, the settings applied
        after the line is read (as LinuxCNC does); M98/M99 call and end subprograms."""
        mac = self.mac
        if ln.text == "%":
            self.out.append("%")
            self.origin.append(i)
            return i + 1
        p = _Parser(ln.text, mac.read, self.fanuc)
        words: list[tuple[str, float]] = []
        texts: list[str] = []
        pointless: list[str] = []  # words written as a number without a decimal point
        sets = []
        while p.peek():
            c = p.peek()
            if c == "#":
                ref = p.param_ref()
                p.need("=")
                # LinuxCNC takes one value ([…] for an expression); Fanuc an expression as it stands
                sets.append((ref, p.expr(1) if self.fanuc else p.value()))  # Fanuc: no comparison here
            elif c.isalpha() or c in "@^":
                p.k += 1
                at = p.k
                p.address = True
                v = p.value()
                p.address = False
                if c != "n":
                    words.append((c, v))
                    written = p.s[at : p.k]
                    if _LITERAL.fullmatch(written) and "." not in written and float(written) != 0.0:
                        pointless.append(c.upper() + written)
                    if not _LITERAL.fullmatch(written):
                        written = _fmt(v, c)
                        if self.fanuc and c not in "gmnopst" and "." not in written:
                            written += "."
                    texts.append(c.upper() + written)
            else:
                raise _Error(f"unexpected '{c}'", p.k + 1)
        if self.fanuc and sets and words:
            raise _Error("a macro statement (#… = …) and NC words in one block: not flattened")
        for ref, v in sets:
            mac.write(ref, v)
        if sets:
            self.fixed.add(i)
        if self.fanuc and any(c == "g" and round(v * 10) == 650 for c, v in words):
            args = [w for w in pointless if w[0] not in "GPL"]
            if args:
                raise _Error(
                    f"G65 argument {args[0]} without a decimal point: the control reads it in least input increments "
                    f"(0.001 mm on IS-B) unless its parameter says units; write the point ({args[0]}.)"
                )
            return self.macro(words, i)
        ms = [round(v) for c, v in words if c == "m"]
        gs = [round(v * 10) for c, v in words if c == "g"]
        if any(g in (700, 710, 711, 712, 720, 721, 722) for g in gs):
            raise _Error("lathe cycles G70-G72 take their contour from the program's subroutines: not flattened")
        if isinstance(mac, _Machine) and (any(g in _MACHINE_CODES for g in gs) or any(m in (6, 61) for m in ms)):
            # probing, offsets, stored positions, tool data: the machine sets its parameters again
            # (LinuxCNC's; the machine's codes change no Fanuc macro variable)
            mac.set_numbered[MACHINE_PARAMETERS:] = False
        if any(m in (98, 99) for m in ms):
            self.fixed.add(i)
            return self.subprogram(words, i)
        if words or ln.comments:
            block = " ".join(t for t in (" ".join(texts), *ln.comments) if t)
            self.out.append(("/" if ln.deleted and words else "") + block)
            self.origin.append(i)
        if len(self.out) > MAX_BLOCKS:
            raise _Error(f"the flattened program has more than {MAX_BLOCKS:,} blocks")
        return None if any(m in (2, 30) for m in ms) else i + 1

    def subprogram(self, words, i: int) -> int:
        """M98 P<program> [L<passes>] calls program O<program> of the file; M99 ends a pass of it."""
        calls = self.calls
        got = dict(words)
        other = sorted(set(got) - {"m", "p", "l"})
        if other:
            raise _Error(f"M98/M99 with a {other[0].upper()} word: not flattened")
        if round(got["m"]) == 99:
            if "p" in got or "l" in got:
                raise _Error("M99 with P or L (a jump within the program): not flattened")
            if not calls or calls[-1][0] not in ("m98", "g65"):
                raise _Error("M99 outside a subprogram call (a main program's M99 repeats it without end)")
            kind, back, start, left, *args = calls.pop()
            if kind == "g65":
                self.mac.levels.pop()  # type: ignore[union-attr]
                if left > 1:
                    calls.append(("g65", back, start, left - 1, *args))
                    self.mac.levels.append(dict(args[0]))  # type: ignore[union-attr]
                    return start
                return back
            if left > 1:
                calls.append(("m98", back, start, left - 1))
                return start
            return back
        pv, lv = got.get("p"), got.get("l", 1.0)
        if pv is None or pv != int(pv) or not 0 <= pv <= 9999:
            raise _Error(
                "M98 needs P, the number of a program in this file (0-9999; a longer P that counts passes in its "
                "first digits, as some Fanuc controls read it, is not flattened: give the passes as L)"
            )
        if lv != int(lv) or lv < 0:
            raise _Error(f"M98 L{lv:g}: the passes are a whole number >= 0")
        if int(pv) not in self.programs:
            raise _Error(f"M98 P{int(pv)}: program O{int(pv)} is not in this file (a program in the control's memory)")
        if len(calls) >= MAX_DEPTH:
            raise _Error(f"subprograms nested deeper than {MAX_DEPTH}")
        if lv == 0:
            return i + 1
        start = self.programs[int(pv)] + 1
        calls.append(("m98", i + 1, start, int(lv)))
        return start
