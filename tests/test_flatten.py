"""Flattening RS274NGC programs (parameters, expressions, O-word flow) into straight G-code.

The truth is LinuxCNC's interpreter: rs274 runs the original program and the flattened one, and
their canonical motion must be the same move for move (to rs274's printed resolution). The rules
the evaluation follows are also checked one by one against their closed forms.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import rs274
from helpers import refused_at
from ncadapt import flatten as fl
from ncadapt import nc
from ncadapt.cli import main
from ncadapt.errors import InputError, RefusedError

NC_FILES = Path("/usr/share/linuxcnc/ncfiles")
CORPUS = Path(__file__).resolve().parents[1].parent / "shared" / "corpus" / "nc"
needs_rs274 = pytest.mark.skipif(rs274.RS274 is None, reason="LinuxCNC rs274 not installed")


def run(text: str) -> list[str]:
    return fl.flatten(text.encode()).data.decode().splitlines()


def value(expr: str) -> float:
    (line,) = run(f"#1 = {expr}\nG0 X#1\n")
    return float(line.split("X")[1])


@pytest.mark.parametrize(
    ("expr", "want"),
    [
        ("[2 + 3 * 4 ** 2]", 50.0),  # ** before * before +
        ("[2 ** 3 ** 2]", 64.0),  # left to right
        ("[10 - 4 - 3]", 3.0),
        ("[-7 MOD 3]", 2.0),  # from 0 up to the divisor
        ("[7 MOD -3]", 1.0),
        ("[1 EQ 1.00005]", 1.0),  # within 0.0001
        ("[1 EQ 1.0002]", 0.0),
        ("[1 NE 1.00005]", 0.0),
        ("[2 GT 1 AND 0]", 0.0),  # comparisons before logic
        ("[0 OR 3 XOR 1]", 0.0),
        ("ROUND[2.5]", 3.0),
        ("ROUND[-2.5]", -3.0),  # halves away from zero
        ("FIX[-2.5]", -3.0),
        ("FUP[-2.5]", -2.0),
        ("ATAN[1]/[-1]", 135.0),  # degrees, by quadrant
        ("SIN[30]", 0.5),
        ("ACOS[0]", 90.0),
        ("SQRT[2]", round(math.sqrt(2), 6)),
        ("[ABS[-3] + EXP[0]]", 4.0),
        ("[LN[EXP[2]]]", 2.0),
        ("-[2]", -2.0),
    ],
)
def test_expressions(expr, want):
    assert value(expr) == pytest.approx(want, abs=1e-6)


def test_parameters_set_on_a_line_take_effect_after_it():
    # LinuxCNC: the line's other words, and the settings on it, see the values before the line
    assert run("#1 = 5\n#1 = 7 #2 = #1 G0 X#1\nG0 Y#2\n") == ["G0 X5", "G0 Y5"]
    assert run("#<a> = 2\n#<_g> = [#<a> * 3]\nG0 X#<_g>\n") == ["G0 X6"]
    assert run("#3 = 2\n#2 = 9\nG0 X##3\n") == ["G0 X9"]  # indirection


def test_subroutines_arguments_locals_and_return_values():
    prog = """o<area> sub
#<r> = #1
o<area> return [#<r> * #<r> * 3]
o<area> endsub
#1 = 11
#<r> = 99
o<area> call [2]
G0 X#<_value> Y#1 Z#<r>
M2
"""
    # the call's #1 and named locals are its own; the caller's come back
    assert run(prog) == ["G0 X12 Y11 Z99", "M2"]


def test_recursion_and_flow():
    prog = """o<fact> sub
o1 if [#1 LE 1]
o<fact> return [1]
o1 endif
o<fact> call [#1 - 1]
o<fact> return [#1 * #<_value>]
o<fact> endsub
o<fact> call [5]
G0 X#<_value>
#1 = 0
o2 while [#1 LT 10]
#1 = [#1 + 1]
o3 if [[#1 MOD 2] EQ 0]
o2 continue
o3 elseif [#1 GT 6]
o2 break
o3 else
G1 X#1
o3 endif
o2 endwhile
#2 = 0
o4 do
#2 = [#2 + 1]
o4 while [#2 LT 0]
G0 Z#2
o5 repeat [0]
G0 Y1
o5 endrepeat
o6 repeat [2]
G0 Y2
o6 endrepeat
"""
    assert run(prog) == ["G0 X120", "G1 X1", "G1 X3", "G1 X5", "G0 Z1", "G0 Y2", "G0 Y2"]


@pytest.mark.parametrize(
    ("prog", "line", "message"),
    [
        ("G0 X#<nope>\n", 1, "named parameter #<nope> is not defined"),
        ("G0 X#<_x>\n", 1, "predefined parameters hold the machine's state"),
        ("G38.2 Z-5 F10\nG0 Z#5063\n", 2, "#5063 holds the machine's state"),
        ("#5063 = 1\nG0 Z#5063\n", None, None),  # set by the program: its value
        ("#5063 = 1\nG38.2 Z-5 F10\nG0 Z#5063\n", 3, "#5063 holds the machine's state"),  # a probe sets it again
        ("G0 X[1/0]\n", 1, "division by zero"),
        ("G0 X SQRT[-1]\n", 1, "has no value"),
        ("o<elsewhere> call\n", 1, "not in this file"),
        ("o1 if [1]\nG0 X1\n", 1, "o1 if without its end"),
        ("o1 endif\n", 1, "without its o1 if"),
        ("M98 P100\n", 1, "program O100 is not in this file"),
        ("o1 while [1]\nG0 X1\no1 endwhile\n", 3, "more than 50 blocks"),
    ],
)
def test_refused_at_their_line(prog, line, message, monkeypatch):
    monkeypatch.setattr(fl, "MAX_BLOCKS", 50)
    if line is None:
        assert run(prog) == ["G0 Z1"]
        return
    with pytest.raises(InputError) as e:
        fl.flatten(prog.encode(), "p.ngc")
    assert e.value.line == line and message in e.value.message


def _programs():
    out = []
    for folder in (NC_FILES, CORPUS):
        if folder.is_dir():
            out += sorted(p for p in folder.glob("*.ngc") if b"o" in p.read_bytes().lower() or b"#" in p.read_bytes())
    return [p for p in out if any(k in p.read_bytes().lower() for k in (b"#", b" sub", b"call", b"while", b"repeat"))]


@needs_rs274
@pytest.mark.parametrize("path", _programs(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_same_motion_as_rs274(path, tmp_path):
    """Where rs274 runs a program (with a tool table of tools 1–99), it runs the flattened one to
    the same motion; where the flattening refuses, it says where."""
    table = tmp_path / "tools.tbl"
    table.write_text("".join(f"T{t} P{t} Z0 D0 ;\n" for t in range(1, 100)))
    before = rs274.canonical(path, tools=table)
    try:
        flat = fl.flatten(path.read_bytes(), path.name)
    except InputError as e:
        assert e.line > 0
        return
    if before.error is not None:
        pytest.skip(f"rs274 does not run the program: {before.error.splitlines()[0]}")
    q = tmp_path / path.name
    q.write_bytes(flat.data)
    after = rs274.canonical(q, tools=table)
    assert after.error is None, after.error
    assert after.kinds == before.kinds
    # the same to the printed resolution (4 decimals of the program's unit, one unit of rounding)
    tol = 2 * max(before.resolution_mm, 1e-4) + 1e-9
    np.testing.assert_allclose(after.ends, before.ends, atol=tol, rtol=0)
    assert len(flat.lines) == len(flat.data.splitlines()) and flat.lines.min() >= 1


SPIRAL = """G21 G90 G64
G0 Z1
G0 X2 Y0
G1 Z-0.1 F100
o100 repeat [40]
G91 G1 @-.05 ^9
o100 endrepeat
G90 G0 Z1
M2
"""


@needs_rs274
def test_cli_expand(tmp_path):
    src = tmp_path / "spiral.ngc"
    src.write_text(SPIRAL)
    out = tmp_path / "out.ngc"
    r = CliRunner().invoke(main, ["correct", str(src), "--shift", "0,0,0.05", "-o", str(out)])
    assert r.exit_code == 1 and "--expand" in r.output
    r = CliRunner().invoke(main, ["correct", str(src), "--shift", "0,0,0.05", "-o", str(out), "--expand"])
    assert r.exit_code == 0, r.output
    # 4 blocks, the repeat, 40 × (the move and the endrepeat), 2 blocks; the shift changes the
    # plunge only (the loop's moves are incremental), which runs once: rewritten in place
    assert "9 lines ran 87 blocks; 1 line(s) rewritten in place, every other line as written" in r.output
    assert out.read_text().splitlines() == SPIRAL.replace("G1 Z-0.1 F100", "G1 Z-0.05 F100").splitlines()
    a, b = rs274.canonical(src), rs274.canonical(out)
    assert a.error is None and b.error is None and a.kinds == b.kinds
    feed = np.array([k != "traverse" for k in a.kinds])
    np.testing.assert_allclose(b.ends[feed, 2], a.ends[feed, 2] + 0.05, atol=1e-4)
    np.testing.assert_allclose(b.ends[:, :2], a.ends[:, :2], atol=1e-4)
    # a zero field changes no block: the program is written as it is
    r = CliRunner().invoke(main, ["correct", str(src), "--shift", "0,0,0", "-o", str(tmp_path / "z.ngc"), "--expand"])
    assert r.exit_code == 0 and (tmp_path / "z.ngc").read_bytes() == src.read_bytes()


def test_errors_of_the_flat_program_name_the_original_line(tmp_path):
    src = tmp_path / "p.ngc"
    src.write_text("G21 G0 X0 Y0 Z0\n#1 = 3\no1 repeat [2]\nG1 X#1 F100\nG5.2 X1 Y1 P1 L3\no1 endrepeat\nM2\n")
    with pytest.raises(RefusedError) as e:
        nc.correct_file(src, tmp_path / "o.ngc", lambda p: 0 * p, expand=True)
    assert e.value.details[0]["line"] == 5 and "flattened" in e.value.message


FANUC_SUBS = """%
O1000 (MAIN)
G21 G90 G17
G0 X0. Y0. Z5.
M98 P2000 L3
G0 Z5.
M98 P3000
M30
O2000 (A STEP: ONE SLOT)
G91 G1 Z-6. F100.
X10.
Z6.
G90
M99
O3000 (NESTED)
M98 P2000
M99
%
"""


@needs_rs274
def test_m98_subprograms_as_rs274_runs_them(tmp_path):
    """M98 P… L… runs program O… of the file L times, M99 ends a pass; rs274 (which reads Fanuc-style
    subprograms) runs the original and the flattened program to the same motion."""
    src = tmp_path / "subs.nc"
    src.write_text(FANUC_SUBS)
    flat = fl.flatten(src.read_bytes(), "subs.nc", "fanuc")
    lines = flat.data.decode().splitlines()
    assert lines.count("G91 G1 Z-6. F100.") == 4 and "O2000" not in flat.data.decode()
    q = tmp_path / "flat.nc"
    q.write_bytes(flat.data)
    a, b = rs274.canonical(src), rs274.canonical(q)
    assert a.error is None and b.error is None and a.kinds == b.kinds
    np.testing.assert_allclose(b.ends, a.ends, atol=1e-6)
    # the flattened program is corrected in the Fanuc dialect (its numbers keep their points)
    out = tmp_path / "out.nc"
    c = nc.correct_file(src, out, lambda p: np.c_[0 * p[:, :2], 0.05 + 0 * p[:, 2]], dialect="fanuc", expand=True)
    assert c.expanded["blocks"] == len(lines)
    d = rs274.canonical(out)
    feed = np.array([k != "traverse" for k in a.kinds])
    np.testing.assert_allclose(d.ends[feed, 2], a.ends[feed, 2] + 0.05, atol=1e-4)


@pytest.mark.parametrize(
    ("prog", "line", "message"),
    [
        ("G0 X0\nM99\n", 2, "M99 outside a subprogram call"),
        ("M98 P12\nM30\n", 1, "program O12 is not in this file"),
        ("M98 P30012\nM30\nO12\nM99\n", 1, "a longer P that counts passes"),
        ("M98 P1 X2.\nM30\nO1\nM99\n", 1, "with a X word"),
        ("O1\nM98 P2\nM30\nO2\nM99 P5\n", 5, "M99 with P or L"),
        # Fanuc Macro B: what the control does not say, or what is not followed
        ("G0 X#1\n", 1, "read before the program sets it"),  # vacant: the control would drop the word
        ("G0 X#500\n", 1, "keeps its value on the machine"),
        ("G0 X#5021\n", 1, "system variable"),
        ("#3000 = 1\n", 1, "system variable"),  # an alarm
        ("G0 X#0\n", 1, "vacant"),
        ("G0 X#<a>\n", 1, "LinuxCNC's"),
        ("G65 P9010 A1.\n", 1, "no such program"),
        ("WHILE [1 LT 2] DO1\n", 1, "DO 1 without its END 1"),
        ("WHILE [1 LT 2] DO4\nEND4\n", 1, "1, 2 and 3"),
        ("DO1\nEND2\n", 2, "END 2 without its DO 2"),
        ("GOTO 20\nN10 G0 X1.\n", 1, "no block N20"),
        ("#1 = 1.\nIF [#1 GT 0] X1.\n", 2, "without GOTO or THEN"),
        ("#1 = ATAN[-1.]/[-1.]\n", 1, "6004#0"),  # -135 or 225: the control's parameter
        ("#1 = ASIN[-0.5]\n", 1, "6004#0"),
        ("#1 = 2. G0 X1.\n", 1, "a macro statement"),
        ("G66 P9010 A1.\nO9010\nM99\n", 1, "G66/G67"),
        ("G65 P1 I1. J2. I3.\nO1\nM99\n", 1, "argument specification II"),
        # from review: how Fanuc evaluates, and what it would not
        ("#7 = 1.2345\nG0 X[ROUND[#7]]\n", 2, "least input increment"),
        ("#1 = 3 GT 2\n", 1, "in a value"),  # a comparison belongs in a condition
        ("#1 = 2 ** 3\n", 1, "unexpected"),
        ("#1 = TAN[90]\n", 1, "no value"),
        ("#1 = ATAN[0]/[0]\n", 1, "no value"),
        ("#1 = 1.5 AND 1\n", 1, "bit by bit"),
        ("#1 = -7 MOD 3\n", 1, "negative"),
        ("#1 = 0\nGOTO 5\nWHILE [#1 LT 2] DO1\nN5 G0 X#1\n#1 = #1 + 1\nEND1\n", 2, "into a DO loop"),
    ],
)
def test_subprogram_refusals(prog, line, message):
    refused_at(fl.flatten, prog, "p.nc", line, message, "fanuc")


def test_fanuc_numbers_keep_their_points():
    # a number without a decimal point stays as written, for the Fanuc reader to refuse
    assert fl.flatten(b"O1\nG0 X10 Y2.5\nM30\n", "p", "fanuc").data == b"O1\nG0 X10 Y2.5\nM30\n"


STRUCTURED = """(a part in two features; parameters, a subroutine called once and a branch)
#<depth> = -0.5
#<width> = 20
o100 sub
  G1 X[#1] Y0 F200
  G1 Y[#<_width_seen>]
o100 endsub
#<_width_seen> = [#<width> / 2]
G21 G90 G17
G0 X0 Y0 Z2
N40 G1 Z#<depth> F100 ; plunge
o100 call [#<width>]
o200 if [#<width> GT 10]
  G1 X0 Y[#<width>]
o200 else
  G1 X99 Y99
o200 endif
#1 = 5 G1 X[#<width> / 4]
G0 Z2
M2
"""


def _slope(p):
    d = np.zeros_like(p)
    d[:, 2] = 0.01 + 0.002 * p[:, 0]
    return d


@needs_rs274
def test_changed_lines_run_once_are_rewritten_in_place(tmp_path):
    """A field changes moves outside loops: those lines are rewritten with the corrected block, the
    parameters, the subroutine, the branch and every other line kept as written; rs274 runs the
    written program as the flat corrected one, and its cutting ends are the input's raised by the
    field there. A changed line that sets a parameter (#1 = 5 G1 X[#<width> / 4]) cannot be rewritten: the
    program is then written flat."""
    src = tmp_path / "part.ngc"
    src.write_text(STRUCTURED.replace("#1 = 5 G1 X[#<width> / 4]\n", ""))
    out = tmp_path / "out.ngc"
    c = nc.correct_file(src, out, _slope, expand=True)
    # the plunge, the subroutine's first move (its second stays at the same height) and the branch's
    assert c.expanded["written"] == "in place" and c.expanded["lines_rewritten"] == 3
    assert "  G1 X20 Y0 Z-0.45 F200" in out.read_text().splitlines()  # in the subroutine, indented
    a, b = src.read_text().splitlines(), out.read_text().splitlines()
    kept = [t for t in a if not t.lstrip().startswith(("G1", "N40"))]
    assert [t for t in b if t in kept] == kept  # every other line as written, in order
    assert "N40 G1 Z-0.49 F100 (plunge)" in b  # the number stays; the comment is the flat block's
    ca, cb = rs274.canonical(src), rs274.canonical(out)
    assert ca.error is None and cb.error is None and ca.kinds == cb.kinds
    feed = np.array([k != "traverse" for k in ca.kinds])
    want = ca.ends[:, :3].copy()
    want[feed] += _slope(want[feed])
    np.testing.assert_allclose(cb.ends[:, :3], want, atol=1e-4)

    src.write_text(STRUCTURED)
    c = nc.correct_file(src, out, _slope, expand=True)
    assert c.expanded["written"] == "straight"
    assert "o100" not in out.read_text() and "#" not in out.read_text()


@needs_rs274
def test_a_line_changed_in_a_loop_writes_the_program_flat(tmp_path):
    src = tmp_path / "spiral.ngc"
    src.write_text(SPIRAL)
    out = tmp_path / "out.ngc"
    c = nc.correct_file(src, out, _slope, expand=True)
    assert c.expanded["written"] == "straight"
    ca, cb = rs274.canonical(src), rs274.canonical(out)
    assert ca.kinds == cb.kinds
    feed = np.array([k != "traverse" for k in ca.kinds])
    want = ca.ends[:, :3].copy()
    want[feed] += _slope(want[feed])
    np.testing.assert_allclose(cb.ends[:, :3], want, atol=1e-4)


MACRO = """%
O1000
G21 G90 G17
#100 = 3 (holes)
#101 = 0
G0 X0. Y0. Z5.
WHILE [#101 LT #100] DO 1
  G65 P9010 X[#101 * 10.] Y5. R2. Z-1. A7.
  #101 = #101 + 1
END 1
IF [#101 EQ 3] GOTO 50
G0 X99. Y99.
N50 G0 Z10.
#1 = 4.
IF [#1 GT 3] THEN #1 = #1 - 1.5
G0 X#1
M30
O9010 (a hole at X Y, from R down to Z; A is #1 here)
G0 X#24 Y#25
G1 Z#26 F100.
G0 Z#18
#102 = #1
M99
%
"""


def test_fanuc_macro_b_runs_as_the_manual_says():
    """Fanuc Custom Macro B (Fanuc 0i-MF operator's manual, "Custom macro"): common variables
    #100-#199 shared, G65's arguments in a new set of locals (X #24, Y #25, Z #26, R #18, A #1)
    given back at M99, WHILE [..] DO m / END m, IF [..] GOTO n to an N number, IF [..] THEN, and
    expressions without brackets on the right of '='. The motion worked out by hand."""
    flat = fl.flatten(MACRO.encode(), "p.nc", "fanuc")
    got = flat.data.decode().splitlines()
    holes = [f"G0 X{x}. Y5." for x in (0, 10, 20)]
    want = ["%", "O1000", "G21 G90 G17", "(holes)", "G0 X0. Y0. Z5."]
    for h in holes:
        want += [h, "G1 Z-1. F100.", "G0 Z2."]
    want += ["G0 Z10.", "G0 X2.5", "M30", "%"]  # the macro's #1 (A7.) did not touch the caller's #1
    assert got == want
    # each block's line: the holes come from the macro's lines, N50 after the GOTO
    assert flat.lines.tolist() == [1, 2, 3, 4, 6] + [19, 20, 21] * 3 + [13, 16, 17, 24]
    # the G65 line and the statements are fixed: they cannot be replaced by a block
    assert flat.fixed[7] and flat.fixed[8] and flat.fixed[14] and not flat.fixed[12]


def test_fanuc_macro_program_corrected_in_place_or_straight(tmp_path):
    """A move computed from a variable outside the loop is rewritten in place; the macro's moves,
    run three times, make the program straight."""
    src = tmp_path / "p.nc"
    src.write_text("%\nO1\nG21 G90 G17\n#1 = -1.\nG0 X0. Y0. Z5.\nG1 Z#1 F100.\nG1 X10.\nM30\n%\n")
    c = nc.correct_file(src, tmp_path / "o.nc", _slope, dialect="fanuc", expand=True)
    assert c.expanded["written"] == "in place"
    out = (tmp_path / "o.nc").read_text().splitlines()
    assert out[3] == "#1 = -1." and out[5] == "G1 Z-0.99 F100." and out[6] == "G1 X10. Z-0.97"
    src.write_text(MACRO)
    c = nc.correct_file(src, tmp_path / "o.nc", _slope, dialect="fanuc", expand=True)
    assert c.expanded["written"] == "straight"
    z = [t for t in (tmp_path / "o.nc").read_text().splitlines() if t.startswith("G1 Z")]
    assert z == ["G1 Z-0.99 F100.", "G1 Z-0.97 F100.", "G1 Z-0.95 F100."]  # -1 + 0.01 + 0.002 X


def test_a_g65_argument_without_a_point_is_refused():
    """Fanuc reads `G65 P9010 X40` as 0.040 mm (IS-B) unless parameter DPI says units: refused,
    as the Fanuc reader refuses such a word; a point, a zero or a variable is a value."""
    prog = "O1\nG65 P9010 X40 Y30.\nM30\nO9010\nG0 X#24 Y#25\nM99\n"
    with pytest.raises(InputError, match="G65 argument X40 without a decimal point") as e:
        fl.flatten(prog.encode(), "p.nc", "fanuc")
    assert e.value.line == 2
    ok = fl.flatten(prog.replace("X40 ", "X40. ").encode(), "p.nc", "fanuc").data.decode()
    assert "G0 X40. Y30." in ok
    assert "G0 X0. Y30." in fl.flatten(prog.replace("X40 ", "X0 ").encode(), "p.nc", "fanuc").data.decode()


# ------------------------------------------------------------------------------ found in review
@pytest.mark.parametrize(
    ("expr", "want"),
    [
        ("FIX[-1.2]", -1.0),  # Fanuc: the fraction dropped
        ("FUP[-1.2]", -2.0),  # raised away from zero
        ("FIX[1.7]", 1.0),
        ("FUP[1.2]", 2.0),
        ("1 + 2 AND 3", 3.0),  # AND with *, bit by bit: 1 + (2 AND 3)
        ("6 AND 3", 2.0),
        ("5 OR 2", 7.0),
        ("6 XOR 3", 5.0),
    ],
)
def test_fanuc_functions_and_logic(expr, want):
    (line,) = fl.flatten(f"#1 = {expr}\nG0 X#1\n".encode(), "p.nc", "fanuc").data.decode().splitlines()
    assert float(line.split("X")[1]) == want


def test_fanuc_eq_is_exact():
    out = fl.flatten(b"#8 = 0.00005\nIF [#8 EQ 0] GOTO 10\nG0 X1.\nN10 G0 Y1.\n", "p.nc", "fanuc").data.decode()
    assert out.splitlines() == ["G0 X1.", "G0 Y1."]


def test_a_linuxcnc_program_setting_an_offset_parameter_is_refused():
    with pytest.raises(InputError, match="machine's state") as e:
        fl.flatten(b"#5241 = 2\nG55\nG0 X0\n", "p.ngc")
    assert e.value.line == 1


@needs_rs274
def test_block_delete_stays_on_flat_and_rewritten_lines(tmp_path):
    src = tmp_path / "p.ngc"
    src.write_text(
        "G21 G90\nG0 X0 Y0 Z1\n#1 = 0\no1 repeat [2]\n/G1 X[#1 + 1] Y0 Z-1 F100\n#1 = [#1 + 1]\no1 endrepeat\nM2\n"
    )
    nc.correct_file(src, tmp_path / "o.ngc", _slope, expand=True)
    body = (tmp_path / "o.ngc").read_text().splitlines()
    moves = body[body.index("G0 X0 Y0 Z1") + 1 : body.index("M2")]
    assert len(moves) > 2 and all(t.startswith("/") for t in moves)  # every piece of a deleted block
    src.write_text("G21 G90\nG0 X0 Y0 Z1\n#1 = 1\n/G1 X[#1] Y0 Z-1 F100\nM2\n")
    nc.correct_file(src, tmp_path / "o.ngc", _slope, expand=True)
    text = (tmp_path / "o.ngc").read_text()
    assert text.splitlines()[3].startswith("/G1 X") and "//" not in text  # rewritten in place, one /


INSPECT_LOOP = """G21 G90 G0 X0 Y0 Z5
#1 = 0
o100 while [#1 LT 4]
  G1 X[#1 * 10] Y[#1 * 5] F100
  #1 = [#1 + 1]
o100 endwhile
G0 Z5
M2
"""


@needs_rs274
def test_inspect_expand_reports_the_flattened_program(tmp_path):
    """`inspect --expand` counts the moves the program makes (rs274's) and names no construct;
    without it, the flow is named as unsupported."""
    p = tmp_path / "loop.ngc"
    p.write_text(INSPECT_LOOP)
    canon = rs274.canonical(p)
    feeds = sum(k == "feed" for k in canon.kinds)
    info = nc.inspect_file(p, "linuxcnc", expand=True)
    assert info["motions"]["feed"] == feeds == 4 and not info["unsupported"]
    assert info["lines"] == 8 and info["blocks_run"] > 8
    assert info["extents"]["feed"]["x"] == [0.0, 30.0]
    r = CliRunner().invoke(main, ["inspect", str(p), "--expand"])
    assert r.exit_code == 0 and "flattened (--expand): 8 lines ran" in r.output, r.output
    r = CliRunner().invoke(main, ["inspect", str(p)])
    assert r.exit_code == 0 and "O-word" in r.output
    g = tmp_path / "p.gcode"
    g.write_text("$H\nG0 X0\n")
    r = CliRunner().invoke(main, ["inspect", str(g), "--expand"])
    assert r.exit_code == 2 and "--expand flattens" in r.output


def test_exists_of_a_global_the_program_has_not_set_is_refused(tmp_path):
    """EXISTS[#<_lathe_diameter_mode>] is 1 in LinuxCNC (it predefines it, on a mill too), and a
    global parameter may come from an earlier program: the branch it takes is the machine's. A
    local name the program has not set does not exist."""
    src = tmp_path / "p.ngc"
    src.write_text(
        "G21 G0 X0 Y0 Z1\no1 if [EXISTS[#<_lathe_diameter_mode>]]\nG1 X20 F100\no1 else\nG1 X10 F100\no1 endif\nM2\n"
    )
    with pytest.raises(InputError, match="EXISTS") as e:
        nc.correct_file(src, tmp_path / "o.ngc", lambda p: 0 * p, expand=True)
    assert e.value.line == 2
    src.write_text("G21 G0 X0 Y0 Z1\no1 if [EXISTS[#<depth>]]\nG1 X20 F100\no1 else\nG1 X10 F100\no1 endif\nM2\n")
    nc.correct_file(src, tmp_path / "o.ngc", lambda p: 0 * p, expand=True)
    assert "X10" in (tmp_path / "o.ngc").read_text().splitlines()[4]


@pytest.mark.parametrize("code", ["G71.2", "G72.2"])
def test_the_lathe_cycles_whose_contour_is_a_subroutine_are_refused(tmp_path, code):
    """G71.2 and G72.2 (LinuxCNC's roughing cycles of type II) take their contour from a
    subroutine too: flattened, the output would keep the cycle and lose the subroutine."""
    src = tmp_path / "p.ngc"
    src.write_text(f"G7 G18 G21\nG0 X30 Z2\no100 sub\nG1 X20 Z0\nG1 Z-10\no100 endsub\n{code} Q100 D1\nM2\n")
    with pytest.raises(InputError, match="lathe cycles G70-G72") as e:
        nc.correct_file(src, tmp_path / "o.ngc", lambda p: 0 * p, expand=True, dialect="linuxcnc-lathe")
    assert e.value.line == 7
    assert any(
        u.construct == f"lathe cycle {code}" for u in nc.parse(src.read_text(), dialect="linuxcnc-lathe").unsupported
    )
