"""Write a corrected straight program back onto the program it was run from.

A program with flow (parameters, loops, subprograms; a Sinumerik program) is run into a straight
program first, one line per block run (:mod:`ncadapt.flatten`, :mod:`ncadapt.sinumerik`). Each
straight line carries a marker comment ``;@k`` (its index), which the engine keeps on the line it
corrects and leaves off the lines it adds after it; the engine's output so splits into one group
of lines per straight line (:func:`groups`), and a straight line whose group is itself alone did
not change. Where every changed line of the straight program comes from a line of the program
that runs once, that line can be rewritten in place and every other line kept as written.
"""

from __future__ import annotations

import re

_MARK = re.compile(rb"[ \t]*;@(\d+)[ \t]*$")


def mark(lines: list[str]) -> bytes:
    """The straight program with each line's marker."""
    return "".join(f"{t} ;@{k}\n" for k, t in enumerate(lines)).encode("utf-8", "surrogateescape")


def groups(corrected: bytes, n: int) -> list[list[str]]:
    """The engine's output lines for each of the ``n`` straight lines: its own line (the marker
    taken off), then the lines the engine added after it."""
    out: list[list[str]] = [[] for _ in range(n)]
    cur = None
    for raw in corrected.splitlines():
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


def lines_of(data: bytes) -> list[tuple[str, str]]:
    """A program's lines, each as (text, its line ending)."""
    out = []
    for raw in data.decode("utf-8", "surrogateescape").splitlines(keepends=True):
        body = raw.rstrip("\r\n")
        out.append((body, raw[len(body) :]))
    return out
