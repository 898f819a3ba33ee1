"""Sinumerik 840D programs: run into straight G-code as the control runs them, corrected, and
written back in Sinumerik's syntax.

Two truths, independent of the reader: the Sinumerik-flavoured interpreter nc-gcode-interpreter
(positions at each block's end) where it reads the program right, and positions worked out by
hand from Siemens' rules where it does not (it reads no R parameters, CIP, ``=AC(…)`` or labels,
adds the frame to an ``=IC(…)`` value a second time, keeps the frame after ``TRANS`` without axes,
and adds G91 values to zero). LinuxCNC's rs274 runs the straight program the engine corrects.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import ncgi
import rs274
from helpers import refused_at
from ncadapt import fields, nc
from ncadapt import sinumerik as sn
from ncadapt.cli import main
from ncadapt.errors import InputError, RefusedError

DATA = Path(__file__).parent / "data" / "sinumerik"
CORPUS = Path(__file__).resolve().parents[1].parent / "shared" / "corpus" / "nc"
needs_rs274 = pytest.mark.skipif(rs274.RS274 is None, reason="LinuxCNC rs274 not installed")
needs_oracle = pytest.mark.skipif(not ncgi.AVAILABLE, reason="nc-gcode-interpreter not installed")


def linear(p: np.ndarray) -> np.ndarray:
    """A field whose z grows along X and Y (mm)."""
    d = np.zeros_like(p)
    d[:, 2] = 0.01 + 0.001 * p[:, 0] + 0.0005 * p[:, 1]
    return d


def source(name: str) -> Path:
    if name.startswith("sinumerik__"):
        p = CORPUS / name
        if not p.is_file():
            pytest.skip(f"no corpus at {CORPUS}")
        return p
    return DATA / name


def straight_motion(data: bytes, tmp_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """rs274's end points of a straight (RS274NGC) program, consecutive repeats removed (mm), and
    whether the move to each is a rapid."""
    p = tmp_path / f"straight{len(list(tmp_path.iterdir()))}.ngc"
    p.write_bytes(data + b"M2\n")  # rs274 wants an end; one after the program's own changes nothing
    canon = rs274.canonical(p)
    assert canon.error is None, canon.error
    ends = canon.ends[:, :3]
    keep = np.any(np.abs(np.diff(np.vstack([np.zeros(3), ends]), axis=0)) > 0, axis=1)
    return ends[keep], np.array([k == "traverse" for k in canon.kinds])[keep]


def straight_ends(data: bytes, tmp_path: Path) -> np.ndarray:
    return straight_motion(data, tmp_path)[0]


# --------------------------------------------------------------------------- reading the program
@needs_rs274
@needs_oracle
@pytest.mark.parametrize("name", ["sinumerik__cead_arc.mpf", "sinumerik__cead_loop.mpf", "pocket.mpf"])
def test_straight_program_moves_as_the_oracle_runs_the_source(name, tmp_path):
    text = source(name).read_text()
    want = ncgi.ends(text)
    got = straight_ends(sn.translate(text.encode(), name).data, tmp_path)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, atol=ncgi.tolerance(want))


# the ends worked out from Siemens' rules (Programming Manual Fundamentals / Job Planning)
FLOW_ENDS = [
    (0, 0, 5),
    (0, 0, -0.5),  # DEPTH = -SQRT(4)/4
    (20.5, 2.5, -0.5),  # R2 = R1*2 + 0.5; Y = I_ROW*STEP
    (10, 2.5, -0.5),  # row 1 odd: X=AC(R1)
    (20.5, 5, -0.5),
    (10.25, 5, -0.5),  # row 2 even: X=IC(-R2/2)
    (20.5, 7.5, -0.5),
    (10, 7.5, -0.5),
    (10, 8.75, -0.5),  # WHILE: Y=IC(1.25) twice
    (10, 10, -0.5),
    (3, 10, -0.5),  # REPEAT … UNTIL: R3 = 1, then 0
    (0, 10, -0.5),
    (5, 8, -0.5),  # IF … GOTOF SKIP jumps over X99 Y99; G91 X5 Y-2
    (5, 8, 5),
]
FRAMES_ENDS = [
    (0, 0, 5),
    (110, 30, -1),  # TRANS X100 Y20
    (115, 40, -1),  # ATRANS X5 adds
    (120, 40, -1),  # X=IC(5): 5 from where the tool is
    (0, 0, 5),  # TRANS without axes takes the frame away
]
INCH_ENDS = [(0, 0, 0.2), (0, 0, -0.05), (1.5, 0.25, -0.05), (1, 1, -0.05), (2, 2, -0.05)]  # then SUPA Z0


@needs_rs274
@pytest.mark.parametrize(
    ("name", "want", "scale"),
    [("flow.mpf", FLOW_ENDS, 1.0), ("frames.mpf", FRAMES_ENDS, 1.0), ("inch.mpf", INCH_ENDS, 25.4)],
)
def test_straight_program_moves_as_siemens_rules_say(name, want, scale, tmp_path):
    got = straight_ends(sn.translate((DATA / name).read_bytes(), name).data, tmp_path)
    want = np.array(want, dtype=float) * scale
    # the SUPA retract goes to machine Z0, which rs274 (no machine offsets) puts at Z0
    np.testing.assert_allclose(got[: len(want)], want, atol=1e-9)


#: rotation.mpf by hand (machine coordinates): base = TRANS + R(angle) · (frame coordinates), an
#: ATRANS along the turned axes, AROT adding to the angle about the frame's origin, ROT alone
#: taking the whole frame away. (nc-gcode-interpreter reads AROT Z-30 as a move to Z-30.)
ROTATION_ENDS = [
    (0, 0, 5),
    (0, 0, -1),
    (10, 15, -1),  # X10 Y0 turned 90: (0, 10), from (10, 5)
    (0, 15, -1),
    (0, 5, -1),  # G2 CR=10 to X0 Y10: (-10, 0)
    (10, 5, -1),  # G3 back to the frame's origin
    (10, 11, -1),  # ATRANS X5 along the turned X: origin (10, 10); X1 Y0 is (0, 1) from it
    (9, 13, -1),  # G91 X2 Y1 turned: (-1, 2)
    (10 + 4 * math.cos(math.radians(60)), 10 + 4 * math.sin(math.radians(60)), -1),  # AROT Z-30: 60 in all
    (0, 0, -1),
    (0, 0, 5),
]


@needs_rs274
def test_a_rotated_frame_moves_as_siemens_rules_say(tmp_path):
    tr = sn.translate((DATA / "rotation.mpf").read_bytes(), "rotation.mpf")
    np.testing.assert_allclose(straight_ends(tr.data, tmp_path), np.array(ROTATION_ENDS, dtype=float), atol=1e-6)


ROTATED_LOOP = """G17 G90 G0 X0 Y0 Z5
TRANS X20
AROT RPL=45
G1 Z-1 F100
R1 = 0
WHILE R1 < 2
  G1 X=10 + R1 * 5 Y0
  G2 X=10 + R1 * 5 Y5 I0 J2.5
  R1 = R1 + 1
ENDWHILE
ROT
G0 Z5
M30
"""


@needs_rs274
@pytest.mark.parametrize("name", ["rotation.mpf", "loop"])
@pytest.mark.parametrize("field", ["shift", "linear"])
def test_a_rotated_frame_is_written_back_in_its_own_coordinates(tmp_path, field, name):
    """Corrected, the moves made in the turned frame are written in its coordinates (X Y both, I J
    turned back), in place or (a loop) straight: read back, the program moves as the engine's
    corrected straight program, and its frame lines are as written."""
    data = (DATA / name).read_bytes() if name != "loop" else ROTATED_LOOP.encode()
    f = fields.Shift((0.01, -0.02, 0.03)) if field == "shift" else linear
    tr = sn.translate(data, name)
    straight = nc.parse(tr.data).correct(f).data
    if name == "loop":  # its lines run twice, corrected differently
        with pytest.raises(sn.NeedsExpand):
            sn.assemble(tr, straight)
    text, _, how = sn.assemble(tr, straight, expand=True)
    assert how == ("straight" if name == "loop" else "in place")
    got = straight_ends(sn.translate(text).data, tmp_path)
    np.testing.assert_allclose(got, straight_ends(straight, tmp_path), atol=1e-4)
    lines = text.decode().splitlines()
    frames = {"TRANS X10 Y5", "AROT RPL=90", "ATRANS X5", "AROT Z-30", "ROT"} if name != "loop" else {"AROT RPL=45"}
    assert frames <= set(lines), lines
    if name != "loop" and field == "shift":
        # the G2 stays an arc, its radius as written; by hand, the shift (0.01, -0.02) in the frame
        # turned 90 degrees is (-0.02, -0.01)
        assert "G2 X-0.02 Y9.99 CR=10" in lines, lines


ROTATION_REVIEW = {
    # a motion code alone, where the engine brings the tool to the corrected start
    "motion code": ("G17 G90 G0 X0 Y0 Z5\nROT Z90\nG0 X10 Y0 Z-1\nG1 F100\nG1 X20 Y0\nG0 Z5\nM30\n", None),
    # a unit change under a rotation: the straight program's numbers change unit
    "inch": ("G71 G17 G90 G0 X0 Y0 Z5\nAROT Z90\nG1 X5 Y-10 F100\nG70\nG1 Z-0.04\nG0 Z0.2\nM30\n", None),
    # G91 after a rotation, on the axis set absolute since: Y, which it does not name, stays unwritten
    "g91": ("G17 G90 G0 X0 Y0 Z5\nROT Z30\nG1 Z-1 F100\nG1 X10\nG91 G1 X5\nG90 G0 Z5\nM30\n", None),
}


def _dx_by_z(q):
    d = np.zeros_like(q)
    d[:, 0], d[:, 2] = 0.01 * q[:, 2], 0.02
    return d


@needs_rs274
@pytest.mark.parametrize("name", sorted(ROTATION_REVIEW))
def test_rotations_found_in_review_are_written_back_right(tmp_path, name):
    """Read back, the written program moves as the engine's corrected straight program."""
    text, _ = ROTATION_REVIEW[name]
    p = tmp_path / "p.mpf"
    p.write_text(text)
    f = fields.Shift((0.1, 0.2, 0.05)) if name == "motion code" else _dx_by_z
    c = correct(p, tmp_path / "o.mpf", f)
    assert c.expanded["written"] == "in place"
    straight = nc.parse(sn.translate(p.read_bytes()).data).correct(f).data
    got = straight_ends(sn.translate((tmp_path / "o.mpf").read_bytes()).data, tmp_path)
    # (rs274 prints 4 decimals of the program's unit: 2.54 µm in inches)
    np.testing.assert_allclose(got, straight_ends(straight, tmp_path), atol=2e-4 if name != "inch" else 2.6e-3)
    if name == "motion code":  # by hand: the shift (0.1, 0.2) turned back 90 degrees is (0.2, -0.1)
        assert (tmp_path / "o.mpf").read_text().splitlines()[3] == "G1 X10.2 Y-0.1 Z-0.95 F100"
    if name == "inch":  # Y (5 mm) in inches, turned to the frame's X
        assert (tmp_path / "o.mpf").read_text().splitlines()[5] == "G1 Z-0.03921 X0.19685 Y-0.3933"


@needs_rs274
def test_a_tangent_is_turned_with_the_frame(tmp_path):
    """CT after AROT Z90: the move before it heads +X (machine), the CT ends at machine (20, 10)
    (frame X10 Y-20 turned 90): by Siemens' rule a G3 about machine (10, 10)."""
    tr = sn.translate(b"G17 G90 G0 X0 Y0 Z5\nG1 Z-1 F100\nG1 X10 Y0\nAROT Z90\nCT X10 Y-20\nM30\n")
    assert [it.rs for it in tr.items if it.line == 4] == ["G3 X20 Y10 I0 J10"]


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("G0 X0 Y0 Z0\nROT X30\n", "only a rotation about Z"),
        ("G0 X0 Y0 Z0\nAROT Y10\n", "only a rotation about Z"),
        ("G0 X0 Y0 Z0\nG18\nROT RPL=30\n", "in G18"),
        ("G0 X0 Y0 Z0\nTRANS RPL=30\n", "RPL= with TRANS"),
        ("G0 X0 Y0 Z0\nROT Z30\nG18 G2 X1 Z1 CR=2\n", "its plane turns"),
        ("G0 X0 Y0 Z0\nROT Z30\nG91 G1 X1\n", "SD42440"),
        ("G0 Z0\nROT Z30\nG1 X1 F100\n", "position of X and Y"),
        # from review
        ("G0 X0 Y0 Z5\nROT Z30 TRANS X5\n", "a block of its own"),
        ("G0 X0 Y0 Z5\nROT Z90\nG0 X10 Y0\nSUPA G0 Y20\nG1 Y5 F100\n", "position of X and Y"),
        ("G0 X0 Y0 Z5\nTRANS X100\nAROT Z90\nG1 X0 Y0 F100\nATRANS X5\nG91 G1 X3\n", "SD42440"),
        ("G0 X0 Y0 Z5\nAROT\n", "without an angle"),
        ("G0 X0 Y0 Z5\nROT RPL=1EX400\n", "out of range"),
        ("G0 X0 Y0 Z5\nAROT Z=1EX308\nAROT Z=1EX308\n", "out of range"),
        ("G0 X0 Y0 Z5\nATRANS X=1EX308\n", "out of range"),
        ("G0 X0 Y0 Z5\nG1 X10 Y0 RPL=30 F100\n", "RPL= without ROT or AROT"),
    ],
)
def test_rotations_refused(text, says):
    with pytest.raises(InputError, match=re.escape(says)):
        sn.translate(text.encode())


@needs_rs274
def test_arcs_have_the_centres_siemens_rules_give(tmp_path):
    p = tmp_path / "arcs.ngc"
    p.write_bytes(sn.translate((DATA / "arcs.mpf").read_bytes()).data)
    canon = rs274.canonical(p)
    arcs = [(a[0], round(a[1], 9), round(a[2], 9), a[3]) for a in canon.arcs if a is not None]
    assert arcs == [
        (-1, 10.0, 0.0, "CANON_PLANE_XY"),  # G2 X20 Y0 I10 J0 from (0, 0)
        (1, 20.0, 10.0, "CANON_PLANE_XY"),  # G3 CR=10 from (20, 0) to (30, 10): the short way, centre (20, 10)
        (-1, 40.0, 10.0, "CANON_PLANE_XY"),  # G2 CR=-10 over a diameter
        (-1, 60.0, 10.0, "CANON_PLANE_XY"),  # CIP through (60, 20): the circle about (60, 10), clockwise
        (1, 80.0, 10.0, "CANON_PLANE_XY"),  # G3 I=AC(80) J=AC(10): the centre in absolute coordinates
        (-1, -1.0, 95.0, "CANON_PLANE_XZ"),  # G18 G2 I5 K0 from X90: centre Z-1 X95 (rs274: Z first)
    ]


@pytest.mark.parametrize(
    ("expr", "want"),
    [
        ("2 + 3 * 4", 14.0),
        ("7 DIV 2", 3.0),
        ("-7 DIV 2", -3.0),
        ("7 MOD 3", 1.0),
        ("SIN(30) + COS(60)", 1.0),
        ("ATAN2(1, -1)", 135.0),
        ("POT(3) + SQRT(16) + ABS(-1)", 14.0),
        ("TRUNC(-2.7) + ROUND(2.5)", 1.0),
        ("1 == 1 + 1EX-14", 1.0),  # relative equality
        ("1 == 1.000001", 0.0),
        ("3 > 1 AND 0", 1.0),  # comparisons last: 3 > (1 AND 0)
        ("(3 > 1) AND 0", 0.0),
        ("NOT 0 OR 0", 1.0),
        ("MINVAL(4, 2) + MAXVAL(4, 2)", 6.0),
        # bit operators (Siemens: B_NOT first, then after + and -: B_AND, B_XOR, B_OR, then AND)
        ("6 B_AND 3", 2.0),
        ("6 B_OR 3", 7.0),
        ("6 B_XOR 3", 5.0),
        ("1 B_OR 2 B_AND 6", 3.0),  # 1 B_OR (2 B_AND 6)
        ("1 + 1 B_AND 3", 2.0),  # (1 + 1) B_AND 3
        ("B_NOT 0 B_AND 5", 5.0),  # (B_NOT 0) B_AND 5: all bits set
        ("1 B_OR 0 AND 0", 0.0),  # (1 B_OR 0) AND 0
    ],
)
def test_expressions_follow_siemens_priorities(expr, want):
    tr = sn.translate(f"DEF REAL V\nV = {expr}\nG1 X=V F100\nM30\n".encode())
    assert tr.items[1].rs == f"G1 X{sn._fmt(want)}"


def test_int_variables_round_and_for_counts_to_its_end():
    tr = sn.translate(b"DEF INT N\nN = 2.5\nG1 X=N F1\nN = 2.4999\nG1 X=N\nFOR N = 1 TO 2\nG1 Y=N\nENDFOR\nM30\n")
    assert [it.rs for it in tr.items if it.kind == "motion"] == ["G1 X3", "G1 X2", "G1 Y1", "G1 Y2"]
    assert tr.runs.tolist() == [1, 1, 1, 1, 1, 1, 2, 2, 1]


# ----------------------------------------------------------------------------------- refusals
@pytest.mark.parametrize(
    ("text", "line", "says"),
    [
        ("G0 X0 Y0\nROT X45\n", 2, "only a rotation about Z"),
        ("G0 X0 Y0\nSCALE X2\n", 2, "scaling or mirroring"),
        ("G0 X0 Y0\nAMIRROR X0\n", 2, "scaling or mirroring"),
        ("G1 X0 Y0 F100\nG41 X5\n", 2, "cutter radius compensation"),
        ("G1 X=R5 F100\n", 1, "R5 is read before the program sets it"),
        ("G1 X=$AA_IM[X] F100\n", 1, "system variable"),
        ("G1 X1 X=2 F100\n", 1, "X is written twice"),
        ("G1 X=IC(5) F100\n", 1, "not known here"),
        ("X1 Y1\n", 1, "motion mode"),
        ("G1 X0 Y0 F100\nCT X10 Y10\n", 2, "CT after a move whose direction"),
        ("G1 X0 Y0 F100\nG2 X10 Y0 I5 TURN=2\n", 2, "TURN="),
        ("G54\nG1 X0 Y0 F100\nG55\n", 3, "changes the work system"),
        ("DEF REAL A[3]\n", 1, "arrays"),
        ("G1 X0 F100\nIF Q > 1\nENDIF\n", 2, "'Q' is not defined"),
        ("G1 X0 F100\n/G1 X5\n", 2, "skipped block"),
        ("G1 X0 Y0 Z5 F100\nMCALL CYCLE81(10, 0, 2, -5)\n", 2, "MCALL"),
        ("G1 X0 Y0 F100\nCYCLE84(10, 0, 2, -5)\n", 2, "CYCLE84 calls a cycle"),
        ("G1 X0 Y0 F100\nL100\n", 2, "L100 calls a subprogram"),
        ("G1 X0 Y0 F100\nG2 X10 Y0\n", 2, "without a centre"),
        ("G1 X0 Y0 F100\nCIP X10 Y0 I1=5 J1=0\n", 2, "three points on a line"),
        ("G1 X0 Y0 F100\nAP=45 RP=10\n", 2, "polar"),
        ("G1 X0 F100\nGOTOF NOWHERE\n", 2, "no such label"),
        ("G1 X0 F100\nIF 1\nG1 X1\n", 2, "IF without its end"),
        ("G1 X0 F100\nENDWHILE\n", 2, "ENDWHILE without"),
        ("G1 X0 F100\nX=1/0\n", 2, "division by zero"),
    ],
)
def test_refused_at_its_line(text, line, says):
    refused_at(sn.translate, text, "p.mpf", line, says)


def test_a_loop_that_does_not_end_is_refused(monkeypatch):
    monkeypatch.setattr(sn, "MAX_BLOCKS", 1000)
    with pytest.raises(InputError, match="more than 1,000 blocks"):
        sn.translate(b"G1 X0 F100\nLOOP\nG1 X1\nENDLOOP\n")


@pytest.mark.parametrize(
    ("name", "line", "says"),
    [
        ("sinumerik__cead_simple.mpf", 2, "G2 without a centre"),
        ("sinumerik__cead_spline.mpf", 10, "spline interpolation"),
        ("sinumerik__cead_trans.mpf", 1, "motion mode"),
        ("sinumerik__syil_TEST.MPF", 13, "WARMUP_CYCLE calls a subprogram"),  # its folder not given
        ("sinumerik__syil_WARMUP_CYCLE.SPF", 9, "PROC"),
    ],
)
def test_corpus_programs_refused_at_their_line(name, line, says):
    p = source(name)
    with pytest.raises(InputError) as e:
        sn.translate(p.read_bytes(), str(p))
    assert (e.value.line, says in e.value.message) == (line, True), e.value


# ------------------------------------------------------------------------------ the corrected program
def correct(path: Path, out: Path, field, **kw):
    return nc.correct_file(path, out, field, dialect="sinumerik", **kw)


@pytest.mark.parametrize(
    "name",
    [
        "sinumerik__cead_arc.mpf",
        "sinumerik__cead_loop.mpf",
        "pocket.mpf",
        "flow.mpf",
        "frames.mpf",
        "inch.mpf",
        "arcs.mpf",
    ],
)
def test_zero_correction_writes_the_program_as_it_is(name, tmp_path):
    p = source(name)
    c = correct(p, tmp_path / "out.mpf", fields.Shift((0.0, 0.0, 0.0)))
    assert (tmp_path / "out.mpf").read_bytes() == p.read_bytes()
    assert c.expanded["written"] == "as it is"


@needs_rs274
@needs_oracle
@pytest.mark.parametrize("name", ["sinumerik__cead_arc.mpf", "sinumerik__cead_loop.mpf", "pocket.mpf"])
def test_a_shift_moves_every_cutting_end_in_the_oracle(name, tmp_path):
    """Rapids are not corrected (without --rapids): the oracle's ends of the output are those of the
    input, shifted where the move that ends there cuts."""
    p = source(name)
    c = correct(p, tmp_path / "out.mpf", fields.Shift((0.0, 0.0, 0.05)), expand=True)
    assert c.expanded["written"] in ("in place", "straight")
    before, after = ncgi.ends(p.read_text()), ncgi.ends((tmp_path / "out.mpf").read_text())
    # which of the input's ends a rapid reaches (rs274 on the straight program, which moves as
    # the oracle runs the input: test_straight_program_moves_as_the_oracle_runs_the_source)
    ends, rapid = straight_motion(sn.translate(p.read_bytes()).data, tmp_path)
    np.testing.assert_allclose(ends, before, atol=ncgi.tolerance(before))
    # the output, run by the oracle, has the input's cutting ends 0.05 higher
    cutting = before[~rapid] + [0.0, 0.0, 0.05]
    ok, where = ncgi.contains_in_order(after, cutting, ncgi.tolerance(after) + 1e-4)
    assert ok, where


@needs_rs274
@needs_oracle
@pytest.mark.parametrize(("name", "expand"), [("pocket.mpf", True), ("arcs.mpf", False), ("frames.mpf", False)])
def test_the_written_program_moves_as_the_corrected_straight_program(name, expand, tmp_path):
    """The engine corrects the straight program; what is written back in Sinumerik's syntax, run
    by the oracle (or read back, where the oracle cannot read it), ends where rs274 runs the
    engine's straight output."""
    p = source(name)
    tr = sn.translate(p.read_bytes(), name)
    straight = nc.parse(tr.data).correct(linear).data
    want = straight_ends(straight, tmp_path)
    text, _, how = sn.assemble(tr, straight, expand)
    assert how == ("straight" if expand else "in place")
    try:
        got = ncgi.ends(text.decode())
    except ValueError:  # CIP, AC(…): the reader reads its own output back
        got = straight_ends(sn.translate(text).data, tmp_path)
    if name == "frames.mpf":  # the oracle adds the frame to IC values twice: read back instead
        got = straight_ends(sn.translate(text).data, tmp_path)
    np.testing.assert_allclose(got, want, atol=ncgi.tolerance(want) + 1e-4)


def test_a_field_written_in_place_keeps_every_other_line(tmp_path):
    p = DATA / "frames.mpf"
    c = correct(p, tmp_path / "out.mpf", linear)
    src = p.read_text().splitlines()
    out = (tmp_path / "out.mpf").read_text().splitlines()
    assert c.expanded["written"] == "in place"
    assert c.expanded["lines_rewritten"] == 3
    # N40 is cut in pieces after it; N60 and N70 get their Z; the frames, comments and the rest stay
    n40 = out.index(next(t for t in out if t.startswith("N40")))
    assert out[:n40] == src[:4]
    assert out[n40].endswith(" F300")  # the feed stays where it was written
    assert out[out.index("N50 ATRANS X5")] == "N50 ATRANS X5"
    z = {t.split()[0]: t for t in out if t.startswith(("N60", "N70"))}
    # the field at the frame's position: X 115 Y 40, then X 120 Y 40
    assert z["N60"] == "N60 G1 X10 Y20 Z-0.855"
    assert z["N70"] == "N70 G1 X15 Z-0.85"  # X=IC(5) written as the position it reaches
    assert out[-3:] == src[-3:]


def test_a_move_in_a_loop_needs_expand(tmp_path):
    p = DATA / "flow.mpf"
    with pytest.raises(RefusedError) as e:
        correct(p, tmp_path / "out.mpf", linear)
    assert e.value.details[0]["line"] == 11 and e.value.details[0]["runs"] == 3
    assert not (tmp_path / "out.mpf").exists()
    c = correct(p, tmp_path / "out.mpf", linear, expand=True)
    assert c.expanded["written"] == "straight"


@needs_oracle
def test_the_expanded_program_is_the_hand_worked_path_displaced(tmp_path):
    """flow.mpf uses what the oracle cannot read (R parameters, labels); its straight output is
    plain G-code the oracle reads: its ends are the hand-worked ends, displaced by the field at
    each cutting end."""
    correct(DATA / "flow.mpf", tmp_path / "out.mpf", linear, expand=True)
    out = (tmp_path / "out.mpf").read_bytes()
    want = np.array(FLOW_ENDS, dtype=float)
    cutting = np.ones(len(want), dtype=bool)
    cutting[[0, -1]] = False  # the rapids
    want[cutting] += linear(want[cutting])
    # the oracle up to the G91 move (it adds G91 values to zero), the reader's own read-back for all
    got = ncgi.ends(out.decode())
    np.testing.assert_allclose(got[:12], want[:12], atol=2e-4)
    if rs274.RS274 is not None:
        np.testing.assert_allclose(straight_ends(sn.translate(out).data, tmp_path), want, atol=1e-4)


def test_a_cip_line_after_a_rewritten_one_keeps_its_motion_mode(tmp_path):
    """A CIP block rewritten as G2/G3 leaves G2/G3 in force: the next CIP block, written without
    its motion code and left as it is, gets CIP written back."""
    p = tmp_path / "cip.mpf"
    p.write_text(
        "G90 G17 G71\nG0 X0 Y0 Z1\nG1 Z0 F100\nCIP X20 Y0 I1=10 J1=10\nX40 Y0 I1=30 J1=10\nX60 Y0 I1=50 J1=10\n"
        "G0 Z5\nM30\n"
    )

    def left(q):  # 0.01 mm up left of X 30, nothing right of X 40
        d = np.zeros_like(q)
        d[:, 2] = 0.01 * np.clip((40.0 - q[:, 0]) / 10.0, 0.0, 1.0)
        return d

    correct(p, tmp_path / "out.mpf", left)
    out = (tmp_path / "out.mpf").read_text().splitlines()
    assert "CIP X60 Y0 I1=50 J1=10" in out
    back = sn.translate((tmp_path / "out.mpf").read_bytes())
    assert [it.mode for it in back.items if it.kind == "motion"][-2] == "CIP"


# ------------------------------------------------------------------------------------ command line
def test_cli_detects_reads_and_says_how_it_wrote(tmp_path):
    p = tmp_path / "part.mpf"
    p.write_bytes((DATA / "pocket.mpf").read_bytes())
    r = CliRunner().invoke(
        main,
        ["correct", str(p), "--shift", "0,0,0.05", "-o", str(tmp_path / "o.mpf"), "--json", str(tmp_path / "c.json")],
    )
    assert r.exit_code == 1, r.output  # the pocket's rows are corrected differently on each pass
    assert "--expand" in r.output and not (tmp_path / "o.mpf").exists()
    r = CliRunner().invoke(main, ["correct", str(p), "--shift", "0,0,0.05", "-o", str(tmp_path / "o.mpf"), "--expand"])
    assert r.exit_code == 0, r.output
    assert "Sinumerik 840D (detected" in r.output and "the corrected program is written straight" in r.output
    r = CliRunner().invoke(main, ["inspect", str(p)])
    assert r.exit_code == 0, r.output


def test_cli_refusal_names_the_line(tmp_path):
    p = tmp_path / "spline.mpf"
    p.write_text("G1 X0 Y0 F100\nBSPLINE\nX10 Y5\n")
    r = CliRunner().invoke(main, ["correct", str(p), "--shift", "0,0,0.05", "-o", str(tmp_path / "o.mpf")])
    assert r.exit_code == 2
    assert re.search(r"spline\.mpf:2:\d+: error: spline interpolation is not followed", r.output), r.output
    assert not (tmp_path / "o.mpf").exists()


# ------------------------------------------------------------------------------ found in review
def test_a_stop_on_a_line_cut_in_pieces_goes_to_its_last_piece(tmp_path):
    """M30 (M0, M1, M2, M17) acts after its block's motion: on a rewritten line cut in pieces it
    must end the last piece, not the first."""
    p = tmp_path / "end.mpf"
    p.write_text("N10 G0 X0 Y0 Z0\nN20 G1 X100 Y0 F100 M30 ; the end\nN30 G1 X0\n")

    def bowl(q):
        d = np.zeros_like(q)
        d[:, 2] = 1e-6 * q[:, 0] ** 2
        return d

    correct(p, tmp_path / "out.mpf", bowl)
    out = (tmp_path / "out.mpf").read_text().splitlines()
    ended = [k for k, t in enumerate(out) if "M30" in t.split(";")[0]]
    assert len(out) > 4 and ended == [len(out) - 2]  # the last piece of N20, before N30
    assert out[1].startswith("N20 G1") and out[1].endswith("F100 ; the end")


@needs_rs274
def test_the_motion_mode_written_back_follows_the_run_not_the_text(tmp_path):
    """N50 (run) is rewritten as G2 or pieces; N70 (not run) is a CIP: N90, which relies on the
    CIP mode in force when it runs, must get CIP written."""
    p = tmp_path / "modes.mpf"
    p.write_text(
        "N10 G0 X0 Y0 Z0\nN20 R1=1\nN30 G1 X10 F100\nN40 IF R1==1\nN50 CIP X30 Y0 I1=20 J1=10\nN60 ELSE\n"
        "N70 CIP X30 Y0 I1=20 J1=-10\nN80 ENDIF\nN90 X50 Y0 I1=40 J1=10\nN100 G1 X60\n"
    )

    def middle(q):
        d = np.zeros_like(q)
        d[:, 2] = 0.02 * np.clip(1.0 - np.abs(q[:, 0] - 20.0) / 10.0, 0.0, 1.0)
        return d

    correct(p, tmp_path / "out.mpf", middle)
    out = (tmp_path / "out.mpf").read_text().splitlines()
    assert "N90 CIP X50 Y0 I1=40 J1=10" in out
    tr = sn.translate(p.read_bytes())
    want = straight_ends(nc.parse(tr.data).correct(middle).data, tmp_path)
    got = straight_ends(sn.translate((tmp_path / "out.mpf").read_bytes()).data, tmp_path)
    np.testing.assert_allclose(got, want, atol=1e-4)


@needs_rs274
@pytest.mark.parametrize(
    ("text", "x_mm"),
    [
        ("G71\nG0 X25.4 Y0 Z0\nG70\nG1 X=IC(1) F10\n", 50.8),  # 25.4 mm and 1 inch
        ("G71\nG0 X25.4 Y0 Z0\nG70\nG91 G1 X=AC(2) F10\n", 50.8),
        ("G71\nTRANS X25.4\nG70\nATRANS X1\nG0 X0 Y0 Z0\n", 50.8),  # the frame stays where it is
    ],
)
def test_a_change_of_units_keeps_positions_and_frames(text, x_mm, tmp_path):
    ends = straight_ends(sn.translate(text.encode()).data, tmp_path)
    assert ends[-1][0] == pytest.approx(x_mm, abs=1e-4)


@pytest.mark.parametrize(
    ("text", "line", "says"),
    [
        ("G0 X10 Y0 Z0\nG1 F100\nCIP X30 Y0 Z10 I1=20 J1=10\n", 3, "CIP moving Z"),
        ("R1=0\nG0 X0 Y0 Z0\nGOTOF L1\nFOR R1=1 TO 3\nL1: G1 X=R1 F100\nENDFOR\n", 6, "jump into a loop"),
        ("G0 X0 Y0 Z0\nG1 X10 F100\nATRANS X5\nG91 X10\n", 4, "SD42440"),
        ("G0 X0 Y0 Z0\nG1 X10 F100\nATRANS X5\nX=IC(10)\n", 4, "SD42440"),
        ("G54\nG91 G1 X10 F100\n", 2, "SD42440"),
        ("G0 X=1EX999\n", 1, "out of range"),
        ("DEF INT N\nN = 3EX9\n", 2, "INT's range"),
    ],
)
def test_refused_after_review(text, line, says):
    refused_at(sn.translate, text, "p.mpf", line, says)


def test_an_absolute_move_after_a_frame_change_allows_incremental_ones_again(tmp_path):
    tr = sn.translate(b"G0 X0 Y0 Z0\nG1 X10 F100\nATRANS X5\nG1 X10\nX=IC(10)\nG91 X1\n")
    assert [it.rs for it in tr.items if it.kind == "motion"][-3:] == ["G1 X10", "X20", "X1"]


@pytest.mark.parametrize(
    ("text", "xs"),
    [
        # CASE dispatch: 4 + 3 is 7
        (
            "DEF INT V=4\nG1 X0 F100\nCASE(V+3) OF 7 GOTOF SEVEN 9 GOTOF NINE DEFAULT GOTOF OTHER\nNINE: X9\n"
            "GOTOF ENDE\nSEVEN: X7\nGOTOF ENDE\nOTHER: X1\nENDE: M30\n",
            ["X0", "X7"],
        ),
        (
            "DEF INT V=2\nG1 X0 F100\nCASE(V) OF 7 GOTOF A 9 GOTOF B DEFAULT GOTOF C\nA: X7\nB: X9\nC: X3\n",
            ["X0", "X3"],
        ),
        ("DEF INT V=2\nG1 X0 F100\nCASE(V) OF 7 GOTOF A\nX5\nA: X7\n", ["X0", "X5", "X7"]),
        # a block number without its N is a destination too; GOTOC to nothing goes on
        ("G1 X0 F100\nGOTOF 90\nX5\nN90 X9\nGOTOC NOWHERE\nX4\n", ["X0", "X9", "X4"]),
    ],
)
def test_case_and_jumps(text, xs):
    tr = sn.translate(text.encode())
    assert [it.rs.split()[-1] for it in tr.items if it.kind == "motion"] == xs


@needs_rs274
def test_tangential_arcs_have_the_centres_their_tangents_give(tmp_path):
    """CT continues the path's direction: worked out by hand, a quarter circle left about (10, 10),
    three quarters right about (30, 10) (the direction +Y at (20, 10)), a CR arc about (30, 10) by
    the short way, then right about (50, 10) from the direction +Y at (40, 10)."""
    p = tmp_path / "ct.ngc"
    prog = b"G17 G0 X0 Y0 Z0\nG1 X10 F100\nCT X20 Y10\nCT X30 Y0\nG3 X40 Y10 CR=10\nCT X50 Y0\n"
    p.write_bytes(sn.translate(prog).data + b"M2\n")
    canon = rs274.canonical(p)
    arcs = [(a[0], round(a[1], 9), round(a[2], 9)) for a in canon.arcs if a is not None]
    assert arcs == [(1, 10.0, 10.0), (-1, 30.0, 10.0), (1, 30.0, 10.0), (-1, 50.0, 10.0)]


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("G0 X0 Y0 Z0\nCT X10 Y10\n", "direction"),  # nothing before it in the plane
        ("G0 X0 Y0 Z0\nG1 Z-1 F100\nCT X10 Y10\n", "direction"),  # a plunge: no direction in G17
        ("G0 X0 Y0 Z0\nG1 X10 F100\nCT X20 Y0\n", "straight line"),
        ("G0 X0 Y0 Z0\nG1 X10 F100\nCT X20 Y5 I5\n", "end point only"),
    ],
)
def test_tangential_arcs_refused(text, says):
    with pytest.raises(InputError, match=says):
        sn.translate(text.encode())


def test_a_ct_line_after_a_rewritten_one_is_written_as_its_arc(tmp_path):
    p = tmp_path / "ct.mpf"
    p.write_text("G17 G0 X0 Y0 Z0\nG1 X10 F100\nCT X20 Y10\nX30 Y20\nG0 Z5\n")

    def low(q):  # 0.01 mm up left of X 12, nothing right of X 18
        d = np.zeros_like(q)
        d[:, 2] = 0.01 * np.clip((18.0 - q[:, 0]) / 6.0, 0.0, 1.0)
        return d

    correct(p, tmp_path / "out.mpf", low)
    out = (tmp_path / "out.mpf").read_text().splitlines()
    # a CT after a rewritten move would start along the rewritten move's last piece, not along
    # the program's arc: it is written as its own arc (about (30, 10), clockwise)
    assert "G2 X30 Y20 I10 J0" in out and not any(t.startswith("CT") for t in out)
    tr = sn.translate(p.read_bytes())
    want = nc.parse(tr.data).correct(low).data
    back = sn.translate((tmp_path / "out.mpf").read_bytes())
    if rs274.RS274 is not None:
        np.testing.assert_allclose(straight_ends(back.data, tmp_path), straight_ends(want, tmp_path), atol=1e-4)


# ---------------------------------------------------------------------------- drilling cycles
@needs_rs274
def test_drilling_cycles_drill_where_siemens_cycles_do(tmp_path):
    """CYCLE81(RTP, RFP, SDIS, DP, DPR): a rapid to RFP + SDIS, a feed to DP (or RFP - DPR), a rapid
    to RTP, at the position reached (Siemens, Cycles: CYCLE81); CYCLE82 dwells DTB seconds at the
    bottom. rs274 runs the straight program (from the retraction plane: G98 G81)."""
    p = tmp_path / "drill.ngc"
    p.write_bytes(sn.translate((DATA / "drill.mpf").read_bytes()).data + b"M2\n")
    canon = rs274.canonical(p)
    assert canon.error is None, canon.error
    ends = ncgi.distinct(canon.ends)
    want = [(10, 20, 50), (10, 20, 2), (10, 20, -10), (10, 20, 50), (30, 20, 50), (30, 20, 2), (30, 20, -8)]
    np.testing.assert_allclose(ends[: len(want)], want, atol=1e-9)
    np.testing.assert_allclose(ends[len(want)], (30, 20, 50))
    assert "G98 G82 R2 Z-8 P1.5" in (tmp_path / "drill.ngc").read_text()  # the dwell, 1.5 s


def test_a_field_moves_a_cycle_s_reference_plane_and_depth(tmp_path):
    def slope(q):
        d = np.zeros_like(q)
        d[:, 2] = 0.01 + 0.001 * q[:, 0]
        return d

    c = correct(DATA / "drill.mpf", tmp_path / "out.mpf", slope)
    out = (tmp_path / "out.mpf").read_text().splitlines()
    # dz is 0.02 at X10, 0.04 at X30: RFP and DP move by it, DPR (relative to RFP) stays
    assert out[5] == "N50 CYCLE81(50, 0.02, 2, -9.98) ; first hole"
    assert out[7] == "N70 CYCLE82(50, 0.04, 2, , 8, 1.5)"
    assert c.expanded["written"] == "in place"
    correct(DATA / "drill.mpf", tmp_path / "flat.mpf", slope, expand=True)
    # --expand writes a program without loops in place too
    assert (tmp_path / "flat.mpf").read_text() == (tmp_path / "out.mpf").read_text()
    if rs274.RS274 is not None:  # what is written reads back to the engine's corrected straight program
        tr = sn.translate((DATA / "drill.mpf").read_bytes())
        want = straight_ends(nc.parse(tr.data).correct(slope).data, tmp_path)
        got = straight_ends(sn.translate((tmp_path / "out.mpf").read_bytes()).data, tmp_path)
        np.testing.assert_allclose(got, want, atol=1e-4)


DEEP = """G17 G90 G0 X10 Y20 Z50
G1 F100
N30 CYCLE83(50, 0, 2, -30, , -5, , 4, 1, 0.5, 1, 1) ; deep hole: first depth -5, degression 4
G0 X40
CYCLE83(50, 0, 2, , 25, , 6, 3, 0, 0, 1, 0, 3)
M30
"""


@needs_rs274
def test_a_deep_hole_cycle_is_drilled_on_its_line_and_moved_whole(tmp_path):
    """CYCLE83's pecks run on the hole's axis between RTP and DP: the straight program drills
    that line as one G81 (from RTP to RFP + SDIS, down to DP or RFP - DPR). Under a field the
    absolute planes RFP, DP and the first depth FDEP move by the field's z at the hole; FDPR,
    DAM and the rest, relative, stay (by hand: dz 0.02 at X10, 0.05 at X40)."""
    p = tmp_path / "deep.mpf"
    p.write_text(DEEP)
    got = straight_ends(sn.translate(p.read_bytes()).data, tmp_path)
    want = [(10, 20, 50), (10, 20, 2), (10, 20, -30), (10, 20, 50), (40, 20, 50), (40, 20, 2), (40, 20, -25)]
    np.testing.assert_allclose(got[: len(want)], want, atol=1e-9)

    def slope(q):
        d = np.zeros_like(q)
        d[:, 2] = 0.001 * q[:, 0] + 0.01
        return d

    correct(p, tmp_path / "out.mpf", slope)
    out = (tmp_path / "out.mpf").read_text().splitlines()
    assert (
        out[2]
        == "N30 CYCLE83(50, 0.02, 2, -29.98, , -4.98, , 4, 1, 0.5, 1, 1) ; deep hole: first depth -5, degression 4"
    )
    assert out[4] == "CYCLE83(50, 0.05, 2, , 25, , 6, 3, 0, 0, 1, 0, 3)"
    tr = sn.translate(p.read_bytes())
    want = straight_ends(nc.parse(tr.data).correct(slope).data, tmp_path)
    np.testing.assert_allclose(straight_ends(sn.translate("\n".join(out).encode()).data, tmp_path), want, atol=1e-4)
    assert correct(p, tmp_path / "zero.mpf", fields.Shift((0.0, 0.0, 0.0))).expanded["written"] == "as it is"


def test_a_cycle_whose_hole_the_field_moves_sideways_is_refused(tmp_path):
    with pytest.raises(RefusedError) as e:
        correct(DATA / "drill.mpf", tmp_path / "out.mpf", fields.Shift((0.01, 0.0, 0.0)))
    assert e.value.details[0]["line"] == 8 and "X or Y" in e.value.message
    assert not (tmp_path / "out.mpf").exists()


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("G0 X0 Y0 Z50\nG1 F100\nCYCLE81(1, 0, 2, -5)\n", "below the safety plane"),
        ("G0 X0 Y0 Z50\nG1 F100\nCYCLE81(50, 0, 2, -5, 3)\n", "different depths"),
        ("G0 X0 Y0 Z50\nG1 F100\nCYCLE81(50, 0, 2)\n", "without a final depth"),
        ("G0 X0 Y0 Z50\nG1 F100\nCYCLE85(50, 0, 2, -5)\n", "CYCLE85 calls a cycle"),
        ("G0 X0 Y0 Z50\nG1 F100\nCYCLE83(50, 0, 2, -5, , -2, 3)\n", "different first depths"),
        ("G0 X0 Y0 Z50\nG1 F100\nCYCLE83(50, 0, 2, -5, , -2, , 1, , , , , 1)\n", "only drilling along Z"),
        ("G0 X0 Y0 Z50\nG1 F100\nCYCLE83(50, 0, 2, -5, , -2, , 1, , , , 2)\n", "VARI=2"),
        ("G0 X0 Y0 Z50\nG1 F100\nCYCLE83(50, 0, 2, -5, , -2, , 1, , , , 1, 3, 1, 1, 0, 1, 7)\n", "17 arguments"),
        ("G0 X0 Y0 Z50\nG1 F100\nMCALL CYCLE81(50, 0, 2, -5)\n", "MCALL"),
        ("G0 X0 Y0 Z50\nG18 G1 F100\nCYCLE81(50, 0, 2, -5)\n", "G17 G90"),
        ("G0 Z50\nG1 F100\nCYCLE81(50, 0, 2, -5)\n", "not known"),
    ],
)
def test_drilling_cycles_refused(text, says):
    with pytest.raises(InputError, match=says):
        sn.translate(text.encode())


# ------------------------------------------------------------------------------- subprograms
SUB_MAIN = """; a main program calling a subprogram beside it
N10 G17 G90 G71 G54
N20 G0 X0 Y0 Z5
N30 G1 Z-1 F200
N40 SQUARE(10, 2)
N50 G0 Z5
N60 G0 X50 Y0
N70 G1 Z-1
N80 SQUARE(5, 1)
N90 G0 Z5
N100 M30
"""
SUB_SQUARE = """; a square of side SIDE from where the tool is, PASSES times
PROC SQUARE(REAL SIDE, INT PASSES) SAVE
DEF INT K
FOR K = 1 TO PASSES
  G91 G1 X=SIDE
  Y=SIDE
  X=-SIDE
  Y=-SIDE
ENDFOR
RET
"""


def _sub_files(tmp_path):
    (tmp_path / "SQUARE.SPF").write_text(SUB_SQUARE)
    p = tmp_path / "MAIN.MPF"
    p.write_text(SUB_MAIN)
    return p


@needs_rs274
def test_a_subprogram_beside_the_program_is_run(tmp_path):
    """SQUARE runs as the control runs it: its parameters by value, its FOR, G91 inside it, and SAVE
    giving G90 back; the ends worked out by hand."""
    p = _sub_files(tmp_path)
    tr = sn.translate(p.read_bytes(), str(p))
    got = straight_ends(tr.data, tmp_path)
    sq = lambda x0, side: [(x0 + side, 0, -1), (x0 + side, side, -1), (x0, side, -1), (x0, 0, -1)]  # noqa: E731
    want = [(0, 0, 5), (0, 0, -1), *sq(0, 10), *sq(0, 10), (0, 0, 5), (50, 0, 5), (50, 0, -1), *sq(50, 5), (50, 0, 5)]
    np.testing.assert_allclose(got, np.array(want, dtype=float), atol=1e-9)
    assert {it.sub for it in tr.items if it.line in (4, 8)} == {"SQUARE"}  # lines N40 and N80


def test_a_subprogram_whose_moves_change_needs_expand(tmp_path):
    p = _sub_files(tmp_path)
    c = correct(p, tmp_path / "zero.mpf", fields.Shift((0.0, 0.0, 0.0)))
    assert (tmp_path / "zero.mpf").read_bytes() == p.read_bytes() and c.expanded["written"] == "as it is"

    def slope(q):
        d = np.zeros_like(q)
        d[:, 2] = 0.001 * q[:, 0]
        return d

    with pytest.raises(RefusedError) as e:
        correct(p, tmp_path / "out.mpf", slope)
    assert e.value.details[0]["line"] == 5 and "SQUARE" in e.value.message
    c = correct(p, tmp_path / "out.mpf", slope, expand=True)
    text = (tmp_path / "out.mpf").read_text()
    assert c.expanded["written"] == "straight" and "SQUARE" not in text
    if rs274.RS274 is not None:  # the straight program moves as the engine's corrected one
        tr = sn.translate(p.read_bytes(), str(p))
        want = straight_ends(nc.parse(tr.data).correct(slope).data, tmp_path)
        got = straight_ends(sn.translate(text.encode()).data, tmp_path)
        np.testing.assert_allclose(got, want, atol=1e-4)


@pytest.mark.parametrize(
    ("sub", "call", "line", "says"),
    [
        (None, "SQUARE(10, 2)", 5, "neither SQUARE.SPF nor _N_SQUARE_SPF is in"),
        ("PROC SQUARE(VAR REAL SIDE)\nRET\n", "SQUARE(10)", 1, "VAR"),
        ("PROC SQUARE(REAL SIDE)\nRET\n", "SQUARE(10, 2)", 5, "takes 1 argument"),
        ("PROC OTHER(REAL SIDE)\nRET\n", "SQUARE(10)", 1, "PROC OTHER"),
        ("PROC SQUARE(REAL SIDE)\nG1 X=SIDE\nM30\n", "SQUARE(10)", 3, "M30 in a subprogram"),
        ("PROC SQUARE(REAL SIDE) SAVE\nTRANS X5\nRET\n", "SQUARE(10)", 3, "changes a frame"),
    ],
)
def test_subprograms_refused(sub, call, line, says, tmp_path):
    if sub is not None:
        (tmp_path / "SQUARE.SPF").write_text(sub)
    p = tmp_path / "MAIN.MPF"
    p.write_text(SUB_MAIN.replace("SQUARE(10, 2)", call))
    with pytest.raises(InputError) as e:
        sn.translate(p.read_bytes(), str(p))
    assert (e.value.line, says in e.value.message) == (line, True), e.value


def _subprogram_folder(tmp_path, name="SQUARE.SPF"):
    """MAIN.MPF in one folder, its subprogram SQUARE in another (the machine's subprogram folder)."""
    (tmp_path / "prog").mkdir()
    (tmp_path / "subs").mkdir()
    (tmp_path / "subs" / name).write_text(SUB_SQUARE)
    p = tmp_path / "prog" / "MAIN.MPF"
    p.write_text(SUB_MAIN)
    return p, tmp_path / "subs"


@needs_rs274
@pytest.mark.parametrize("name", ["SQUARE.SPF", "_N_SQUARE_SPF", "square.spf"])
def test_a_subprogram_in_a_folder_given_is_run(tmp_path, name):
    """Found in the folder given under the file names a control or a copy of it uses; it runs as
    when it is beside the program (the ends worked out by hand, above)."""
    p, subs = _subprogram_folder(tmp_path, name)
    with pytest.raises(InputError, match="--subprograms DIR"):
        sn.translate(p.read_bytes(), str(p))
    tr = sn.translate(p.read_bytes(), str(p), [subs])
    assert tr.subprograms == {"SQUARE": str(subs / name)}
    (tmp_path / "prog" / "SQUARE.SPF").write_text(SUB_SQUARE)
    beside = sn.translate(p.read_bytes(), str(p), [subs])  # the program's own folder comes first
    assert beside.subprograms == {"SQUARE": str(tmp_path / "prog" / "SQUARE.SPF")}
    np.testing.assert_allclose(straight_ends(tr.data, tmp_path), straight_ends(beside.data, tmp_path), atol=1e-12)


@needs_rs274
def test_a_frame_set_in_a_subprogram_is_followed(tmp_path):
    """TRANS in a called subprogram only (the main program has none): the frame, empty at the
    start, is followed from there (by hand: X1 in the frame X5 is at X6)."""
    (tmp_path / "SUB1.SPF").write_text("PROC SUB1\nTRANS X5\nG1 X1 Y0\nRET\n")
    p = tmp_path / "MAIN.MPF"
    p.write_text("G0 X0 Y0 Z0\nG1 X2 F100\nSUB1\nG1 X0\nM30\n")
    tr = sn.translate(p.read_bytes(), str(p))
    np.testing.assert_allclose(straight_ends(tr.data, tmp_path), [(2, 0, 0), (6, 0, 0), (5, 0, 0)], atol=1e-9)
    info = nc.inspect_file(p, "sinumerik")
    assert info["extents"]["feed"]["x"][1] == 6.0, info["extents"]  # (before the fix: no extents at all)


def test_a_subprogram_twice_in_a_folder_is_refused(tmp_path):
    p, subs = _subprogram_folder(tmp_path)
    (subs / "_N_SQUARE_SPF").write_text(SUB_SQUARE.replace("X=SIDE", "X=2*SIDE"))
    with pytest.raises(InputError) as e:
        sn.translate(p.read_bytes(), str(p), [subs])
    assert e.value.line == 5 and "which one runs is not known" in e.value.message


def test_the_command_line_takes_the_subprogram_folder(tmp_path):
    p, subs = _subprogram_folder(tmp_path)
    out, js = tmp_path / "out.mpf", tmp_path / "c.json"
    args = ["correct", str(p), "--shift", "0,0,0", "-o", str(out), "--json", str(js)]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2 and "SQUARE" in r.output and not out.exists()
    r = CliRunner().invoke(main, [*args, "--subprograms", str(subs)])
    assert r.exit_code == 0, r.output
    assert out.read_bytes() == p.read_bytes() and f"subprogram SQUARE: {subs / 'SQUARE.SPF'}" in r.output
    payload = json.loads(js.read_text())
    assert payload["expanded"]["subprograms"] == {"SQUARE": str(subs / "SQUARE.SPF")}
    assert payload["options"]["subprograms"] == [str(subs)]
    r = CliRunner().invoke(main, ["inspect", str(p), "--subprograms", str(subs)])
    assert r.exit_code == 0 and "subprogram SQUARE" in r.output, r.output
    g = tmp_path / "p.ngc"
    g.write_text("G0 X0\n")
    r = CliRunner().invoke(main, ["inspect", str(g), "--subprograms", str(subs)])
    assert r.exit_code == 2 and "for Sinumerik programs" in r.output


@needs_rs274
def test_the_corpus_warmup_routine_runs_its_subprogram(tmp_path):
    """syil's TEST.MPF calls WARMUP_CYCLE(3600, 5), which the repository keeps in another folder.
    Siemens' rules, by hand: CYCLES (INT) = 5/15 rounds to 0, IF CYCLES < 1 makes it 1, so the FOR
    loop runs once: the 13 SUPA moves of its body, in inches (G70), between the caller's SUPA moves
    to Z0 and X0 Y0. nc-gcode-interpreter, which runs no subprograms, runs the body given the same
    parameters and agrees."""
    caller, sub = source("sinumerik__syil_TEST.MPF"), source("sinumerik__syil_WARMUP_CYCLE.SPF")
    (tmp_path / "subroutines").mkdir()
    (tmp_path / "subroutines" / "WARMUP_CYCLE.SPF").write_bytes(sub.read_bytes())
    tr = sn.translate(caller.read_bytes(), str(caller), [tmp_path / "subroutines"])
    body = [(0, 0, -4), (-5, 0, -4), (-5, -5, -4), (-5, -5, 0), (0, -5, 0), (0, 0, 0)]
    body += [(-5, -5, 0), (-5, -5, -4), (0, 0, -4), (0, 0, 0), (0, -5, 0), (-5, 0, 0), (0, 0, 0)]
    got = straight_ends(tr.data, tmp_path) / 25.4
    np.testing.assert_allclose(got, np.array(body, dtype=float), atol=1e-9)  # the caller's moves are at 0
    if ncgi.AVAILABLE:
        text = [ln for ln in sub.read_text().splitlines() if not ln.lstrip().startswith(("PROC", "RET"))]
        want = ncgi.ends("DEF REAL _RPM, _DURATION\n_RPM = 3600\n_DURATION = 5\n" + "\n".join(text) + "\n")
        np.testing.assert_allclose(want, np.array(body, dtype=float), atol=ncgi.tolerance(want))
    c = correct(caller, tmp_path / "zero.mpf", fields.Shift((0.0, 0.0, 0.0)), subprograms=[tmp_path / "subroutines"])
    assert (tmp_path / "zero.mpf").read_bytes() == caller.read_bytes() and c.expanded["written"] == "as it is"


# ------------------------------------------------------------------------ found in the second review
def _bowl(q):
    d = np.zeros_like(q)
    d[:, 2] = 1e-6 * q[:, 0] ** 2
    return d


def test_an_incremental_word_the_correction_adds_after_a_frame_change_is_refused(tmp_path):
    p = tmp_path / "p.mpf"
    p.write_text("G0 X0 Y0 Z0\nG1 Z0 F100\nTRANS X5 Z1\nG0 X0\nG91 G1 X10\n")
    with pytest.raises(RefusedError) as e:
        correct(p, tmp_path / "o.mpf", _bowl)
    assert e.value.details[0]["line"] == 5 and "SD42440" in e.value.message


def test_stops_before_the_move_and_words_in_strings(tmp_path):
    p = tmp_path / "p.mpf"
    p.write_text("G0 X0 Y0 Z0\nN20 M30 G1 X100 F100\n")
    correct(p, tmp_path / "o.mpf", _bowl)
    out = (tmp_path / "o.mpf").read_text().splitlines()
    assert "M30" not in out[1] and out[-1].endswith(" M30") and len(out) > 3
    p.write_text('G0 X0 Y0 Z0\nN20 G1 X100 F100 MSG("done M30 G2")\nN30 X0\n')
    correct(p, tmp_path / "o.mpf", _bowl)
    out = (tmp_path / "o.mpf").read_text().splitlines()
    assert out[1].endswith('MSG("done M30 G2")') and not any(t.endswith(" M30") for t in out)
    n30 = [t for t in out if t.startswith("N30")]
    assert n30 and "G2" not in n30[0]  # the G2 in the string set no mode


def test_a_subprogram_s_m17_is_not_written_into_the_straight_program(tmp_path):
    (tmp_path / "SUBA.SPF").write_text("PROC SUBA\nG1 X20\nM17\n")
    p = tmp_path / "MAIN.MPF"
    p.write_text("N10 G0 X0 Y0 Z0\nN20 G1 X10 F100\nN30 SUBA\nN40 G1 X30\nN50 M30\n")
    correct(p, tmp_path / "o.mpf", _bowl, expand=True)
    out = (tmp_path / "o.mpf").read_text().splitlines()
    assert "M17" not in out and out[-1] == "M30" and any(t.startswith("G1 X30") for t in out)


def test_save_gives_back_the_mode_the_call_found(tmp_path):
    """N30 is rewritten as G1 chords; SUBA (SAVE) moves in G1 and G2; the control gives back the
    mode in force at the call, G1 as written, so N50 (a CR arc relying on N30's G2) gets its G2."""
    (tmp_path / "SUBA.SPF").write_text("PROC SUBA SAVE\nG1 X15\nG2 X20 Y0 CR=2.5\nRET\n")
    p = tmp_path / "MAIN.MPF"
    p.write_text("N10 G0 X0 Y0 Z0\nN20 G1 F100\nN30 G2 X10 Y0 CR=5\nN40 SUBA\nN50 X30 Y0 CR=5\n")

    def left(q):
        d = np.zeros_like(q)
        d[:, 2] = 0.02 * np.clip((10.0 - q[:, 0]) / 10.0, 0.0, 1.0) * (q[:, 0] < 10.0)
        return d

    correct(p, tmp_path / "o.mpf", left)
    out = (tmp_path / "o.mpf").read_text().splitlines()
    assert "N50 G2 X30 Y0 CR=5" in out
    back = sn.translate((tmp_path / "o.mpf").read_bytes(), str(tmp_path / "o.mpf"))
    assert [it.mode for it in back.items if it.kind == "motion"][-1] == "G2"
    correct(p, tmp_path / "x.mpf", _bowl, expand=True)
    assert not any(t.strip() in ("G2", "G3", "CIP", "CT") for t in (tmp_path / "x.mpf").read_text().splitlines())


def test_a_safety_plane_raised_above_the_retraction_plane_is_refused(tmp_path):
    p = tmp_path / "p.mpf"
    p.write_text("G0 X0 Y0 Z2\nG1 F100\nCYCLE81(2, 0, 2, -5)\n")
    with pytest.raises(RefusedError, match="above the retraction"):
        correct(p, tmp_path / "o.mpf", fields.Shift((0.0, 0.0, 0.1)))


@pytest.mark.parametrize(
    "text", ["R1=1EX300 DIV 1EX-300\n", "R1=R[1EX400]\n", "R1=R[1EX400-1EX400]\n", "R1=1EX400 MOD 2\n"]
)
def test_values_out_of_range_are_refused_not_crashing(text):
    with pytest.raises(InputError):
        sn.translate(text.encode())


def test_a_negative_dpr_is_its_magnitude():
    tr = sn.translate(b"G0 X0 Y0 Z10\nG1 F100\nCYCLE81(10, 0, 2, -5, -5)\n")
    assert "G98 G81 R2 Z-5" in tr.data.decode()


# --------------------------------------------------------------------- the machine's start mode
#: A program whose first moves come before it states a motion mode (as nc-gcode-interpreter's
#: examples are written): the machine's machine data decides whether they are rapids or cuts.
NO_MODE = "X0 Y0 Z0 F500\nTRANS X100 Y2\nX10 Y0\nX10 Y10\nG0 Z5\n"


@needs_rs274
@needs_oracle
def test_the_start_motion_stated_makes_the_first_moves_rapids_or_cuts(tmp_path):
    """Without --start-motion the first move is refused at its line (nothing written); with G1 its
    moves are cuts, corrected: the oracle runs the output to the input's ends (with the frame)
    shifted; with G0 they are rapids, left as written (the program comes back as it is)."""
    p = tmp_path / "p.mpf"
    p.write_text(NO_MODE)
    out, js = tmp_path / "o.mpf", tmp_path / "c.json"
    args = ["correct", str(p), "--dialect", "sinumerik", "--shift", "0.1,0,0.05", "-o", str(out)]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2 and "p.mpf:1:1" in r.output and "--start-motion" in r.output and not out.exists()
    r = CliRunner().invoke(main, [*args, "--start-motion", "g1", "--json", str(js)])
    assert r.exit_code == 0, r.output
    assert json.loads(js.read_text())["options"]["start_motion"] == "G1"
    before = ncgi.ends(NO_MODE)
    # by hand: (0,0,0); TRANS X100 Y2 puts X10 Y0 at (110, 2); then (110, 12); Z5 a rapid
    np.testing.assert_allclose(before, [[110, 2, 0], [110, 12, 0], [110, 12, 5]], atol=1e-4)
    after = ncgi.ends(out.read_text())
    # the first move (from where the machine stands, not known) is left as written: the
    # correction starts from it
    ok, where = ncgi.contains_in_order(after, before[:2] + [0.1, 0.0, 0.05], 1e-4)
    assert ok, where
    assert "G1" not in out.read_text()  # the machine's mode is not written into the program
    # the straight program's moves are cuts for rs274 too
    _, rapid = straight_motion(sn.translate(NO_MODE.encode(), "p", (), "G1").data, tmp_path)
    assert rapid.tolist() == [False, False, True]  # (the move to 0, 0, 0 goes nowhere from the start)
    out.unlink()
    r = CliRunner().invoke(main, [*args, "--start-motion", "G0"])
    assert r.exit_code == 0 and out.read_bytes() == p.read_bytes(), r.output
    _, rapid = straight_motion(sn.translate(NO_MODE.encode(), "p", (), "G0").data, tmp_path)
    assert rapid.tolist() == [True, True, True]


def test_the_start_motion_is_for_sinumerik_programs(tmp_path):
    g = tmp_path / "p.ngc"
    g.write_text("G0 X0\n")
    for cmd in (["inspect", str(g)], ["correct", str(g), "--shift", "0,0,0", "-o", str(tmp_path / "o.ngc")]):
        r = CliRunner().invoke(main, [*cmd, "--start-motion", "G1"])
        assert r.exit_code == 2 and "--start-motion is for Sinumerik programs" in r.output, r.output
    with pytest.raises(ValueError):
        sn.translate(b"X1\n", "p", (), "G2")


def test_bit_operators_take_whole_numbers():
    with pytest.raises(InputError, match="B_AND of 2.5: the bit operators are read for whole numbers"):
        sn.translate(b"R1 = 2.5 B_AND 1\nG1 X=R1 F100\n")


def test_an_alarm_set_is_copied_as_a_message_is():
    src = b'G1 X0 Y0 Z0 F100\nSETAL(65000)\nMSG("check")\nX10\nM30\n'
    tr = sn.translate(src, "p")
    assert [it.rs.split(" ;")[0] for it in tr.items if it.kind == "motion"] == ["G1 X0 Y0 Z0", "X10"]
    out = nc.parse(tr.data).correct(fields.Shift((0, 0, 0.05))).data
    text, _, _ = sn.assemble(tr, out)
    assert text == b'G1 X0 Y0 Z0.05 F100\nSETAL(65000)\nMSG("check")\nX10\nM30\n'  # (X10 at Z0.05 already)


def test_string_variables_are_kept_and_never_read_as_numbers():
    """DEF STRING[n]: set to a text or another STRING, used by MSG and the like; read as a number
    (its conversion is the control's), or built with << and the string functions: refused at
    the line."""
    src = b'DEF STRING[28] NAME = "baseline"\nDEF STRING[8] TAG = "A-7", NOTE = ""\nNOTE = TAG\nG1 X0 Y0 Z0 F100\nX10\nM30\n'
    tr = sn.translate(src, "p")
    assert [it.rs.split(" ;")[0] for it in tr.items if it.kind == "motion"] == ["G1 X0 Y0 Z0", "X10"]
    for text, line, says in (
        (b'DEF STRING[8] TAG = "x"\nG1 X=TAG F100\n', 2, "TAG is a STRING: read as a number"),
        (b'DEF STRING[8] TAG\nTAG = "a" << "b"\n', 2, "string operations are not read"),
        (b"DEF STRING[8] TAG\nTAG = 3\n", 2, "only a text in quotes or another STRING"),
        (b"DEF STRING TAG\n", 1, "DEF STRING without its length"),
    ):
        with pytest.raises(InputError) as e:
            sn.translate(text, "p")
        assert (e.value.line, says in e.value.message) == (line, True), e.value
