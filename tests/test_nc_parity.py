"""The engine against LinuxCNC's rs274 on the constructs where a program could come out silently
wrong: each is either run as rs274 runs it or refused at its line with the construct named."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import needs_rs274
from ncadapt import InputError, fields, nc
from ncadapt.errors import RefusedError
from rs274 import canonical

pytestmark = [needs_rs274, pytest.mark.rs274]

ZERO = fields.Shift((0, 0, 0))


def _write(tmp_path, src: str | bytes, name="p.ngc"):
    p = tmp_path / name
    p.write_bytes(src.encode() if isinstance(src, str) else src)
    return p


def _run(tmp_path, src: str, name="c.ngc"):
    return canonical(_write(tmp_path, src, name))


# ------------------------------------------------------------------------------------------ axes
@pytest.mark.parametrize("axis", list("ABCUVW"))
def test_a_split_move_carries_its_share_of_another_axis(tmp_path, axis):
    """G1 X10 A90 cut into four pieces: each piece ends at its quarter of A, as LinuxCNC moves
    every axis linearly together (closed form), and rs274 runs the output."""
    src = f"G21 G90 G0 X0 Y0 Z0.2 {axis}0\nG1 X10 Y0 {axis}90 F1200\nM2\n"
    out = nc.read(_write(tmp_path, src)).correct(fields.Shift((0, 0, 0.01)), max_segment=2.5)
    text = out.text.splitlines()
    assert [ln.split(axis)[1].split()[0] for ln in text[1:5]] == ["22.5", "45.0", "67.5", "90.0"]
    if axis in "ABC":  # rs274 without a machine configuration has no U V W axes
        canon = canonical(out.write(tmp_path / "c.ngc"))
        assert canon.error is None, canon.error
        feeds = canon.ends[[k == "feed" for k in canon.kinds]]
        np.testing.assert_allclose(feeds[:, :3], [[2.5 * k, 0, 0.21] for k in (1, 2, 3, 4)], atol=1e-4)
        np.testing.assert_allclose(feeds[:, "ABC".index(axis) + 3], [22.5, 45, 67.5, 90], atol=1e-4)


@pytest.mark.parametrize("axis", list("ABCUVW"))
def test_zero_shift_with_another_axis_is_byte_identical(tmp_path, axis):
    src = f"G21 G0 X0 Y0 Z0 {axis}0\nG1 X10 {axis}5 F100\nG2 X20 Y0 I5 J0 {axis}7\nM2\n"
    prog = nc.read(_write(tmp_path, src))
    assert prog.correct(ZERO).data == prog.data


def test_a_field_moves_xyz_and_keeps_a_interpolated(tmp_path):
    """A field that varies along the move: pieces are not merged, A follows X linearly."""
    src = "G21 G90 G0 X0 Y0 Z0 A0\nG1 X10 A90 F100\nM2\n"
    out = nc.read(_write(tmp_path, src)).correct(
        lambda p: np.column_stack([0 * p[:, 0], 0 * p[:, 0], 0.001 * p[:, 0] ** 2])
    )
    canon = canonical(out.write(tmp_path / "c.ngc"))
    assert canon.error is None
    feeds = canon.ends[[k == "feed" for k in canon.kinds]]
    assert len(feeds) == 10
    np.testing.assert_allclose(feeds[:, 3], 9 * feeds[:, 0], atol=2e-4)
    np.testing.assert_allclose(feeds[:, 2], 0.001 * feeds[:, 0] ** 2, atol=1e-4)


def test_another_axis_from_an_unknown_start_is_kept_and_warned(tmp_path):
    """A never set before the move: its pieces cannot be interpolated, so the block is copied."""
    src = "G21 G90 G0 X0 Y0 Z0.2\nG1 X10 Y0 A90 F1200\nM2\n"
    prog = nc.read(_write(tmp_path, src))
    out = prog.correct(fields.Shift((0, 0, 0.01)), max_segment=2.5)
    assert out.data == prog.data
    assert "NaN" not in out.text
    (w,) = out.correction.warnings
    assert "line 2: the start of A unknown" in w


# ----------------------------------------------------------------------------- unknown starts
@pytest.mark.parametrize(
    "src",
    [
        "G21 G0 X0 Y0\nG2 X10 Y0 Z-1 R5 F100\nM2\n",  # Z never set
        "G21 G0 X0 Y0 Z5\nG53 G0 Z0\nG2 X10 Y0 Z-1 R5 F100\nM2\n",  # Z unknown after G53
        "G21 G0 X0 Y0 Z5\nG28 Z1\nG3 X10 Y0 Z-1 I5 J0 F100\nM2\n",  # Z unknown after G28
    ],
)
@pytest.mark.parametrize("shift", [(0, 0, 0), (0, 0, 0.05)])
def test_an_arc_from_an_unknown_start_stays_the_arc_it_was(tmp_path, src, shift):
    prog = nc.read(_write(tmp_path, src))
    out = prog.correct(fields.Shift(shift))
    assert out.data == prog.data
    assert out.correction.arcs_linearised == 0
    assert any("not corrected because the position is unknown" in w for w in out.correction.warnings)


# ------------------------------------------------------------------------ only moves move
@pytest.mark.parametrize(
    "src, construct",
    [
        ("G21 G0 X0 Y0 Z0\nG1 X1 F100\nM205 X10.00 Y10.00 Z0.20\nG1 X2\nM2\n", "M code M205"),
        ("G21 G0 X0 Y0 Z0\nG1 X1 F100\nM201 X500 Y500\nM2\n", "M code M201"),
        ("G21 G0 X0 Y0 Z0\nG1 X1 F100\nM203 X100 Y100 Z5\nM2\n", "M code M203"),
        ("G21 G0 X0 Y0 Z0\nG1 X1 F100\nG50 X100 Z50\nG1 X3\nM2\n", "coordinate setting G50"),
        ("G21 G0 X0 Y0 Z0\nG1 X99.853 Y103.192 E0.33188 F100\nM2\n", "E word"),
    ],
)
def test_axis_words_of_other_codes_are_not_moves(tmp_path, src, construct):
    """rs274 refuses each of these (an M code above 199, G50, an E word): the engine names the
    construct and writes nothing. (G43.1's words are tool lengths: tests/test_rs274.py.)"""
    p = _write(tmp_path, src)
    prog = nc.read(p)
    assert any(construct in u.construct for u in prog.unsupported), prog.unsupported
    with pytest.raises(RefusedError):
        prog.correct(fields.Shift((0, 0, 0.01)))
    canon = canonical(p)
    if construct != "G43.1":
        assert canon.error is not None
    # kept unchanged on request, and no later move is corrected from a position the code may have changed
    out = prog.correct(fields.Shift((0, 0, 0.01)), keep_unsupported=True)
    line = next(u.line for u in prog.unsupported if construct in u.construct)
    assert out.text.splitlines()[line - 1] == src.splitlines()[line - 1]


def test_an_extruder_reset_alone_moves_nothing(tmp_path):
    prog = nc.read(_write(tmp_path, "G21 G0 X0 Y0 Z0\nG92 E0\nG1 X1 F100\nM2\n"))
    assert not prog.unsupported
    assert prog.correct(fields.Shift((0, 0, 0.01))).text.splitlines()[2] == "G1 X1 Z0.01 F100"


# ------------------------------------------------------------------------ malformed programs
@pytest.mark.parametrize(
    "src, where, message",
    [
        (b"G21 G0 X0 Y0 Z0\nG1 X1 X2 F100\nM2\n", ":2:7:", "more than one X word"),
        (b"G21 G0 X0 Y0 Z0\nG0 G1 X5 F100\nM2\n", ":2:4:", "G0 and G1 are of one modal group"),
        (b"G21 G0 X0 Y0 Z0\nG1 X1e3 F100\nM2\n", ":2:6:", "exponent"),
        (b"G21 G0 X0 Y0 Z0\rG1 X5 F100\rM2\r", ":1:16:", "carriage return"),
        (b"G21 G0 X0 Y0 Z0\nM3 M4 S100\nM2\n", ":2:4:", "M3 and M4 are of one modal group"),
        (b"G21 G0 X0 Y0 Z0\nM7 M8\nM2\n", ":2:4:", "M7 and M8 are of one modal group"),
        # words no code of the block uses (a Fanuc G1 with R, I or K rounds or chamfers its corner)
        (b"G21 G0 X0 Y0 Z0\nG1 X10 R2 F100\nM2\n", ":2:8:", "R word with no"),
        (b"G21 G0 X0 Y0 Z0\nG0 X5 R2\nM2\n", ":2:7:", "R word with no"),
        (b"G21 G0 X0 Y0 Z0\nG1 X30 I1 F100\nM2\n", ":2:8:", "I word with no"),
        (b"G21 G0 X0 Y0 Z0\nG1 X10 K1 F100\nM2\n", ":2:8:", "K word with no"),
        (b"G21 G0 X0 Y0 Z0\nG1 X10 Q3 F100\nM2\n", ":2:8:", "Q word with no"),
        (b"G21 G0 X0 Y0 Z0\nG1 X10 H1 F100\nM2\n", ":2:8:", "H word with no"),
        (b"G21 G0 X0 Y0 Z0\nG1 X10 D2 F100\nM2\n", ":2:8:", "D word with no"),
        (b"G21 G0 X0 Y0 Z0\nG1 X10 L2 F100\nM2\n", ":2:8:", "L word with no"),
        (b"G21 G0 X0 Y0 Z0\nG1 X10 P2 F100\nM2\n", ":2:8:", "P word with no"),
        (b"G21 G0 X0 Y0 Z0\nG2 X10 Y0 I5 J0 F100\nR3\nM2\n", ":3:1:", "R word with no"),
    ],
)
def test_programs_rs274_rejects_are_refused_at_their_line(tmp_path, src, where, message):
    p = _write(tmp_path, src)
    assert canonical(p).error is not None
    with pytest.raises(InputError, match=where + ".*" + message):
        nc.read(p)


@pytest.mark.parametrize(
    "line",
    ["G2 X10 Y0 I5 J0", "I5 J0", "X5 R3", "G43 H1", "G64 P0.01 Q0.01", "G4 P0.5", "G10 L2 P1 X0", "M19 R90 P1"],
)
def test_words_their_codes_use_are_read(tmp_path, line):
    """The same letters where a code uses them (a modal arc's centre or radius included): rs274 runs
    the block and so does the engine."""
    p = _write(tmp_path, f"G21 G90 G0 X0 Y0 Z0\nG2 X10 Y0 I5 J0 F100\n{line}\nM2\n")
    assert canonical(p).error is None
    nc.read(p)  # no error (G10 is reported as unsupported, not as a misplaced word)


def test_codes_rs274_allows_together_are_read(tmp_path):
    """G80 beside a motion code is allowed by LinuxCNC (the motion code holds)."""
    src = "G21 G80 G90 G1 X1 Y2 Z3 F100\nM8\nG1 X2 G80\nM2\n"
    p = _write(tmp_path, src)
    assert canonical(p).error is None
    prog = nc.read(p)
    assert prog.blocks.end[:, 0].tolist() == [1.0, 2.0]


def test_text_after_the_program_end_is_copied(tmp_path):
    """LinuxCNC reads nothing after M2/M30 or a closing %: text there is copied as it is."""
    src = "%\nG21 G0 X0 Y0 Z0\nG1 X5 F100\nM30\n( Output Ends Here )\nPost Process Timed at; 32 Min, 50.0 sec\n%\nnot g-code!\n"
    p = _write(tmp_path, src)
    assert canonical(p).error is None
    prog = nc.read(p)
    assert prog.correct(ZERO).data == prog.data
    assert prog.correct(fields.Shift((0, 0, 0.01))).text.endswith(src.split("M30\n")[1])


# ------------------------------------------------------------------------------- arc radius
@pytest.mark.parametrize(
    "units, r, limit",
    [
        # (program units, radius, the largest start/end radius difference rs274 accepts) — the limit
        # is LinuxCNC 2.9's: 0.0283 mm (0.00283 in), or 0.1 % of the radius, up to 100 × 0.0283
        ("G21", 0.5, 0.02828),
        ("G21", 5, 0.02828),
        ("G21", 100, 0.1001),
        ("G21", 10000, 2.8284),
        ("G20", 0.5, 0.002828),
        ("G20", 5, 0.005005),
    ],
)
def test_centre_arc_radius_tolerance_is_linuxcnc_s(tmp_path, units, r, limit):
    for factor, accepted in ((0.97, True), (1.03, False)):
        d = limit * factor
        src = f"{units} G90 G0 X0 Y0 Z0\nG2 X{2 * r + d:.6f} Y0 I{r} J0 F100\nM2\n"
        p = _write(tmp_path, src, f"arc{factor}.ngc")
        canon = canonical(p)
        assert (canon.error is None) == accepted, (src, canon.error)
        if accepted:
            end = nc.read(p).blocks.end[-1, :3]
            np.testing.assert_allclose(end, canon.ends[-1, :3], atol=canon.resolution_mm + 1e-9)
        else:
            with pytest.raises(InputError, match=":2:1: radius to the end of the arc"):
                nc.read(p)


# -------------------------------------------------------------------------------- bounds
@pytest.mark.parametrize(
    "src, kw",
    [
        ("G21 G0 X0 Y0 Z0\nG1 X100000000000000000000 F100\nM2\n", {}),
        ("G21 G0 X0 Y0 Z0\nG2 X0 Y0 I1 J0 P999999999 F100\nM2\n", {}),
        ("G21 G0 X0 Y0 Z0\nG1 X2000 F100\nM2\n", {"max_segment": 0.001}),
    ],
)
def test_a_block_that_would_make_too_many_pieces_is_refused(tmp_path, src, kw):
    prog = nc.read(_write(tmp_path, src))
    with pytest.raises(InputError, match=r":2:1: this move would be cut into .* pieces, more than the 1000000"):
        prog.correct(fields.Shift((0, 0, 0.01)), **kw)
    out = tmp_path / "out.ngc"
    with pytest.raises(InputError):
        prog.correct_to(out, fields.Shift((0, 0, 0.01)), **kw)
    assert not out.exists()


@pytest.mark.parametrize("kw", [{"max_segment": 1e-9}, {"chord_tol": 1e-300}, {"chord_tol": float("nan")}])
def test_sampling_options_out_of_range_are_refused(tmp_path, kw):
    prog = nc.read(_write(tmp_path, "G21 G0 X0 Y0 Z0\nG1 X1 F100\nM2\n"))
    with pytest.raises(ValueError, match="must be within"):
        prog.correct(fields.Shift((0, 0, 0.01)), **kw)


@pytest.mark.parametrize("stop", ["M0", "M2", "M30"])
def test_a_program_stop_on_an_arc_made_one_piece_is_kept(tmp_path, stop):
    """A short arc linearised into a single piece keeps its program stop (found by the fuzz)."""
    src = f"G21 G90 G0 X0 Y0 Z0\nG2 X-0.0034243 Y-0.0784322 I-0.5 J0 F100 {stop}\n"
    out = nc.read(_write(tmp_path, src)).correct(fields.Shift((0, 0, 0.05)))
    assert out.correction.arcs_linearised == 1
    assert out.text.splitlines()[1].endswith(stop)
    if stop != "M0":
        assert canonical(out.write(tmp_path / "c.ngc")).error is None


# ------------------------------------------------------------------------------------- R arcs
R_ARCS = "G21 G90 G17 G90.1\nG0 X0 Y0 Z1\nG1 Z-1 F100\nG2 X10 Y0 R5\nG1 X20\nG3 X30 Y0 R5\nG18 G2 X38 Z-1 R5\nM2\n"


@pytest.mark.parametrize("shift", [(0, 0, 0), (0.1, 0.2, 0.03)])
def test_r_arcs_under_absolute_centres_keep_their_r_alone(tmp_path, shift):
    """Under G90.1 an R-format arc names no centre: a uniform shift moves it whole, with R alone
    (LinuxCNC refuses R beside I/J/K), and rs274 runs it as the input's arcs shifted."""
    prog = nc.read(_write(tmp_path, R_ARCS))
    out = prog.correct(fields.Shift(shift), rapids=True)
    if shift == (0, 0, 0):
        assert out.data == prog.data
        return
    assert all(not any(w in ln for w in ("I", "J", "K")) for ln in out.text.splitlines()[1:])
    a, b = _run(tmp_path, R_ARCS, "in.ngc"), canonical(out.write(tmp_path / "c.ngc"))
    assert b.error is None, b.error
    assert a.kinds == b.kinds and "arc" in a.kinds
    np.testing.assert_allclose(b.ends[:, :3], a.ends[:, :3] + shift, atol=1e-4)
    for ra, rb in zip(a.arcs, b.arcs):
        if ra is not None:
            # the centre moves with the arc in the arc's own plane
            plane = {"CANON_PLANE_XY": (0, 1), "CANON_PLANE_XZ": (2, 0), "CANON_PLANE_YZ": (1, 2)}[ra[3]]
            want = (ra[1] + shift[plane[0]], ra[2] + shift[plane[1]])
            assert rb[0] == ra[0] and rb[3] == ra[3]
            np.testing.assert_allclose(rb[1:3], want, atol=1e-4)


# ----------------------------------------------------------------------- spindle-synchronised G33
#: A thread cut with G33 as LinuxCNC's threading.ngc cuts it: a feed to the start, the thread
#: along Z, the exit at 45° still synchronised, a rapid out.
G33_PASS = "G20 G18\nG0 X0.2 Y0 Z0.5\nS500 M3\nG1 X0.15 F10\nG33 Z-0.5 K0.05\nG33 X0.2 Z-0.55 K0.07\nG0 X0.3\nM2\n"


def _synced(canon):
    """rs274's feeds (mm) and how many synchronised motions it starts."""
    return canon.ends[[k for k, kind in enumerate(canon.kinds) if kind == "feed"], :3]


def test_a_synchronised_move_is_moved_whole(tmp_path):
    """Each G33 block synchronises anew with the spindle (rs274: START_SPEED_FEED_SYNC per block),
    so it stays one block: a shift moves its end, and its start by the corrected feed before it,
    so rs274 runs the same synchronised moves displaced; a field that bends it is refused."""
    shift = (0.01, 0.0, 0.02)
    out = nc.read(_write(tmp_path, G33_PASS)).correct(fields.Shift(shift))
    text = out.text
    assert text.count("G33") == 2 and "K0.05" in text and "K0.07" in text
    before, after = _run(tmp_path, G33_PASS, "in.ngc"), canonical(out.write(tmp_path / "out.ngc"))
    assert after.error is None, after.error
    np.testing.assert_allclose(
        _synced(after)[-2:], _synced(before)[-2:] + shift, atol=3e-3
    )  # rs274: 4 decimals of an inch
    syncs = lambda p: p.read_text().count("G33")  # noqa: E731
    assert syncs(tmp_path / "out.ngc") == 2

    def bend(p):
        d = np.zeros_like(np.asarray(p, float))
        d[:, 0] = 0.02 * np.sin(np.asarray(p, float)[:, 2] / 5.0)
        return d

    with pytest.raises(
        InputError, match=r":5:1: a spindle-synchronised move \(G33\) (must stay one move|starts where)"
    ):
        nc.read(_write(tmp_path, G33_PASS)).correct(bend)


def test_a_synchronised_move_after_a_rapid_needs_the_rapid_corrected(tmp_path):
    src = G33_PASS.replace("G1 X0.15 F10", "G0 X0.15")
    with pytest.raises(
        InputError, match=r":5:1: a spindle-synchronised move \(G33\) starts where the tool stands.*--rapids"
    ):
        nc.read(_write(tmp_path, src)).correct(fields.Shift((0.0, 0.0, 0.02)))
    out = nc.read(_write(tmp_path, src)).correct(fields.Shift((0.0, 0.0, 0.02)), rapids=True)
    assert canonical(out.write(tmp_path / "out.ngc")).error is None


@pytest.mark.parametrize(
    ("src", "where", "says"),
    [
        # rs274: "K word missing with g33/g33.1", on each block
        (G33_PASS.replace("G33 X0.2 Z-0.55 K0.07", "X0.2 Z-0.55"), ":6:", "K word missing with G33"),
        (G33_PASS.replace("G33 Z-0.5 K0.05", "G33 Z-0.5"), ":5:", "K word missing with G33"),
    ],
)
def test_a_synchronised_move_without_its_pitch_is_refused(tmp_path, src, where, says):
    assert "K word missing" in _run(tmp_path, src).error
    with pytest.raises(InputError, match=f"{where}.*{says}"):
        nc.read(_write(tmp_path, src)).blocks  # noqa: B018


def test_a_synchronised_move_under_cutter_compensation_is_refused(tmp_path):
    src = "G20 G17\nG0 X0 Y0 Z0.1\nS500 M3\nG41 D1\nG1 X1 F10\nG33 X2 K0.05\nG40\nM2\n"
    (u,) = nc.read(_write(tmp_path, src), tools={1: 2.54}).unsupported
    assert (u.line, "G33 under cutter compensation" in u.construct) == (6, True)


# ------------------------------------------------------------------------- LinuxCNC's G76 cycle
G76_PASS = (
    "G20 G18 G8\nG0 X0.6 Z0.1\nS500 M3\nG1 X0.55 F10\n"
    "G76 P0.05 Z-0.5 I-0.075 J0.008 K0.045 Q29.5 H1 E0.02 L2\nG0 X0.7\nM2\n"
)


@pytest.mark.parametrize("before", ["G1 X0.55 F10", "G0 X0.55"])
def test_linuxcnc_threading_cycle_moves_as_one(tmp_path, before):
    """rs274 runs G76 as passes from where the tool stands (the drive line) to the block's Z and a
    rapid to its end: moved as one by a shift, every move of the cycle is the input's shifted. The
    start moves with it: by the corrected feed before it, or by a move added before the block
    where the move there is a rapid."""
    src = G76_PASS.replace("G1 X0.55 F10", before)
    shift = (0.01, 0.0, 0.02)
    out = nc.read(_write(tmp_path, src), dialect="linuxcnc-lathe").correct(fields.Shift(shift))
    lines = out.text.splitlines()
    assert "G76 P0.05 Z-0.49921 I-0.075 J0.008 K0.045 Q29.5 H1 E0.02 L2" in lines
    if before.startswith("G0"):
        assert lines[lines.index("G0 X0.55") + 1] == "G0 X0.55039 Z0.10079"  # the start, moved
    canon_in = _run(tmp_path, src, "in.ngc")
    canon_out = canonical(out.write(tmp_path / "out.ngc"))
    assert canon_in.error is None and canon_out.error is None, canon_out.error
    # the cycle's moves: after the move to the start, before the last rapid
    n = len(canon_in.ends) - 3
    assert n > 20
    cycle_in, cycle_out = canon_in.ends[2:-1, :3], canon_out.ends[-1 - n : -1, :3]
    np.testing.assert_allclose(cycle_out, cycle_in + shift, atol=3e-3)  # (rs274: 4 decimals of an inch)


def test_linuxcnc_threading_cycle_refusals(tmp_path):
    def wave(p):
        p = np.asarray(p, float)
        d = np.zeros_like(p)
        d[:, 0] = 0.01 * np.sin(p[:, 2] / 3.0)
        return d

    with pytest.raises(RefusedError, match=r"line 5: threading cycle G76: the field varies"):
        nc.read(_write(tmp_path, G76_PASS), dialect="linuxcnc-lathe").correct(wave)
    # rs274's own errors, at the line
    for bad, says in (("I-0.075", "I must not be 0"), ("K0.045", "K must be greater than J")):
        src = G76_PASS.replace(bad, bad[0] + "0")
        assert says in _run(tmp_path, src).error
        with pytest.raises(InputError, match=f":5:.*{says}"):
            nc.read(_write(tmp_path, src), dialect="linuxcnc-lathe").blocks  # noqa: B018


def _feeds(canon):
    return canon.ends[[k for k, kind in enumerate(canon.kinds) if kind == "feed"], :3]


@pytest.mark.parametrize(
    ("src", "dialect"),
    [
        # the move added to the moved start is written in the state before the block: G91 ...
        ("G21 G18 G8\nG0 X10 Z2\nS500 M3\nG91\nG76 P1 Z-12 I-1 J0.2 K0.8 X2\nG90 G0 X20\nM2\n", "linuxcnc-lathe"),
        # ... radius mode when the block turns diameter mode on, mm when it turns inches on ...
        ("G21 G18 G8\nG0 X10 Z2\nS500 M3\nG7 G76 P1 Z-10 I-1 J0.2 K0.8\nG8 G0 X20\nM2\n", "linuxcnc-lathe"),
        ("G21 G18 G8\nG0 X10 Z2\nS500 M3\nG20 G76 P0.04 Z-0.4 I-0.04 J0.008 K0.03\nG21 G0 X20\nM2\n", "linuxcnc-lathe"),
        # ... and a mill's Y too
        ("G21 G18\nG0 X10 Y5 Z2\nS500 M3\nG76 P1 Z-10 I-1 J0.2 K0.8\nG0 X20\nM2\n", "linuxcnc"),
    ],
)
def test_the_move_to_a_cycle_s_moved_start_runs_in_the_state_before_it(tmp_path, src, dialect):
    """rs274 runs the output's thread passes where it runs the input's, shifted."""
    shift = (0.01, 0.02 if dialect == "linuxcnc" else 0.0, 0.02)
    out = nc.read(_write(tmp_path, src), dialect=dialect).correct(fields.Shift(shift))
    assert len(out.text.splitlines()) == len(src.splitlines()) + 1  # (the added move)
    canon_in, canon_out = _run(tmp_path, src, "in.ngc"), canonical(out.write(tmp_path / "out.ngc"))
    assert canon_in.error is None and canon_out.error is None, canon_out.error
    feeds_in, feeds_out = _feeds(canon_in), _feeds(canon_out)
    assert len(feeds_in) == len(feeds_out) >= 4
    np.testing.assert_allclose(feeds_out, feeds_in + shift, atol=3e-3)


@pytest.mark.parametrize(
    "before",
    [
        "G81 X10 Y0 Z-1 R3 F100\nG18\n",  # a drilling cycle still in force (group 1)
        "G33 Z1.5 K1\n",  # a synchronised move in force
    ],
)
def test_no_move_is_added_to_a_cycle_s_start_in_another_mode(tmp_path, before):
    src = f"G21 G17\nG0 X10 Y0 Z5\nS500 M3\n{before}G18\nG76 P1 Z-10 I-1 J0.2 K0.8\nG0 X20\nM2\n".replace(
        "G18\nG18\n", "G18\n"
    )

    def lean(p):
        d = np.zeros_like(np.asarray(p, float))
        d[:, 0] = 0.01 + 0.00015 * np.asarray(p, float)[:, 2]
        d[:, 2] = 0.02
        return d

    with pytest.raises(InputError, match="no G0 or G1 is in force"):
        nc.read(_write(tmp_path, src)).correct(lean, chord_tol=0.01, rapids=True)


def test_a_repeated_g76_and_a_copied_one(tmp_path):
    # a G76 block repeated without its code (modal, as rs274 runs it): read
    src = "G21 G18 G8\nG0 X10 Z2\nS500 M3\nG76 P1 Z-3 I-1 J0.2 K0.8\nP1 Z-6 I-1 J0.2 K0.8\nG80\nM2\n"
    assert _run(tmp_path, src).error is None
    assert nc.read(_write(tmp_path, src), dialect="linuxcnc-lathe").unsupported == ()
    # a G76 copied (--keep-unsupported) ends at its end: an increment after it is from there
    src = "G21 G18\nG0 X10 Y0 Z2\nS500 M3\nG76 P1 Z-10 I-1 J0.2 K0.8 Y1\nG91\nG1 X1 F100\nG90\nM2\n"
    out = nc.read(_write(tmp_path, src)).correct(fields.Shift((0.0, 0.0, 0.02)), keep_unsupported=True)
    canon = canonical(out.write(tmp_path / "out.ngc"))
    assert canon.error is None, canon.error
    np.testing.assert_allclose(_feeds(canon)[-1], [11.0, 1.0, -9.98], atol=2e-3)


def test_cycles_too_large_to_check_and_g33_from_nowhere_are_refused(tmp_path):
    huge = "O1\nG18 G21\nG0 X30. Z5.\nG75 X-20000. Z-50000. I2. K3. F0.1\nM30\n"
    with pytest.raises(InputError, match="pieces"):
        nc.parse(huge, dialect="fanuc-lathe").correct(fields.Shift((0, 0, 0.01)))
    # a G33 from where the program does not tell (Y here): left as written, with the warning
    src = "G21 G18\nG0 X10 Z2\nS500 M3\nG33 Z-5 K1\nM2\n"
    out = nc.read(_write(tmp_path, src)).correct(fields.Shift((0, 0, 0.01)))
    assert out.text == src and "not corrected because the position is unknown" in " ".join(out.correction.warnings)
