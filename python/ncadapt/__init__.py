"""ncadapt: correct CNC machining from measurements."""

from __future__ import annotations

from .errors import InputError, NcadaptError, RefusedError

__all__ = ["NcadaptError", "InputError", "RefusedError", "__version__"]
__version__ = "0.1.0"
