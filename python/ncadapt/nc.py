"""NC programs and toolpaths: the Python face of the NC engine.

A :class:`Program` keeps every byte of the file it was read from. :meth:`Program.toolpath` samples
its motion (arcs linearised by a chord tolerance, moves split to a maximum length) and
:meth:`Program.correct` applies a correction field and returns a new program in which only the
blocks the field changes differ from the input.

Examples
--------
>>> from ncadapt import nc, fields
>>> prog = nc.parse("G21 G90 G0 X0 Y0 Z1\\nG1 Z-1 F100\\nG1 X2\\n")
>>> out = prog.correct(fields.Shift((0, 0, 0.05)))
>>> print(out.text, end="")
G21 G90 G0 X0 Y0 Z1
G1 Z-0.95 F100
G1 X2
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from . import constants
from ._io import atomic_open, atomic_write
from ._nc import Corrector as _NativeCorrector
from ._nc import EngineError
from ._nc import Program as _Native
from .correction import (
    _PIECE_BYTES,
    Correction,
    Unsupported,
    _BackgroundWriter,
    _correct,
    _engine,
    _engine_error,
    _unsupported_error,
    check_sampling,
)
from .errors import InputError, RefusedError

__all__ = [
    "Program",
    "Toolpath",
    "Blocks",
    "Correction",
    "Unsupported",
    "read",
    "parse",
    "correct_file",
    "inspect_file",
    "MOTIONS",
    "DIALECTS",
]

#: Names of the motion codes in :attr:`Toolpath.motion`.
MOTIONS = ("rapid", "feed", "arc_cw", "arc_ccw", "other", "spline", "spline_quadratic")


@dataclass(frozen=True)
class Toolpath:
    """Sampled motion of a program: one row per straight piece.

    Attributes
    ----------
    starts, points : (n, 3) float, mm
        Start and end of every piece (program coordinates, millimetres whatever the program's units).
    line : (n,) int
        1-based source line of the block the piece belongs to.
    motion : (n,) uint8
        Index into :data:`MOTIONS` (0 rapid, 1 feed, 2 clockwise arc, 3 counter-clockwise arc, 5
        cubic spline G5, 6 quadratic spline G5.1).
    block : (n,) int
        Index of the block among the program's position-changing blocks.
    """

    starts: np.ndarray
    points: np.ndarray
    line: np.ndarray
    motion: np.ndarray
    block: np.ndarray

    def __len__(self) -> int:
        return len(self.line)

    @property
    def length(self) -> float:
        """Total path length, mm."""
        return float(np.linalg.norm(self.points - self.starts, axis=1).sum()) if len(self) else 0.0


@dataclass(frozen=True)
class Blocks:
    """The blocks of a program that change the position, in program order.

    Attributes
    ----------
    line : (m,) int
        1-based source line.
    motion : (m,) uint8
        Index into :data:`MOTIONS`; 4 ("other") for moves the engine does not trace (G53, G28,
        canned cycles it refuses, ...). A canned cycle it follows makes one block per move, as
        LinuxCNC runs it.
    end : (m, 9) float
        Position after the block: X Y Z U V W in mm, A B C in degrees (order ``XYZABCUVW``);
        NaN where the program does not determine it.
    supported : (m,) bool
        The block can be corrected (of a canned cycle's moves, the feed to each hole's bottom,
        where the hole's displacement is evaluated).
    cycle : (m,) bool
        A move of a canned cycle: it moves with its hole.
    """

    line: np.ndarray
    motion: np.ndarray
    end: np.ndarray
    supported: np.ndarray
    cycle: np.ndarray

    def __len__(self) -> int:
        return len(self.line)


#: The dialects the engine reads (``dialect=`` of :func:`read`, :func:`parse`,
#: :func:`correct_file`, :func:`inspect_file`): where they differ, blocks are read as that
#: controller reads them (see :mod:`ncadapt.dialects`). ``linuxcnc-lathe`` and ``fanuc-lathe`` are
#: those controls on a lathe: no Y (0 throughout, the field evaluated there and its y not
#: applied); X a diameter after LinuxCNC's G7, and always on a Fanuc lathe, whose U and W are
#: increments of X and Z and whose G90/G92/G94 and G70-G76 are turning cycles (docs/nc-engine.md,
#: "Lathes": which are followed and which refused).
DIALECTS = ("linuxcnc", "fanuc", "grbl", "marlin", "linuxcnc-lathe", "fanuc-lathe")


def _check_dialect(dialect: str) -> str:
    if dialect not in DIALECTS:
        raise ValueError(f'Parameter "dialect" must be one of {", ".join(DIALECTS)}; got {dialect!r}')
    return dialect


def parse(
    text: str | bytes, name: str | None = None, dialect: str = "linuxcnc", tools: Mapping[int, float] | None = None
) -> Program:
    """Read a program from a string or bytes; ``name`` is used in error messages, ``dialect``
    (one of :data:`DIALECTS`) is the controller it is written for, ``tools`` the tool table
    for cutter radius compensation (:attr:`Program.tools`)."""
    data = text.encode("utf-8", "surrogateescape") if isinstance(text, str) else bytes(text)
    return Program(data, name=name or "<string>", dialect=dialect, tools=tools)


def correct_file(
    path: str | os.PathLike,
    output: str | os.PathLike,
    field: Callable[[np.ndarray], np.ndarray],
    *,
    dialect: str = "linuxcnc",
    read_ahead=None,
    expand: bool = False,
    subprograms: Sequence[str | os.PathLike] = (),
    start_motion: str | None = None,
    **options,
) -> Correction:
    """Correct the program in file ``path`` and write it to ``output``, reading and writing it
    piece by piece: memory stays bounded whatever the program's length.

    Takes the options of :meth:`Program.correct`, and the program's ``dialect`` (one of
    :data:`DIALECTS`; ``ncadapt.dialects.resolve`` detects it). ``read_ahead``: a
    ``ncadapt._nc.read_ahead(path, constants.PIECE_BYTES, dialect)`` started earlier on the same
    file (the command line starts one before its imports), whose pieces the engine takes.
    ``expand``: the program's parameters, expressions and O-word flow (LinuxCNC's), and its M98/M99
    subprograms (LinuxCNC's and Fanuc's), are first flattened into straight G-code
    (:func:`ncadapt.flatten.flatten`), which is corrected. A Sinumerik program (``dialect="sinumerik"``)
    is always run into straight G-code first (:func:`ncadapt.sinumerik.translate`). The program is
    then written as it is when no block changed; with its changed lines rewritten in place when
    each runs once (its structure and every other line kept); and otherwise straight, one line per
    block run (a Sinumerik program only with ``expand``, else :class:`RefusedError` naming the
    line). ``Correction.expanded`` says which (``written``) and how many blocks. A subprogram a
    Sinumerik program calls is looked for beside it, then in the folders ``subprograms``
    (``Correction.expanded["subprograms"]`` names the files read); ``start_motion`` (``"G0"`` or
    ``"G1"``) is the motion mode the machine starts a Sinumerik program in (its machine data), for
    a program that moves before it states one.

    The output is written atomically: when a check refuses (an unsupported construct, a
    displacement over the limit, a point outside the field), nothing is written. Raises
    :class:`InputError` naming ``path:line:col`` on bad input.
    """
    p, out = Path(path), Path(output)
    _refuse_overwrite(out, p)
    _check_expand(expand, dialect)
    if dialect in ("sinumerik", "marlin"):
        if read_ahead is not None:
            read_ahead.cancel()
        if dialect == "marlin":
            return _correct_marlin(p, out, field, options)
        return _correct_sinumerik(p, out, field, expand, subprograms, start_motion, options)
    if expand:
        if read_ahead is not None:
            read_ahead.cancel()
        return _correct_flat(p, out, field, dialect, options)
    with atomic_open(out) as f:
        with _BackgroundWriter(f) as w:
            try:
                c = _correct(
                    str(p),
                    str(p),
                    w.write,
                    field,
                    keep_points=False,
                    out_file=f,
                    dialect=_check_dialect(dialect),
                    read_ahead=read_ahead,
                    **options,
                )
            except InputError as e:
                raise _macro_hint(e, p, dialect) from None
    return c


#: A Fanuc Custom Macro B statement (the engine reads the words of straight G-code only).
_MACRO_B = re.compile(r"^\s*(?:N\d+\s*)?(?:IF\s*\[|WHILE\s*\[|DO\s*\d|END\s*\d|GOTO|#\d)|G0*65(?![\d.])", re.I)


def _macro_hint(e: InputError, p: Path, dialect: str) -> InputError:
    """``e``, or where it falls on a Fanuc Custom Macro B statement, the refusal that names it and
    ``--expand``."""
    if dialect not in ("fanuc", "fanuc-lathe") or not e.line:
        return e
    try:
        with open(p, "rb") as f:
            for k, raw in enumerate(f, 1):
                if k == e.line:
                    text = raw.decode("utf-8", "replace").split("(", 1)[0].strip()
                    break
            else:
                return e
    except OSError:
        return e
    if not _MACRO_B.search(text):
        return e
    return InputError(
        f"Fanuc Custom Macro B ({text[:40]}): `ncadapt correct --expand` runs the program's variables and flow "
        "and writes the moves they make",
        str(p),
        e.line,
        1,
    )


def _read_program(p: Path) -> bytes:
    try:
        return p.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read program: {e.strerror}", str(p)) from None


#: What the engine calls the moves it keeps in machine coordinates, in the words of the programs
#: whose straight programs write them as G53.
_MACHINE_MOVES = {
    "sinumerik": "machine-coordinate move (SUPA, G53, G153)",
    "marlin": "homing or bed probing (G28, G29)",
}


#: The dialects a translator turns into straight G-code first: the dialect the engine then reads
#: it in, and how the straight program was made (for messages).
_TRANSLATED = {
    "sinumerik": ("linuxcnc", "run as straight G-code"),
    "marlin": ("marlin", "read with its E as a U axis"),
}


def _check_expand(expand: bool, dialect: str) -> None:
    """``expand`` flattens or runs LinuxCNC's (mills and lathes), Fanuc's and Sinumerik's (mills)
    programs only."""
    if expand and dialect not in ("linuxcnc", "linuxcnc-lathe", "fanuc", "sinumerik"):
        raise ValueError(
            f"expand reads the programs of LinuxCNC (mills and lathes), Fanuc and Sinumerik mills; the dialect is {dialect}"
        )


def _program_note(message: str, of: str | None) -> str:
    """A note of the straight program in the words of the program's dialect ``of``."""
    return message.replace("G53 machine-coordinate move", _MACHINE_MOVES[of]) if of in _MACHINE_MOVES else message


def _program_line(lines: np.ndarray, k):
    """The program's line of line ``k`` (1-based) of its straight program."""
    return int(lines[k - 1]) if isinstance(k, int) and 1 <= k <= len(lines) else k


def _correct_straight(straight: bytes, flat, p: Path, field, dialect: str, how: str, options: dict, of=None):
    """Correct a straight program (``flat.lines``: the program's line of each of its lines) in
    memory: the correction (its warnings and notes on the program's lines) and the engine's
    output. An error names the program's line."""
    import io

    buf = io.BytesIO()
    try:
        c = _correct(straight, str(p), buf.write, field, keep_points=False, dialect=dialect, **options)
    except (InputError, RefusedError) as e:
        raise _flat_error(e, flat, str(p), how) from None
    c = _original_lines(c, flat.lines)
    return dataclasses.replace(c, notes=tuple((k, _program_note(m, of)) for k, m in c.notes)), buf.getvalue()


def _written(c: Correction, out: Path, data: bytes, text: bytes, written: str, rewritten: int, blocks: int, run: int):
    """Write ``text`` to ``out`` and say how (``Correction.expanded``); the lines read and
    written are the program's and the output's (the other figures the straight program's)."""
    atomic_write(out, text)
    n_in, n_out = _count_lines(data), _count_lines(text)
    c = dataclasses.replace(c, lines_in=n_in, lines_out=n_out, lines_added=max(0, n_out - n_in))
    expanded = {
        "lines_in": n_in,
        "blocks": blocks,
        "blocks_run": run,
        "kept": written == "as it is",
        "written": written,
        "lines_rewritten": rewritten,
    }
    return dataclasses.replace(c, expanded=expanded)


def _correct_flat(p: Path, out: Path, field, dialect: str, options: dict) -> Correction:
    """:func:`correct_file` with ``expand``: the program flattened
    (:func:`ncadapt.flatten.flatten`) and corrected; written as it is when no block changed, with
    its changed lines rewritten in place when each of them runs once and sets no parameter (its
    parameters, O-words and every other line kept), and flat otherwise."""
    from . import rewrite
    from .flatten import flatten

    data = _read_program(p)
    # (a LinuxCNC lathe's parameters and flow are read as a mill's: its X words are numbers)
    flat = flatten(data, str(p), dialect.removesuffix("-lathe"))
    straight = rewrite.split_lines(flat.data.decode("utf-8", "surrogateescape"))
    c, corrected = _correct_straight(
        rewrite.mark(straight), flat, p, field, dialect, "flattened with --expand", options
    )
    groups = rewrite.groups(corrected, len(straight))
    changed = rewrite.changed(groups, straight)
    lines = {int(flat.lines[k]) - 1: k for k, ch in enumerate(changed) if ch}  # original line → flat line
    if not lines:
        text, written, n = data, "as it is", 0
    elif all(flat.runs[i] == 1 and not flat.fixed[i] for i in lines):
        src = rewrite.lines_of(data)
        repl = {}
        for i, k in lines.items():
            # the line's indent, block delete and number stay; its words are the corrected block's
            m = re.match(r"[ \t]*/?[ \t]*(?:[Nn][ \t]*\d+[ \t]*)?", src[i][0])
            head = m.group() if m else ""
            first = groups[k][0].strip()
            if "/" in head and first.startswith("/"):
                first = first[1:].lstrip()  # the line's own block delete is in its head
            repl[i] = [head + first] + [t.strip() for t in groups[k][1:]]
        text, written, n = rewrite.splice(data, repl), "in place", len(lines)
    else:
        text, written = "".join(t + "\n" for g in groups for t in g).encode("utf-8", "surrogateescape"), "straight"
        n = _count_lines(text)
    return _written(c, out, data, text, written, n, len(flat.lines), flat.blocks_run)


def _correct_sinumerik(
    p: Path, out: Path, field, expand: bool, subprograms, start_motion: str | None, options: dict
) -> Correction:
    """:func:`correct_file` for a Sinumerik program: run into straight RS274NGC
    (:func:`ncadapt.sinumerik.translate`), corrected, and written back in Sinumerik's syntax."""
    from . import sinumerik

    data = _read_program(p)
    tr = sinumerik.translate(data, str(p), subprograms, start_motion)
    c, corrected = _correct_straight(tr.data, tr, p, field, *_TRANSLATED["sinumerik"], options, "sinumerik")
    try:
        text, rewritten, written = sinumerik.assemble(tr, corrected, expand)
    except sinumerik.Unwritable as e:
        raise RefusedError(f"{p}:{e.line}: {e.message}", [{"line": e.line, "reason": e.message}]) from None
    except sinumerik.NeedsExpand as e:
        if e.sub is not None:
            raise RefusedError(
                f"{p}:{e.line}: the line calls subprogram {e.sub}, whose moves the correction changes (or which finds another "
                "motion mode than it was written for): the corrected program cannot keep the call; --expand writes "
                "its moves into the program",
                [{"line": e.line, "subprogram": e.sub, "reason": "corrected in a subprogram"}],
            ) from None
        raise RefusedError(
            f"{p}:{e.line}: the line runs {e.runs} times (a loop or a jump) and its move is corrected differently on each run: "
            "the corrected program cannot keep the loop; --expand writes it straight, one block per move run",
            [{"line": e.line, "runs": e.runs, "reason": "corrected in a loop"}],
        ) from None
    c = _written(c, out, data, text, written, rewritten, len(tr.items), tr.blocks_run)
    return dataclasses.replace(c, expanded={**c.expanded, "subprograms": tr.subprograms})


def _correct_marlin(p: Path, out: Path, field, options: dict) -> Correction:
    """:func:`correct_file` for a Marlin program: its E carried as a U axis the engine shares out
    among a move's pieces (:mod:`ncadapt.marlin`), and written back as E."""
    from . import marlin

    data = _read_program(p)
    tr = marlin.translate(data, str(p))
    c, corrected = _correct_straight(tr.data, tr, p, field, *_TRANSLATED["marlin"], options, "marlin")
    text, rewritten = marlin.assemble(tr, corrected)
    written = "as it is" if rewritten == 0 else "in place"
    return _written(c, out, data, text, written, rewritten, len(tr.straight), tr.blocks_run)


def _original_lines(c: Correction, lines: np.ndarray) -> Correction:
    """``c`` with the lines its warnings and notes name, lines of a straight program (1-based),
    turned into the lines ``lines`` says they come from."""

    at_line = re.compile(r"(\bline )(\d+)")
    return dataclasses.replace(
        c,
        warnings=tuple(
            at_line.sub(lambda m: f"{m.group(1)}{_program_line(lines, int(m.group(2)))}", w) for w in c.warnings
        ),
        notes=tuple(dict.fromkeys((_program_line(lines, k), m) for k, m in c.notes)),  # once per line of the program
    )


def _count_lines(data: bytes) -> int:
    """A program's lines, as the engine counts them (LF ends a line)."""
    return data.count(b"\n") + (0 if data.endswith(b"\n") or not data else 1)


def _flat_error(e, flat, name, how="flattened with --expand"):
    """An error of the flattened program, located at the original line its block comes from."""
    if isinstance(e, InputError):
        k = e.line
        if 1 <= k <= len(flat.lines):
            return InputError(f"{e.message} (block {k} of the program {how})", name, _program_line(flat.lines, k))
        return e
    details = []
    for d in e.details:
        if isinstance(d, dict) and isinstance(d.get("line"), int) and 1 <= d["line"] <= len(flat.lines):
            d = {**d, "line": int(flat.lines[d["line"] - 1]), "flat_line": d["line"]}
        details.append(d)
    return RefusedError(
        f"{e.message} (the program was {how}: line numbers in this message are of that "
        "program; the details give the original lines)",
        details,
    )


def inspect_file(
    path: str | os.PathLike,
    dialect: str = "linuxcnc",
    subprograms: Sequence[str | os.PathLike] = (),
    expand: bool = False,
    start_motion: str | None = None,
) -> dict:
    """What the program in file ``path`` contains (as :meth:`Program.inspect`), read piece by
    piece: memory stays bounded whatever the program's length. A Sinumerik program is run into
    straight G-code first (:func:`ncadapt.sinumerik.translate`, its subprograms looked for beside
    it and in ``subprograms``, ``start_motion`` as :func:`correct_file` takes it; ``subprograms`` in
    the result names the files read); with
    ``expand``, a LinuxCNC or Fanuc program's parameters, flow, subprograms and macros are first
    flattened as ``correct_file(expand=True)`` does (:func:`ncadapt.flatten.flatten`). The lines
    named are the program's own."""
    _check_expand(expand, dialect)
    if dialect not in ("sinumerik", "marlin") and not expand:
        try:
            return _inspect(str(path), str(path), _check_dialect(dialect))
        except InputError as e:
            raise _macro_hint(e, Path(path), dialect) from None
    from . import marlin, sinumerik
    from .flatten import Flat, flatten

    data = _read_program(Path(path))
    tr: sinumerik.Translation | marlin.Translation | Flat
    if dialect == "sinumerik":
        tr = sinumerik.translate(data, str(path), subprograms, start_motion)
    elif dialect == "marlin":
        tr = marlin.translate(data, str(path))
    else:
        tr = flatten(data, str(path), dialect.removesuffix("-lathe"))
    engine, how = _TRANSLATED.get(dialect, (dialect, "flattened with --expand"))
    try:
        info = _inspect(tr.data, str(path), engine)
    except InputError as e:
        raise _flat_error(e, tr, str(path), how) from None
    info["lines"] = _count_lines(data)
    info["blocks_run"] = tr.blocks_run
    if dialect == "marlin":  # the straight program's preamble (G0 U0) is not the program's
        info["motions"]["rapid"] -= 1
    info["end_line"] = _program_line(tr.lines, info["end_line"])
    info["unsupported"] = [{**u, "line": _program_line(tr.lines, u["line"])} for u in info["unsupported"]]
    notes = dict.fromkeys(
        (_program_line(tr.lines, n["line"]), _program_note(n["message"], dialect)) for n in info["notes"]
    )
    info["notes"] = [{"line": k, "message": m} for k, m in notes]  # once per line of the program
    if isinstance(tr, sinumerik.Translation):
        info["subprograms"] = tr.subprograms
    return info


def read(path: str | os.PathLike, dialect: str = "linuxcnc", tools: Mapping[int, float] | None = None) -> Program:
    """Read a program file written for ``dialect`` (one of :data:`DIALECTS`), with the tool
    table ``tools`` for cutter radius compensation (:attr:`Program.tools`). Raises
    :class:`InputError` naming ``path:line:col`` on bad input."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read program: {e.strerror}", str(p)) from None
    return Program(data, path=p, dialect=dialect, tools=tools)


class Program:
    """An NC program: its exact bytes, its interpretation and what can be done with it.

    Create one with :func:`read` or :func:`parse`.
    """

    def __init__(
        self,
        data: bytes,
        path: Path | None = None,
        name: str | None = None,
        *,
        lazy: bool = False,
        dialect: str = "linuxcnc",
        tools: Mapping[int, float] | None = None,
    ):
        self._data = data
        #: The controller the program is written for (one of :data:`DIALECTS`).
        self.dialect = _check_dialect(dialect)
        #: Tool diameters (mm) by tool number (:func:`ncadapt.tooltable.read`): cutter radius
        #: compensation (G41/G42) takes its radius from them; without them it is unsupported.
        self.tools = {int(t): float(d) for t, d in (tools or {}).items()}
        self.path = Path(path) if path is not None else None
        self.name = str(path) if path is not None else (name or "<program>")
        self.correction: Correction | None = None
        self._native = None
        self._rec: dict | None = None
        if not lazy:
            self._p  # noqa: B018 - parse now so errors surface where the program is read

    @property
    def _p(self):
        """The native program, parsed on first use."""
        if self._native is None:
            try:
                self._native = _Native.parse(self._data, self.dialect, sorted(self.tools.items()))
            except EngineError as e:
                raise _engine_error(e, self.name) from None
        return self._native

    # ----------------------------------------------------------------------------- contents
    @property
    def data(self) -> bytes:
        """The program's bytes, exactly."""
        return self._data

    @property
    def text(self) -> str:
        """The program as text (bytes that are not UTF-8 are kept as surrogates)."""
        return self._data.decode("utf-8", "surrogateescape")

    @property
    def lines(self) -> int:
        """Number of lines."""
        return self._p.n_lines()

    @property
    def unsupported(self) -> tuple[Unsupported, ...]:
        """Constructs the engine does not interpret, in line order."""
        return tuple(Unsupported(*u) for u in self._p.unsupported())

    @property
    def notes(self) -> tuple[tuple[int, str], ...]:
        """Remarks on blocks kept but not corrected (G53 moves): (line, message)."""
        return tuple(self._p.notes())

    def _records(self) -> dict:
        if self._rec is None:
            r = self._p.records()
            self._rec = {
                "line": np.frombuffer(r["line"], dtype="<u4").astype(np.int64) + 1,
                "motion": np.frombuffer(r["motion"], dtype=np.uint8),
                "plane": np.frombuffer(r["plane"], dtype=np.uint8),
                "flags": np.frombuffer(r["flags"], dtype=np.uint8),
                "end": np.frombuffer(r["end"], dtype="<f8").reshape(-1, 9),
                "named": np.frombuffer(r["named"], dtype="<u2"),
            }
        return self._rec

    @property
    def blocks(self) -> Blocks:
        """Every block that changes the position, with where it ends."""
        r = self._records()
        return Blocks(r["line"], r["motion"], r["end"], (r["flags"] & 8) != 0, (r["flags"] & 16) != 0)

    # ----------------------------------------------------------------------------- sampling
    @staticmethod
    def _check_sampling(chord_tol, max_segment) -> None:
        check_sampling(chord_tol, max_segment)

    def _sample(self, chord_tol, max_segment, rapids, supported_only):
        self._check_sampling(chord_tol, max_segment)
        try:
            xyz, rec = self._p.sample(float(chord_tol), float(max_segment), bool(rapids), bool(supported_only), [], [])
        except EngineError as e:
            raise _engine_error(e, self.name) from None
        pts = np.frombuffer(xyz, dtype="<f8").reshape(-1, 3)
        return pts, np.frombuffer(rec, dtype="<u4").astype(np.int64)

    def toolpath(
        self,
        chord_tol: float = constants.CHORD_TOL,
        max_segment: float = constants.MAX_SEGMENT,
        rapids: bool = True,
        supported_only: bool = False,
    ) -> Toolpath:
        """Sample the program's motion.

        Parameters
        ----------
        chord_tol : float, mm
            Largest distance between an arc and its chords.
        max_segment : float, mm
            Longest piece.
        rapids : bool
            Include rapid (G0) moves.
        supported_only : bool
            Only blocks the engine can correct (else every block whose start and end are known).
        """
        pts, rec = self._sample(chord_tol, max_segment, rapids, supported_only)
        r = self._records()
        starts = np.empty_like(pts)
        if len(pts):
            starts[1:] = pts[:-1]
            first = np.ones(len(rec), dtype=bool)
            first[1:] = rec[1:] != rec[:-1]
            prev = rec[first] - 1
            block_start = np.full((len(prev), 3), np.nan)
            ok = prev >= 0
            block_start[ok] = r["end"][prev[ok], :3]
            starts[first] = block_start
        return Toolpath(starts, pts.copy(), r["line"][rec], r["motion"][rec], rec)

    # ----------------------------------------------------------------------------- summary
    @property
    def units(self) -> str:
        """``"mm"``, ``"inch"`` or ``"mixed"``."""
        s = self._p.summary()
        if s["inch_lines"] and s["mm_lines"]:
            return "mixed"
        return "inch" if s["inch_lines"] else "mm"

    def inspect(self) -> dict:
        """Units, planes, motion counts, extents and unsupported constructs, as plain values."""
        return _inspect(self._data, self.name, self.dialect)

    # ----------------------------------------------------------------------------- correction
    def correct(
        self,
        field: Callable[[np.ndarray], np.ndarray],
        *,
        chord_tol: float = constants.CHORD_TOL,
        max_segment: float = constants.MAX_SEGMENT,
        limit: float = constants.LIMIT,
        rapids: bool = False,
        keep_unsupported: bool = False,
        clearance: float | None = None,
        progress: Callable[[str], None] | None = None,
        expand_cycles: bool = False,
        tools: Mapping[int, float] | None = None,
    ) -> Program:
        """Apply a correction field and return the corrected program.

        Parameters
        ----------
        field : callable, (n, 3) float mm -> (n, 3) float mm
            The displacement to add at each point, usually an :mod:`ncadapt.fields` field. A field
            with ``grid_lines`` makes moves split where they cross its cell lines; one with
            ``uses_axes = True`` is called ``field(points, axes)`` with axes (n, 9) XYZABCUVW at
            every point (for corrections that depend on a rotary axis); it may return (n, 9)
            displacements in that order to move U, V and W too (A, B, C zero).
        chord_tol, max_segment : float, mm
            Sampling of arcs and long moves.
        limit : float, mm
            Largest displacement allowed; above it :class:`RefusedError` lists the worst points.
        rapids : bool
            Correct rapid moves too (by default they keep their programmed targets).
        keep_unsupported : bool
            Copy blocks with unsupported constructs unchanged instead of refusing the program.
        clearance : float, mm, optional
            Report uncorrected rapids that end below this Z inside the field's area.
        progress : callable, optional
            Called with a message for each piece of the program.
        expand_cycles : bool
            Write canned cycles (G73, G81-G83, G85, G89) as the G0/G1 moves (and G4 dwells)
            LinuxCNC makes of them. By default a cycle block stays a cycle block, each hole moved
            by the displacement at its bottom: X and Y by its x and y, Z and R by its z.
        tools : mapping of int to float, mm, optional
            Tool diameters by tool number (:func:`ncadapt.tooltable.read`; default
            :attr:`tools`): cutter radius compensation (G41/G42 D…, or the tool loaded by M6)
            takes its radius from it, and the field is evaluated where the tool centre is
            (docs/nc-engine.md). Without one such programs are refused; G41.1/G42.1 give their
            diameter themselves.

        Returns
        -------
        Program
            The corrected program; its :attr:`correction` says what was done, with every sample
            point and its displacement. :meth:`correct_to` writes a file without holding them.
        """
        parts: list[bytes] = []
        tools = self.tools if tools is None else tools
        self._refuse_unsupported(keep_unsupported, tools)
        c = _correct(
            self._data,
            self.name,
            parts.append,
            field,
            chord_tol=chord_tol,
            max_segment=max_segment,
            limit=limit,
            rapids=rapids,
            keep_unsupported=keep_unsupported,
            clearance=clearance,
            progress=progress,
            keep_points=True,
            expand_cycles=expand_cycles,
            dialect=self.dialect,
            tools=tools,
        )
        # the corrected program is parsed only if it is used as a program again
        result = Program(b"".join(parts), name=f"{self.name} (corrected)", lazy=True, dialect=self.dialect, tools=tools)
        result.correction = c
        return result

    def correct_to(self, path: str | os.PathLike, field: Callable[[np.ndarray], np.ndarray], **options) -> Correction:
        """Correct the program and write it to ``path``, one piece at a time.

        Takes the options of :meth:`correct`. The points and displacements are not kept
        (``Correction.points`` is None). The file is written atomically: when a check refuses,
        ``path`` is left as it was. :func:`correct_file` does the same from a file without
        reading it whole.
        """
        p = Path(path)
        _refuse_overwrite(p, self.path)
        options.setdefault("tools", self.tools)
        self._refuse_unsupported(options.get("keep_unsupported", False), options["tools"])
        with atomic_open(p) as f, _BackgroundWriter(f) as w:
            return _correct(
                self._data, self.name, w.write, field, keep_points=False, out_file=f, dialect=self.dialect, **options
            )

    def _refuse_unsupported(self, keep_unsupported, tools) -> None:
        """Refuse now what the program was read with (the reading pass checks it again; with
        another tool table than :attr:`tools`, what compensation it follows is its to say)."""
        if tools != self.tools:
            return
        uns = self.unsupported
        if uns and not keep_unsupported:
            raise _unsupported_error(self.name, uns)

    # ----------------------------------------------------------------------------- output
    def write(self, path: str | os.PathLike) -> Path:
        """Write the program atomically (temporary file, then rename).

        Refuses to write over the file the program was read from.
        """
        p = Path(path)
        _refuse_overwrite(p, self.path)
        atomic_write(p, self._data)
        return p

    def __repr__(self) -> str:
        return f"<Program {self.name!r}: {self.lines} lines>"


def _refuse_overwrite(output: Path, source: Path | None) -> None:
    if source is not None and output.exists() and os.path.samefile(output, source):
        raise InputError("refusing to overwrite the input program; choose another output", str(output))


def _inspect(source, name, dialect="linuxcnc") -> dict:
    """Units, planes, motion counts, extents, unsupported constructs and notes, piece by piece."""
    run = _engine(
        lambda: _NativeCorrector(
            source, constants.CHORD_TOL, constants.MAX_SEGMENT, True, False, [], [], _PIECE_BYTES, False, dialect
        ),
        name,
    )
    lo = {k: np.full(3, np.inf) for k in ("all", "feed")}
    hi = {k: np.full(3, -np.inf) for k in ("all", "feed")}
    while (chunk := _engine(run.next, name)) is not None:
        _, _, xyz, rec, recs, _ = chunk
        pts = np.frombuffer(xyz, dtype="<f8").reshape(-1, 3)
        motion = np.frombuffer(recs["motion"], dtype=np.uint8)[np.frombuffer(rec, dtype="<u4")]
        run.discard()
        ok = np.isfinite(pts).all(axis=1)
        for k, sel in (("all", ok), ("feed", ok & (motion != 0))):
            if sel.any():
                lo[k] = np.minimum(lo[k], pts[sel].min(axis=0))
                hi[k] = np.maximum(hi[k], pts[sel].max(axis=0))
    s = run.summary()
    ext = {
        k: ({a: [float(lo[k][i]), float(hi[k][i])] for i, a in enumerate("xyz")} if np.isfinite(lo[k]).all() else None)
        for k in ("all", "feed")
    }
    units = "mixed" if s["inch_lines"] and s["mm_lines"] else ("inch" if s["inch_lines"] else "mm")
    return {
        "file": name,
        "lines": run.lines_read(),
        "units": units,
        "planes": {"G17": s["planes"][0], "G18": s["planes"][1], "G19": s["planes"][2]},
        "motions": dict(zip(MOTIONS, s["counts"])),
        "extents": ext,
        "work_offsets": [_wcs_name(c) for c in s["work_offsets"]],
        "tools": s["tools"],
        "block_delete_lines": s["block_delete_lines"],
        "end_line": s["end_line"],
        "unsupported": [asdict(Unsupported(*u)) for u in run.unsupported()],
        "notes": [{"line": ln, "message": m} for ln, m in run.notes()],
    }


def _wcs_name(code: int) -> str:
    if code >= _EXTENDED_WCS:  # Fanuc's G54.1 P n (Haas G154 P n)
        return f"G54.1 P{code - _EXTENDED_WCS}"
    return f"G{code // 10}" if code % 10 == 0 else f"G{code // 10}.{code % 10}"


#: The engine's code of the extended work system G54.1 P n is this plus n.
_EXTENDED_WCS = 10000
