"""Fanuc's coordinate rotation G68/G69 (mills, G17), followed and corrected.

The truth is the rule of the Fanuc manuals (coordinate system rotation: the programmed X Y
turned by R degrees about the centre X Y of the G68 block, a move's increments and an arc's
centre offsets with them) run by LinuxCNC: rs274 has no G68, but a rotation about a point is a
rotation of the work system about its origin set there with the point's G52 offset taken back
(``G10 L2 P1 X a Y b R r`` and ``G52 X-a Y-b``: LinuxCNC adds the G52 offset, turns, then adds
the origin), so each Fanuc program here is run by rs274 with its G68/G69 written that way, input
and corrected output alike, and their motions compared.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import corpus
import rs274
from ncadapt import fields, nc
from ncadapt.errors import InputError

needs_rs274 = pytest.mark.skipif(rs274.RS274 is None, reason="LinuxCNC rs274 not installed")

PROGRAM = """%
O1
G21 G90 G17
G0 X0. Y0. Z5.
G1 Z-1. F100.
G68 X10. Y5. R30.
G1 X20. Y5.
Y15.
G2 X30. Y15. I5. J0.
G3 X20. Y25. R10.
G91 G1 X-5. Y0.
G90 X10. Y25. Z-1.5
G69
G1 X0. Y0.
G68 X0. Y0. R-90.
G1 X5. Y5.
G69
G1 X0. Y0.
G0 Z5.
M30
%
"""


def as_linuxcnc(text: str) -> str:
    """The Fanuc program as LinuxCNC runs it: G68 X a Y b R r as the work system's rotation about
    its origin moved to (a, b) with a G52 offset of (-a, -b); G69 both undone. A Fanuc control
    leaves the tool where it is in X and Y across G68 and G69 until a move names them, where
    LinuxCNC reads the old programmed X Y in the new system: a block naming neither gets the
    tool's X Y, as programmed in the new system (absolute programs only)."""
    out: list[str] = []
    rot = None  # (a, b, cos, sin)
    tool = (0.0, 0.0)  # where the tool is in X Y (machine)
    changed = False
    for line in text.splitlines():
        s = line.strip()
        if s in ("%", "") or re.fullmatch(r"O\d+", s):
            continue
        m = re.match(r"G68 X(\S+) Y(\S+) R(\S+)$", s)
        if m:
            a, b, r = (float(m.group(k)) for k in (1, 2, 3))
            rot = (a, b, np.cos(np.radians(r)), np.sin(np.radians(r)))
            out += [f"G10 L2 P1 X{a} Y{b} R{r}", f"G52 X{-a} Y{-b}"]
            changed = True
            continue
        if s == "G69":
            rot = None
            out += ["G10 L2 P1 X0 Y0 R0", "G52 X0 Y0"]
            changed = True
            continue
        x, y = (re.search(rf"{k}(-?[\d.]+)", s) for k in "XY")
        # the tool's X Y as programmed under the rotation in force
        px, py = turn(rot, tool, -1)
        if x or y:
            px, py = float(x.group(1)) if x else px, float(y.group(1)) if y else py
            tool = turn(rot, (px, py), 1)
            changed = False
        elif changed and re.search(r"\bZ", s):
            s += f" X{px:.6f} Y{py:.6f}"
        out.append(s)
    return "\n".join(out) + "\n"


def turn(rot, p, sign):
    """Point ``p`` turned by the rotation ``rot`` (a, b, cos, sin) about (a, b), or back when
    ``sign`` is -1; as it is without one."""
    if rot is None:
        return p
    a, b, c, n = rot
    n *= sign
    dx, dy = p[0] - a, p[1] - b
    return a + c * dx - n * dy, b + n * dx + c * dy


def field(p):
    p = np.asarray(p, float)
    d = np.zeros_like(p)
    d[:, 0] = 0.002 * p[:, 1]
    d[:, 1] = -0.001 * p[:, 0]
    d[:, 2] = 0.03 * np.sin(p[:, 0] / 8.0) * np.cos(p[:, 1] / 6.0)
    return d


def motion(tmp_path, text, name):
    p = tmp_path / name
    p.write_text(as_linuxcnc(text))
    canon = rs274.canonical(p)
    assert canon.error is None, canon.error
    return canon


@needs_rs274
@pytest.mark.parametrize("fld", [field, fields.Shift((0.01, -0.02, 0.05))], ids=["field", "shift"])
def test_moves_under_a_rotation_are_corrected_where_the_rotation_puts_them(tmp_path, fld):
    prog = nc.parse(PROGRAM, dialect="fanuc")
    assert prog.unsupported == ()
    out = prog.correct(fld, max_segment=2.0)
    canon_in = motion(tmp_path, PROGRAM, "in.ngc")
    canon_out = motion(tmp_path, out.text, "out.ngc")
    # the engine reads the input's moves where rs274 runs them
    b = prog.blocks
    assert len(b.end) == len(canon_in.kinds)
    assert np.abs(b.end[:, :3] - canon_in.ends[:, :3]).max() < 1e-4
    # and the output runs as the input displaced by the field
    displaced = np.array([k != "traverse" for k in canon_in.kinds])
    problems = corpus.compare_motion(canon_in, canon_out, displaced, fld, 0.005, b.line, 2.0)
    assert problems == []


def test_a_zero_field_gives_the_program_back():
    assert nc.parse(PROGRAM, dialect="fanuc").correct(fields.Shift((0, 0, 0))).text == PROGRAM


@pytest.mark.parametrize(
    ("text", "line", "says"),
    [
        # after G68 (and G69) the first move naming X or Y gives both, absolute
        ("G68 X0. Y0. R30.\nG1 X5.\nG1 X6. Y1.\n", 6, "first move after G68 or G69"),
        ("G68 X0. Y0. R30.\nG91 G1 X5. Y1.\n", 6, "first move after G68 or G69"),
        ("G68 X0. Y0. R30.\nG1 X5. Y1.\nG69\nG1 X6.\n", 8, "first move after G68 or G69"),
        ("G68 X0. Y0.\nG1 X5. Y1.\n", 5, "without R"),
        ("G91 G68 X0. Y0. R30.\nG90 G1 X5. Y1.\n", 5, "G91"),
        ("G68 X0. Y0. R30.\nG1 X5. Y1.\nG81 X5. Y5. Z-2. R1. F50.\nG80\n", 7, "canned cycles"),
        ("G68 X0. Y0. R30.\nG1 X5. Y1.\nG92 X0. Y0.\n", 7, "offsets"),
        ("G68 X0. Y0. R30.\nG1 X5. Y1.\nG41 D1 G1 X10. Y1.\n", 7, "cutter compensation"),
        ("G68 X0. Y0. R30.\nG1 X5. Y1.\nG68 X1. Y1. R10.\n", 7, "in force"),
        ("G18 G68 X0. Y0. R30.\n", 5, "XY plane"),
        # about where the tool stands, which the correction moves
        ("G68 R30.\nG1 X5. Y1.\n", 5, "without X and Y"),
        # a three-dimensional conversion; a plane code under a rotation (Fanuc: not to be given)
        ("G68 X0. Y0. I1. J0. K0. R30.\nG1 X5. Y1.\n", 5, "I, J or K"),
        ("G68 X0. Y0. R30.\nG1 X5. Y1.\nG17 G1 X6. Y1.\n", 7, "plane code"),
        # whether a block-delete line runs is the machine's switch
        ("/G68 X0. Y0. R30.\nG1 X5. Y1.\n", 5, "block-delete"),
        ("G68 X0. Y0. R30.\nG1 X5. Y1.\n/G69\nG1 X6. Y1.\n", 7, "block-delete"),
    ],
)
def test_what_is_not_followed_is_refused_at_its_line(text, line, says):
    src = "%\nO1\nG21 G90 G17\nG0 X0. Y0. Z5.\n" + text + "M30\n%\n"
    [u, *_] = nc.parse(src, dialect="fanuc").unsupported
    assert u.line == line and says in u.construct, u


def test_an_angle_without_a_point_is_refused():
    with pytest.raises(InputError):
        nc.parse("%\nO1\nG21 G90 G17\nG0 X0. Y0. Z5.\nG68 X0. Y0. R30\nG1 X5. Y1.\nM30\n%\n", dialect="fanuc")


def test_after_a_rotation_not_followed_the_position_is_unknown():
    """A G68 the engine does not follow (no R: the control's setting), kept as written: the moves
    under it go where the rotation puts them, so after G69 a move from there is not corrected as
    if from the unrotated point (it was: along the wrong path)."""
    src = "%\nO1\nG21 G90 G17\nG0 X0. Y0. Z1.\nG1 Z0. F100.\nG68 X0. Y0.\nG1 X10. Y0.\nG69\nG1 X20.\nY5.\nM30\n%\n"
    prog = nc.parse(src, dialect="fanuc")
    assert [u.line for u in prog.unsupported] == [6]

    def tilt(p):
        return np.c_[0 * p[:, 0], 0 * p[:, 0], 0.002 * p[:, 0] + 0.01 * p[:, 1]]

    out = prog.correct(tilt, keep_unsupported=True)
    lines = out.text.splitlines()
    # Y unknown: the move left as written (with a warning); the next, which gives Y, corrected
    # at its end (20, 5)
    assert lines[8] == "G1 X20." and lines[9] == "Y5. Z0.09"
    assert any("not corrected" in w for w in out.correction.warnings)


@needs_rs274
@pytest.mark.parametrize(
    "text",
    [
        "G0 X5. Y5. Z1.\nG68 X10. Y5. R90.\nG1 Z-1. F100.\nG1 X20. Y5.\nG69\nG0 Z5.\n",
        "G0 X0. Y0. Z1.\nG68 X10. Y5. R90.\nG0 X20. Y5.\nG69\nG1 Z-1. F100.\nG1 X0. Y15.\nG0 Z5.\n",
    ],
)
def test_a_move_before_the_first_giving_x_and_y_gets_both(tmp_path, text):
    """A plunge between G68 (or G69) and the first move giving X and Y that the field moves in X
    is written with X and Y, absolute: with one alone, the control would take the other by its
    setting, the construct the engine refuses in a program."""
    src = "%\nO1\nG21 G90 G17\n" + text + "M30\n%\n"
    shift = fields.Shift((0.05, 0.0, 0.0))
    out = nc.parse(src, dialect="fanuc").correct(shift).text
    plunge = next(ln for ln in out.splitlines() if ln.startswith("G1 Z"))
    assert " X" in plunge and " Y" in plunge, plunge
    assert nc.parse(out, dialect="fanuc").unsupported == ()
    canon_in = motion(tmp_path, src, "in.ngc")
    canon_out = motion(tmp_path, out, "out.ngc")
    prog = nc.parse(src, dialect="fanuc")
    displaced = np.array([k != "traverse" for k in canon_in.kinds])
    assert corpus.compare_motion(canon_in, canon_out, displaced, shift, 0.005, prog.blocks.line) == []


def test_an_incremental_move_before_the_first_giving_x_and_y_is_refused_when_moved_in_x_or_y():
    src = "%\nO1\nG21 G90 G17\nG0 X5. Y5. Z1.\nG68 X10. Y5. R90.\nG91 G1 Z-2. F100.\nG90 G1 X20. Y5.\nM30\n%\n"
    with pytest.raises(InputError, match="before the first move giving X and Y"):
        nc.parse(src, dialect="fanuc").correct(fields.Shift((0.05, 0.0, 0.0)))
    # a field along Z alone moves no X or Y: followed
    nc.parse(src, dialect="fanuc").correct(fields.Shift((0.0, 0.0, 0.05)))
