"""What every command shares: error reporting, exit codes, JSON output and progress."""

from __future__ import annotations

import contextlib
import functools
import json
import os
import sys
from pathlib import Path

import click
from rich.console import Console

from .._io import atomic_write
from ..errors import InputError, NcadaptError, RefusedError

#: Exit codes.
EXIT_OK, EXIT_REFUSED, EXIT_BAD_INPUT = 0, 1, 2

err_console = Console(stderr=True, highlight=False)


def echo_err(msg: str) -> None:
    click.echo(msg, err=True)


def handle_errors(f):
    """Turn ncadapt errors into compiler-style messages and the documented exit codes."""

    @functools.wraps(f)
    def wrapper(*args, **kwargs):
        try:
            return f(*args, **kwargs)
        except InputError as e:
            where = e.path or "<input>"
            if e.line:
                where += f":{e.line}:{e.col or 1}"
            echo_err(f"{where}: error: {e.message}")
            sys.exit(EXIT_BAD_INPUT)
        except RefusedError as e:
            echo_err(f"error: {e.message}")
            for d in e.details[:10]:
                echo_err("  " + _detail(d))
            sys.exit(EXIT_REFUSED)
        except NcadaptError as e:  # pragma: no cover - every error has a subclass above
            echo_err(f"error: {e}")
            sys.exit(EXIT_BAD_INPUT)

    return wrapper


def _detail(d) -> str:
    if isinstance(d, dict):
        if "construct" in d:
            return f"line {d['line']}:{d['col']}: {d['construct']}" + (
                f" ({d['blocks']} motion block(s))" if d.get("blocks") else "")
        parts = [f"line {d['line']}"] if "line" in d else []
        if "position" in d:
            parts.append("at " + " ".join(f"{a}{v:.4f}" for a, v in zip("XYZ", d["position"])))
        if "displacement" in d:
            parts.append("displacement " + " ".join(f"{a}{v:+.4f}" for a, v in zip(("dX", "dY", "dZ"), d["displacement"])))
            parts.append(f"|d|={d['magnitude']:.4f} mm")
        return ", ".join(parts)
    return str(d)


class FiniteRange(click.FloatRange):
    """``click.FloatRange`` that also refuses NaN (which compares false with every bound)."""

    def convert(self, value, param, ctx):
        v = super().convert(value, param, ctx)
        if v != v:
            self.fail(f"{value!r} is not a number", param, ctx)
        return v


def comma_floats(value: str, n: int, what: str) -> list[float]:
    """``n`` comma-separated numbers of an option, or a click usage error saying ``what``."""
    try:
        parts = [float(v) for v in value.split(",")]
    except ValueError:
        parts = []
    if len(parts) != n:
        raise click.BadParameter(f"expected {what}, got {value!r}")
    return parts


def _same(a: Path, b: Path) -> bool:
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)  # hard links, and paths the resolution cannot join
    except OSError:  # one of them does not exist yet
        return False


def check_outputs(inputs: dict, outputs: dict) -> None:
    """Refuse, before any work, an output that would replace an input (an input error naming the
    output) or two outputs naming one file (a usage error). Both map a name shown to the user, such
    as ``"thickness map"`` or ``"--json"``, to a path or None (not given)."""
    outs = [(name, Path(p)) for name, p in outputs.items() if p is not None]
    ins = [(name, Path(p)) for name, p in inputs.items() if p is not None]
    for name, out in outs:
        for what, inp in ins:
            if _same(out, inp):
                raise InputError(f"refusing to overwrite the {what} with {name}; choose another output", str(out))
    for i, (a, pa) in enumerate(outs):
        for b, pb in outs[i + 1:]:
            if _same(pa, pb):
                raise click.UsageError(f"{a} and {b} name the same file")


def write_json(path, payload: dict) -> None:
    atomic_write(path, (json.dumps(payload, indent=2, allow_nan=False) + "\n").encode())


@contextlib.contextmanager
def progress():
    """A status line on a terminal (quiet otherwise); yields a function taking a message."""
    if err_console.is_terminal:
        with err_console.status("") as status:
            yield lambda msg: status.update(msg)
    else:
        yield lambda msg: None
