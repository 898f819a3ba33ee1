"""Reading text inputs with located errors; writing files safely: to a temporary file beside the
target, then an atomic rename."""

from __future__ import annotations

import contextlib
import csv
import io
import os
import tempfile
from pathlib import Path

from .errors import InputError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """A temporary path beside ``path`` (same suffix) for a writer that wants a file name; it
    replaces ``path`` only when the block ends without an error, else it is removed and the
    target is left as it was. The result gets the mode any new file would get."""
    p = Path(path)
    d = p.parent if str(p.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{p.stem}.", suffix=p.suffix or ".tmp", dir=d)
    os.close(fd)
    try:
        yield tmp
        # mkstemp makes the file private
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


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
        bad = data[e.start:e.start + 1].hex()
        raise InputError(f"not UTF-8 text: byte 0x{bad} ({e.reason}); save the file as UTF-8", str(p), line, col) \
            from None


def csv_reader(path: str | os.PathLike):
    """A :func:`csv.reader` over an input file read by :func:`read_text` (its ``line_num`` is the
    file's line)."""
    return csv.reader(io.StringIO(read_text(path), newline=""))


def csv_column(row: list[str], k: int) -> int:
    """The 1-based character column where field ``k`` of an unquoted CSV ``row`` starts."""
    return sum(len(v) + 1 for v in row[:k]) + 1
