"""Write a corrected straight program back onto the program it was run from.

A program with flow (parameters, loops, subprograms; a Sinumerik program) is run into a straight
program first, one line per block run (:mod:`ncadapt.flatten`, :mod:`ncadapt.sinumerik`). Each
straight line carries a marker comment ``;@k`` (its index), which the engine keeps on the line it
corrects and leaves off the lines it adds after it; the engine's output so splits into one group
of lines per straight line (:func:`groups`), and a straight line whose group is itself alone did
not change. Where every changed line of the straight program comes from a line of the program
that runs once, that line can be rewritten in place and every other line kept as written.

It also holds what the programs' runners share: how a program's bytes are read
(:func:`program_text`), the error a line's reading raises (:class:`LineError`), the rounding of their controls (:func:`round_half_away`) and the way a
straight line writes a number (:func:`number`).
"""

from __future__ import annotations

import math
import re

#: A UTF-8 byte order mark, which editors put before a file's first byte: no part of the program.
BOM = "\ufeff"


def program_text(data: bytes) -> str:
    """A program's bytes as the runners read them: UTF-8 (a byte that is not kept as it is), a
    byte order mark at the start read as a blank (columns stay the file's)."""
    text = data.decode("utf-8", "surrogateescape")
    return " " + text[1:] if text.startswith(BOM) else text


class LineError(Exception):
    """Something wrong in the line being run, at column ``col`` of its code (1-based; 0 unknown):
    the runner names the line."""

    def __init__(self, message: str, col: int = 0):
        super().__init__(message)
        self.message, self.col = message, col


def round_half_away(x: float) -> float:
    """``x`` rounded to a whole number, halves away from zero (as the controls' ROUND)."""
    return float(math.floor(abs(x) + 0.5)) * (1.0 if x >= 0 else -1.0)


def number(v: float, decimals: int = 6) -> str:
    """``v`` as a straight line writes it: ``decimals`` places, no trailing zeros, never ``-0``."""
    t = f"{v:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if t in ("-0", "") else t


_MARK = re.compile(rb"[ \t]*;@(\d+)[ \t]*$")


def mark(lines: list[str]) -> bytes:
    """The straight program with each line's marker."""
    return "".join(f"{t} ;@{k}\n" for k, t in enumerate(lines)).encode("utf-8", "surrogateescape")


def groups(corrected: bytes, n: int) -> list[list[str]]:
    """The engine's output lines for each of the ``n`` straight lines: its own line (the marker
    taken off), then the lines the engine added after it."""
    out: list[list[str]] = [[] for _ in range(n)]
    cur = None
    lines = corrected.split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    for raw in lines:
        raw = raw[:-1] if raw.endswith(b"\r") else raw
        m = _MARK.search(raw)
        if m:
            cur = int(m.group(1))
            raw = raw[: m.start()]
        if cur is None:
            raise RuntimeError(f"the engine wrote a line before the first marked one: {raw!r}")
        out[cur].append(raw.decode("utf-8", "surrogateescape").rstrip())
    return out


def changed(gs: list[list[str]], straight: list[str]) -> list[bool]:
    """Which straight lines the correction changed (or added lines after)."""
    return [len(g) != 1 or g[0] != t.rstrip() for g, t in zip(gs, straight, strict=True)]


def split_lines(text: str) -> list[str]:
    """A program's lines as a control reads them: split at LF (a CR before it is the line's
    ending), not at the other characters Python's ``splitlines`` takes for line ends (form feed,
    vertical tab, U+2028 …), which a control reads as part of the line."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return [t[:-1] if t.endswith("\r") else t for t in lines]


def splice(source: bytes, repl: dict[int, list[str]]) -> bytes:
    """The program ``source`` with each line ``j`` of ``repl`` (0-based) replaced by the lines
    ``repl[j]``, written with its line ending (LF where it has none); every other line as written.
    A byte order mark the program starts with stays first."""
    out = []
    for j, (body, eol) in enumerate(lines_of(source)):
        out += [t + (eol or "\n") for t in repl[j]] if j in repl else [body + eol]
    if out and source.startswith(BOM.encode()) and not out[0].startswith(BOM):
        out[0] = BOM + out[0]
    return "".join(out).encode("utf-8", "surrogateescape")


def lines_of(data: bytes) -> list[tuple[str, str]]:
    """A program's lines, each as (text, its line ending), split as :func:`split_lines` does."""
    out = []
    for raw in data.decode("utf-8", "surrogateescape").split("\n"):
        out.append((raw[:-1], "\r\n") if raw.endswith("\r") else (raw, "\n"))
    if out and out[-1][0] == "":
        out.pop()
    elif out:
        out[-1] = (out[-1][0], "")  # the last line without an ending keeps none
    return out
