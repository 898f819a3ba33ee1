"""The ``ncadapt`` command: a thin click layer over the library.

Exit codes: 0 success, 1 refused by a safety check (nothing written), 2 bad input or usage.
"""

from __future__ import annotations

import click

from .. import __version__
from ._bore import bore
from ._correct import correct
from ._demo import demo
from ._freeform import analyze, compensate
from ._inspect import inspect
from ._skin import skin
from ._turning import turning
from ._waffle import waffle

__all__ = ["main"]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="ncadapt")
def main() -> None:
    """Correct CNC machining from measurements."""


main.add_command(correct)
main.add_command(inspect)
main.add_command(analyze)
main.add_command(compensate)
main.add_command(demo)
main.add_command(bore)
main.add_command(skin)
main.add_command(waffle)
main.add_command(turning)
