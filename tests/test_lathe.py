"""Lathe programs: no Y (the tool in the plane through the spindle's axis), X a diameter under
LinuxCNC's G7 and always on a Fanuc lathe, whose U and W are increments of X and Z.

rs274 is the oracle: it reads G7 (diameter mode) and prints the radius, so the input's motion,
displaced by an analytic field evaluated at that radius, must be the output's motion as rs274
reads the output (both ways, within the chord tolerance and the printed digits). A Fanuc lathe's
U and W are given to rs274 as ``X[#5420*2+U]`` and ``Z[#5422+W]``: rs274 adds them to the
position it holds itself (``#5420`` is its X, a radius, ``#5422`` its Z).
"""

from __future__ import annotations

import math
import random
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import needs_rs274
from ncadapt import InputError, RefusedError, dialects, fields, nc
from rs274 import canonical, moves

LINUXCNC = """G21 G18 G7 G90
G0 X30 Z2
G1 Z0 F100
X10
G3 X20 Z-5 I0 K-5
G1 Z-20
G2 X30 Z-25 I5 K0
G91 G1 X4 Z-5
G90 G8 G1 X17 Z-35
G7 G1 X40 Z-36
M2
"""

FANUC = """%
O0100
G18 G21 G99
T0101
G50 S2000
G96 S200 M03
G00 X30. Z2.
G01 Z0. F0.1
X10.
G03 X20. Z-5. R5.
G01 W-15.
G02 U10. W-5. I5. K0.
G01 U4. W-5.
X40. W-1.
G04 X1.5
G28 U0. W0.
M30
%
"""


def _field(p):
    """Radial x and axial z that change fast across the radius: evaluated at the diameter, or
    at another radius, the correction would be off by far more than the tolerance."""
    p = np.asarray(p, dtype=float)
    d = np.zeros((len(p), 3))
    d[:, 0] = 0.01 * np.cos(p[:, 2] / 4) + 0.01 * np.sin(p[:, 0] / 3)
    d[:, 2] = 0.02 * np.sin(p[:, 0] / 2)
    return d


def _for_rs274(text: str) -> str:
    """A Fanuc lathe program as rs274 reads it: G7 first, U and W added to rs274's own position,
    the lines it has no use for (framing, program number, spindle limit, tool, G28) left out."""
    out = ["G7"]
    for line in text.splitlines():
        if line in ("%",) or line.startswith(("O", "G50", "T", "G28")):
            continue
        line = re.sub(r"\bU(-?[\d.]+)", r"X[#5420*2+\1]", line)
        line = re.sub(r"\bW(-?[\d.]+)", r"Z[#5422+\1]", line)
        out.append(line.replace("G04 X", "G04 P"))
    return "\n".join(out) + "\n"


def _path(tmp_path, text, name):
    path = tmp_path / name
    path.write_text(text)
    c = canonical(path)
    assert c.error is None, f"{name}: {c.error}"
    mv = moves(c)[1:]  # (the first move comes from where rs274 starts, the origin)
    assert mv
    return np.concatenate([m.dense(step=0.002, sagitta=1e-7) for m in mv])


def _check_displaced(tmp_path, inp_text, out_text, tol):
    inp = _path(tmp_path, inp_text, "in.ngc")
    out = _path(tmp_path, out_text, "out.ngc")
    assert np.abs(inp[:, 1]).max() == 0 and np.abs(out[:, 1]).max() == 0  # no Y
    want = inp + _field(inp)
    far = max(cKDTree(want).query(out)[0].max(), cKDTree(out).query(want)[0].max())
    assert far <= tol, far
    # (not by chance: the field moves the path by up to 28 µm; evaluated at the diameter it would
    # be off by four times the tolerance or more)
    assert np.abs(_field(inp)).max() > 0.015
    assert np.abs(_field(inp * [2, 1, 1]) - _field(inp)).max() > 4 * tol


@needs_rs274
def test_linuxcnc_lathe_is_corrected_at_the_radius(tmp_path):
    out = nc.parse(LINUXCNC, dialect="linuxcnc-lathe").correct(_field, rapids=True)
    assert out.correction.blocks_changed >= 8
    _check_displaced(tmp_path, LINUXCNC, out.text, 0.0035)


@needs_rs274
def test_fanuc_lathe_is_corrected_with_its_diameters_and_increments(tmp_path):
    out = nc.parse(FANUC, dialect="fanuc-lathe").correct(_field, rapids=True)
    assert out.correction.blocks_changed >= 8
    # written in the program's words: diameters, increments kept increments, the dwell as it was
    assert "G04 X1.5\n" in out.text and "G28 U0. W0.\n" in out.text
    assert re.search(r"^G01 U[-\d.]+ W[-\d.]+$", out.text, re.M)
    _check_displaced(tmp_path, _for_rs274(FANUC), _for_rs274(out.text), 0.0035)


@pytest.mark.parametrize(("text", "dialect"), [(LINUXCNC, "linuxcnc-lathe"), (FANUC, "fanuc-lathe")])
def test_a_zero_field_gives_the_lathe_program_back(text, dialect):
    assert nc.parse(text, dialect=dialect).correct(fields.Shift((0, 0, 0))).text == text


def test_a_shift_moves_a_diameter_by_twice_the_radius():
    # 0.05 mm outwards: every X a diameter 0.1 larger, U and W kept (both ends move alike)
    out = nc.parse(FANUC, dialect="fanuc-lathe").correct(fields.Shift((0.05, 0, 0)), rapids=True)
    assert "X10.1\n" in out.text and "G03 X20.1 Z-5. R5.\n" in out.text
    assert "G02 U10. W-5. I5. K0.\n" in out.text and "X40.1 W-1.\n" in out.text


def test_the_field_s_y_is_not_applied_on_a_lathe(tmp_path):
    prog = nc.parse(FANUC, dialect="fanuc-lathe")
    # within the chord tolerance: left out (the machine has no Y)
    out = prog.correct(fields.Shift((0.05, 0.001, 0)), rapids=True)
    assert "Y" not in out.text
    assert out.text == prog.correct(fields.Shift((0.05, 0, 0)), rapids=True).text
    with pytest.raises(RefusedError, match="a lathe has no Y axis"):
        prog.correct(fields.Shift((0, 0.01, 0)))
    # a field evaluated in Python: refused at the line where it moves Y
    src = tmp_path / "p.nc"
    src.write_text(FANUC)

    def tilted(p):
        d = _field(p)
        d[:, 1] = 0.01
        return d

    with pytest.raises(RefusedError, match=r"line \d+: the field moves Y by 0.0100 mm"):
        nc.correct_file(src, tmp_path / "o.nc", tilted, dialect="fanuc-lathe")
    assert not (tmp_path / "o.nc").exists()


def _unsupported(text, dialect="fanuc-lathe"):
    return [(u.line, u.construct) for u in nc.parse(text, dialect=dialect).unsupported]


def test_what_a_lathe_program_does_that_is_not_followed_is_refused_at_its_line():
    head = "O1\nG18 G21\nG0 X20. Z1.\n"
    # G-code system A's taper turning cycle, where a block runs it (G90 alone sets it up)
    assert _unsupported(head + "G90 X18. Z-10. R-1. F0.2\nX16.\nG0 X30.\nM30\n") == [
        (4, "taper turning cycle G90 (R, or I on a Haas: a Fanuc lathe's, G-code system A)"),
        (5, "taper turning cycle G90 (R, or I on a Haas: a Fanuc lathe's, G-code system A)"),  # (R is modal)
    ]
    assert _unsupported(head + "G90 G54\nG01 X18. Z-10. F0.2\nM30\n") == []
    # and after G80 the cycle is still the motion (group 01): its axis words are not a G1 move
    assert _unsupported(head + "G01 X19. F0.2\nG90 X18. Z-10.\nG80\nX16.\nM30\n")[-1] == (
        7,
        "axis words with no motion mode (G80 or none yet)",
    )
    assert _unsupported(head + "G73 U1. W1. R3.\nM30\n") == [(4, "lathe cycle G73")]
    assert _unsupported(head + "G71 P10 Q20 U0.2 W0.1 D1. F0.2\nM30\n") == [
        (5, "the contour of G71 P10 Q20 does not follow it from block N10")
    ]
    assert "G91 on a Fanuc lathe" in _unsupported(head + "G91\nG1 X1. F0.2\nM30\n")[0][1]
    assert "Y word on a lathe" in _unsupported(head + "G1 Y1. F0.2\nM30\n")[0][1]
    assert "C word on a Fanuc lathe" in _unsupported(head + "G1 X10. C1. F0.2\nM30\n")[0][1]
    with pytest.raises(InputError, match="X and U in one block"):
        _ = nc.parse(head + "G1 X10. U1. F0.2\nM30\n", dialect="fanuc-lathe").blocks
    # LinuxCNC: X before the program says whether it is a diameter (G7) or a radius (G8)
    assert "X before G7 or G8" in _unsupported("G18 G21\nG0 X10 Z1\nG7\nG1 X8\nM2\n", "linuxcnc-lathe")[0][1]
    assert _unsupported("G18 G21 G8\nG0 X10 Z1\nG7\nG1 X8\nM2\n", "linuxcnc-lathe") == []


def test_a_dwell_moves_nothing():
    # Fanuc: G04 X is the dwell's time (seconds), not a move
    text = "O1\nG21 G17\nG0 X0. Y0. Z0.\nG1 X1. F100.\nG04 X1.5\nG04 P500\nM30\n"
    out = nc.parse(text, dialect="fanuc").correct(fields.Shift((0.01, 0, 0)))
    assert "G04 X1.5\n" in out.text and "G1 X1.01 F100.\n" in out.text
    with pytest.raises(InputError, match="axis words in a G04 block"):
        _ = nc.parse("O1\nG0 X0. Y0. Z0.\nG04 X1. Z1.\nM30\n", dialect="fanuc").blocks
    # written without a point, its time is in least increments (or seconds, by a parameter)
    with pytest.raises(InputError, match=r"X15 = 0\.015 s"):
        _ = nc.parse("O1\nG0 X0. Y0. Z0.\nG04 X15\nM30\n", dialect="fanuc").blocks
    # LinuxCNC wants P (rs274: "Dwell time missing with g4")
    with pytest.raises(InputError, match="dwell time missing with G4"):
        _ = nc.parse("G21\nG0 X0 Y0 Z0\nG4 X1.5\nM2\n").blocks


@pytest.mark.parametrize(
    ("text", "dialect", "line"),
    [
        ("O1\nG18\nT0101\nG0 X10. Z1.\n", "fanuc", 3),
        ("O1\nG97 S500\nG96 S200 M3\n", "fanuc", 3),
        ("O1\n(G96 in a comment)\nG50 S2500\n", "fanuc", 3),
        ("O1\nG0 X10. Z1.\nG71 P10 Q20 U.2 W.1 D1. F.2\n", "fanuc", 3),
        ("G21\nG18 G7\nG0 X10 Z1\n", "linuxcnc", 2),
    ],
)
def test_a_lathe_s_program_is_detected(tmp_path, text, dialect, line):
    p = tmp_path / "p.nc"
    p.write_text(text)
    d = dialects.resolve(p)
    assert (d.name, d.lathe, d.machine_line, d.engine) == (dialect, True, line, f"{dialect}-lathe")
    assert dialects.resolve(p, machine="mill").engine == dialect


@pytest.mark.parametrize(
    "text",
    [
        "O1\nG17 G90\nT1 M6\nG43 H1 Z10.\nG81 X1. Y1. Z-1. R1. F100.\n",  # a mill: T1, a G81
        "O1\nG50\nG51 X0. Y0. P2.\n",  # a Fanuc mill's scaling off and on
        "O1\nG73 X1. Y1. Z-2. R1. Q.5 P100 F50.\n",  # a mill's peck drilling
        "G21\nG70 G71\n",  # (not LinuxCNC's lathe codes)
    ],
)
def test_a_mill_s_program_is_not_a_lathe_s(tmp_path, text):
    p = tmp_path / "p.nc"
    p.write_text(text)
    assert not dialects.resolve(p).lathe


def test_the_corpus_lathe_programs_are_detected():
    folder = Path(__file__).resolve().parents[1] / ".." / "shared" / "corpus" / "nc"
    if not folder.is_dir():
        pytest.skip("the shared corpus is not beside the repository")
    lathes = sorted(p.name for p in folder.iterdir() if p.suffix != ".tsv" and p.name != "README.md" and _lathe(p))
    assert lathes == ["haas__lathe_241006_weld_pin.nc", "linuxcnc__lathe_pawn.ngc"]


def _lathe(p):
    try:
        return dialects.resolve(p).lathe
    except InputError:  # (a dialect the engine does not read)
        return False


# ------------------------------------------------------------- nose radius compensation
NOSE = """G21 G18 G7 G90
T1 M6
G0 X40 Z5
G42 G1 X20 Z2 F100
G1 Z-10
G2 X30 Z-15 I5 K0
G1 Z-30
X40
G40 G0 X50 Z5
M2
"""
#: the nose radius (mm) of tool 1, and the table rs274 reads it from (in inches, its units)
NOSE_R = 0.8
NOSE_TABLE = f"T1 P1 D{2 * NOSE_R / 25.4:.7f} Q3 ;\n"


def _gentle(p):
    """A field whose change within the nose radius is far below the chord tolerance."""
    p = np.asarray(p, dtype=float)
    d = np.zeros((len(p), 3))
    d[:, 0] = 0.01 * np.sin(p[:, 2] / 60)
    d[:, 2] = 0.008 * np.cos(p[:, 0] / 40)
    return d


def _compensated(tmp_path, text, name):
    (tmp_path / "tool.tbl").write_text(NOSE_TABLE)
    path = tmp_path / name
    path.write_text(text)
    c = canonical(path, tools=tmp_path / "tool.tbl")
    assert c.error is None, f"{name}: {c.error}"
    return c, np.concatenate([m.dense(step=0.002, sagitta=1e-7) for m in moves(c)[1:] if m.kind != "traverse"])


@needs_rs274
def test_nose_compensation_offsets_the_corrected_contour(tmp_path):
    """rs274 offsets the nose from the contour (its tool table's nose radius and orientation): a
    shift moves the compensated path by the shift exactly; a field that changes little within
    the nose radius moves it by the field within the chord tolerance."""
    prog = nc.parse(NOSE, dialect="linuxcnc-lathe", tools={1: 2 * NOSE_R})
    assert prog.unsupported == ()
    inp, inp_path = _compensated(tmp_path, NOSE, "in.ngc")
    shift = (0.05, 0.0, -0.02)
    out, _ = _compensated(tmp_path, prog.correct(fields.Shift(shift), rapids=True).text, "out.ngc")
    feeds = [k for k, kind in enumerate(inp.kinds) if kind != "traverse"]
    assert len(feeds) == 6 and [k for k, kind in enumerate(out.kinds) if kind != "traverse"] == feeds
    np.testing.assert_allclose(out.ends[feeds, :3], inp.ends[feeds, :3] + shift, atol=2e-4)
    # (the nose is off the contour: rs274 compensates)
    assert np.abs(inp.ends[feeds[1], 0] - 10.0) > NOSE_R
    out_text = prog.correct(_gentle, rapids=True).text
    _, out_path = _compensated(tmp_path, out_text, "out2.ngc")
    want = inp_path + _gentle(inp_path)
    far = max(cKDTree(want).query(out_path)[0].max(), cKDTree(out_path).query(want)[0].max())
    assert far <= 0.002 + 0.0006, far


def test_nose_compensation_needs_its_radius_and_a_field_calm_within_it():
    # no tool table: refused at G42, naming what is missing
    (u,) = nc.parse(NOSE, dialect="linuxcnc-lathe").unsupported
    assert (u.line, "its nose radius is not known" in u.construct) == (4, True)
    # a field that changes by microns within the nose radius: refused at the line
    with pytest.raises(
        RefusedError,
        match="line [4-8]: radius compensation in G18/G19 .a lathe.s nose radius, or a cutter outside G17.: the field changes",
    ):
        nc.parse(NOSE, dialect="linuxcnc-lathe", tools={1: 2 * NOSE_R}).correct(_field)
    # a Fanuc lathe's nose radius is its offset's: T0101 is tool 1, offset 1
    fanuc = "O1\nG21\nT0202\nG0 X40. Z5.\nG42 G1 X20. Z2. F0.1\nG1 Z-10.\nG40 G0 X50. Z5.\nM30\n"
    assert nc.parse(fanuc, dialect="fanuc-lathe", tools={2: 1.6}).unsupported == ()
    # another offset under compensation: another nose radius, not followed
    changed = fanuc.replace("G1 Z-10.", "T0101\nG1 Z-10.")
    assert [
        (u.line, u.construct) for u in nc.parse(changed, dialect="fanuc-lathe", tools={1: 0.4, 2: 1.6}).unsupported
    ] == [
        (
            6,
            "a tool offset changed under radius compensation in G18/G19 (a lathe's nose radius, a cutter's "
            "outside G17): its radius is not followed",
        )
    ]
    (u,) = nc.parse(fanuc, dialect="fanuc-lathe", tools={1: 1.6}).unsupported
    assert "offset 2: its nose radius is not known" in u.construct
    # offset 00 (T0000, T0100): no offset, no nose radius: compensation moves nothing
    for t in ("T0000", "T0100"):
        none = fanuc.replace("T0202", t)
        assert nc.parse(none, dialect="fanuc-lathe").unsupported == ()
        assert "X20.1 Z2." in nc.parse(none, dialect="fanuc-lathe").correct(fields.Shift((0.05, 0, 0))).text
    # a T of two digits does not say which offset
    (u,) = nc.parse(fanuc.replace("T0202", "T2"), dialect="fanuc-lathe").unsupported
    assert "no tool offset selected" in u.construct


def test_a_roughing_cycle_s_contour_is_not_read_as_moves():
    """G71 P10 Q20 runs the blocks N10-N20 inside the cycle, then goes on after N20 from the
    cycle's start: a contour the engine does not follow (type I: N10 names X alone), kept with
    --keep-unsupported, is written as it is, and the move after it, an increment from a position
    the engine does not follow, as written."""
    text = "O1\nG18 G21\nG00 X32. Z2.\nG71 P10 Q20 U0.2 W0.1 F0.2\nN10 G00 X10.\nN20 G01 X30. Z-15.\nG01 U-4. W-2. F0.1\nX20. Z-20.\nM30\n"
    prog = nc.parse(text, dialect="fanuc-lathe")
    ((line, what, blocks),) = [(u.line, u.construct, u.blocks) for u in prog.unsupported]
    assert (line, blocks, "names X and Z (absolute) here" in what) == (5, 2, True)
    out = prog.correct(_field, keep_unsupported=True)
    lines = out.text.splitlines()
    assert lines[:7] == text.splitlines()[:7]
    assert lines[7] != "X20. Z-20." and lines[7].startswith("X20.")  # (the first known move again)


def test_a_lathe_s_arcs_are_in_the_zx_plane():
    # a Fanuc lathe starts in G18: its arcs are in ZX (no Y written)
    text = "O1\nG21\nT0101\nG00 X10. Z2.\nG01 Z0. F0.1\nG03 X20. Z-5. R5.\nG01 Z-10.\nM30\n"
    out = nc.parse(text, dialect="fanuc-lathe").correct(_field)
    assert out.correction.arcs_linearised == 1 and "Y" not in out.text
    # on a LinuxCNC lathe the start-up plane is the machine's; another plane has no arcs on a lathe
    assert (
        "before the program states its plane"
        in _unsupported("G21 G8\nG0 X10 Z2\nG3 X20 Z-5 R5\nM2\n", "linuxcnc-lathe")[0][1]
    )
    assert "outside the ZX plane" in _unsupported("G21 G8 G17\nG0 X10 Z2\nG3 X20 R5\nM2\n", "linuxcnc-lathe")[0][1]


# ------------------------------------------------------------- roughing cycles' contours
CONTOUR = """%
O2
G18 G21 G99
T0101
G00 X12. Z3.
G71 P10 Q20 U0.4 W0.1 D1. F0.2
N10 G00 X10. Z2.
G01 Z0. F0.1
G03 X20. Z-5. R5.
G01 W-15.
G02 U10. W-5. I5. K0.
G01 Z-30.
N20 G01 U1. W-0.5
G70 P10 Q20 F0.05
G00 X50. Z10.
G01 X45. Z5. F0.2
G71 P30 Q40 U0.4 W0.1 D1. F0.2
N30 G00 X44. Z5.
N40 G01 Z4.
G01 X46. Z-31. F0.1
M30
%
"""


def _contour_lines(text):
    """The contour of CONTOUR's cycle (N10 through N20) as rs274 runs it from the cycle's start
    (the move before the cycle), and the lines before and after it."""
    lines = text.splitlines()
    a = next(k for k, s in enumerate(lines) if s.startswith("N10"))
    b = next(k for k, s in enumerate(lines) if s.startswith("N20"))
    return "\n".join(["G18 G21"] + lines[a - 2 : a - 1] + lines[a : b + 1]) + "\nM2\n", lines[:a], lines[b + 1 :]


@needs_rs274
def test_a_roughing_cycle_s_contour_is_corrected_where_it_is(tmp_path):
    """G71 P10 Q20 roughs along the blocks N10-N20 and G70 finishes along them: corrected in
    place (the control follows the corrected contour), the cycles' blocks copied, N10 and N20
    still the contour's first and last blocks; the contour, run by rs274, is the input's displaced."""
    prog = nc.parse(CONTOUR, dialect="fanuc-lathe")
    assert prog.unsupported == ()
    out = prog.correct(_field, rapids=True)
    c_in, before_in, after_in = _contour_lines(CONTOUR)
    c_out, before_out, after_out = _contour_lines(out.text)
    # the cycle's start corrected as a rapid (--rapids), the cycle's block copied
    assert before_out[:4] + before_out[5:] == before_in[:4] + before_in[5:]
    assert after_out[0] == after_in[0] == "G70 P10 Q20 F0.05"
    assert c_out.count("\n") > c_in.count("\n") + 10  # cut in pieces, between N10 and N20
    _check_displaced(tmp_path, _for_rs274(c_in), _for_rs274(c_out), 0.0035)
    # after the cycles the control is back at the cycle's start (12, 3): the move from there is
    # corrected along its length (--rapids: in pieces), to its end moved by the field there
    assert after_out[1].startswith("G00 X13.") and "X50.0017 Z9.9987" in after_out
    d = _field([[25.0, 0.0, 10.0]])[0]
    assert (round(50 + 2 * d[0], 4), round(10 + d[2], 4)) == (50.0017, 9.9987)
    # (likewise after the second cycle's contour, from its start (45, 5))
    d = _field([[23.0, 0.0, -31.0]])[0]
    assert after_out[-3] == f"X{46 + 2 * d[0]:.4f} Z{-31 + d[2]:.4f}"
    assert any(ln.startswith("G01 X45.0565 Z4.0077") for ln in after_out)  # (its first piece, from there)


def test_what_a_roughing_cycle_s_contour_cannot_be():
    def refused(text):
        return [(u.line, u.construct) for u in nc.parse(text, dialect="fanuc-lathe").unsupported]

    # its first block must follow the cycle, numbered P
    assert "does not follow it from block N10" in refused(CONTOUR.replace("N10 G00", "N11 G00"))[0][1]
    # and name X and Z (a type I contour names X alone: adding a Z would change its type)
    assert "names X and Z (absolute) here" in refused(CONTOUR.replace("N10 G00 X10. Z2.", "N10 G00 X10."))[0][1]
    # (and G70 along a contour not followed is not either)
    assert refused(CONTOUR.replace("N10 G00 X10. Z2.", "N10 G00 X10."))[1] == (14, "lathe cycle G70")
    # G70 along a contour no roughing cycle read
    assert refused(CONTOUR.replace("G70 P10 Q20", "G70 P30 Q40")) == [(14, "lathe cycle G70")]
    # the last block must stay one block: a feed the field bends is refused at its line
    bent = CONTOUR.replace("N20 G01 U1. W-0.5", "N20 G01 X40. Z-40.")
    with pytest.raises(InputError, match="the last block of a roughing cycle's contour") as e:
        nc.parse(bent, dialect="fanuc-lathe").correct(_field)
    assert e.value.line == 13
    # and the first (its pieces would move the point the cycle roughs from)
    bent = CONTOUR.replace("N10 G00 X10. Z2.", "N10 G00 X10. Z20.")
    with pytest.raises(InputError, match="the first and the last block") as e:
        nc.parse(bent, dialect="fanuc-lathe").correct(_field, rapids=True)
    assert e.value.line == 7
    # a contour with no block numbered Q before the program goes on: the control alarms
    with pytest.raises(InputError, match="has no block numbered Q20 before this one") as e:
        _ = nc.parse(CONTOUR.replace("N20 G01", "N21 G01"), dialect="fanuc-lathe").blocks
    assert e.value.line == 14


def test_a_haas_contour_with_nose_compensation_keeps_its_shape():
    """As Haas posts write it: G42 on the contour's first block, G40 on its last."""
    text = CONTOUR.replace("N10 G00 X10. Z2.", "N10 G00 G42 X10. Z2.").replace("N20 G01 U1.", "N20 G01 G40 U1.")
    prog = nc.parse(text, dialect="fanuc-lathe", tools={1: 1.6})
    assert prog.unsupported == ()
    out = prog.correct(fields.Shift((0.05, 0, 0)), rapids=True).text
    assert "N10 G00 G42 X10.1 Z2.\n" in out and "N20 G01 G40 U1. W-0.5\n" in out
    assert "G71 P10 Q20 U0.4 W0.1 D1. F0.2\n" in out and "G70 P10 Q20 F0.05\n" in out


# ------------------------------------------------------------- random lathe programs
def _num(v):
    return f"{v:.3f}"


def _random_program(rng, fanuc):
    """A seeded lathe profile: straight moves and R or I/K arcs, X as diameters or radii (G7/G8
    switched on LinuxCNC), absolute or incremental (U/W on Fanuc, G91 on LinuxCNC)."""
    lines = ["%", "O1", "G18 G21 G99"] if fanuc else ["G21 G18 G90 G7"]
    dia, absolute = True, True
    r, z = 15.0, 2.0
    lines += [f"G00 X{_num(2 * r)} Z{_num(z)}", f"G01 Z{_num(0)} F0.1" if fanuc else "G1 Z0 F100"]
    z = 0.0
    for _ in range(rng.randint(3, 9)):
        pre = []
        if not fanuc and rng.random() < 0.3:
            dia = not dia
            pre.append("G7" if dia else "G8")
        if not fanuc and rng.random() < 0.3:
            absolute = not absolute
            pre.append("G90" if absolute else "G91")
        nr, nz = min(25.0, max(2.0, r + rng.uniform(-6, 6))), z - rng.uniform(0.5, 6)
        k = 2 if dia else 1
        if fanuc:
            x = f"X{_num(2 * nr)}" if rng.random() < 0.5 else f"U{_num(2 * (nr - r))}"
            w = f"Z{_num(nz)}" if rng.random() < 0.5 else f"W{_num(nz - z)}"
        else:
            x = f"X{_num(k * (nr if absolute else nr - r))}"
            w = f"Z{_num(nz if absolute else nz - z)}"
        d = math.hypot(nr - r, nz - z)
        if rng.random() < 0.5:
            lines.append(" ".join(pre + [rng.choice(["G00", "G01"]), x, w]))
        else:
            arc = rng.choice(["G02", "G03"])
            if rng.random() < 0.5:
                tail = [f"R{_num(d / 2 * rng.uniform(1.05, 3))}"]
            else:  # a centre on the chord's bisector
                t = rng.uniform(-2, 2)
                cr, cz = (r + nr) / 2 - t * (nz - z) / d, (z + nz) / 2 + t * (nr - r) / d
                tail = [f"I{_num(cr - r)}", f"K{_num(cz - z)}"]
            lines.append(" ".join(pre + [arc, x, w] + tail))
        r, z = nr, nz
    lines += ["M30", "%"] if fanuc else ["M2"]
    return "\n".join(lines) + "\n"


@needs_rs274
@pytest.mark.parametrize("fanuc", [True, False], ids=["fanuc", "linuxcnc"])
def test_random_lathe_programs_are_corrected_at_the_radius(tmp_path, fanuc):
    """Seeded profiles (rs274 reads each input; what it refuses, such as an arc whose written
    numbers miss its radius, is skipped), corrected in pieces of several lengths: rs274's
    reading of the output is the input's displaced."""
    rng = random.Random(23)
    checked = 0
    for _ in range(24):
        text = _random_program(rng, fanuc)
        given = _for_rs274(text) if fanuc else text
        (tmp_path / "probe.ngc").write_text(given)
        if canonical(tmp_path / "probe.ngc").error is not None:
            continue
        piece = rng.choice([0.25, 0.5, 1.0])
        out = nc.parse(text, dialect="fanuc-lathe" if fanuc else "linuxcnc-lathe")
        out = out.correct(_field, rapids=True, max_segment=piece)
        _check_displaced(tmp_path, given, _for_rs274(out.text) if fanuc else out.text, 0.004)
        checked += 1
    assert checked >= 12, checked


def test_the_two_block_roughing_cycle():
    """Fanuc's two-block form: `G71 U(depth) R(retract)` sets the cycle's parameters (its U is no
    move), the second block names the contour."""
    text = CONTOUR.replace("G71 P10 Q20 U0.4 W0.1 D1. F0.2", "G71 U1. R0.5\nG71 P10 Q20 U0.4 W0.1 F0.2")
    prog = nc.parse(text, dialect="fanuc-lathe")
    assert prog.unsupported == ()
    out = prog.correct(fields.Shift((0.05, 0, 0)), rapids=True).text
    assert "G71 U1. R0.5\nG71 P10 Q20 U0.4 W0.1 F0.2\nN10 G00 X10.1 Z2.\n" in out


# ------------------------------------------------------------- G90 / G94 box cycles
BOXES = """O1
G18 G21
T0101
G00 X42. Z2.
G90 X38. Z-30. F0.2
X36.
X34.
U-10. W-28.
G00 X45. Z5.
G94 X20. Z-1. F0.15
Z-2.
G00 X50. Z10.
M30
"""


def _corners(text):
    """Each G90/G94 block's start and corner (radius, Z), by the Fanuc manual's rules: the cycle
    starts where the tool stands, X (a diameter) and Z are its corner, U and W increments from
    the start, a word left out the block before's (modal), and the tool is back at the start after."""
    out, pos, mode, modal = [], None, None, None
    for line in text.splitlines():
        words = dict((m[0], float(m[1:])) for m in re.findall(r"[A-Z]-?[\d.]+", line))
        g = words.get("G")
        if g is not None and g in (0, 1, 90, 94):
            mode, modal = g, None if g != mode else modal
        if not any(k in words for k in "XZUW"):
            continue
        x = words["X"] / 2 if "X" in words else None
        z = words.get("Z")
        if mode in (90, 94):
            x = pos[0] + words["U"] / 2 if "U" in words else (x if x is not None else modal[0])
            z = pos[1] + words["W"] if "W" in words else (z if z is not None else modal[1])
            modal = (x, z)
            out.append((pos, (x, z)))
        else:
            pos = (x if x is not None else pos[0], z if z is not None else pos[1])
    return out


def _box_field(p):
    p = np.asarray(p, dtype=float)
    d = np.zeros((len(p), 3))
    d[:, 0] = 0.02 + 0.0001 * p[:, 0]
    d[:, 2] = -0.01 + 0.0003 * p[:, 2] / 30
    return d


def test_box_cycles_move_their_corner_by_the_field():
    prog = nc.parse(BOXES, dialect="fanuc-lathe")
    assert prog.unsupported == ()
    assert prog.correct(fields.Shift((0, 0, 0))).text == BOXES
    out = prog.correct(_box_field).text
    before, after = _corners(BOXES), _corners(out)
    assert len(before) == len(after) == 6
    for (a0, c0), (a1, c1) in zip(before, after):
        assert a1 == a0  # (the start is a rapid's end, not corrected)
        d = _box_field([[c0[0], 0, c0[1]]])[0]
        assert c1 == pytest.approx((c0[0] + d[0], c0[1] + d[2]), abs=5e-4), (c0, c1)
    # blocks that leave out X or Z keep doing so where the corrected modal value is the same
    assert "\nX36.04" in out or "\nX36.03" in out


def test_box_cycles_the_engine_does_not_follow_are_refused():
    def refused(text):
        return [u.construct for u in nc.parse(text, dialect="fanuc-lathe").unsupported]

    head = "O1\nG18 G21\nG00 X42. Z2.\n"
    assert refused(head + "G90 X38. Z-30. R-1. F0.2\nM30\n") == [
        "taper turning cycle G90 (R, or I on a Haas: a Fanuc lathe's, G-code system A)"
    ]
    assert refused(head + "G92 X38. Z-30. F1.5\nM30\n") == ["threading cycle G92 (a Fanuc lathe's, G-code system A)"]
    assert refused("O1\nG18 G21\nG90 X38. Z-30. F0.2\nM30\n") == [
        "turning cycle G90 from a position the program does not tell"
    ]
    assert refused(head + "G90 X38. F0.2\nM30\n") == [
        "turning cycle G90 without X or Z, which no block of it before gives"
    ]
    # a field that varies along the cuts more than the chord tolerance: one corner displacement
    # cannot follow it
    with pytest.raises(RefusedError, match=r"line 5: a turning or facing cycle \(G90, G94\): the field varies"):
        nc.parse(BOXES, dialect="fanuc-lathe").correct(_field)


def test_what_box_cycles_the_engine_does_not_follow_leave_out_is_not_taken_from_a_corrected_one():
    # a taper block (refused, kept with --keep-unsupported) leaving out X would take the output's
    # rewritten X: refused even then
    text = "O1\nG18 G21\nG00 X42. Z2.\nG90 X38. Z-30. F0.2\nZ-25. R-1.\nG00 X50.\nM30\n"
    with pytest.raises(InputError, match="leaves out X or Z, which a block before gives") as e:
        nc.parse(text, dialect="fanuc-lathe").correct(fields.Shift((0.05, 0, 0)), keep_unsupported=True)
    assert e.value.line == 5
    # Haas writes a G90 taper with I and a G94 taper with K: refused as the taper it is
    haas = "O1\nG18 G21\nG00 X42. Z2.\nG90 X38. Z-30. I-1. F0.2\nG00 X50.\nM30\n"
    assert [(u.line, u.construct) for u in nc.parse(haas, dialect="fanuc-lathe").unsupported] == [
        (4, "taper turning cycle G90 (R, or I on a Haas: a Fanuc lathe's, G-code system A)")
    ]


# ------------------------------------------------------------ grooving and threading cycles
#: Haas's one-block forms (X, Z the end: the root diameter and the thread's end; K the thread's
#: height, D the first cut, A the tool's angle, I a taper; a groove's I and K its increments) and
#: Fanuc's two-block forms (the first block's P Q R the parameters).
CUTS = """%
O2
G18 G21 G99
T0303
G00 X30. Z5.
G01 X26. Z2. F0.2
G76 X22.2 Z-30. K1. D0.3 A60 F1.5
G00 X40.
Z-40.
G01 X36. F0.1
G75 X20. I0.5
G01 X36.
G00 X30. Z5.
G76 P020060 Q50 R0.05
G76 U-7.8 W-35. R0. P1000 Q300 F1.5
G00 X50.
G00 Z-50.
G75 X20. Z-60. I0.5 K2. D0.1
M30
%
"""


def _cut_words(text, code):
    """(X, Z) of each G<code> block that has them, and each block's line (1-based)."""
    out = []
    for k, ln in enumerate(text.splitlines(), 1):
        if re.search(rf"\bG{code}\b", ln) and re.search(r"\b[XU]-?[\d.]", ln):
            out.append((k, ln))
    return out


def test_grooving_and_threading_cycles_move_as_one():
    """Fanuc's rules: the cycle runs from where the tool stands (its start) and back there; its
    X (a diameter) and Z (U, W from the start) give the end. A constant field moves the cut: the
    end by the field (X by twice its x), and the start with it, so that the thread's phase and the
    groove's place move too. Where the move to the start is a rapid (not corrected), a move to the
    moved start is written before the block, in the mode in force."""
    prog = nc.parse(CUTS, dialect="fanuc-lathe")
    assert prog.unsupported == ()
    assert prog.correct(fields.Shift((0, 0, 0))).text == CUTS
    out = prog.correct(fields.Shift((0.05, 0.0, -0.1)), rapids=False).text.splitlines()
    # line 6 (a cut) ends at its end moved; the G76 after it starts there: no move added
    k = out.index("G76 X22.3 Z-30.1 K1. D0.3 A60 F1.5")
    assert out[k - 1] == "X26.1 Z1.9"  # (the cut's last piece)
    # the groove: its start (line 10, a cut) moved, its bottom X moved, no Z (the start's)
    assert "G75 X20.1 I0.5" in out
    # the two-block thread starts after a rapid to X30. Z5.: a rapid to the moved start is
    # added, and its U W (from there) stay
    k = out.index("G76 P020060 Q50 R0.05")
    assert (
        out[k - 1] == "G00 X30. Z5."
        and out[k + 1] == "G00 X30.1 Z4.9"
        and out[k + 2] == "G76 U-7.8 W-35. R0. P1000 Q300 F1.5"
    )
    # the last groove: after two rapids, its start moved by a move added in G00
    k = out.index("G75 X20.1 Z-60.1 I0.5 K2. D0.1")
    assert out[k - 1] == "G00 X50.1 Z-50.1" and out[k - 2] == "G00 Z-50."


def test_grooving_and_threading_cycles_the_engine_does_not_follow():
    head = "O1\nG18 G21\nG0 X30. Z5.\n"
    # from where the program does not tell, and under nose radius compensation
    assert _unsupported("O1\nG18 G21\nG76 X22. Z-30. K1. D0.3 F1.5\nM30\n") == [
        (3, "threading cycle G76 from a position the program does not tell")
    ]
    nose = "O1\nG18 G21\nT0101\nG0 X30. Z5.\nG42 G1 X28. Z2. F0.2\nG75 X20. I0.5\nG40 G0 X40.\nM30\n"
    assert (6, "grooving cycle G75 under cutter (nose) radius compensation") in [
        (u.line, u.construct) for u in nc.parse(nose, dialect="fanuc-lathe", tools={1: 0.8}).unsupported
    ]
    # a field that varies over the area the cycle cuts in more than the chord tolerance
    with pytest.raises(RefusedError, match=r"line 4: threading cycle G76: the field varies by [\d.]+ µm over the area"):
        nc.parse(head + "G76 X22. Z-30. K1. D0.3 F1.5\nM30\n", dialect="fanuc-lathe").correct(_field)
    # the move to the moved start needs G0 or G1 in force
    arc = "O1\nG18 G21\nG0 X30. Z5.\nG02 X32. Z4. R1. F0.2\nG76 X22. Z-30. K1. D0.3 F1.5\nM30\n"
    nc.parse(arc, dialect="fanuc-lathe").correct(fields.Shift((0, 0, 0.05)))  # (the arc's end moved: no move added)

    # a field that moves the start a little less than the thread: within the chord tolerance,
    # but the start must move with the thread, and G02 is in force
    def slope(p):
        d = np.zeros_like(np.asarray(p, float))
        d[:, 2] = 1e-4 * np.asarray(p, float)[:, 2]
        return d

    with pytest.raises(InputError, match="no G0 or G1 is in force") as e:
        nc.parse(arc, dialect="fanuc-lathe").correct(slope, chord_tol=0.005)
    assert e.value.line == 5


def test_a_cycle_s_start_moved_by_a_corrected_cut_needs_no_move_before_it():
    text = "O1\nG18 G21\nG00 X40. Z-20.\nG01 X36. F0.1\nG75 X20. I0.5\nG00 X40.\nM30\n"
    out = nc.parse(text, dialect="fanuc-lathe").correct(fields.Shift((0.02, 0, 0.03))).text.splitlines()
    k = out.index("G75 X20.04 I0.5")
    assert out[k - 1] == "X36.04"  # (the cut's last piece: the groove starts where it ends)


def test_after_a_roughing_contour_the_control_is_back_at_the_cycle_s_start():
    """Fanuc's G71 roughs, then goes back to where the tool stood at its block (the start), and G70
    finishes and goes back to its own: the position after them is known, so a grooving cycle from
    there is moved with its start (a rapid brought the tool to the start: a move to the moved
    start is added, in G00, the motion in force)."""
    text = (
        "%\nO1\nG18 G20 G99\nT0101\nG00 X3.0 Z0.1\nG71 P10 Q20 U0.01 W0.005 D0.05 F0.010\n"
        "N10 G00 X1.0 Z0.1\nG01 Z-1.0\nX3.0\nN20 G00 Z0.1\nG70 P10 Q20 F0.005\nG75 X0.5 I0.005 F0.005\n"
        "G00 X4.0\nM30\n%\n"
    )
    prog = nc.parse(text, dialect="fanuc-lathe", tools={1: 0.0})
    assert prog.unsupported == ()
    out = prog.correct(fields.Shift((0.0254, 0.0, 0.0508))).text.splitlines()
    k = out.index("G75 X0.50200 I0.005 F0.005")
    assert out[k - 1] == "G00 X3.00200 Z0.10200" and out[k - 2] == "G70 P10 Q20 F0.005"


def test_after_a_contour_whose_start_is_not_traced_the_position_is_unknown():
    """A roughing cycle's block with a code the engine does not trace (kept with
    --keep-unsupported): where the control goes back to is not known, so the increments after the
    contour are copied as written, not aimed from a place the output is not at."""
    text = "O1\nG18 G21\nG01 X50. Z2. F0.3\nG71 P10 Q20 U0.4 W0.1 D1. F0.2 G66\nN10 G00 X20. Z2.\nG01 Z-20.\nN20 X40.\nU-4. W-3.\nM30\n"
    out = nc.parse(text, dialect="fanuc-lathe").correct(fields.Shift((0.01, 0, 0.02)), keep_unsupported=True)
    assert out.text.splitlines()[-2] == "U-4. W-3."


def test_after_a_contour_the_nose_turns_from_the_return_to_its_start():
    """After the contour the control goes back to the cycle's start: the next move turns from that
    return, not from the contour's last block (no reversal there)."""
    text = (
        "O1\nG18 G21\nT0101\nG42 G01 X50. Z2. F0.3\nG71 P10 Q20 U0.4 W0.1 D1. F0.2\nN10 G01 X20. Z2.\n"
        "G01 Z-20.\nX40.\nN20 Z-30.\nG01 W3.\nG40 U4.\nM30\n"
    )
    prog = nc.parse(text, dialect="fanuc-lathe", tools={1: 0.8})
    assert prog.unsupported == ()
    prog.correct(fields.Shift((0.01, 0, 0.02)))


def test_after_an_offset_on_x_in_diameter_mode_kept_as_written_x_is_unknown():
    """G92 X50 under G7 is not followed (whether its X is a diameter); kept with
    --keep-unsupported, the moves after it are not corrected in the old frame (they were: 100 µm
    off under a field whose x grows by 1 % of X), they are left as written until the program
    tells where the tool is, and the correction says so."""
    from ncadapt import nc

    src = "G7 G18 G21 G90\nF100\nG0 X30 Z2\nG1 X20 Z0\nG92 X50\nG1 X40 Z-10\nG1 Z-20\nM2\n"
    prog = nc.parse(src, dialect="linuxcnc-lathe")
    assert [u.line for u in prog.unsupported] == [5]
    out = prog.correct(lambda p: np.c_[0.01 * p[:, 0], 0 * p[:, 0], 0 * p[:, 0]], keep_unsupported=True)
    assert out.text.splitlines()[-3:] == ["G1 X40 Z-10", "G1 Z-20", "M2"]
    assert any("not corrected because the position is unknown" in w for w in out.correction.warnings)
