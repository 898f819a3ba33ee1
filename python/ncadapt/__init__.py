"""ncadapt: correct CNC machining from measurements."""

from __future__ import annotations

from .errors import InputError, NcadaptError, RefusedError

__all__ = ["NcadaptError", "InputError", "RefusedError", "__version__"]
try:  # the Rust crates' version, which the build also gives the distribution
    from ._nc import __version__
except ImportError:  # a source tree without its extension built
    __version__ = "0+unknown"
