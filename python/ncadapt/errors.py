"""The exception hierarchy of ncadapt.

Every error ncadapt raises on purpose derives from :class:`NcadaptError`. Errors in the input derive
from :class:`InputError`, which is also a :class:`ValueError`, and carry the file, line and column
where the input was wrong. A safety check that refuses to write raises :class:`RefusedError`.
"""

from __future__ import annotations

__all__ = ["NcadaptError", "InputError", "RefusedError", "cut"]

#: A message cuts an offending token to about this many characters.
TOKEN_CHARS = 80


def cut(token, n: int = TOKEN_CHARS) -> str:
    """``repr`` of an offending token for a message, cut to about ``n`` characters."""
    r = repr(token)
    return r if len(r) <= n else r[: n - 5] + "…" + r[-4:]


class NcadaptError(Exception):
    """Base of every ncadapt error."""


class InputError(NcadaptError, ValueError):
    """Wrong input, located by file, line and column (1-based; 0 when not known).

    ``str(err)`` is ``path:line:col: message`` so it can be printed as a compiler-style diagnostic.
    """

    def __init__(self, message: str, path: str | None = None, line: int = 0, col: int = 0):
        self.message = message
        self.path = path
        self.line = line
        self.col = col
        super().__init__(str(self))

    def __str__(self) -> str:
        where = self.path or "<input>"
        if self.line:
            where += f":{self.line}"
            if self.col:
                where += f":{self.col}"
        return f"{where}: {self.message}"


class RefusedError(NcadaptError):
    """A safety check refused to write anything.

    ``details`` holds the items that made it refuse (worst points, unsupported constructs).
    """

    def __init__(self, message: str, details: list | None = None):
        self.message = message
        self.details = list(details or [])
        super().__init__(message)
