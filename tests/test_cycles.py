"""Canned cycles (G73, G74, G81-G86, G89; G98/G99; R, Z, Q, P, L; G91) against LinuxCNC's rs274.

The correction moves each hole as a whole: the field is evaluated at the hole, X and Y move by
its x and y, Z (the bottom) and R (the R plane) by its z. The truth the corrected programs are held
to is rs274's own expansion of the input whose holes the test has displaced itself (every X Y Z R
written out, with the displacement the test computes from the field's formula at the hole): the
corrected program, kept as cycle blocks or written as moves (``expand_cycles``), must make that
motion move for move within 5 µm, and every cutting move must be rs274's cutting move of the
input plus the field at its hole.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import needs_rs274
from ncadapt import InputError, fields, nc
from ncadapt.errors import RefusedError
from rs274 import Canon, canonical

pytestmark = [needs_rs274, pytest.mark.rs274]

TOL = 0.005  # mm


def _wavy(x, y):
    """A displacement that depends on x and y only (mm): the field's value at a hole is the same
    for every point of it."""
    return (
        0.01 * math.cos(y / 7.0),
        -0.02 * math.sin(x / 5.0),
        0.03 * math.sin(x / 6.0) * math.cos(y / 4.0) + 0.001 * x,
    )


def _field_of(d):
    def field(p):
        return np.array([d(x, y) for x, y in p[:, :2]], dtype=float).reshape(-1, 3)

    return field


def _zero(x, y):
    return (0.0, 0.0, 0.0)


class _Holes:
    """Writes a drilling program: the nominal one (``d`` None: sticky words left out as shops write
    them) or the one whose holes are displaced by ``d(x, y)`` (every X Y Z R written)."""

    def __init__(self, d=None):
        self.d, self.lines, self.z, self.r = d, [], None, None

    def raw(self, text):
        self.lines.append(text)

    def hole(self, head, x, y, z=None, r=None, tail=""):
        self.z = self.z if z is None else z
        self.r = self.r if r is None else r
        if self.d is None:
            words = [f"X{x:.4f}", f"Y{y:.4f}"] + ([f"Z{z:.4f}"] if z is not None else [])
            words += [f"R{r:.4f}"] if r is not None else []
        else:
            dx, dy, dz = self.d(x, y)
            words = [f"X{x + dx:.4f}", f"Y{y + dy:.4f}", f"Z{self.z + dz:.4f}", f"R{self.r + dz:.4f}"]
        self.lines.append(" ".join(w for w in [head, *words, tail] if w))

    def text(self):
        return "\n".join(self.lines) + "\n"


def _pattern(p):
    """G98 G81 over a 3 x 3 grid of holes, from Z 10 above an R plane at 1."""
    p.raw("G21 G90 G17 G0 X0 Y0 Z10")
    p.raw("M3 S1000")
    first = True
    for j in range(3):
        for i in range(3):
            x, y = 5.0 + 12.5 * i, 4.0 + 9.0 * j
            if first:
                p.hole("G98 G81", x, y, z=-3.0, r=1.0, tail="F120")
                first = False
            else:
                p.hole("", x, y)
    p.raw("G80")
    p.raw("G0 X0 Y0")
    p.raw("M2")


def _peck(p):
    """G99 G83 with Q (a hole deeper than the others), then G73."""
    p.raw("G21 G90 G17 G0 X0 Y0 Z8")
    p.raw("M3 S1000")
    p.hole("G99 G83", 3.0, 2.0, z=-6.0, r=0.5, tail="Q1.25 F90")
    p.hole("", 11.0, 2.0)
    p.hole("", 19.0, 7.5, z=-8.0)
    p.hole("G73", 25.0, 12.0, z=-4.0, r=1.0, tail="Q0.7")
    p.hole("", 31.0, 3.0)
    p.raw("G80")
    p.raw("G0 Z8")
    p.raw("M2")


def _dwell(p):
    """G82 with P, G85, G89 and a G81 whose hole stays where the tool is (no X or Y)."""
    p.raw("G21 G90 G17 G0 X4 Y3 Z6")
    p.raw("M3 S800")
    p.hole("G98 G82", 4.0, 3.0, z=-2.5, r=1.5, tail="P0.5 F60")
    p.hole("", 14.0, 9.0)
    p.hole("G85", 22.0, 6.0, z=-3.0, r=1.0)
    p.hole("G89", 30.0, 2.0, z=-2.0, r=1.0, tail="P0.2")
    p.raw("G80")
    p.raw("G0 X30 Y12")
    if p.d is None:
        p.raw("G81 Z-1.5 R1 F60")  # at the current X and Y
    else:
        dx, dy, dz = p.d(30.0, 12.0)
        p.raw(f"G81 X{30 + dx:.4f} Y{12 + dy:.4f} Z{-1.5 + dz:.4f} R{1 + dz:.4f} F60")
    p.raw("G80")
    p.raw("M2")


def _retract_modes(p):
    """G98 and G99 alternating; a cycle started below its R plane (the tool rises to R first)."""
    p.raw("G21 G90 G17 G0 X0 Y0 Z12")
    p.raw("M3 S1000")
    p.hole("G98 G81", 2.0, 2.0, z=-2.0, r=3.0, tail="F100")
    p.hole("G99", 8.0, 2.0)
    p.hole("", 14.0, 5.0)
    p.hole("G98", 20.0, 5.0, r=2.5)
    p.raw("G80")
    p.raw("G0 X24 Y8 Z0.5")
    p.hole("G99 G81", 26.0, 8.0, z=-1.0, r=2.0)
    p.hole("G98", 30.0, 8.0)
    p.raw("G80")
    p.raw("M2")


CASES = {"g81_pattern": _pattern, "g83_g73_peck": _peck, "g82_g85_g89_dwell": _dwell, "g98_g99": _retract_modes}


def _program(case, d=None):
    p = _Holes(d)
    CASES[case](p)
    return p.text()


def _canon(tmp_path, text, name) -> Canon:
    path = tmp_path / name
    path.write_text(text) if isinstance(text, str) else path.write_bytes(text)
    c = canonical(path)
    assert c.error is None, f"{name}: {c.error}"
    return c


def _same_motion(got: Canon, want: Canon, what: str):
    assert got.kinds == want.kinds, f"{what}: {len(got.kinds)} moves, expected {len(want.kinds)}"
    err = np.abs(got.ends[:, :3] - want.ends[:, :3]).max(axis=1)
    bad = np.flatnonzero(err > TOL)
    assert not len(bad), f"{what}: move {bad[0]} ends at {got.ends[bad[0], :3]}, expected {want.ends[bad[0], :3]}"


def _feeds_displaced(out: Canon, inp: Canon, d, what: str, last: int | None = None):
    """Every cutting move of the output is rs274's cutting move of the input plus the field there,
    in order. (The rapids may differ in number: in G99 a hole whose corrected R plane is lower
    than the one before gets a rapid down to it, as LinuxCNC runs any cycle.)"""

    def feeds(c: Canon):
        # (a peck that rounding lands on the bottom makes LinuxCNC feed to the bottom twice, the
        # second after backing off: a feed to where the last one ended cuts nothing new)
        k = np.flatnonzero(np.array(c.kinds) == "feed")
        again = np.r_[False, np.abs(np.diff(c.ends[k, :3], axis=0)).max(axis=1) <= 0.002]
        return k[~again]

    feed_in, feed_out = feeds(inp), feeds(out)
    if last is not None:  # the cycle's (a move before it may be written in pieces)
        feed_in, feed_out = feed_in[-last:], feed_out[-last:]
    assert len(feed_in) and len(feed_out) == len(feed_in), what
    want = inp.ends[feed_in, :3] + np.array([d(x, y) for x, y in inp.ends[feed_in, :2]])
    err = np.abs(out.ends[feed_out, :3] - want).max()
    assert err <= TOL, f"{what}: cutting moves {err * 1000:.1f} µm off the displaced input"


@pytest.mark.parametrize("expand", [False, True], ids=["cycles", "expanded"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_corrected_cycles_are_the_displaced_holes(tmp_path, case, expand):
    src = _program(case)
    inp = _canon(tmp_path, src, "in.ngc")
    oracle = _canon(tmp_path, _program(case, _wavy), "displaced.ngc")
    prog = nc.parse(src)
    assert not prog.unsupported
    out = prog.correct(_field_of(_wavy), expand_cycles=expand)
    got = _canon(tmp_path, out.data, "out.ngc")
    _same_motion(got, oracle, case)
    _feeds_displaced(got, inp, _wavy, case)
    text = out.text
    if expand:
        assert not any(f"G{c}" in text for c in (73, 81, 82, 83, 85, 89)), text
    else:  # cycle blocks stay cycle blocks, one line each
        assert out.correction.lines_added == 0 and text.count("\n") == src.count("\n")


@pytest.mark.parametrize("case", sorted(CASES))
def test_zero_correction_gives_the_program_back(case):
    src = _program(case)
    prog = nc.parse(src)
    for field in (fields.Shift((0, 0, 0)), _field_of(_zero)):
        assert prog.correct(field).data == src.encode()


def test_grid_field_moves_the_holes_by_its_dz(tmp_path):
    """A probed grid (dz only): the holes keep X and Y, their Z and R move by the grid's bilinear
    value at the hole (closed form below), and rs274 runs the output as the displaced input."""
    xs, ys = np.array([0.0, 20.0, 40.0]), np.array([0.0, 15.0, 30.0])
    dz = np.array([[0.00, 0.02, 0.05], [0.01, -0.03, 0.04], [0.02, 0.00, -0.02]])  # [y, x]
    grid = fields.GridField(xs, ys, dz)

    def bilinear(x, y):
        i, j = min(int(x // 20), 1), min(int(y // 15), 1)
        u, v = (x - xs[i]) / 20, (y - ys[j]) / 15
        z = (
            (1 - u) * (1 - v) * dz[j, i]
            + u * (1 - v) * dz[j, i + 1]
            + (1 - u) * v * dz[j + 1, i]
            + u * v * dz[j + 1, i + 1]
        )
        return (0.0, 0.0, z)

    src = _program("g81_pattern")
    out = nc.parse(src).correct(grid)
    got = _canon(tmp_path, out.data, "out.ngc")
    _same_motion(got, _canon(tmp_path, _program("g81_pattern", bilinear), "d.ngc"), "grid")
    _feeds_displaced(got, _canon(tmp_path, src, "in.ngc"), bilinear, "grid")


def test_g73_in_inches(tmp_path):
    """Inch program: the pecks, and rs274's extra zero-length peck where the last lands on the bottom."""
    src = "G20 G90 G17 G0 X0 Y0 Z1\nG98 G73 X1 Y2 Z-0.1 R0.05 Q0.03 F10\nX1.5\nG80\nM2\n"

    def d(x, y):
        return (0.0, 0.0, 0.0254 * 0.3)  # 0.3 thousandth of an inch

    inp = _canon(tmp_path, src, "in.ngc")
    prog = nc.parse(src)
    assert len(prog.blocks.line) == len(inp.kinds)  # the engine reads rs274's moves one for one
    assert np.abs(prog.blocks.end[:, :3] - inp.ends[:, :3]).max() <= 0.0001 * 25.4
    for expand in (False, True):
        out = prog.correct(fields.Shift((0, 0, 0.0254 * 0.3)), expand_cycles=expand)
        _feeds_displaced(_canon(tmp_path, out.data, "o.ngc"), inp, d, f"inch expand={expand}")


def test_g91_cycle_with_repeats(tmp_path):
    """G91 G81 L4 (holes 6 mm apart, R and Z relative): after a corrected feed the output's
    position is already displaced, so a uniform shift writes the block unchanged but for R;
    a field that moves the holes differently needs --expand-cycles, and is refused without it."""
    src = "G21 G90 G17 G0 X0 Y0 Z10\nG1 Z5 F200\nG91 G98 G81 X6 Y1 Z-7 R-4 L4 F100\nG90 G80\nG0 Z10\nM2\n"
    inp = _canon(tmp_path, src, "in.ngc")
    prog = nc.parse(src)
    assert not prog.unsupported
    shift = (0.02, -0.01, 0.04)
    out = prog.correct(fields.Shift(shift))
    assert "G91 G98 G81 X6 Y1 Z-7 R-4 L4 F100" in out.text.splitlines()  # relative to a displaced start
    _feeds_displaced(_canon(tmp_path, out.data, "o.ngc"), inp, lambda x, y: shift, "g91 shift", last=4)
    with pytest.raises(InputError, match=r":3:1: G91 canned cycle G81 with L4: .*--expand-cycles"):
        prog.correct(_field_of(_wavy))
    out = prog.correct(_field_of(_wavy), expand_cycles=True)
    got = _canon(tmp_path, out.data, "e.ngc")
    # the feed before the cycle is displaced too; its end is the cycle's initial level
    _feeds_displaced(got, inp, _wavy, "g91 expanded", last=4)


def test_cycle_then_g80_and_ordinary_moves(tmp_path):
    """After G80 the ordinary moves are corrected as ever, from where the cycle left the tool
    (G99: the corrected R plane)."""

    def affine(x, y):
        return (0.001 * y, -0.002 * x, 0.01 + 0.002 * x - 0.001 * y)

    src = (
        "G21 G90 G17 G0 X0 Y0 Z5\nG99 G81 X3 Y4 Z-2 R1 F100\nX9\nG80\n"
        "G1 X12 Y4 Z-1 F200\nX20 Y10\nG91 X-4 Y2\nG90 G0 Z5\nM2\n"
    )
    inp = _canon(tmp_path, src, "in.ngc")
    for expand in (False, True):
        out = nc.parse(src).correct(_field_of(affine), expand_cycles=expand)
        _feeds_displaced(_canon(tmp_path, out.data, "o.ngc"), inp, affine, f"after G80 expand={expand}")


# ------------------------------------------------------------------------------ minimal cases
# program body after "G21 G90 G17 G0 X0 Y0 Z10\nM3 S1000\n" -> (construct refused, or None)
REFUSED = {
    "g18_plane": ("G18 G81 X1 Y2 Z-3 R2 F100\nG80\n", "canned cycle G81 in the G18 plane"),
    "g19_plane": ("G19 G81 X1 Y2 Z-3 R2 F100\nG80\n", "canned cycle G81 in the G19 plane"),
    "g87_back_boring": ("G87 X1 Y2 Z-3 R2 I1 J0 K-1 F100\nG80\n", "canned cycle G87"),
    "g88_manual_retract": ("G88 X1 Y2 Z-3 R2 P1 F100\nG80\n", "canned cycle G88"),
    "rotary_word": ("G81 X1 Y2 Z-3 R2 A10 F100\nG80\n", "canned cycle G81 with A B C U V W words"),
    "unknown_position": ("G53 G0 Z0\nG81 X1 Y2 Z-3 R2 F100\nG80\n", "canned cycle G81 from an unknown position"),
    # a polar word from an unknown X Y (from review)
    "polar_unknown": ("G28\nG0 Z5\nG98 G81 ^30 R1 Z-4 F100\nG80\n", "canned cycle G81 from an unknown position"),
}


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_cycles_the_engine_does_not_follow_are_refused_at_their_line(tmp_path, name):
    body, construct = REFUSED[name]
    src = "G21 G90 G17 G0 X0 Y0 Z10\nM3 S1000\n" + body + "M2\n"
    prog = nc.parse(src)
    uns = prog.unsupported
    assert uns and uns[0].construct.startswith(construct), uns
    assert uns[0].line >= 3
    with pytest.raises(RefusedError, match="unsupported construct"):
        prog.correct(fields.Shift((0, 0, 0.01)))


# words LinuxCNC requires: rs274 refuses these programs too (message checked against rs274's)
ERRORS = {
    "no_r": ("G81 X1 Y2 Z-3 F100\n", "needs an R word", "R clearance plane unspecified"),
    "no_z": ("G81 X1 Y2 R2 F100\n", "needs a Z word", "Z value unspecified"),
    "no_q": ("G83 X1 Y2 Z-3 R2 F100\n", "needs a Q word", "Q word missing"),
    "q_zero": ("G73 X1 Y2 Z-3 R2 Q0 F100\n", "must be > 0", "Q value used"),
    "no_p": ("G82 X1 Y2 Z-3 R2 F100\n", "needs a P word", "P word missing"),
    "l_zero": ("G81 X1 Y2 Z-3 R2 L0 F100\n", "must be a whole number", "zero repeats"),
    "r_below_z": ("G81 X1 Y2 Z-3 R-4 F100\n", "is below its bottom", "R less than Z"),
}


@pytest.mark.parametrize("name", sorted(ERRORS))
def test_cycle_words_checked_as_rs274_checks_them(tmp_path, name):
    body, ours, theirs = ERRORS[name]
    src = "G21 G90 G17 G0 X0 Y0 Z10\nM3 S1000\n" + body + "G80\nM2\n"
    path = tmp_path / "e.ngc"
    path.write_text(src)
    err = canonical(path).error
    assert err is not None and theirs.lower() in err.lower(), err
    with pytest.raises(InputError, match=ours):
        nc.read(path)


def test_tapping_and_g86_kept_as_cycles_but_not_expanded(tmp_path):
    """G84 (tapping, spindle reversed) and G86 (spindle stopped): moved as holes, but the spindle
    commands they make are not G0/G1 moves: --expand-cycles refuses them."""
    for code in ("G84", "G86 P0.5"):
        src = f"G21 G90 G17 G0 X0 Y0 Z10\nM3 S500\nG99 {code} X5 Y5 Z-4 R2 F100\nX9\nG80\nM2\n"
        inp = _canon(tmp_path, src, "in.ngc")
        prog = nc.parse(src)
        assert not prog.unsupported
        out = prog.correct(fields.Shift((0.0, 0.0, 0.02)))
        _feeds_displaced(_canon(tmp_path, out.data, "o.ngc"), inp, lambda x, y: (0.0, 0.0, 0.02), code)
        with pytest.raises(InputError, match="cannot write; correct it without --expand-cycles"):
            prog.correct(fields.Shift((0.0, 0.0, 0.02)), expand_cycles=True)


@pytest.mark.parametrize("expand", [False, True], ids=["cycles", "expanded"])
def test_correct_command_on_a_file(tmp_path, expand):
    """``ncadapt correct`` (the engine's own grid evaluation, piece by piece) writes what
    Program.correct writes; ``--expand-cycles`` is the option."""
    from click.testing import CliRunner

    from ncadapt.cli import main

    xs, ys = np.linspace(-5, 45, 6), np.linspace(-5, 35, 5)
    X, Y = np.meshgrid(xs, ys)
    dz = 0.02 * np.sin(X / 9) * np.cos(Y / 7)
    grid = tmp_path / "grid.csv"
    grid.write_text("x,y,dz\n" + "".join(f"{x},{y},{z}\n" for x, y, z in zip(X.ravel(), Y.ravel(), dz.ravel())))
    for case in sorted(CASES):
        src = tmp_path / f"{case}.ngc"
        src.write_text(_program(case))
        out = tmp_path / f"{case}-out.ngc"
        args = ["correct", str(src), "--field", str(grid), "-o", str(out)] + (["--expand-cycles"] if expand else [])
        r = CliRunner().invoke(main, args, catch_exceptions=False)
        assert r.exit_code == 0, r.output
        want = nc.read(src).correct(fields.read(grid), expand_cycles=expand)
        assert out.read_bytes() == want.data, case
        _canon(tmp_path, out.read_bytes(), "o.ngc")
    r = CliRunner().invoke(main, ["correct", "--help"])
    assert "--expand-cycles" in r.output


@pytest.mark.parametrize("case", sorted(CASES))
def test_corpus_comparison_follows_cycles(tmp_path, case):
    """The corpus check (tests/corpus.py) reads the engine's cycle moves: the corrected program
    matches, the input left as written does not."""
    import corpus

    src = _program(case)
    prog = nc.parse(src)
    field = _field_of(_wavy)
    inp = _canon(tmp_path, src, "in.ngc")
    displaced, lines, start_known, why = corpus.displaced_moves(prog, inp)
    assert why is None, why

    def compare(out):
        return corpus.compare_motion(inp, out, displaced, field, TOL, lines, None, start_known, prog.blocks.cycle)

    assert compare(_canon(tmp_path, prog.correct(field).data, "o.ngc")) == []
    assert compare(inp), "the uncorrected holes pass for corrected ones"


def test_g98_after_g99_at_the_r_plane(tmp_path):
    """G99 holes leave the tool at the R plane; a G98 hole with that R plane is reached at the
    initial level (LinuxCNC compares the tool's height with R: equal, it travels at the retract
    level). A correction that lowers this hole's R plane below the last one would make LinuxCNC
    travel at the tool's height instead: refused as a cycle block; --expand-cycles writes the
    programmed approach, up to the initial level."""
    src = "G21 G90 G17 G0 X0 Y0 Z12\nG99 G81 X2 Y2 Z-2 R3 F100\nG98 X20 Y5\nG80\nM2\n"

    def d(x, y):
        return (0.0, 0.0, 0.02 - 0.001 * x)  # lower at the second hole

    field = _field_of(d)
    prog = nc.parse(src)
    with pytest.raises(InputError, match=r":3:1: canned cycle G81: the correction moves the R plane past"):
        prog.correct(field)
    inp = _canon(tmp_path, src, "in.ngc")
    got = _canon(tmp_path, prog.correct(field, expand_cycles=True).data, "o.ngc")
    assert got.kinds == inp.kinds
    _feeds_displaced(got, inp, d, "g98 after g99")
    assert got.ends[5, 2] == inp.ends[5, 2] == 12.0  # to the second hole at the initial level
    # a field that keeps the order of the two R planes: a cycle block as ever
    out = prog.correct(_field_of(lambda x, y: (0.0, 0.0, 0.001 * x)))
    _feeds_displaced(_canon(tmp_path, out.data, "k.ngc"), inp, lambda x, y: (0.0, 0.0, 0.001 * x), "kept")


# ------------------------------------------------------------- cycles kept with --keep-unsupported
# A second work coordinate system after moves in the first is a construct the engine does not
# correct (a field is in one system's coordinates): the blocks in it are copied with
# keep_unsupported, canned cycles too.
_IN_G55 = """G21 G90 G17
G0 X0 Y0 Z10
G1 Z5 F100
G55
G0 X0 Y0 Z10
G99 G81 X10 Y5 Z-2 R2 F100
X20
G80
G54
G0 Z20
M2
"""


@pytest.mark.parametrize("expand", [False, True], ids=["cycles", "expanded"])
def test_a_cycle_under_an_unsupported_construct_is_copied(tmp_path, expand):
    """With keep_unsupported, a cycle in G55 is copied byte for byte (not rewritten, not
    expanded), and rs274 runs its holes as in the input; the cut before it is corrected."""
    prog = nc.parse(_IN_G55)
    assert [u.construct for u in prog.unsupported] == [
        "work coordinate system G55 after moves in G54 (a field is in one system's coordinates)"
    ]
    out = prog.correct(fields.Shift((0.0, 0.0, 0.05)), keep_unsupported=True, expand_cycles=expand)
    src, got = _IN_G55.splitlines(), out.text.splitlines()
    assert got[2] == "G1 Z5.05 F100"
    assert got[:2] + got[3:] == src[:2] + src[3:], out.text
    inp, cout = _canon(tmp_path, _IN_G55, "in.ngc"), _canon(tmp_path, out.data, "out.ngc")
    feeds = [e[:3].round(4).tolist() for k, e in zip(inp.kinds, inp.ends) if k == "feed"]
    assert feeds == [[0.0, 0.0, 5.0], [10.0, 5.0, -2.0], [20.0, 5.0, -2.0]]
    want = inp.ends.copy()
    want[1, 2] += 0.05
    _same_motion(cout, Canon(inp.kinds, want, [], 0, None), "kept")


# G10 L2 (a work offset set in the program) is a construct the engine does not follow either, and
# with P1 R0 it leaves the position as it is: a cycle block under it is kept within a cycle the
# engine corrects.
_OFFSET_MID_RUN = """G21 G90 G17
G0 X0 Y0 Z10
G99 G81 X5 Y5 Z-2 R2 F100
G10 L2 P1 R0
X20
Y8 Z-3
G80
G0 Z20
M2
"""


def test_a_kept_cycle_block_keeps_the_holes_of_the_program(tmp_path):
    """A sticky cycle block copied after a corrected one of the same cycle: the R and Z the
    corrected block wrote would drill its hole at the corrected depth, so the program's are written
    into it; rs274 drills the copied holes where the input does and the first one displaced. With
    --expand-cycles the copied block would no longer be in a cycle: refused at its line."""
    prog = nc.parse(_OFFSET_MID_RUN)
    shift = (0.0, 0.0, 0.05)
    out = prog.correct(fields.Shift(shift), keep_unsupported=True)
    inp, cout = _canon(tmp_path, _OFFSET_MID_RUN, "in.ngc"), _canon(tmp_path, out.data, "out.ngc")
    fin = [i for i, k in enumerate(inp.kinds) if k == "feed"]
    fout = [i for i, k in enumerate(cout.kinds) if k == "feed"]
    assert len(fin) == len(fout) == 3
    np.testing.assert_allclose(cout.ends[fout[0], :3], inp.ends[fin[0], :3] + shift, atol=TOL)
    np.testing.assert_allclose(cout.ends[fout[1:], :3], inp.ends[fin[1:], :3], atol=TOL)
    with pytest.raises(InputError, match="continues a cycle whose earlier blocks --expand-cycles wrote") as e:
        prog.correct(fields.Shift(shift), keep_unsupported=True, expand_cycles=True)
    assert e.value.line == 5


# ---------------------------------------------------------------- the retract mode nobody states
_UNSTATED = """G21 G90 G17
G0 X0. Y0. Z10.
G81 X5. Y5. Z-2. R2. F100.
X10.
G80
G0 Z20.
G1 X20. F100.
M2
"""


def test_unstated_retract_mode_in_linuxcnc_is_rs274s(tmp_path):
    """LinuxCNC: a program without G98/G99 runs in rs274's mode (G99, retract to R); the expanded
    output makes rs274's motion of the input whose holes the test displaced."""
    d = (0.0, 0.0, 0.05)
    displaced = _UNSTATED.replace("Z-2.", "Z-1.95").replace("R2.", "R2.05").replace("X10.", "X10. Z-1.95 R2.05")
    want = _canon(tmp_path, displaced, "displaced.ngc")
    assert want.ends[4, 2] == pytest.approx(2.05)  # G99: back to the R plane, not to Z10
    out = nc.parse(_UNSTATED).correct(fields.Shift(d), expand_cycles=True)
    got = _canon(tmp_path, out.data, "out.ngc")
    n = len(want.kinds) - 2  # up to the G0 Z20 (the G1 after it is corrected too)
    _same_motion(Canon(got.kinds[:n], got.ends[:n], [], 0, None), Canon(want.kinds[:n], want.ends[:n], [], 0, None), "")


def test_unstated_retract_mode_on_fanuc_is_the_controls(tmp_path):
    """Fanuc/Haas: the mode a program starts in is the control's (G98 at power-on, or what the last
    program left): --expand-cycles refuses at the first cycle, naming the fix; kept as cycle
    blocks the control decides, and the height after the cycles is unknown until Z is set."""
    prog = nc.parse(_UNSTATED, dialect="fanuc")
    with pytest.raises(InputError, match="state G98 or G99") as e:
        prog.correct(fields.Shift((0, 0, 0.05)), expand_cycles=True)
    assert e.value.line == 3
    out = prog.correct(fields.Shift((0, 0, 0.05)))
    assert out.text.splitlines()[2:4] == ["G81 X5. Y5. Z-1.95 R2.05 F100.", "X10."]
    assert any("canned cycle G81 with neither G98 nor G99" in m for _, m in prog.notes)
    stated = nc.parse(_UNSTATED.replace("G81", "G98 G81"), dialect="fanuc")
    exp = stated.correct(fields.Shift((0, 0, 0.05)), expand_cycles=True)
    got = _canon(tmp_path, exp.data, "out.ngc")
    want = _canon(
        tmp_path, _UNSTATED.replace("G81", "G98 G81").replace("Z-2.", "Z-1.95").replace("R2.", "R2.05"), "w.ngc"
    )
    n = len(want.kinds) - 2
    _same_motion(Canon(got.kinds[:n], got.ends[:n], [], 0, None), Canon(want.kinds[:n], want.ends[:n], [], 0, None), "")
    assert want.ends[4, 2] == pytest.approx(10.0)  # G98: back to the initial level


def test_cycle_moves_are_bounded():
    """L repeats and G73/G83 pecks make moves; more than a block's bound is refused at the line."""
    for bad in ("G83 X1 Y1 Z-1000 R1 Q0.0001 F100", "G81 X1 Y1 Z-1 R1 L999999 F100"):
        with pytest.raises(InputError, match="more than the 1000000 allowed for one block") as e:
            nc.parse(f"G21 G90 G0 X0 Y0 Z10\n{bad}\n")
        assert e.value.line == 2


# ------------------------------------------------------------------- polar words (LinuxCNC's @ ^)
POLAR = """G21 G90 G17 G0 X0 Y0 Z5
G0 X25 Y0
G98 G81 R1 Z-4 F100
^120
^240
G90 G0 @10 ^33
G91 G81 @10 R1 Z-4 L5
G90 G0 X40 Y0
G91 G81 ^21.17647 R1 Z-4 L17
G90 G80
G0 Z5
M2
"""


def _lifted(x, y):
    return (0.0, 0.0, 0.03 + 0.0005 * x)


@needs_rs274
def test_polar_holes_are_read_as_rs274_drills_them(tmp_path):
    """Each hole where rs274 drills it, G91 repeats turning (^) or stretching (@) about the origin
    from the hole before; a zero correction gives the program back."""
    inp = _canon(tmp_path, POLAR, "in.ngc")
    prog = nc.parse(POLAR)
    assert not prog.unsupported
    np.testing.assert_allclose(prog.blocks.end[:, :3], inp.ends[:, :3], atol=6e-5)  # rs274 prints 4 decimals
    bottoms = prog.blocks.end[prog.blocks.motion == 1, :2]
    a = np.radians(np.r_[0, 120, 240])
    np.testing.assert_allclose(bottoms[:3], 25 * np.c_[np.cos(a), np.sin(a)], atol=1e-9)  # by hand
    r = 10 + 10 * np.arange(1, 6)
    np.testing.assert_allclose(bottoms[3:8], np.c_[r * math.cos(math.radians(33)), r * math.sin(math.radians(33))])
    a = np.radians(21.17647 * np.arange(1, 18))
    np.testing.assert_allclose(bottoms[8:], 40 * np.c_[np.cos(a), np.sin(a)], atol=1e-9)
    assert prog.correct(fields.Shift((0, 0, 0))).data == POLAR.encode()


@needs_rs274
def test_polar_cycles_keep_their_words_when_the_holes_move_only_in_z(tmp_path):
    inp = _canon(tmp_path, POLAR, "in.ngc")
    prog = nc.parse(POLAR)
    out = prog.correct(fields.Shift((0, 0, 0.03)))
    text = out.text.splitlines()
    # (in G91 R is from where the tool stands: at the first G91 cycle, the G98 level the
    # uncorrected rapids left; at the second, the corrected R plane the first retracted to)
    assert text[2:5] == ["G98 G81 R1.03 Z-3.97 F100", "^120", "^240"], out.text
    assert text[6] == "G91 G81 @10 R1.03 Z-4 L5" and text[8] == "G91 G81 ^21.17647 R1 Z-4 L17", out.text
    _feeds_displaced(_canon(tmp_path, out.data, "o.ngc"), inp, lambda x, y: (0, 0, 0.03), "polar shift")


@needs_rs274
@pytest.mark.parametrize(
    ("field", "says", "line"),
    [(lambda x, y: (0.01, 0.0, 0.0), "a hole in X or Y", 4), (_lifted, "by different amounts in Z", 7)],
    ids=["sideways", "tilted"],
)
def test_polar_cycles_the_words_cannot_say_need_expand_cycles(tmp_path, field, says, line):
    """Moved sideways, or (G91 repeats) by different amounts in Z: refused at the block, and
    written as moves with --expand-cycles, which rs274 runs as the displaced holes."""
    prog = nc.parse(POLAR)
    with pytest.raises(InputError, match=f"polar words .*{says}.*--expand-cycles") as e:
        prog.correct(_field_of(field))
    assert e.value.line == line  # (line 3 has no polar words: its X Y are written)
    out = prog.correct(_field_of(field), expand_cycles=True)
    assert "G81" not in out.text and "L5" not in out.text  # (the rapid G0 @10 ^33 stays)
    _feeds_displaced(_canon(tmp_path, out.data, "o.ngc"), _canon(tmp_path, POLAR, "in.ngc"), field, "polar expanded")


def _bump_at_40(x, y):
    """0.2 mm in X at (40, 0) only, 0.05 up everywhere."""
    return (0.2 if math.hypot(x - 40, y) < 1 else 0.0, 0.0, 0.05)


@needs_rs274
@pytest.mark.parametrize(
    "src",
    [
        "G21 G90 G17 G0 X0 Y0 Z5\nG98 G81 X40 Y0 R1 Z-4 F100\nG91 ^30 R-4 Z-5 L11\nG90 G80\nG0 Z5\nM2\n",
        "G21 G90 G17 G0 X0 Y0 Z5\nG98 G81 X40 Y0 R1 Z-4 F100\n^120\n^240\nG80\nG0 Z5\nM2\n",
    ],
    ids=["g91", "g90"],
)
def test_polar_words_measured_from_a_moved_point_need_expand_cycles(tmp_path, src):
    """From review: the field moves the hole before (the point the polar words measure from) but
    none of the polar holes: kept, the polar words would drill every hole 0.2 mm off. Refused,
    and right with --expand-cycles."""
    prog = nc.parse(src)
    with pytest.raises(InputError, match="polar words measure from") as e:
        prog.correct(_field_of(_bump_at_40))
    assert e.value.line == 3
    out = prog.correct(_field_of(_bump_at_40), expand_cycles=True)
    _feeds_displaced(_canon(tmp_path, out.data, "o.ngc"), _canon(tmp_path, src, "in.ngc"), _bump_at_40, "moved point")


def test_a_cycle_continuation_kept_after_expanded_cycle_blocks_is_refused():
    """From review: with --expand-cycles the output leaves the cycle; a later block of it copied
    as written (its position unknown after G28, kept with --keep-unsupported) would be a rapid
    there, not a hole. Refused at its line; without --expand-cycles the output stays in the cycle."""
    src = "G21 G90 G17 G0 X0 Y0 Z5\nG98 G81 X25 Y0 R1 Z-4 F100\nG28\nX10 Y10\nG80 G0 Z5\nM2\n"
    prog = nc.parse(src)
    shift = fields.Shift((0, 0, 0.05))
    with pytest.raises(InputError, match="no longer in the cycle") as e:
        prog.correct(shift, keep_unsupported=True, expand_cycles=True)
    assert e.value.line == 4
    assert "X10 Y10" in prog.correct(shift, keep_unsupported=True).text.splitlines()


def _rise(x, y):
    """Every hole higher by an amount that grows with x (mm): the first R plane ends above the
    height the tool waits at, so LinuxCNC rises to it first, where the tool stands."""
    return (0.0, 0.0, 0.01 + 0.002 * x)


@needs_rs274
@pytest.mark.parametrize("d", [_rise, _wavy], ids=["rise", "wavy"])
def test_a_g90_cycle_entered_with_x_and_y_unknown_is_corrected(tmp_path, d):
    """pcb2gcode's drill files set only Z before their first G81 (the tool is wherever the tool
    change left it): a G90 cycle goes to its hole whatever X and Y were, so the block is
    corrected, its X and Y written. rs274 (which starts at 0 0 0) drills the output's holes where
    it drills the input's, displaced: the same as the displaced program's motion."""
    src = (
        "G94 G21 G90\nG00 Z10\nT1 M6\nG0 Z5\n"
        "G81 R5 Z-2.5 F1000 X12.555 Y10.945\nX12.555 Y8.945\nX30 Y8.945\nG80\nG0 Z10\nM2\n"
    )
    displaced = "".join(
        f"G81 R{5 + dz:.5f} Z{-2.5 + dz:.5f} F1000 X{x + dx:.5f} Y{y + dy:.5f}\n"
        for x, y in ((12.555, 10.945), (12.555, 8.945), (30, 8.945))
        for dx, dy, dz in [d(x, y)]
    )
    oracle_src = "G94 G21 G90\nG00 Z10\nT1 M6\nG0 Z5\n" + displaced + "G80\nG0 Z10\nM2\n"
    out = nc.parse(src).correct(_field_of(d))
    got = _canon(tmp_path, out.data, "out.ngc")
    _same_motion(got, _canon(tmp_path, oracle_src, "displaced.ngc"), "unknown X Y")
    _feeds_displaced(got, _canon(tmp_path, src, "in.ngc"), d, "unknown X Y")
    assert out.correction.lines_added == 0


@pytest.mark.parametrize(
    "src",
    [
        # G91: the holes are steps from where the tool is
        "G21 G0 Z5\nG91 G81 R0 Z-2 X10 Y10 F100\nG80 G90\nM2\n",
        # the hole's Y is the tool's, which no move has set
        "G21 G0 Z5\nG81 R5 Z-2 X10 F100\nG80\nM2\n",
    ],
)
def test_a_cycle_whose_holes_depend_on_an_unknown_position_is_refused(src):
    prog = nc.parse(src)
    (u,) = prog.unsupported
    assert u.line == 2 and "from an unknown position" in u.construct
    with pytest.raises(RefusedError):
        prog.correct(fields.Shift((0, 0, 0.05)))
