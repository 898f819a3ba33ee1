"""Reader and interpreter: every byte kept, words and errors located, constructs reported."""

from __future__ import annotations

import re

import numpy as np
import pytest

from ncadapt import InputError, fields, nc


def test_every_byte_is_kept(tmp_path):
    data = b"%\r\nO1234 (HEAD)\r\n\r\n/N010 G1. X-.5 y+2\t; tail\r\n  \t\r\n(only a comment)\nG0 Z1 (no newline at end)"
    p = tmp_path / "a.nc"
    p.write_bytes(data)
    prog = nc.read(p)
    assert prog.data == data
    assert prog.lines == 7
    assert prog.text.encode() == data


@pytest.mark.parametrize(
    "text, line, col, message",
    [
        ("G0 X1\nG1 X\n", 2, 5, "expected a number after 'X'"),
        ("G1 (open comment\n", 1, 4, "comment '(' is not closed"),
        ("G1 X1 & Y2\n", 1, 7, "unexpected '&'"),
        ("G0 X0 Y0 Z0\nG2 X1 Y1 R0.1\n", 2, 10, "too small"),
        ("G0 X0 Y0 Z0\nG2 X10 Y0 I3 J0\n", 2, 1, "differs from radius to its start"),
        ("G0 X0 Y0 Z0\nG2 X1 Y0 I.5 R.5\n", 2, 14, "both R and I/J/K"),
        ("G0 X0 Y0 Z0\nG3 F10\n", 2, 1, "no axis words"),
        ("M3 M7 M8 M48 M50 M51 M52 M53 M54\n", 1, 30, "too many M words in one block"),
    ],
)
def test_errors_name_line_and_column(text, line, col, message):
    with pytest.raises(InputError, match=re.escape(message)) as e:
        nc.parse(text, name="part.ngc")
    assert (e.value.path, e.value.line, e.value.col) == ("part.ngc", line, col)
    assert str(e.value).startswith(f"part.ngc:{line}:{col}: ")


@pytest.mark.parametrize(
    "text, line, construct",
    [
        (
            "G0 X0 Y0 Z0\nG18 G81 X1 Y1 Z-1 R1 F10\n",
            2,
            "canned cycle G81 in the G18 plane (only G17 cycles are followed)",
        ),
        (
            "G0 X0 Y0\nG83 X1 Y1 Z-1 R1 Q.5 F10\n",
            2,
            "canned cycle G83 from an unknown position (give X, Y and Z a G0 or G1 move before it)",
        ),
        (
            "G0 X0 Y0 Z0\nG88 X1 Y1 Z-1 R1 P1 F10\n",
            2,
            "canned cycle G88 (the operator retracts by hand: the position after it is unknown)",
        ),
        ("G0 X0 Y0 Z0\nS100 M3\nG33.1 Z-1 K0.05\n", 3, "spindle-synchronised motion G33.1"),
        (
            "G0 X0 Y0 Z0\nG41 D1 G1 X5\n",
            2,
            "cutter compensation G41 with tool 1: its diameter is not known; give the tool table (--tool-table)",
        ),
        (
            "G0 X0 Y0 Z0\nG42.1 D2 L3 G1 X5\n",
            2,
            "cutter compensation G42.1 with an L word (a lathe tool's orientation): not treated",
        ),
        ("G0 X0 Y0 Z0\nG10 L2 P1 X1 R30\n", 2, "offset setting G10 L2"),
        ("G0 X0 Y0 Z0\nG10 L10 P1 Z5\n", 2, "offset setting G10 L10"),
        ("G0 X0 Y0 Z0\nG68 X0 Y0 R30\n", 2, "coordinate rotation G68"),
        ("#1 = 5\nG0 X#1\n", 1, "parameters or expressions (# or [ ])"),
        ("G0 X[1+2]\n", 1, "parameters or expressions (# or [ ])"),
        ("o100 sub\nG0 X1\no100 endsub\n", 1, "O-word subroutine or control flow"),
        ("o<probe> call\n", 1, "O-word subroutine or control flow"),
        ("G0 X0 Y0 Z0\nM98 P1000\n", 2, "subprogram M98"),
        ("G0 X0 Y0 Z0\nG16\nG1 X10 Y30\n", 2, "polar coordinates G16"),
        ("G0 X0 Y0 Z0\nG28 @1 ^60\n", 2, "polar coordinates (@ ^) with G28, G30, G53, G10, G52 or G92"),
        ("G0 X0 Y0 Z0\nG28.1 X1\n", 2, "G28.1 with axis words"),
        (
            "G0 X0 Y0 Z5\nG93 G81 X1 R1 Z0 F2\n",
            2,
            "canned cycle under inverse-time feed G93 (LinuxCNC refuses it)",
        ),
        ("G0 X0 Y0 Z0\nG5.2 X1 Y1 P1 L3\n", 2, "spline G5.2"),
    ],
)
def test_unsupported_constructs_are_reported(text, line, construct):
    prog = nc.parse(text)
    assert prog.unsupported, "construct not detected"
    u = prog.unsupported[0]
    assert (u.line, u.construct) == (line, construct)


def test_modal_blocks_after_a_construct_are_counted():
    # (the move after G40 leaves the offset the compensation put the tool at: not followed either)
    prog = nc.parse("G0 X0 Y0 Z0\nG41 D1 G1 X1\nX2\nY2\nG40 G1 X3\nX4\n")
    (u,) = prog.unsupported
    assert u.blocks == 4
    assert prog.blocks.supported.tolist() == [True, False, False, False, False, True]


def test_many_g_words_in_one_block_are_all_read():
    prog = nc.parse("G17 G21 G40 G49 G54 G61 G80 G90 G94 G97 G98 G1 X1 Y2 Z3 F100\n")
    assert prog.blocks.end[0, :3].tolist() == [1.0, 2.0, 3.0]
    assert prog.inspect()["motions"]["feed"] == 1


def test_work_offsets_tools_and_g53():
    prog = nc.parse("G55 T3 M6\nG0 X1 Y2 Z3\nG53 G0 Z0\nG59.3 G0 X0\n")
    info = prog.inspect()
    assert info["work_offsets"] == ["G55", "G59.3"]
    assert info["tools"] == [3]
    # moves in a second work system are elsewhere on the machine than the field was measured
    (u,) = info["unsupported"]
    assert (u["line"], u["col"]) == (4, 1) and "work coordinate system G59.3 after moves in G55" in u["construct"]
    assert info["notes"][0]["line"] == 3 and "G53" in info["notes"][0]["message"]
    # after G53 the Z the program runs at is not known
    assert np.isnan(prog.blocks.end[1, 2])


def test_one_work_system_is_read_and_a_change_forgets_the_position():
    # G54 named again, or a system chosen before any move: nothing to refuse
    assert not nc.parse("G55\nG0 X1 Y2 Z3\nG55 G1 X4 F100\nM2\n").unsupported
    prog = nc.parse("G0 X1 Y2 Z3\nG55\nG1 X4 F100\nG54\nG1 X5\nM2\n")
    assert [u.line for u in prog.unsupported] == [2]
    # the tool's coordinates in G55 depend on offsets the program does not give: unknown, not X1 Y2 Z3
    ends = prog.blocks.end
    assert np.isnan(ends[1, 1]) and np.isnan(ends[1, 2]) and ends[1, 0] == 4.0
    # back in G54 the position is unknown too until a move names the axes
    assert np.isnan(ends[2, 1])


def test_inch_and_incremental_positions():
    prog = nc.parse("G20 G90 G0 X1 Y1 Z0.5\nG91 G1 X0.5 Y-0.25\nG21 X10\n")
    end = prog.blocks.end[:, :3]
    np.testing.assert_allclose(end, [[25.4, 25.4, 12.7], [38.1, 19.05, 12.7], [48.1, 19.05, 12.7]], atol=1e-12)
    assert prog.units == "mixed"


def test_arcs_in_every_plane_trace_circles():
    # counter-clockwise quarter circles of radius 5 in G17, G18 (Z, X) and G19 (Y, Z) with I/J/K
    prog = nc.parse("G21 G90 G0 X5 Y0 Z0\nG17 G3 X0 Y5 I-5 J0\nG18 G3 X-5 Z5 I0 K5\nG19 G3 Y0 Z0 J-5 K0\n")
    tp = prog.toolpath(chord_tol=1e-4, max_segment=10, rapids=False)
    p = {line: tp.points[tp.line == line] for line in (2, 3, 4)}
    np.testing.assert_allclose(np.hypot(p[2][:, 0], p[2][:, 1]), 5, atol=1e-12)
    np.testing.assert_allclose(np.hypot(p[3][:, 2] - 5, p[3][:, 0]), 5, atol=1e-12)
    np.testing.assert_allclose(p[3][:, 1], 5, atol=1e-12)
    np.testing.assert_allclose(np.hypot(p[4][:, 1], p[4][:, 2] - 5), 5, atol=1e-12)
    np.testing.assert_allclose(p[4][:, 0], -5, atol=1e-12)
    np.testing.assert_allclose(p[4][-1], [-5, 0, 0], atol=1e-12)
    # counter-clockwise quarter turns: each stays in its quadrant (no long way round)
    assert (p[2][:, 0] >= -1e-12).all() and (p[2][:, 1] >= -1e-12).all()
    # chord tolerance: the sagitta of each piece stays under 1e-4 mm
    theta = (np.pi / 2) / len(p[2])
    assert 5 * (1 - np.cos(theta / 2)) <= 1e-4


def test_full_circle_and_turns():
    prog = nc.parse("G21 G90 G0 X10 Y0 Z0\nG3 X10 Y0 I-10 J0 P2 Z-2\n")
    tp = prog.toolpath(chord_tol=0.002, max_segment=100, rapids=False)
    ang = np.unwrap(np.arctan2(tp.points[:, 1], tp.points[:, 0]))
    assert ang[-1] == pytest.approx(4 * np.pi, abs=1e-9)
    np.testing.assert_allclose(tp.points[:, 2], -2 * ang / (4 * np.pi), atol=1e-9)


@pytest.mark.parametrize("head", ["G91 G28 Z0\nG90", "G53 G0 Z0\n", "G10 L2 P2 X0 Y0 Z0\n"])
def test_a_work_system_chosen_after_a_homing_or_machine_move_is_the_first(head):
    # post headers home Z (or move in machine coordinates) before they choose the part's system:
    # those axis words are no move in a work system, so G55 is the system the moves begin in
    prog = nc.parse(f"{head} G55 G0 X0 Y0 Z5\nG1 Z-1 F100\nM2\n")
    assert not [u for u in prog.unsupported if "work coordinate system" in u.construct]


def test_probing_moves_are_copied_and_leave_their_axes_unknown():
    """G38.2–G38.5 stop where the probe trips: copied as written (not refused), noted, the axes
    they move unknown until a move sets them; the mode stays (a later block of axis words alone
    probes too), as in LinuxCNC."""
    src = "G21 G90 G0 X0 Y0 Z5\nG38.2 Z-10 F50\nZ-12\nG0 Z5\nG1 X10 F100\nM2\n"
    prog = nc.parse(src)
    assert not prog.unsupported
    b = prog.blocks
    assert b.motion.tolist() == [0, 4, 4, 0, 1]
    assert np.isnan(b.end[1:3, 2]).all() and b.end[3, 2] == 5
    out = prog.correct(fields.Shift((0, 0, 0.05)), rapids=True)
    lines = out.text.splitlines()
    assert lines[1:3] == ["G38.2 Z-10 F50", "Z-12"]
    assert [n for n, _ in out.correction.notes] == [2, 3]
