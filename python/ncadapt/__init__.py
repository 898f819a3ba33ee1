"""ncadapt: correct CNC machining from measurements."""

from __future__ import annotations

from .errors import InputError, NcadaptError, RefusedError

__all__ = ["NcadaptError", "InputError", "RefusedError", "__version__"]
from importlib.metadata import PackageNotFoundError, version as _version

try:  # the installed distribution's version, which the build takes from the Rust crates
    __version__ = _version("ncadapt")
except PackageNotFoundError:  # a source tree on sys.path, not installed
    __version__ = "0+unknown"
