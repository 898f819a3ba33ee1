"""Reading text inputs with located errors; writing files safely: to a temporary file beside the
target, then an atomic rename."""

from __future__ import annotations

import contextlib
import contextvars
import csv
import io
import os
import tempfile
from pathlib import Path

from .errors import InputError

#: Temporary files are named with this prefix (and the target's name, so its suffix is kept).
TMP_PREFIX = ".ncadapt-tmp-"

#: Files written inside :func:`all_or_nothing`: (temporary, target), renamed together at its end.
_STAGED: contextvars.ContextVar[list | None] = contextvars.ContextVar("ncadapt_staged", default=None)
#: Every temporary file not yet renamed or removed, for the signal handlers.
_LIVE: set[str] = set()


def write_target(path: Path) -> Path:
    """Where writing ``path`` lands: a symbolic link's target (the link stays)."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def _mode_for(target: Path) -> int:
    """An existing file keeps its permission bits; a new one gets those any new file would get."""
    try:
        return os.stat(target).st_mode & 0o7777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _remove(tmp: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(tmp)
    _LIVE.discard(tmp)


def remove_temporaries() -> None:
    """Remove every temporary file still open (on a signal that ends the process)."""
    for tmp in list(_LIVE):
        _remove(tmp)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """A temporary path beside ``path`` (named ``.ncadapt-tmp-*``, ending with the target's name)
    for a writer that wants a file name; it replaces ``path`` only when the block ends without an
    error, else it is removed and the target is left as it was. Inside :func:`all_or_nothing` the
    rename waits for the end of that block. An existing target keeps its permission bits; a
    symbolic link's target is replaced (the link stays)."""
    p = write_target(Path(path))
    d = p.parent if str(p.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=TMP_PREFIX, suffix="-" + (p.name or "out"), dir=d)
    os.close(fd)
    _LIVE.add(tmp)
    staged = _STAGED.get()
    try:
        yield tmp
        os.chmod(tmp, _mode_for(p))
        if staged is not None:
            staged.append((tmp, p))
            return
        os.replace(tmp, p)
        _LIVE.discard(tmp)
    except BaseException:
        _remove(tmp)
        raise


@contextlib.contextmanager
def all_or_nothing():
    """Every file written with :func:`atomic_path`, :func:`atomic_open` or :func:`atomic_write`
    inside the block replaces its target only when the whole block ends without an error; when it
    fails (or is interrupted), none does and the temporary files are removed."""
    staged: list[tuple[str, Path]] = []
    token = _STAGED.set(staged)
    try:
        yield
    except BaseException:
        for tmp, _ in staged:
            _remove(tmp)
        raise
    finally:
        _STAGED.reset(token)
    for tmp, target in staged:
        os.replace(tmp, target)
        _LIVE.discard(tmp)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike):
    """A binary file to write that replaces ``path`` only when the block ends without an error."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        yield f


def atomic_write(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; on any failure the target is left as it was."""
    with atomic_open(path) as f:
        f.write(data)
    return Path(path)


def read_text(path: str | os.PathLike) -> str:
    """The text of an input file (UTF-8, with or without a byte-order mark). A file that cannot be
    read, or is not UTF-8 text, is an :class:`InputError` naming the file (and the line and column of
    the first byte that is not UTF-8)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror}", str(p)) from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        col = e.start - (data.rfind(b"\n", 0, e.start) + 1) + 1
        bad = data[e.start : e.start + 1].hex()
        raise InputError(
            f"not UTF-8 text: byte 0x{bad} ({e.reason}); save the file as UTF-8", str(p), line, col
        ) from None


#: The longest CSV field read (characters); a longer one is an error at its line.
CSV_FIELD_LIMIT = 128 * 1024


class CsvRows:
    """The rows of a CSV input file read by :func:`read_text`, with ``line_num`` the file's line
    of the row last read. Line ends may be LF, CRLF or CR alone; the delimiter is the comma, or the
    semicolon (or tab) when the first line that is not blank or a ``#`` comment has one and no
    comma. A malformed row (a field over :data:`CSV_FIELD_LIMIT`, a stray quote) is an
    :class:`InputError` at its line."""

    def __init__(self, path: str | os.PathLike):
        self.path = str(path)
        text = read_text(path)
        if "\r" in text:
            text = text.replace("\r\n", "\n").replace("\r", "\n")
        first = next((ln for ln in text.split("\n", 64)[:64] if ln.strip() and not ln.lstrip().startswith("#")), "")
        self.delimiter = ","
        if "," not in first:
            self.delimiter = ";" if ";" in first else ("\t" if "\t" in first else ",")
        self.text = text  # line ends made LF, one for one
        self._rows = csv.reader(io.StringIO(text, newline=""), delimiter=self.delimiter)
        self.line_num = 0

    def __iter__(self):
        return self

    def __next__(self) -> list[str]:
        old = csv.field_size_limit(CSV_FIELD_LIMIT)
        try:
            row = next(self._rows)
        except csv.Error as e:
            line = self._rows.line_num
            msg = str(e)
            if "field larger than field limit" in msg:
                msg = f"a field longer than {CSV_FIELD_LIMIT // 1024} KB"
            raise InputError(f"not a readable CSV row: {msg}", self.path, line) from None
        finally:
            csv.field_size_limit(old)
        self.line_num = self._rows.line_num
        return row


def csv_reader(path: str | os.PathLike) -> CsvRows:
    """The rows of a CSV input file (see :class:`CsvRows`)."""
    return CsvRows(path)


def csv_column(row: list[str], k: int) -> int:
    """The 1-based character column where field ``k`` of an unquoted CSV ``row`` starts."""
    return sum(len(v) + 1 for v in row[:k]) + 1


def plain_csv(text: str, width: int, idx: list[int], id_col: int | None = None):
    """The rows of a plain comma-separated file's ``text`` (as :class:`ncadapt._io.CsvRows` read it,
    line ends LF) — the header on line 1, no quotes, no blank line, every row of ``width`` fields,
    every wanted field a number — parsed at once
    (numpy's C parser: a million rows in about a second): the columns ``idx`` as floats, the ids,
    the line numbers. None when the file is not that plain: the row-by-row reader reads it then,
    and locates what is wrong."""
    import numpy as np

    if '"' in text:
        return None
    body = text.split("\n")[1:]
    if body and body[-1] == "":
        body.pop()
    if not body or any(not ln.strip() or ln.count(",") != width - 1 for ln in body):
        return None
    try:
        a = np.loadtxt(body, delimiter=",", usecols=idx, dtype=float, ndmin=2, comments=None)
    except ValueError:
        return None
    ids = [ln.split(",")[id_col].strip() for ln in body] if id_col is not None else None
    return a, ids, np.arange(2, len(body) + 2)
