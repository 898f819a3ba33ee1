"""The ``ncadapt`` command: a thin click layer over the library.

Exit codes: 0 success, 1 refused by a safety check (nothing written), 2 bad input or usage (a
located message), 3 internal error (a bug: ``--debug`` shows the traceback).
"""

from __future__ import annotations

import importlib
import os

# numpy's OpenBLAS starts its threads on import and lets them spin for about 2**28 cycles (0.1 s of
# a core) before they sleep; the engine's own threads want that core. With the shortest timeout
# they sleep at once and still work in parallel for large products (set before numpy is imported;
# a value the user gave is kept).
os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")

import click  # noqa: E402

from .. import __version__  # noqa: E402
from ._common import EXIT_BAD_INPUT, internal_error  # noqa: E402

__all__ = ["main"]

# each command and the module that defines it: a command's module (and what it imports: numpy,
# OCP, scipy, asyncua) is imported only when that command runs, or when the help lists them all
_COMMANDS = {
    "correct": "_correct",
    "inspect": "_inspect",
    "analyze": "_freeform",
    "compensate": "_freeform",
    "demo": "_demo",
    "bore": "_bore",
    "skin": "_skin",
    "waffle": "_waffle",
    "turning": "_turning",
    "probe": "_probe",
}


class _Main(click.Group):
    """The command group: whatever escapes a command (an option's conversion included) that is
    not a usage error is an internal error, exit 3."""

    def list_commands(self, ctx):
        return sorted(_COMMANDS)

    def get_command(self, ctx, cmd_name):
        module = _COMMANDS.get(cmd_name)
        if module is None:
            return None
        return getattr(importlib.import_module(f".{module}", __name__), cmd_name)

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
