"""The ``ncadapt`` command: a thin click layer over the library.

Exit codes: 0 success, 1 refused by a safety check (nothing written), 2 bad input or usage (a
located message), 3 internal error (a bug: ``--debug`` shows the traceback).
"""

from __future__ import annotations

import click

from .. import __version__
from ._bore import bore
from ._common import EXIT_BAD_INPUT, internal_error
from ._correct import correct
from ._demo import demo
from ._freeform import analyze, compensate
from ._inspect import inspect
from ._probe import probe
from ._skin import skin
from ._turning import turning
from ._waffle import waffle

__all__ = ["main"]


class _Main(click.Group):
    """The command group: whatever escapes a command (an option's conversion included) that is
    not a usage error is an internal error, exit 3."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except click.exceptions.ClickException as e:
            if e.exit_code == 1:  # click's own errors (a file it could not open): bad input
                e.exit_code = EXIT_BAD_INPUT
            raise
        except (click.exceptions.Exit, click.exceptions.Abort, SystemExit, KeyboardInterrupt):
            raise
        except Exception as e:  # noqa: BLE001 - the contract: anything unexpected is exit 3
            sub = ctx.invoked_subcommand
            internal_error(e, f"ncadapt {sub}" if sub else "ncadapt")


@click.group(
    cls=_Main,
    context_settings={"help_option_names": ["-h", "--help"]},
    epilog="Exit codes: 0 success; 1 refused by a safety check, nothing written; 2 bad input or "
    "usage, located (path:line:col or --option); 3 internal error, a bug (rerun with --debug "
    "for the traceback).",
)
@click.version_option(__version__, prog_name="ncadapt")
@click.option("--debug", is_flag=True, help="Show the traceback of an internal error (also NCADAPT_DEBUG=1).")
@click.pass_context
def main(ctx, debug) -> None:
    """Correct CNC machining from measurements."""
    ctx.meta["ncadapt.debug"] = debug


main.add_command(correct)
main.add_command(inspect)
main.add_command(analyze)
main.add_command(compensate)
main.add_command(demo)
main.add_command(bore)
main.add_command(skin)
main.add_command(waffle)
main.add_command(turning)
main.add_command(probe)
