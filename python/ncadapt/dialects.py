"""NC dialects: which controller family a program is written for, detected from its text.

The engine reads RS274NGC as LinuxCNC reads it. grbl's G-code is a subset of it; Fanuc/Haas
programs share most of it, and what they write differently, or what the engine does not know, is
refused at its line by the engine (an M code it does not know, a macro call). Marlin programs are
read with their extruder E carried as an axis (:mod:`ncadapt.marlin`), and Sinumerik 840D programs
are run into straight RS274NGC first (:mod:`ncadapt.sinumerik`). Heidenhain conversational
programs are refused here, at the line that shows the dialect, with the dialect named, instead of
failing on the first word the RS274NGC reader cannot parse.

Detection reads the program's first :data:`HEAD_BYTES` only (a program of any length is detected
at once) and looks, in this order, for: a Heidenhain ``BEGIN PGM`` line; Sinumerik syntax (a
``.mpf``/``.spf`` file, ``X=…`` assignments, ``DEF``/``EXTERN``/``PROC``, ``MSG(…)``,
``CYCLE81(…)``, frames ``TRANS``/``ROT``…, ``CIP``/``CT``/``CR=``, ``DIAMON``, ``LIMS=``); a 3D
printer's Marlin G-code (``;FLAVOR:Marlin``, ``M82``/``M83``, heater and fan codes, E words on
moves, a dwell in seconds ``G4 S…``, FABtotum's ``M728``/``M793``); grbl system commands (``$H``, ``$J=…``); a Fanuc program number (``O1234`` not followed by
a LinuxCNC O-word keyword), ``M98 P``, ``G65 P``, ``M99``. Anything else is LinuxCNC RS274NGC.

The machine, a mill or a lathe, is detected in the same head for the LinuxCNC and Fanuc dialects
(``--machine`` states it): a LinuxCNC program is a lathe's when it states G7 or G8 (diameter or
radius mode, a lathe's codes); a Fanuc/Haas program when it has a T word of three or four digits
(``T0101``, ``T101``: tool and offset), ``G28`` with U or W, constant surface speed ``G96``,
``G50`` with a spindle limit or a coordinate (``G50 S2500``), or a roughing or finishing cycle
``G70``/``G71``/``G72`` with its ``P`` word.
On a lathe the engine reads no Y (the tool is in the plane through the spindle's axis); a Fanuc
lathe's X is a diameter, U and W its increments, and G90/G92/G94 its turning cycles.
"""

from __future__ import annotations

import re
import string
from dataclasses import dataclass, replace
from pathlib import Path

from .errors import InputError

#: The dialects ``--dialect`` takes (``auto`` detects one of them, or ``heidenhain``).
CHOICES = ("auto", "linuxcnc", "fanuc", "sinumerik", "grbl", "marlin")

#: Dialects whose programs are read (as RS274NGC, Sinumerik's run into it first; what differs is
#: refused at its line).
READ = ("linuxcnc", "fanuc", "sinumerik", "grbl", "marlin")

#: How much of a program detection reads.
HEAD_BYTES = 64 * 1024

#: The machines ``--machine`` takes (``auto`` detects one of them).
MACHINES = ("auto", "mill", "lathe")

#: The dialects a program can be a lathe's in.
LATHE_DIALECTS = ("linuxcnc", "fanuc")

#: What shows a lathe's program, per dialect (read in the upper-cased text without comments).
_LATHE = {
    "linuxcnc": re.compile(r"\bG0*[78](?![.\d])"),
    "fanuc": re.compile(
        r"\bT\d{3,4}\b|\bG0*28(?![.\d])[^\n]*?(?<![A-Z])[UW][-+.\d]|\bG0*96(?![.\d])|\bG0*50(?![.\d])[^\n]*?(?<![A-Z])[SXZUW][-+.\d]|\bG0*7[012](?![.\d])[^\n]*?(?<![A-Z])P\d"
    ),
}

NAMES = {
    "linuxcnc": "LinuxCNC RS274NGC",
    "fanuc": "Fanuc/Haas",
    "sinumerik": "Sinumerik 840D",
    "grbl": "grbl",
    "marlin": "Marlin (3D printer G-code)",
    "heidenhain": "Heidenhain conversational (Klartext)",
}

_UPPER = str.maketrans(string.ascii_lowercase, string.ascii_uppercase)
_O_KEYWORDS = r"(?:SUB|ENDSUB|CALL|RETURN|IF|ELSEIF|ELSE|ENDIF|WHILE|ENDWHILE|DO|REPEAT|ENDREPEAT|BREAK|CONTINUE)"
_MARLIN_M = ("M82", "M83", "M104", "M105", "M106", "M107", "M109", "M140", "M190", "M204", "M205")
_SINUMERIK_WORDS = ("TRANS", "ROT", "SCALE", "MIRROR", "CIP", "DIAMO", "SUPA", "G64", "G70", "G71")


class _Assignment:
    """Sinumerik's axis assignments (``X=10``, ``Y = IC(5)``, ``Z1=AC(2)``): a pattern whose
    ``search`` finds each ``=`` first (a literal, fast) and then looks at the word before it."""

    _AFTER = re.compile(r"=[ \t]*(?:IC|AC|DC|ACP|ACN)?[ \t]*[-+.(\d]")
    _BEFORE = re.compile(r"(?<![#<\w])[XYZABCUVW]\d?[ \t]*\Z")

    def search(self, t: str) -> re.Match[str] | None:
        for m in self._AFTER.finditer(t):
            b = self._BEFORE.search(t, max(0, m.start() - 8), m.start())
            if b:
                return b
        return None


# The rules, in order: (dialect, read the text with its comments (else without), literals one of
# which the text must hold for the pattern to be tried (a fast test), pattern). Patterns read the
# upper-cased text, one line per ``^``.
_RULES: tuple[tuple[str, bool, tuple[str, ...], re.Pattern[str] | _Assignment], ...] = (
    ("heidenhain", False, ("BEGIN",), re.compile(r"^[ \t]*(?:\d+[ \t]+)?BEGIN[ \t]+PGM\b", re.M)),
    ("sinumerik", False, ("=",), _Assignment()),
    (
        "sinumerik",
        False,
        ("EXTERN", "PROC", "DEF"),
        re.compile(r"^[ \t]*(?:N\d+[ \t]+)?(?:EXTERN|PROC|DEF[ \t]+(?:REAL|INT|BOOL|CHAR|STRING|AXIS|FRAME))\b", re.M),
    ),
    ("sinumerik", False, ("(",), re.compile(r"\b(?:MSG|CYCLE\d+|POCKET\d+|SLOT\d+|HOLES\d+)[ \t]*\(")),
    (
        "sinumerik",
        False,
        _SINUMERIK_WORDS,
        re.compile(r"\b(?:A?TRANS|A?ROT|A?SCALE|A?MIRROR|CIP|DIAMON|DIAMOF|SUPA|G64\d|G70\d|G71\d)\b"),
    ),
    ("sinumerik", False, ("=",), re.compile(r"\b(?:CR|LIMS|AR|TURN)[ \t]*=")),
    ("marlin", True, ("FLAVOR",), re.compile(r"^;[ \t]*FLAVOR:", re.M)),
    # (M100-M199 are LinuxCNC's user M codes, which take P and Q: a Marlin heater or fan code takes S)
    (
        "marlin",
        False,
        _MARLIN_M,
        re.compile(
            r"^[ \t]*(?:N\d+[ \t]+)?M(?:82|83|104|105|106|107|109|140|190|204|205)\b(?![^\n]*\b[PQ][-+.\d])", re.M
        ),
    ),
    # (LinuxCNC's analog outputs M67/M68 and inputs M66 take E, on a move too)
    ("marlin", False, ("E",), re.compile(r"^[ \t]*G0*1\b(?![^\n]*\bM6[678]\b)[^\n]*\bE[-+.\d]", re.M)),
    # a dwell in seconds (RS274NGC's and grbl's G4 take P), FABtotum's (FABlin) head and light codes
    ("marlin", False, ("G4", "G04", "M728", "M793"), re.compile(r"^[ \t]*(?:G0*4[ \t]+S[-+.\d]|M728\b|M793\b)", re.M)),
    ("grbl", False, ("$",), re.compile(r"^[ \t]*\$(?:[HXCIGN#$]|J=|\d+=)", re.M)),
    ("fanuc", False, ("O",), re.compile(rf"^[ \t]*%?[ \t]*O\d{{1,5}}\b(?![ \t]*{_O_KEYWORDS}\b)", re.M)),
    ("fanuc", False, ("M98", "G65", "M99"), re.compile(r"\bM98[ \t]*P|\bG65[ \t]*P|\bM99\b")),
)


@dataclass(frozen=True)
class Dialect:
    """A program's dialect: ``name`` (a key of :data:`NAMES`), whether it was ``detected`` (or
    given), and the ``line`` (1-based) and ``text`` that show it (None when nothing did)."""

    name: str
    detected: bool
    line: int | None = None
    text: str | None = None
    #: The machine is a lathe (LinuxCNC and Fanuc/Haas programs only), whether that was
    #: detected (or given), and the line and text that show it.
    lathe: bool = False
    machine_detected: bool = True
    machine_line: int | None = None
    machine_text: str | None = None

    @property
    def read(self) -> bool:
        """Whether the engine reads programs of this dialect."""
        return self.name in READ

    @property
    def engine(self) -> str:
        """The dialect as the engine takes it (:data:`ncadapt.nc.DIALECTS`): a lathe's is
        ``linuxcnc-lathe`` or ``fanuc-lathe``."""
        return f"{self.name}-lathe" if self.lathe else self.name

    def describe(self) -> str:
        """One line for a summary."""
        how = "detected" if self.detected else "given"
        shown = f", line {self.line}: {self.text}" if self.line is not None else ""
        return f"{NAMES[self.name]} ({how}{shown})"

    def describe_machine(self) -> str:
        """One line for a summary: the machine, and how its program is read."""
        how = "detected" if self.machine_detected else "given"
        shown = f", line {self.machine_line}: {self.machine_text}" if self.machine_line is not None else ""
        if not self.lathe:
            return f"mill ({how}{shown})"
        reading = (
            "X a diameter, U and W its increments, no Y"
            if self.name == "fanuc"
            else "X a diameter after G7, a radius after G8; no Y"
        )
        return f"lathe ({how}{shown}): {reading}"

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "detected": self.detected,
            "line": self.line,
            "evidence": self.text,
            "machine": {
                "name": "lathe" if self.lathe else "mill",
                "detected": self.machine_detected,
                "line": self.machine_line,
                "evidence": self.machine_text,
            },
        }


#: A ``(…)`` comment, unless a name comes right before it (Sinumerik's ``MSG(…)``, ``IC(…)``,
#: ``CYCLE81(…)`` are calls, not comments).
_PAREN = re.compile(r"(?<![A-Za-z0-9_])\([^)]*\)?")


def _blank_comments(text: str) -> str:
    """``text`` with its comments (``(…)``, and what follows ``;``) blanked to the same length."""
    out = []
    for line in text.split("\n"):
        k = line.find(";")
        if k >= 0:
            line = line[:k] + " " * (len(line) - k)
        if "(" in line:
            line = _PAREN.sub(lambda m: " " * len(m.group()), line)
        out.append(line)
    return "\n".join(out)


#: LinuxCNC's names: a named parameter ``#<scale>``, ``#<_hal[x-rot-point]>``, a subroutine
#: ``o<rotate>``, whose text is no dialect's word.
_NAME = re.compile(r"(?<=[#oO])<[^>\n]*>")


def _blank_names(text: str) -> str:
    """``text`` with LinuxCNC's ``<…>`` names after ``#`` or ``o`` blanked to the same length."""
    return _NAME.sub(lambda m: " " * len(m.group()), text) if "<" in text else text


@dataclass(frozen=True)
class _Head:
    """A program's first bytes as detection reads them: the text (its last line left out when it
    may be cut), upper-cased, and upper-cased with its comments blanked to the same length (so
    that a match's offset gives its line in the text; ASCII only: offsets stay)."""

    text: str
    up: str
    up_code: str


def _read_head(head: bytes) -> _Head:
    text = head.decode("utf-8", "replace").replace("\r\n", "\n").removeprefix("\ufeff")
    if len(head) >= HEAD_BYTES:
        text = text[: text.rfind("\n") + 1]  # the last line may be cut
    return _Head(text, text.translate(_UPPER), _blank_names(_blank_comments(text)).translate(_UPPER))


def detect(head: bytes, name: str | None = None) -> Dialect:
    """The dialect of a program from its first bytes ``head`` (and its file ``name``, whose
    ``.mpf``/``.spf`` suffix is Sinumerik's)."""
    return _detect(_read_head(head), name)


def _detect(h: _Head, name: str | None) -> Dialect:
    text, up, up_code = h.text, h.up, h.up_code
    found: tuple[int, str] | None = None  # the first rule's dialect that matches, at its match
    for dialect, with_comments, gate, rule in _RULES:
        if found is not None and found[1] != dialect:
            break
        t = up if with_comments else up_code
        m = rule.search(t) if any(g in t for g in gate) else None
        if m and (found is None or m.start() < found[0]):
            found = (m.start(), dialect)
    if found is not None:
        at, dialect = found
        return Dialect(dialect, True, *_line_of(text, at))
    if name is not None and Path(name).suffix.lower() in (".mpf", ".spf"):
        return Dialect("sinumerik", True, 1, f"the file name {Path(name).name}")
    return Dialect("linuxcnc", True)


def _line_of(text: str, at: int) -> tuple[int, str]:
    """The 1-based line of offset ``at`` in ``text`` and that line's text (stripped, 80 characters)."""
    start = text.rfind("\n", 0, at) + 1
    end = text.find("\n", at)
    return text.count("\n", 0, at) + 1, text[start : end if end >= 0 else len(text)].strip()[:80]


def _detect_lathe(h: _Head, dialect: str) -> tuple[int, str] | None:
    """Where the program's head, written in ``dialect``, shows a lathe's program: (line, its
    text), or None."""
    rule = _LATHE.get(dialect)
    m = None if rule is None else rule.search(h.up_code)
    return None if m is None else _line_of(h.text, m.start())


def resolve(path: str | Path, choice: str = "auto", machine: str = "auto") -> Dialect:
    """The dialect ``--dialect choice`` gives the program at ``path``: detected with ``auto``,
    and the machine ``--machine machine`` (a lathe's program is read as a lathe's: detected with
    ``auto``). A dialect the engine does not read is an :class:`InputError` at the line that
    shows it; a lathe in a dialect without lathes a :class:`ValueError`."""
    if choice not in CHOICES:
        raise ValueError(f"dialect must be one of {', '.join(CHOICES)}; got {choice!r}")
    if machine not in MACHINES:
        raise ValueError(f"machine must be one of {', '.join(MACHINES)}; got {machine!r}")
    raw = b""
    if choice == "auto" or machine == "auto":
        try:
            with open(path, "rb") as f:
                raw = f.read(HEAD_BYTES)
        except OSError as e:
            raise InputError(f"cannot read program: {e.strerror}", str(path)) from None
    head = _read_head(raw)
    if choice == "auto":
        d = _detect(head, str(path))
    else:
        d = Dialect(choice, False)
    if not d.read:
        what = f"a {NAMES[d.name]} program" if d.detected else f"--dialect {d.name}"
        shown = f" ({d.text})" if d.text else ""
        raise InputError(
            f"{what}{shown}: its syntax is not read; ncadapt reads RS274NGC and the dialects that share it "
            "(LinuxCNC, grbl, Fanuc/Haas, Marlin), and Sinumerik 840D's",
            str(path),
            d.line or 0,
            1 if d.line else 0,
        )
    if machine == "lathe":
        if d.name not in LATHE_DIALECTS:
            raise ValueError(
                f"--machine lathe: lathe programs are read in the {' and '.join(LATHE_DIALECTS)} dialects; "
                f"this one is {NAMES[d.name]}"
            )
        return replace(d, lathe=True, machine_detected=False)
    if machine == "mill":
        return replace(d, machine_detected=False)
    at = _detect_lathe(head, d.name)
    if at is None:
        return d
    return replace(d, lathe=True, machine_line=at[0], machine_text=at[1])
