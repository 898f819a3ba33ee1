"""What every command shares: error reporting, exit codes, outputs, JSON and progress."""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import signal
import stat
import sys
import tempfile
import traceback
from pathlib import Path
from typing import TYPE_CHECKING

import click

from .. import dialects
from .._io import TMP_PREFIX, all_or_nothing, atomic_write, remove_temporaries, write_target
from ..constants import COORD_MAX
from ..errors import InputError, NcadaptError, RefusedError, cut

if TYPE_CHECKING:
    from rich.console import Console

#: Exit codes: success, refused by a safety check (nothing written), bad input or usage, internal error.
EXIT_OK, EXIT_REFUSED, EXIT_BAD_INPUT, EXIT_INTERNAL = 0, 1, 2, 3


@functools.cache
def err_console() -> Console:
    """The console of progress bars, on stderr (rich is imported when a bar may be shown)."""
    from rich.console import Console

    return Console(stderr=True, highlight=False)


#: Where summaries go: stdout, or stderr when stdout carries the JSON (``--json -``).
_state = {"summary_to_stderr": False}


#: The options many commands share.
json_option = click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the figures as JSON (- for standard output).",
)
seed_option = click.option(
    "--seed",
    type=click.IntRange(0, 2**63 - 1),
    default=1,
    show_default=True,
    help="Seed of the simulation's random numbers: the same seed gives the same run.",
)


def echo_err(msg: str) -> None:
    click.echo(msg, err=True)


def summary(msg: str = "") -> None:
    """A line of a command's human summary: on stdout (stderr when ``--json -`` writes there)."""
    echo_out(msg, err=_state["summary_to_stderr"])


def echo_out(msg: str, err: bool = False, nl: bool = True) -> None:
    """``click.echo``, except that a reader who went away (``ncadapt … | head``) ends the printing,
    not the command: the rest of what it prints is dropped, its files are still written."""
    try:
        click.echo(msg, err=err, nl=nl)
    except BrokenPipeError:
        stream = sys.stderr if err else sys.stdout
        with contextlib.suppress(OSError, ValueError):  # what is left goes nowhere, flushes included
            os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())


def debugging() -> bool:
    """``ncadapt --debug`` or NCADAPT_DEBUG=1: internal errors show their traceback."""
    if os.environ.get("NCADAPT_DEBUG", "") not in ("", "0"):
        return True
    ctx = click.get_current_context(silent=True)
    return bool(ctx is not None and ctx.find_root().meta.get("ncadapt.debug"))


def internal_error(e: BaseException, what: str) -> None:
    """Exit 3 with one line (or the traceback with --debug)."""
    if debugging():
        traceback.print_exception(e)
    msg = str(e).strip().splitlines()[0] if str(e).strip() else ""
    echo_err(
        f"error: internal error in {what}: {type(e).__name__}{': ' + msg[:200] if msg else ''}; "
        "this is a bug; rerun with --debug for the traceback"
    )
    sys.exit(EXIT_INTERNAL)


@contextlib.contextmanager
def about(path):
    """Problems a computation finds in the data of input ``path`` (a ``ValueError`` of a process
    function: too few rows, a constant column) are errors of that input."""
    try:
        yield
    except InputError:
        raise
    except ValueError as e:
        raise InputError(str(e), str(path)) from None


def _on_signal(signum, frame):  # noqa: ARG001 - a signal handler's signature
    # unwind (the open outputs are removed by all_or_nothing), then exit as the signal asks
    remove_temporaries()
    raise SystemExit(128 + signum)


#: The optional parts of ncadapt (pyproject's extras): the module a command imports when it needs
#: one, the extra that installs it and what it is for.
EXTRAS = {
    "OCP": ("cad", "OpenCASCADE (STEP and IGES files)"),
    "asyncua": ("opcua", "asyncua (OPC UA)"),
    "matplotlib": ("report", "matplotlib (reports and plots)"),
    "plotly": ("report", "plotly (the reports' interactive 3-D views)"),
}


def handle_errors(f=None, *, staged: bool = True):
    """Run a command with the documented exit codes: ncadapt's errors become compiler-style
    messages (exit 2 bad input, 1 refused), anything unexpected exit 3. Every file the command
    writes is written all or nothing: to temporary files renamed when the whole command succeeded
    (``staged=False``: each file on its own, for a command that reads back what it wrote)."""
    if f is None:
        return functools.partial(handle_errors, staged=staged)

    @functools.wraps(f)
    def wrapper(*args, **kwargs):
        _state["summary_to_stderr"] = False
        old = signal.getsignal(signal.SIGTERM)
        with contextlib.suppress(ValueError):  # not the main thread (tests)
            signal.signal(signal.SIGTERM, _on_signal)
        try:
            with all_or_nothing() if staged else contextlib.nullcontext():
                return f(*args, **kwargs)
        except InputError as e:
            if e.path:
                where = e.path + (f":{e.line}:{e.col or 1}" if e.line else "")
                echo_err(f"{where}: error: {e.message}")
            else:  # a value given on the command line
                echo_err(f"error: {e.message}")
            sys.exit(EXIT_BAD_INPUT)
        except RefusedError as e:
            echo_err(f"error: {e.message}")
            for d in e.details[:10]:
                echo_err("  " + _detail(d))
            sys.exit(EXIT_REFUSED)
        except NcadaptError as e:  # pragma: no cover - every error has a subclass above
            echo_err(f"error: {e}")
            sys.exit(EXIT_BAD_INPUT)
        except (
            click.exceptions.ClickException,
            click.exceptions.Exit,
            click.exceptions.Abort,
            SystemExit,
            KeyboardInterrupt,
        ):
            raise
        except ModuleNotFoundError as e:
            extra = EXTRAS.get((e.name or "").split(".")[0])
            if extra is None:
                raise
            echo_err(f"error: this needs {extra[1]}, an optional part of ncadapt: pip install 'ncadapt[{extra[0]}]'")
            sys.exit(EXIT_BAD_INPUT)
        except Exception as e:  # noqa: BLE001 - the contract: anything unexpected is exit 3
            ctx = click.get_current_context(silent=True)
            internal_error(e, " ".join(["ncadapt"] + (ctx.command_path.split()[1:] if ctx else [f.__name__])))
        finally:
            with contextlib.suppress(ValueError):
                signal.signal(signal.SIGTERM, old)

    return wrapper


def _detail(d) -> str:
    if isinstance(d, dict):
        if "construct" in d:
            return f"line {d['line']}:{d['col']}: {d['construct']}" + (
                f" ({d['blocks']} motion block(s))" if d.get("blocks") else ""
            )
        parts = [f"line {d['line']}"] if "line" in d else []
        if "position" in d:
            parts.append("at " + " ".join(f"{a}{v:.4f}" for a, v in zip("XYZ", d["position"])))
        if "displacement" in d:
            parts.append(
                "displacement " + " ".join(f"{a}{v:+.4f}" for a, v in zip(("dX", "dY", "dZ"), d["displacement"]))
            )
            parts.append(f"|d|={d['magnitude']:.4f} mm")
        return ", ".join(parts)
    return str(d)


class FiniteRange(click.FloatRange):
    """``click.FloatRange`` that also refuses NaN (which compares false with every bound) and
    infinities: every number option of ncadapt is a finite quantity."""

    name = "number"

    def convert(self, value, param, ctx):
        v = super().convert(value, param, ctx)
        if v != v:
            self.fail(f"{cut(value)} is not a number", param, ctx)
        if v in (float("inf"), float("-inf")):
            self.fail(f"{cut(value)} is not a finite number", param, ctx)
        return v


def comma_floats(value: str, n: int, what: str) -> list[float]:
    """``n`` comma-separated lengths of an option (within ±``COORD_MAX`` mm), or a click usage
    error saying ``what``."""
    try:
        parts = [float(v) for v in value.split(",")]
    except ValueError:
        parts = []
    if len(parts) != n:
        raise click.BadParameter(f"expected {what}, got {cut(value)}")
    if not all(math.isfinite(v) for v in parts):
        raise click.BadParameter(f"expected {what} (finite), got {cut(value)}")
    if any(abs(v) > COORD_MAX for v in parts):
        raise click.BadParameter(f"expected {what} within ±{COORD_MAX:g} mm, got {cut(value)}")
    return parts


def extent_value(ctx, param, value):  # noqa: ARG001 - a click callback's signature
    """A click callback: ``XMIN,XMAX,YMIN,YMAX`` in mm with XMIN < XMAX and YMIN < YMAX."""
    if value is None:
        return None
    v = comma_floats(value, 4, "XMIN,XMAX,YMIN,YMAX in mm")
    if v[0] >= v[1] or v[2] >= v[3]:
        raise click.BadParameter(f"expected XMIN < XMAX and YMIN < YMAX, got {value!r}")
    return tuple(v)


def _same(a: Path, b: Path) -> bool:
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)  # hard links, and paths the resolution cannot join
    except OSError:  # one of them does not exist yet
        return False


_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISSOCK, "a socket"),
)


def _check_output(name: str, path: Path) -> None:
    """An output must be a regular file (or not exist yet) in an existing folder ncadapt can
    write in; a symbolic link is followed (its target is replaced)."""
    target = write_target(path)
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise click.BadParameter(f"{cut(str(path))}: {e.strerror}", param_hint=f"'{name}'") from None
    if st is not None and not stat.S_ISREG(st.st_mode):
        kind = next((k for test, k in _KINDS if test(st.st_mode)), "not a regular file")
        raise click.BadParameter(
            f"{cut(str(path))} is {kind}; ncadapt writes regular files only", param_hint=f"'{name}'"
        )
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise click.BadParameter(
            f"{cut(str(path))}: the folder {cut(str(folder))} does not exist", param_hint=f"'{name}'"
        )
    try:  # what the command will do: a temporary file in the folder
        fd, probe = tempfile.mkstemp(prefix=TMP_PREFIX, dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise click.BadParameter(
            f"{cut(str(path))}: cannot write in {cut(str(folder))}: {e.strerror}", param_hint=f"'{name}'"
        ) from None


def check_outputs(inputs: dict, outputs: dict) -> None:
    """Refuse, before any work, an output that cannot be written as a regular file (a device, a
    FIFO, a folder, a missing or read-only folder), that would replace an input (an input error
    naming the output), or two outputs naming one file (usage errors). Both map a name shown to
    the user, such as ``"thickness map"`` or ``"--json"``, to a path or None (not given). ``-``
    as ``--json`` is standard output (the summary then goes to stderr); elsewhere it is refused."""
    outs = []
    for name, p in outputs.items():
        if p is None:
            continue
        if str(p) == "-":
            if name != "--json":
                raise click.BadParameter(
                    "'-' (standard output) is only for --json; name a file", param_hint=f"'{name}'"
                )
            _state["summary_to_stderr"] = True
            continue
        _check_output(name, Path(p))
        outs.append((name, Path(p)))
    ins = [(name, Path(p)) for name, p in inputs.items() if p is not None]
    for name, out in outs:
        for what, inp in ins:
            if _same(out, inp):
                raise InputError(f"refusing to overwrite the {what} with {name}; choose another output", str(out))
    for i, (a, pa) in enumerate(outs):
        for b, pb in outs[i + 1 :]:
            if _same(pa, pb):
                raise click.UsageError(f"{a} and {b} name the same file")


def write_json(path, payload: dict) -> None:
    """The JSON of a command, to a file (all or nothing) or to stdout (``-``)."""
    text = json.dumps(payload, indent=2, allow_nan=False) + "\n"
    if str(path) == "-":
        echo_out(text, nl=False)
    else:
        atomic_write(path, text.encode())


@contextlib.contextmanager
def progress(console: Console | None = None):
    """Progress on a terminal, quiet otherwise (a pipe, a file, a CI log).

    Yields ``say(message, done=None, total=None)``: with a total, a bar with the percentage and
    the time left; without, the message beside a spinner. The bar is removed when the work ends.
    """
    if console is None and not sys.stderr.isatty() and not os.environ.get("FORCE_TERMINAL"):
        # not a terminal (rich would say the same): no bar, and rich is not imported
        yield lambda msg, done=None, total=None: None
        return
    from rich.progress import BarColumn, Progress, SpinnerColumn, TaskProgressColumn, TextColumn, TimeRemainingColumn

    con = console or err_console()
    if not con.is_terminal:
        yield lambda msg, done=None, total=None: None
        return
    bar = Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TaskProgressColumn(),
        TimeRemainingColumn(),
        console=con,
        transient=True,
    )
    task = bar.add_task("", total=None)

    def say(msg, done=None, total=None):
        bar.update(task, description=msg, completed=done or 0, total=total)

    with bar:
        yield say


@contextlib.contextmanager
def progress_bar(description: str, total: int):
    """:func:`progress` with a fixed description and total; yields ``advance(done)``."""
    with progress() as say:
        say(description, 0, total)
        yield lambda done: say(description, done, total)


#: ``--subprograms`` of the commands that read an NC program.
subprograms_option = click.option(
    "--subprograms",
    "subprograms",
    multiple=True,
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    metavar="DIR",
    help="A folder of Sinumerik subprograms (NAME.SPF or _N_NAME_SPF), searched after the program's own folder, "
    "in the order given (repeatable): the machine's subprogram folder, copied. A call found in none is refused.",
)


#: ``--start-motion`` of the commands that read an NC program.
start_motion_option = click.option(
    "--start-motion",
    type=click.Choice(["G0", "G1"], case_sensitive=False),
    callback=lambda _ctx, _param, v: None if v is None else v.upper(),
    help="The motion mode the machine starts a Sinumerik program in (its machine data, "
    "$MC_GCODE_RESET_VALUES), for a program that moves before it writes G0, G1, G2, G3 or CIP. "
    "Without it such a move is refused: the program does not say whether it is a rapid or a cut.",
)


def sinumerik_only(d, subprograms, start_motion) -> None:
    """``--subprograms`` and ``--start-motion`` are for Sinumerik programs: given for another,
    they would be ignored."""
    for given, name in ((subprograms, "--subprograms"), (start_motion, "--start-motion")):
        if given and d.name != "sinumerik":
            raise click.UsageError(f"{name} is for Sinumerik programs; this program is read as {d.describe()}")


def expand_read(expand: bool, d) -> None:
    """``--expand`` flattens or runs the programs of LinuxCNC (mills and lathes), Fanuc and
    Sinumerik mills only."""
    if expand and (d.name not in ("linuxcnc", "fanuc", "sinumerik") or (d.lathe and d.name != "linuxcnc")):
        what = f"a lathe's ({d.describe_machine()})" if d.lathe else d.describe()
        raise click.UsageError(
            "--expand flattens the programs of LinuxCNC (mills and lathes), Fanuc and Sinumerik mills; "
            f"this program is read as {what}"
        )


def resolve_dialect(program, dialect: str, machine: str):
    """The program's dialect and machine (:func:`ncadapt.dialects.resolve`); a machine its
    dialect has none of is a usage error."""
    try:
        return dialects.resolve(program, dialect, machine)
    except InputError:
        raise
    except ValueError as e:
        raise click.UsageError(str(e)) from None


#: ``--machine`` of the commands that read an NC program.
machine_option = click.option(
    "--machine",
    type=click.Choice(dialects.MACHINES),
    default="auto",
    show_default=True,
    help="A mill's or a lathe's program; auto detects a lathe's (LinuxCNC: G7 or G8; Fanuc/Haas: a T word "
    "such as T0101 or T101, G28 U/W, G96, G50 S…, G70-G72 with P). On a lathe Y is 0 (the field's y there is not applied: "
    "refused above --chord-tol); a Fanuc lathe's X is a diameter and U, W its increments.",
)


#: ``--dialect`` of the commands that read an NC program.
dialect_option = click.option(
    "--dialect",
    type=click.Choice(dialects.CHOICES),
    default="auto",
    show_default=True,
    help="The program's controller dialect; auto detects it from the program's first 64 KB. Sinumerik programs "
    "are run into straight G-code and written back in their syntax; Heidenhain programs are refused, naming the "
    "line that shows the dialect.",
)
