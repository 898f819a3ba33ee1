"""The NC engine on real programs (``../shared/corpus/nc``): a refusal names its line, a zero
correction gives the program back byte for byte, and a corrected program runs in LinuxCNC's rs274
as the input displaced by the field (see :mod:`corpus`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import corpus
from rs274 import RS274, Canon

ENTRIES = corpus.manifest()


@pytest.mark.parametrize("entry", [pytest.param(e, id=e.file) for e in ENTRIES] or [pytest.param(None, id="no-corpus")])
def test_program(entry, tmp_path):
    if entry is None:
        pytest.skip(f"no corpus of NC programs at {corpus.CORPUS}")
    r = corpus.run(entry, tmp_path)
    outcome, line, identity, motion = r.outcome, r.refusal_line, r.identity, r.motion
    assert not outcome.startswith("error"), outcome
    if r.refused:  # a refusal is an outcome, but it says where
        assert line is not None and line >= 1, f"the refusal names no line: {outcome}"
        return
    assert identity, f"a zero correction changed the program: {r.identity_detail}"
    if RS274 is None:
        pytest.skip("LinuxCNC's rs274 is not installed: motion not compared")
    # when rs274 runs the input, it runs the corrected programs as the input displaced
    assert motion != "mismatch", r.motion_detail


# --------------------------------------------------------------------------------- the comparison
def _field(p):
    d = np.zeros_like(p)
    d[:, 2] = 0.01 + 0.002 * p[:, 0]
    return d


def _canon(moves) -> Canon:
    """moves: (kind, end xyz[, arc])."""
    kinds = [m[0] for m in moves]
    ends = np.array([list(m[1]) + [0.0, 0.0, 0.0] for m in moves], dtype=float)
    arcs = [m[2] if len(m) > 2 else None for m in moves]
    return Canon(kinds, ends, arcs, 0.00005, None)


# a rapid above the start, a plunge, a line, a clockwise half circle, a line, a rapid up
INPUT = [
    ("traverse", (0, 0, 5)),
    ("feed", (0, 0, -1)),
    ("feed", (10, 0, -1)),
    ("arc", (20, 0, -1), (-1, 15.0, 0.0, "CANON_PLANE_XY")),
    ("feed", (20, 10, -1)),
    ("traverse", (20, 10, 5)),
]
DISPLACED = np.array([False, True, True, True, True, False])


def _corrected(arc_points=8):
    """What an exact correction of INPUT by _field writes: cutting moves displaced, pieces of them
    (the arc as straight pieces), rapids as they were."""

    def d(x, y, z):
        return (x, y, z + 0.01 + 0.002 * x)

    out = [("traverse", (0, 0, 5)), ("feed", d(0, 0, -1)), ("feed", d(5, 0, -1)), ("feed", d(10, 0, -1))]
    for a in np.linspace(math.pi, 0, arc_points + 1)[1:]:
        out.append(("feed", d(15 + 5 * math.cos(a), 5 * math.sin(a), -1)))
    out += [("feed", d(20, 5, -1)), ("feed", d(20, 10, -1)), ("traverse", (20, 10, 5))]
    return out


def _compare(out_moves):
    return corpus.compare_motion(_canon(INPUT), _canon(out_moves), DISPLACED, _field, 0.005)


def test_comparison_accepts_an_exact_correction():
    assert _compare(_corrected(arc_points=64)) == []


def test_comparison_accepts_a_shifted_arc_and_a_move_left_as_written():
    """A shift keeps the arc an arc; a move whose position the engine does not know (here the
    plunge) is left as written, and the next move starts from its uncorrected end."""

    def shift(p):
        return np.broadcast_to([0.0, 0.0, 0.03], p.shape).copy()

    out = [
        ("traverse", (0, 0, 5)),
        ("feed", (0, 0, -1)),
        ("feed", (10, 0, -0.97)),
        ("arc", (20, 0, -0.97), (-1, 15.0, 0.0, "CANON_PLANE_XY")),
        ("feed", (20, 10, -0.97)),
        ("traverse", (20, 10, 5)),
    ]
    displaced = np.array([False, False, True, True, True, False])
    assert corpus.compare_motion(_canon(INPUT), _canon(out), displaced, shift, 0.005) == []
    # ... but not a move it should have corrected
    assert corpus.compare_motion(_canon(INPUT), _canon(out), DISPLACED, shift, 0.005)


def _off(moves, i, dz):
    m = list(moves)
    kind, (x, y, z), *rest = m[i]
    m[i] = (kind, (x, y, z + dz), *rest)
    return m


WRONG = {
    # a corner of the linearised arc 8 µm off the displaced arc
    "point_off": lambda: _off(_corrected(64), 20, 0.008),
    # the arc written with too few pieces: its chords leave the arc by 0.1 mm
    "coarse_arc": lambda: _corrected(arc_points=4),
    # the last line left at its programmed depth
    "not_displaced": lambda: _off(_corrected(64), -2, -(0.01 + 0.04)),
    # the arc turned the other way (counter-clockwise, through y < 0)
    "arc_reversed": lambda: (
        _corrected()[:4] + [("arc", (20, 0, -1 + 0.05), (1, 15.0, 0.0, "CANON_PLANE_XY"))] + _corrected()[-3:]
    ),
    # a rapid that no longer ends where it did
    "rapid_moved": lambda: _off(_corrected(64), -1, 0.05),
    # a piece of the line missing and another added (the line goes 10 mm back and forth)
    "extra_piece": lambda: _corrected(64)[:3] + [("feed", (0, 0, -1 + 0.01))] + _corrected(64)[3:],
    # pieces of the arc out of order
    "out_of_order": lambda: (lambda m: m[:10] + [m[11], m[10]] + m[12:])(_corrected(64)),
    # the corrected field is not the field: a constant 0.01 mm
    "wrong_field": lambda: [
        (k, (x, y, z - 0.002 * x) if k != "traverse" else (x, y, z), *r) for k, (x, y, z), *r in _corrected(64)
    ],
}


@pytest.mark.parametrize("name", sorted(WRONG))
def test_comparison_detects_a_wrong_correction(name):
    problems = _compare(WRONG[name]())
    assert problems, f"{name}: not detected"


def test_comparison_bounds_the_piece_that_leaves_an_uncorrected_point():
    """After a rapid the first piece goes from an uncorrected point to the corrected path: beyond the
    correction's max_segment the path must be followed all the same."""

    def shift(p):
        return np.broadcast_to([0.0, 0.0, 0.05], p.shape).copy()

    def compare(inp, out, **kw):
        return corpus.compare_motion(_canon(inp), _canon(out), [False, True, False], shift, 0.005, max_piece=5.0, **kw)

    inp = [("traverse", (0, 0, -1)), ("feed", (20, 0, -1)), ("traverse", (20, 0, 5))]
    split = [("traverse", (0, 0, -1)), ("feed", (5, 0, -0.95)), ("feed", (20, 0, -0.95)), ("traverse", (20, 0, 5))]
    ramp = [("traverse", (0, 0, -1)), ("feed", (20, 0, -0.95)), ("traverse", (20, 0, 5))]
    assert compare(inp, split) == []
    assert compare(inp, ramp), "a ramp over the whole move is not the displaced path"
    # where the engine does not know the start, a straight move is corrected at its end only
    assert compare(inp, ramp, start_known=[False, False, True]) == []
    # a plunge stays one straight piece
    plunge = [("traverse", (0, 0, 10)), ("feed", (0, 0, -1)), ("traverse", (0, 0, 10))]
    assert compare(plunge, [("traverse", (0, 0, 10)), ("feed", (0, 0, -0.95)), ("traverse", (0, 0, 10))]) == []


def test_comparison_lets_a_rapid_keep_the_corrected_depth_of_an_axis_it_does_not_move():
    def shift(p):
        return np.broadcast_to([0.0, 0.0, 0.05], p.shape).copy()

    def compare(out):
        return corpus.compare_motion(_canon(inp), _canon(out), [False, True, False, True], shift, 0.005)

    # a rapid in XY at cutting depth, between two cuts
    inp = [("traverse", (0, 0, -1)), ("feed", (5, 0, -1)), ("traverse", (9, 0, -1)), ("feed", (10, 0, -1))]
    stays = [("traverse", (0, 0, -1)), ("feed", (5, 0, -0.95)), ("traverse", (9, 0, -0.95)), ("feed", (10, 0, -0.95))]
    back = [("traverse", (0, 0, -1)), ("feed", (5, 0, -0.95)), ("traverse", (9, 0, -1)), ("feed", (10, 0, -0.95))]
    assert compare(stays) == []
    assert compare(back) == []  # re-aimed at its programmed depth: also the input's target
    # ... but not to anywhere else, nor elsewhere in an axis it moves
    assert compare(_off(stays, 2, 0.02))
    assert compare([m if i != 2 else ("traverse", (9.02, 0, -0.95)) for i, m in enumerate(stays)])


@pytest.mark.skipif(RS274 is None, reason="LinuxCNC rs274 not installed")
def test_offsets_set_before_the_first_move_are_the_frame(tmp_path):
    """A program that sets its work offsets before it moves (LinuxCNC's puma_cube.ngc: G10 L2 P0
    first) is read in its own coordinates, as the field is: rs274's motion (offsets added) is
    compared in them, and a field that varies is evaluated there."""
    (tmp_path / "p.ngc").write_text(
        "G21 G10 L2 P0 X450 Y100 Z-495\nF1000\nG0 X-100 Y-100 Z-10\nG1 Z-20\nG1 X100\nG2 X100 Y100 R100\nG1 X-100\nG0 Z0\nM2\n"
    )
    r = corpus.run(corpus.Entry("p.ngc", "LinuxCNC/RS274NGC", "test", 9, root=tmp_path), tmp_path)
    assert r.outcome == "accepted" and r.motion == "matched", (r.outcome, r.motion_detail)


@pytest.mark.skipif(RS274 is None, reason="LinuxCNC rs274 not installed")
def test_a_lathe_program_with_a_loop_is_flattened_and_corrected(tmp_path, monkeypatch):
    """A LinuxCNC lathe's program (G7: X a diameter) with parameters and an O-word loop, read as
    `ncadapt correct --expand` reads it: flattened, corrected, and its motion matched by rs274."""
    (tmp_path / "p.ngc").write_text(
        "G7 G18 G21 G90\nF100\nG0 X30 Z2\n#1 = 28\no100 while [#1 GT 22]\n"
        "G1 X#1\nG1 Z-20\nG0 X[#1 + 2]\nG0 Z2\n#1 = [#1 - 2]\no100 endwhile\nG0 X40\nM2\n"
    )
    monkeypatch.setattr(corpus, "CORPUS", tmp_path)
    (tmp_path / "work").mkdir()
    r = corpus.run(corpus.Entry("p.ngc", "LinuxCNC/RS274NGC", "test", 13), tmp_path / "work")
    assert r.outcome == "accepted (--expand)" and r.motion == "matched", (r.outcome, r.motion_detail)
