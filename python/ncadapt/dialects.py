"""NC dialects: which controller family a program is written for, detected from its text.

The engine reads RS274NGC as LinuxCNC reads it. grbl's G-code is a subset of it; Fanuc/Haas and
Marlin programs share most of it, and what they write differently, or what the engine does not
know, is refused at its line by the engine (an M code it does not know, an E word, a macro call).
Sinumerik 840D and Heidenhain conversational programs have their own syntax: they are refused
here, at the line that shows the dialect, with the dialect named, instead of failing on the first
word the RS274NGC reader cannot parse.

Detection reads the program's first :data:`HEAD_BYTES` only (a program of any length is detected
at once) and looks, in this order, for: a Heidenhain ``BEGIN PGM`` line; Sinumerik syntax (a
``.mpf``/``.spf`` file, ``X=…`` assignments, ``DEF``/``EXTERN``/``PROC``, ``MSG(…)``,
``CYCLE81(…)``, frames ``TRANS``/``ROT``…, ``CIP``/``CT``/``CR=``, ``DIAMON``, ``LIMS=``); a 3D
printer's Marlin G-code (``;FLAVOR:Marlin``, ``M82``/``M83``, heater and fan codes, E words on
moves); grbl system commands (``$H``, ``$J=…``); a Fanuc program number (``O1234`` not followed by
a LinuxCNC O-word keyword), ``M98 P``, ``G65 P``, ``M99``. Anything else is LinuxCNC RS274NGC.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from .errors import InputError

#: The dialects ``--dialect`` takes (``auto`` detects one of them, or ``heidenhain``).
CHOICES = ("auto", "linuxcnc", "fanuc", "sinumerik", "grbl", "marlin")

#: Dialects whose programs the engine reads (as RS274NGC; what differs is refused at its line).
READ = ("linuxcnc", "fanuc", "grbl", "marlin")

#: How much of a program detection reads.
HEAD_BYTES = 64 * 1024

NAMES = {
    "linuxcnc": "LinuxCNC RS274NGC",
    "fanuc": "Fanuc/Haas",
    "sinumerik": "Sinumerik 840D",
    "grbl": "grbl",
    "marlin": "Marlin (3D printer G-code)",
    "heidenhain": "Heidenhain conversational (Klartext)",
}

_O_KEYWORDS = r"(?:sub|endsub|call|return|if|elseif|else|endif|while|endwhile|do|repeat|endrepeat|break|continue)"
_RULES: tuple[tuple[str, re.Pattern[str]], ...] = (
    ("heidenhain", re.compile(r"^\s*(?:\d+\s+)?BEGIN\s+PGM\b", re.I)),
    (
        "sinumerik",
        re.compile(
            r"(?<![#<\w])[XYZABCUVW]\d?\s*=\s*(?:IC|AC|DC|ACP|ACN)?\s*[-+.(\d]"
            r"|^\s*(?:N\d+\s+)?(?:EXTERN|PROC|DEF\s+(?:REAL|INT|BOOL|CHAR|STRING|AXIS|FRAME))\b"
            r"|\b(?:MSG|CYCLE\d+|POCKET\d+|SLOT\d+|HOLES\d+)\s*\("
            r"|\b(?:A?TRANS|A?ROT|A?SCALE|A?MIRROR|CIP|DIAMON|DIAMOF|SUPA|G64\d|G70\d|G71\d)\b"
            r"|\b(?:CR|LIMS|AR|TURN)\s*=",
            re.I,
        ),
    ),
    (
        "marlin",
        re.compile(
            r"^;\s*FLAVOR:|^\s*(?:N\d+\s+)?M(?:82|83|104|105|106|107|109|140|190|204|205)\b|^\s*G0*1\b[^;(]*\bE[-+.\d]",
            re.I,
        ),
    ),
    ("grbl", re.compile(r"^\s*\$(?:[HXCIGN#$]|J=|\d+=)", re.I)),
    (
        "fanuc",
        re.compile(rf"^\s*%?\s*O\d{{1,5}}\b(?!\s*{_O_KEYWORDS}\b)|\bM98\s*P|\bG65\s*P|\bM99\b", re.I),
    ),
)


@dataclass(frozen=True)
class Dialect:
    """A program's dialect: ``name`` (a key of :data:`NAMES`), whether it was ``detected`` (or
    given), and the ``line`` (1-based) and ``text`` that show it (None when nothing did)."""

    name: str
    detected: bool
    line: int | None = None
    text: str | None = None

    @property
    def read(self) -> bool:
        """Whether the engine reads programs of this dialect."""
        return self.name in READ

    def describe(self) -> str:
        """One line for a summary."""
        how = "detected" if self.detected else "given"
        shown = f", line {self.line}: {self.text}" if self.line is not None else ""
        return f"{NAMES[self.name]} ({how}{shown})"

    def as_dict(self) -> dict:
        return {"name": self.name, "detected": self.detected, "line": self.line, "evidence": self.text}


def _code(line: str) -> str:
    """A line without its comments: what follows ``;``, and ``(…)`` unless a name comes right before
    it (Sinumerik's ``MSG(…)``, ``IC(…)``, ``CYCLE81(…)`` are calls, not comments)."""
    return re.sub(r"(?<![A-Za-z0-9_])\([^)]*\)?", " ", line.split(";", 1)[0])


def detect(head: bytes, name: str | None = None) -> Dialect:
    """The dialect of a program from its first bytes ``head`` (and its file ``name``, whose
    ``.mpf``/``.spf`` suffix is Sinumerik's)."""
    text = head.decode("utf-8", "replace")
    lines = text.splitlines()
    if len(head) >= HEAD_BYTES and lines:
        lines.pop()  # the last line may be cut
    for dialect, rule in _RULES:
        for k, raw in enumerate(lines, 1):
            # Marlin's flavour comment is read with its ';'; every other rule reads the code only
            probe = raw if dialect == "marlin" else _code(raw)
            if rule.search(probe):
                return Dialect(dialect, True, k, raw.strip()[:80])
    if name is not None and Path(name).suffix.lower() in (".mpf", ".spf"):
        return Dialect("sinumerik", True, 1, f"the file name {Path(name).name}")
    return Dialect("linuxcnc", True)


def resolve(path: str | Path, choice: str = "auto") -> Dialect:
    """The dialect ``--dialect choice`` gives the program at ``path``: detected with ``auto``.
    A dialect the engine does not read is an :class:`InputError` at the line that shows it."""
    if choice not in CHOICES:
        raise ValueError(f"dialect must be one of {', '.join(CHOICES)}; got {choice!r}")
    if choice == "auto":
        try:
            with open(path, "rb") as f:
                head = f.read(HEAD_BYTES)
        except OSError as e:
            raise InputError(f"cannot read program: {e.strerror}", str(path)) from None
        d = detect(head, str(path))
    else:
        d = Dialect(choice, False)
    if not d.read:
        what = f"a {NAMES[d.name]} program" if d.detected else f"--dialect {d.name}"
        shown = f" ({d.text})" if d.text else ""
        hint = (
            "; if the program is written in ISO G-code only, --dialect linuxcnc reads it as RS274NGC"
            if d.name == "sinumerik" and d.detected
            else ""
        )
        raise InputError(
            f"{what}{shown}: its syntax is not read; ncadapt reads RS274NGC and the dialects that share it "
            f"(LinuxCNC, grbl, Fanuc/Haas, Marlin){hint}",
            str(path),
            d.line or 0,
            1 if d.line else 0,
        )
    return d
