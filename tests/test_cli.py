"""The ncadapt command: exit codes, messages and JSON, through click's CliRunner."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from ncadapt.cli import main


@pytest.fixture
def plate(tmp_path, examples):
    for name in ("plate.ngc", "plate_probe.csv"):
        shutil.copy(examples / "nc" / name, tmp_path / name)
    return tmp_path


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def test_correct_writes_program_and_json(plate):
    r = run(
        "correct",
        plate / "plate.ngc",
        "--field",
        plate / "plate_probe.csv",
        "-o",
        plate / "out.ngc",
        "--json",
        plate / "out.json",
    )
    assert r.exit_code == 0, r.output
    d = json.loads((plate / "out.json").read_text())
    for key in ("lines_in", "lines_out", "blocks_changed", "max_displacement", "mean_displacement"):
        assert key in d
    assert d["lines_in"] == 34 and d["lines_out"] == d["lines_in"] + d["lines_added"]
    assert 0 < d["mean_displacement"] <= d["max_displacement"] <= 0.03
    assert "blocks changed" in r.stdout
    assert (plate / "out.ngc").read_text().count("\n") == d["lines_out"]


def test_shift_and_exit_codes(plate):
    r = run("correct", plate / "plate.ngc", "--shift", "0,0,0.8", "-o", plate / "o.ngc")
    assert r.exit_code == 1
    assert "exceeds the limit 0.5 mm; nothing written" in r.stderr
    assert not (plate / "o.ngc").exists()
    r = run("correct", plate / "plate.ngc", "--shift", "0,0,0.01", "-o", plate / "plate.ngc")
    assert r.exit_code == 2
    assert r.stderr.startswith(f"{plate / 'plate.ngc'}: error: refusing to overwrite the input program")
    r = run("correct", plate / "plate.ngc", "-o", plate / "o.ngc")
    assert r.exit_code == 2 and "exactly one of --field FILE or --shift" in r.stderr
    r = run("correct", plate / "plate.ngc", "--shift", "1,2", "-o", plate / "o.ngc")
    assert r.exit_code == 2 and "expected DX,DY,DZ" in r.stderr


def test_parse_error_is_path_line_col(tmp_path):
    p = tmp_path / "bad.ngc"
    p.write_text("G0 X0\nG1 Y\n")
    r = run("correct", p, "--shift", "0,0,0", "-o", tmp_path / "o.ngc")
    assert r.exit_code == 2
    assert r.stderr == f"{p}:2:5: error: expected a number after 'Y'\n"


def test_refused_construct_then_kept(tmp_path):
    p = tmp_path / "c.ngc"
    p.write_text("G0 X0 Y0 Z5\nG41 D1 G1 X5 F100\nG40 G1 X10\n")
    r = run("correct", p, "--shift", "0,0,0.01", "-o", tmp_path / "o.ngc")
    assert (
        r.exit_code == 1
        and "line 2:1: cutter compensation G41 with tool 1: its diameter is not known; give the tool table (--tool-table) (2 motion block(s))"
        in r.stderr
    )
    r = run("correct", p, "--shift", "0,0,0.01", "-o", tmp_path / "o.ngc", "--keep-unsupported")
    assert r.exit_code == 0 and "unsupported constructs kept unchanged (1)" in r.stdout


def test_outside_field_option(plate):
    f = plate / "small.csv"
    f.write_text("x,y,dz\n0,0,0\n10,0,0\n0,10,0\n10,10,0.01\n")
    r = run("correct", plate / "plate.ngc", "--field", f, "-o", plate / "o.ngc")
    assert r.exit_code == 1 and "outside the field's domain" in r.stderr
    r = run("correct", plate / "plate.ngc", "--field", f, "-o", plate / "o.ngc", "--outside", "clamp")
    assert r.exit_code == 0


def test_inspect_json(tmp_path, plate):
    r = run("inspect", plate / "plate.ngc", "--json", tmp_path / "i.json")
    assert r.exit_code == 0
    d = json.loads((tmp_path / "i.json").read_text())
    assert d["units"] == "mm" and d["lines"] == 34
    assert d["motions"] == {
        "rapid": 4,
        "feed": 15,
        "arc_cw": 0,
        "arc_ccw": 4,
        "other": 0,
        "spline": 0,
        "spline_quadratic": 0,
    }
    assert d["extents"]["feed"]["x"] == [-6.0, 66.0]
    assert d["unsupported"] == []
    assert d["notes"][0]["line"] == 32
    p = tmp_path / "u.ngc"
    p.write_text("G0 X0 Y0 Z0\nG88 X1 Y1 Z-3 R1 P1 F50\nX2\nG80\n")
    r = run("inspect", p, "--json", tmp_path / "u.json")
    d = json.loads((tmp_path / "u.json").read_text())
    assert d["unsupported"] == [{"line": 2, "col": 1, "construct": G88_REFUSED, "blocks": 2}]


G88_REFUSED = "canned cycle G88 (the operator retracts by hand: the position after it is unknown)"


def test_plate_example(tmp_path):
    """The README's `correct` example on the files in examples/nc."""
    ex = Path(__file__).resolve().parents[1] / "examples" / "nc"
    r = run("correct", ex / "plate.ngc", "--field", ex / "plate_probe.csv", "-o", tmp_path / "c.ngc")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "c.ngc").read_text() != (ex / "plate.ngc").read_text()


_EX = {
    "nc": ("plate.ngc", "plate_probe.csv"),
    "skin": ("pocket1_finish.ngc", "pocket1_thickness.csv"),
    "waffle": ("cell_r1c1.ngc", "tracking.csv", "thickness_r1c1.csv", "backlash_signals.csv"),
    "turning": ("shaft_d20_l430.toml",),
}

# every command with an input file: (arguments, the input given again as an output, what the message calls it)
_GUARDED = [
    (("correct", "plate.ngc", "--shift", "0,0,0.01", "-o", "o.ngc", "--json"), "plate_probe.csv", None),
    (("correct", "plate.ngc", "--field", "plate_probe.csv", "-o", "o.ngc", "--json"), "plate_probe.csv", "field file"),
    (("inspect", "plate.ngc", "--json"), "plate.ngc", "program"),
    (("analyze", "plate_probe.csv", "--report"), "plate_probe.csv", "measurements"),
    (
        ("compensate", "plate_probe.csv", "--program", "plate.ngc", "-o", "o.ngc", "--points-out"),
        "plate.ngc",
        "input program",
    ),
    (
        (
            "skin",
            "correct",
            "pocket1_finish.ngc",
            "--thickness",
            "pocket1_thickness.csv",
            "--target",
            "1.5",
            "-o",
            "o.ngc",
            "--json",
        ),
        "pocket1_thickness.csv",
        "thickness map",
    ),
    (
        ("waffle", "tilt", "--tracking", "tracking.csv", "--tool-radius", "5", "--diameter", "2000", "--json"),
        "tracking.csv",
        "tracking log",
    ),
    (
        (
            "waffle",
            "correct",
            "cell_r1c1.ngc",
            "--tracking",
            "tracking.csv",
            "--tool-radius",
            "5",
            "--diameter",
            "2000",
            "--thickness",
            "thickness_r1c1.csv",
            "--target",
            "2",
            "-o",
            "o.ngc",
            "--json",
        ),
        "thickness_r1c1.csv",
        "thickness map",
    ),
    (("waffle", "backlash", "--signals", "backlash_signals.csv", "--json"), "backlash_signals.csv", "signals"),
    (("turning", "plan", "shaft_d20_l430.toml", "--report"), "shaft_d20_l430.toml", "configuration"),
    (
        (
            "bore",
            "plan",
            "--diameter",
            "40",
            "--t0",
            "0.5",
            "--allowance",
            "0.1",
            "--measured",
            "plate_probe.csv",
            "--json",
        ),
        "plate_probe.csv",
        "probe file",
    ),
    (("turning", "simulate", "shaft_d20_l430.toml", "plate.ngc", "--json"), "plate.ngc", "program"),
]


@pytest.fixture
def inputs(tmp_path, examples):
    for sub, names in _EX.items():
        for name in names:
            shutil.copy(examples / sub / name, tmp_path / name)
    return tmp_path


@pytest.mark.parametrize("args,victim,what", _GUARDED, ids=lambda v: "-".join(v[:2]) if isinstance(v, tuple) else None)
def test_no_output_replaces_an_input(inputs, monkeypatch, args, victim, what):
    monkeypatch.chdir(inputs)
    before = {p.name: p.read_bytes() for p in inputs.iterdir()}
    r = run(*args, victim)
    if what is None:  # the field file is not an input of a --shift correction: the JSON may go there
        assert r.exit_code == 0, r.output
        assert json.loads((inputs / victim).read_text())["lines_in"] == 34
        return
    assert r.exit_code == 2, r.output
    assert r.stderr.startswith(f"{victim}: error: refusing to overwrite the {what} with "), r.stderr
    assert {p.name: p.read_bytes() for p in inputs.iterdir()} == before  # nothing written, nothing changed


def test_a_hard_link_to_an_input_is_the_input(inputs):
    (inputs / "link.csv").hardlink_to(inputs / "tracking.csv")
    r = run(
        "waffle",
        "tilt",
        "--tracking",
        inputs / "tracking.csv",
        "--tool-radius",
        5,
        "--diameter",
        2000,
        "--json",
        inputs / "link.csv",
    )
    assert r.exit_code == 2 and "refusing to overwrite the tracking log with --json" in r.stderr
    assert (
        (inputs / "link.csv").read_bytes()
        == (inputs / "tracking.csv").read_bytes()
        == (Path(__file__).parent.parent / "examples" / "waffle" / "tracking.csv").read_bytes()
    )


def test_two_outputs_naming_one_file_is_a_usage_error(tmp_path):
    r = run(
        "skin", "simulate", "--protocol", "--method", "mirror", "--json", tmp_path / "r", "--report", tmp_path / "r"
    )
    assert r.exit_code == 2 and "--json and --report name the same file" in r.stderr
    assert list(tmp_path.iterdir()) == []


# every kind of text input, with one byte that is not UTF-8 (Latin-1 'é') at a known line and column
_NOT_UTF8 = [
    (
        "map.csv",
        b"x,y,thickness\n0,0,1.6\n10,0,1.5\n0,10,1.\xe95\n",
        ("skin", "correct", "pocket1_finish.ngc", "--thickness", "map.csv", "--target", "1.5", "-o", "o.ngc"),
        (4, 8),
    ),
    ("m.csv", b"x,y,z,i,j,k,dev\n0,0,0,0,0,1,0.01 \xe9\n", ("analyze", "m.csv"), (2, 18)),
    (
        "t.csv",
        b"B,Z,V\n\xe90,0,1\n",
        ("waffle", "tilt", "--tracking", "t.csv", "--tool-radius", "5", "--diameter", "2000"),
        (2, 1),
    ),
    ("c.toml", b"# r\xe9glage\n", ("turning", "plan", "c.toml"), (1, 4)),
    (
        "p.csv",
        b"plane,x,y,z\nA,1,0,5\xe9\n",
        ("bore", "plan", "--diameter", "40", "--t0", "0.5", "--allowance", "0.1", "--measured", "p.csv"),
        (2, 8),
    ),
]


@pytest.mark.parametrize("name,data,args,where", _NOT_UTF8, ids=[c[0] for c in _NOT_UTF8])
def test_an_input_that_is_not_utf8_is_located(inputs, monkeypatch, name, data, args, where):
    monkeypatch.chdir(inputs)
    (inputs / name).write_bytes(data)
    r = run(*args)
    assert r.exit_code == 2, r.output
    assert (
        r.stderr == f"{name}:{where[0]}:{where[1]}: error: not UTF-8 text: byte 0xe9 (invalid continuation byte); "
        "save the file as UTF-8\n"
    )


@pytest.mark.parametrize(
    "option, value",
    [("--chord-tol", "nan"), ("--chord-tol", "1e-300"), ("--max-segment", "1e-9"), ("--max-segment", "nan")],
)
def test_sampling_options_out_of_range_are_usage_errors(tmp_path, option, value):
    src = tmp_path / "p.ngc"
    src.write_text("G21 G0 X0 Y0 Z0\nG1 X1 F100\nM2\n")
    r = run("correct", src, "--shift", "0,0,0.01", option, value, "-o", tmp_path / "out.ngc")
    assert r.exit_code == 2 and f"Invalid value for '{option}'" in r.output
    assert not (tmp_path / "out.ngc").exists()
