"""The command's contract on outputs and exit codes: every output is checked before any work,
written all or nothing (temporary files renamed when the whole command succeeded, removed on a
failure or a signal), and anything unexpected is exit 3 with one line."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from ncadapt.cli import main

PROGRAM = "G21 G90\nG0 X0 Y0 Z1\nG1 Z-1 F100\nG1 X10 Y5\nG1 X20 Y0\nG0 Z5\nM30\n"


def run(*args, env=None):
    return CliRunner(env=env).invoke(main, [str(a) for a in args])


def temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".ncadapt-tmp-"))


@pytest.fixture
def prog(tmp_path):
    p = tmp_path / "in.ngc"
    p.write_text(PROGRAM)
    return p


def correct(prog, out, *extra):
    return run("correct", prog, "--shift", "0,0,0.01", "-o", out, *extra)


# ------------------------------------------------------------------ outputs checked before any work
def test_a_character_device_is_not_replaced(prog, tmp_path):
    dev = tmp_path / "null"
    try:
        os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("making a device node needs root")
    r = correct(prog, dev)
    assert r.exit_code == 2, r.output
    assert "is a character device; ncadapt writes regular files only" in r.stderr
    assert stat.S_ISCHR(os.stat(dev).st_mode)


def test_a_fifo_is_refused(prog, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    r = correct(prog, fifo)
    assert r.exit_code == 2 and "is a FIFO" in r.stderr, r.output
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_a_folder_is_refused(prog, tmp_path):
    r = run("correct", prog, "--shift", "0,0,0.01", "-o", "x.ngc", "--json", tmp_path)
    assert r.exit_code == 2, r.output


def test_a_missing_folder_is_refused_before_any_output_is_written(prog, tmp_path):
    out = tmp_path / "out.ngc"
    r = correct(prog, out, "--json", tmp_path / "nodir" / "x.json")
    assert r.exit_code == 2 and "does not exist" in r.stderr, r.output
    assert not out.exists() and temporaries(tmp_path) == []


def test_a_folder_that_cannot_be_written_is_refused(prog, tmp_path):
    if os.geteuid() == 0:
        folder = Path("/proc")  # root writes everywhere but in the kernel's folders
    else:
        folder = tmp_path / "ro"
        folder.mkdir()
        folder.chmod(0o555)
    r = correct(prog, folder / "out.ngc")
    assert r.exit_code == 2 and "cannot write in" in r.stderr, r.output


def test_dash_is_standard_output_for_json_only(prog, tmp_path):
    r = correct(prog, tmp_path / "out.ngc", "--json", "-")
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["output"] == str(tmp_path / "out.ngc") and d["lines_in"] == 7
    assert "blocks changed" in r.stderr  # the summary moves to stderr
    assert not (Path.cwd() / "-").exists()
    r = run("analyze", tmp_path / "none.csv", "--report", "-")
    assert r.exit_code == 2
    r = correct(prog, "-")
    assert r.exit_code == 2 and "only for --json" in r.stderr


# ------------------------------------------------------------------ all or nothing
def test_a_late_failure_leaves_every_output_as_it_was(prog, tmp_path, monkeypatch):
    out, js = tmp_path / "out.ngc", tmp_path / "out.json"
    out.write_text("previous\n")
    import ncadapt.cli._correct as cc

    def fail(path, payload):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(cc, "write_json", fail)
    r = correct(prog, out, "--json", js)
    assert r.exit_code == 3, r.output
    assert out.read_text() == "previous\n" and not js.exists()
    assert temporaries(tmp_path) == []


def test_an_existing_output_keeps_its_mode_and_a_link_its_target(prog, tmp_path):
    out = tmp_path / "out.ngc"
    out.write_text("previous\n")
    out.chmod(0o640)
    assert correct(prog, out).exit_code == 0
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o640 and "Z-0.99" in out.read_text()
    target, link = tmp_path / "target.ngc", tmp_path / "link.ngc"
    target.write_text("previous\n")
    link.symlink_to(target)
    assert correct(prog, link).exit_code == 0
    assert link.is_symlink() and "Z-0.99" in target.read_text()


def test_sigterm_mid_write_leaves_no_file(tmp_path):
    big = tmp_path / "big.ngc"
    body = "".join(f"G1 X{i % 100}.5 Y{(i * 7) % 100}.25 Z-1\n" for i in range(200_000))
    big.write_text("G21 G90 G0 X0 Y0 Z1\nG1 Z-1 F100\n" + body * 5 + "M30\n")
    out = tmp_path / "out.ngc"
    exe = Path(sys.executable).with_name("ncadapt")
    proc = subprocess.Popen(
        [str(exe), "correct", str(big), "--shift", "0,0,0.01", "--max-segment", "0.01", "-o", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    t0 = time.monotonic()
    while not temporaries(tmp_path) and proc.poll() is None and time.monotonic() - t0 < 30:
        time.sleep(0.01)
    assert proc.poll() is None, "the correction ended before it could be stopped"
    time.sleep(0.3)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert temporaries(tmp_path) == [] and not out.exists()


# ------------------------------------------------------------------ exit codes
def test_an_internal_error_is_exit_3_in_one_line(prog, tmp_path, monkeypatch):
    import ncadapt.nc as ncmod

    def boom(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(ncmod, "correct_file", boom)
    r = correct(prog, tmp_path / "out.ngc")
    assert r.exit_code == 3
    assert r.stderr == (
        "error: internal error in ncadapt correct: RuntimeError: boom; this is a bug; "
        "rerun with --debug for the traceback\n"
    )
    r = run("--debug", "correct", prog, "--shift", "0,0,0.01", "-o", tmp_path / "out.ngc")
    assert r.exit_code == 3 and "Traceback" in r.stderr and "RuntimeError: boom" in r.stderr
    r = run("correct", prog, "--shift", "0,0,0.01", "-o", tmp_path / "out.ngc", env={"NCADAPT_DEBUG": "1"})
    assert r.exit_code == 3 and "Traceback" in r.stderr
    assert not (tmp_path / "out.ngc").exists() and temporaries(tmp_path) == []


def test_the_exit_codes_are_in_the_help():
    r = run("--help")
    assert "Exit codes: 0 success; 1 refused" in " ".join(r.stdout.split()) and "3 internal error" in r.stdout


# ------------------------------------------------------------------ options
def _options():
    import click

    def walk(cmd, path):
        if isinstance(cmd, click.Group):
            for name, sub in cmd.commands.items():
                yield from walk(sub, path + [name])
        else:
            for p in cmd.params:
                if isinstance(p, click.Option) and p.name != "help":
                    yield " ".join(path), p

    return list(walk(main, []))


def test_every_option_has_help_and_numbers_are_finite_and_bounded():
    import click

    from ncadapt.cli._common import FiniteRange

    missing = [f"{c} {p.opts[0]}" for c, p in _options() if not p.help]
    assert missing == []
    loose = [
        f"{c} {p.opts[0]}"
        for c, p in _options()
        if type(p.type) in (click.types.FloatParamType, click.types.IntParamType, click.FloatRange)
    ]
    assert loose == [], "number options without bounds or a finiteness check"
    for _c, p in _options():
        if isinstance(p.type, FiniteRange):
            for bad in ("nan", "inf", "-inf"):
                with pytest.raises(click.BadParameter):
                    p.type.convert(bad, p, None)


@pytest.mark.parametrize("value", ["nan", "inf", "-1"])
def test_a_bad_number_is_a_usage_error_naming_the_option(prog, tmp_path, value):
    r = run("correct", prog, "--shift", "0,0,0.01", "--limit", value, "-o", tmp_path / "o.ngc")
    assert r.exit_code == 2 and "--limit" in r.stderr, r.output


def test_a_non_finite_shift_is_a_usage_error(prog, tmp_path):
    r = run("correct", prog, "--shift", "0,0,nan", "-o", tmp_path / "o.ngc")
    assert r.exit_code == 2 and "--shift" in r.stderr and "finite" in r.stderr, r.output


def test_a_shift_beyond_any_machine_is_a_usage_error(prog, tmp_path):
    r = run("correct", prog, "--shift", "6e106,0,0", "-o", tmp_path / "o.ngc")
    assert r.exit_code == 2 and "--shift" in r.stderr and "within ±1e+06 mm" in r.stderr, r.output
    assert not (tmp_path / "o.ngc").exists()


def test_a_reader_that_goes_away_ends_the_printing_not_the_command(tmp_path, prog):
    # `ncadapt correct … | head -1`: the pipe closes after the first line; the command still writes
    # its output and exits 0, without an internal error
    exe = Path(sys.executable).with_name("ncadapt")
    out = tmp_path / "o.ngc"
    proc = subprocess.Popen(
        [str(exe), "correct", str(prog), "--shift", "0,0,0.01", "-o", str(out), "--json", "-"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.readline()
    proc.stdout.close()
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 0 and "internal error" not in err, err
    assert out.stat().st_size > 0


@pytest.mark.parametrize(
    "module, args, extra",
    [
        ("OCP", ["compensate", "{m}", "--surface", "{tmp}/s.step"], "cad"),
        ("matplotlib", ["analyze", "{m}", "--report", "{tmp}/r.html"], "report"),
    ],
)
def test_a_missing_optional_part_is_named_with_its_extra(tmp_path, monkeypatch, module, args, extra):
    import sys as _sys

    from click.testing import CliRunner

    from ncadapt.cli import main

    m = tmp_path / "m.csv"
    m.write_text(
        "x,y,z,i,j,k,dev\n"
        + "".join(f"{x},{y},0,0,0,1,{0.01 + 0.0003 * x:.5f}\n" for x in range(0, 50, 5) for y in range(0, 50, 5))
    )
    for name in [n for n in _sys.modules if n == module or n.startswith(module + ".")]:
        monkeypatch.delitem(_sys.modules, name)
    monkeypatch.setitem(_sys.modules, module, None)  # import raises ModuleNotFoundError
    r = CliRunner().invoke(main, [a.format(m=m, tmp=tmp_path) for a in args])
    assert r.exit_code == 2 and f"pip install 'ncadapt[{extra}]'" in r.output, r.output
    assert not any(tmp_path.glob("[sr].*"))
