"""Inverse-time feed (G93): a move's F is the inverse of its time in minutes, so a move the
correction cuts into pieces gives each piece the F that keeps the piece's share of that time.

rs274 is the oracle: under G93 it sets, before every move, the feed rate ``length × F`` (its own
length of the move, printed), so ``length / rate`` is the time LinuxCNC gives each output piece.
The pieces of a move must add up to the move's time ``1 / F``, taken from the input program, and
run at the speed of the move.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import needs_rs274
from ncadapt import InputError, fields, nc
from rs274 import canonical

PROGRAM = """G21 G90 G17
G0 X0 Y0 Z1 A0
G93 G1 Z0 F60
G1 X10 A90 F2
G2 X20 Y0 I5 J0 F3
G1 X30 Y4 F0.5
G94 G1 X40 F100
G0 Z5
M2
"""
#: the F of each G93 move of PROGRAM, in order
INVERSE_F = [60, 2, 3, 0.5]


def _wave(p):
    p = np.asarray(p, dtype=float)
    d = np.zeros((len(p), 3))
    d[:, 2] = 0.01 * np.sin(p[:, 0])
    return d


def _run(tmp_path, text, name):
    path = tmp_path / name
    path.write_text(text)
    c = canonical(path)
    assert c.error is None, f"{name}: {c.error}"
    return c


@needs_rs274
@pytest.mark.parametrize("max_segment", [1.0, 3.0])
def test_pieces_keep_each_move_s_time(tmp_path, max_segment):
    out = nc.parse(PROGRAM).correct(_wave, max_segment=max_segment)
    assert out.correction.lines_added > 10  # the moves were cut in pieces
    inp = _run(tmp_path, PROGRAM, "in.ngc")
    got = _run(tmp_path, out.text, "out.ngc")
    # the input's G93 moves, and where each ends displaced
    cut = [k for k, kind in enumerate(inp.kinds) if kind != "traverse"][: len(INVERSE_F)]
    targets = inp.ends[cut, :3] + _wave(inp.ends[cut, :3])
    j = next(i for i, kind in enumerate(got.kinds) if kind != "traverse")
    start = got.ends[j - 1, :3]
    for k, (f, target) in enumerate(zip(INVERSE_F, targets)):
        time, length, speeds = 0.0, 0.0, []
        while True:
            piece = float(np.linalg.norm(got.ends[j, :3] - start))
            assert got.kinds[j] == "feed" and got.rates[j] > 0, (k, j)
            time += piece / got.rates[j]
            length += piece
            if piece > 0.1:  # (shorter ones: the printed digits say little of their speed)
                speeds.append(piece / (piece / got.rates[j]))
            start = got.ends[j, :3]
            j += 1
            if np.abs(start - target).max() <= 0.005:
                break
        # the move's time, 1/F minutes, to the printed digits (4 decimals of mm and of the rate)
        assert time == pytest.approx(1 / f, rel=2e-3), (k, time, 1 / f)
        # and every piece at the move's speed (the field changes the lengths by µm only)
        assert np.allclose(speeds, length / time, rtol=1e-2), (k, speeds, length / time)


def test_a_zero_field_gives_the_program_back():
    assert nc.parse(PROGRAM).correct(fields.Shift((0, 0, 0))).text == PROGRAM


def test_a_move_kept_whole_keeps_its_f():
    out = nc.parse(PROGRAM).correct(fields.Shift((0, 0, 0.05))).text.splitlines()
    assert out[3] == "G1 X10 A90 F2" and out[4] == "G2 X20 Y0 I5 J0 F3"


@pytest.mark.parametrize(
    ("text", "line", "says"),
    [
        ("G21 G0 X0 Y0 Z0\nG93 G1 X10\nM2\n", 2, "F word missing with inverse time G1"),
        ("G21 G0 X0 Y0 Z0\nG93 G1 X10 F0\nM2\n", 2, "above 0"),
    ],
)
def test_refused_as_rs274_refuses_them(text, line, says):
    with pytest.raises(InputError, match=says) as e:
        nc.parse(text)
    assert e.value.line == line


def test_a_canned_cycle_under_g93_is_unsupported():
    prog = nc.parse("G21 G90 G0 X0 Y0 Z5\nG93 G81 X10 R1 Z-1 F2\nG80 G94\nM2\n")
    (u,) = prog.unsupported
    assert u.line == 2 and "inverse-time" in u.construct


@needs_rs274
@pytest.mark.parametrize("max_segment", [0.1, 1.0])
def test_the_piece_that_joins_the_corrected_path_runs_at_the_move_s_speed(tmp_path, max_segment):
    """From review: a shift the rapid before the move does not take (rapids are not corrected)
    makes the first piece join the corrected path sideways; sharing the time by fraction along
    the move ran that piece at 3 times the feed. Shared by length, every piece runs at the
    corrected path's length over the move's time (rs274's rates)."""
    src = "G21 G90\nG0 X0 Y0 Z0\nG93 G1 X10 F2\nG94\nM2\n"
    out = nc.parse(src).correct(fields.Shift((0, 0.3, 0)), max_segment=max_segment)
    got = _run(tmp_path, out.text, "out.ngc")
    k = [i for i, kind in enumerate(got.kinds) if kind == "feed"]
    starts = got.ends[[i - 1 for i in k], :3]
    lens = np.linalg.norm(got.ends[k, :3] - starts, axis=1)
    times = lens / np.array(got.rates)[k]
    assert times.sum() == pytest.approx(0.5, rel=2e-3)  # the move's time, 1/F
    speed = lens.sum() / times.sum()  # 20.4 mm/min: the path is 0.3 mm longer
    long = lens > 0.05
    assert np.allclose(lens[long] / times[long], speed, rtol=2e-2), (lens / times, speed)


def test_g93_on_a_fanuc_family_control_is_unsupported():
    """From review: a Fanuc reads an arc's F under G93 as feed / radius (Haas: 1/time), and an F
    without a point by a parameter; the program does not say which, so G93 is not followed."""
    prog = nc.parse("%\nO1000\nG21 G90 G0 X10. Y0. Z0.\nG93 G3 X10. Y0. I-10. J0. F2.\nG94\nM30\n%\n", dialect="fanuc")
    (u,) = prog.unsupported
    assert u.line == 4 and "G93 on a Fanuc-family control" in u.construct
