"""LinuxCNC's interpreter as the peer: our motion must equal its canonical motion."""

from __future__ import annotations

import glob

import numpy as np
import pytest

from conftest import needs_rs274
from helpers import endpoints_agree, match_moves
from ncadapt import InputError, fields, nc
from ncadapt.constants import CHORD_TOL
from rs274 import canonical, moves

pytestmark = [needs_rs274, pytest.mark.rs274]

NCFILES = sorted(glob.glob("/usr/share/linuxcnc/ncfiles/**/*.ngc", recursive=True))
TOL_MM = 1e-4


def _compare_endpoints(prog: nc.Program, path) -> int:
    """Compare every traced block end with rs274; return the number compared."""
    canon = canonical(path)
    assert canon.error is None or len(canon.ends) >= len(prog.blocks), canon.error
    return endpoints_agree(prog.blocks, canon, str(path))


def test_linuxcnc_ncfiles(capsys):
    """Every shipped program we accept matches rs274; every one we refuse names its reason."""
    assert NCFILES, "linuxcnc-uspace ships /usr/share/linuxcnc/ncfiles"
    accepted, refused, compared = [], [], 0
    for f in NCFILES:
        prog = nc.read(f)
        if prog.unsupported:
            u = prog.unsupported[0]
            assert u.line >= 1 and u.construct
            refused.append((f, u.construct))
            continue
        accepted.append(f)
        compared += _compare_endpoints(prog, f)
    reasons = {}
    for _, why in refused:
        reasons[why] = reasons.get(why, 0) + 1
    with capsys.disabled():
        print(
            f"\nLinuxCNC ncfiles: {len(accepted)} accepted ({compared} block ends equal to rs274), "
            f"{len(refused)} refused"
        )
        for why, n in sorted(reasons.items(), key=lambda kv: -kv[1]):
            print(f"  refused {n:3d}: {why}")
    assert len(accepted) >= 10 and compared > 1500


def _corrected_matches(tmp_path, src: str, field, name="p.ngc", **kw):
    """Correct ``src`` with ``field``; check rs274 accepts the output and traces the predicted path."""
    inp = tmp_path / name
    inp.write_text(src)
    prog = nc.read(inp)
    out = prog.correct(field, **kw)
    outp = out.write(tmp_path / ("c-" + name))
    canon = canonical(outp)
    assert canon.error is None, canon.error
    # our reading of our own output agrees with rs274
    _compare_endpoints(nc.read(outp), outp)
    # and the feed moves follow the corrected path we predicted
    c = out.correction
    predicted = c.points + c.displacements
    feed = [m for m in moves(canon) if m.kind in ("feed", "arc")]
    # rs274 prints 4 decimals, we write 4 (mm) or 5 (inch): in mm the two roundings add up to the
    # 1e-4 mm required; in inch programs to 0.00005 + 0.000005 in
    ours = 0.5e-5 * 25.4 if prog.units == "inch" else 0.5e-4
    # (+1e-6 mm: pieces that far from a straight line are merged into one move)
    tol = canon.resolution_mm + ours + 1e-6
    assert prog.units == "inch" or tol <= TOL_MM + 1e-6
    # an arc kept an arc is within the chord tolerance of the displaced arc at every point (as
    # close as its chords would be); rs274 prints its centre rounded too
    tol_arc = kw.get("chord_tol", CHORD_TOL) + tol + 2 * canon.resolution_mm
    match_moves(predicted, feed, tol, tol_arc, lambda i: f"feed move {i}")
    return out


def _wavy(points):
    x, y = points[:, 0], points[:, 1]
    d = np.zeros_like(points)
    d[:, 2] = 0.02 * np.sin(x / 7.0) * np.cos(y / 5.0) + 0.0004 * x
    d[:, 0] = 0.003 * np.cos(y / 3.0)
    d[:, 1] = -0.002 * np.sin(x / 4.0)
    return d


PROGRAMS = {
    "absolute_mm": """G21 G90 G17 G0 X0 Y0 Z5
G1 Z-1 F300 (plunge)
X20.5 Y3
G2 X30.5 Y13 I10 J0
G3 X20.5 Y23 R10
G1 X0 ; back
G18 G2 X10 Z-1 I5 K0
G19 G3 Y13 Z-1 J-5 K0
G17 G2 X10 Y13 I-3 J0 Z-2 P2 (helix, two turns)
G0 Z5
M2
""",
    "incremental_inch": """G20 G90 G17 G0 X0.5 Y0.5 Z0.2
G91 G1 Z-0.25 F10
X1.2345 Y0.1
G3 X0.5 Y0.5 R0.5
G2 X-0.5 Y0.5 I0 J0.5
G1 X-0.7 Y-0.2
G90 G0 Z0.2
M2
""",
    "fanuc_post_g28": """%
O1001
G21 G90 G17 G54
G91 G28 Z0.
G90 G0 X0. Y0.
G43 Z15. H1
G0 Z2.
G1 Z-1. F300.
X20. Y5.
G2 X30. Y15. R10.
G0 Z15.
G91 G28 Z0.
G28 X0. Y0.
M30
%
""",
    "compact_fanuc": """%
O0042
N1G21G90G54G0X0.Y0.Z2.
N2G1Z-.5F200.
N3X15.Y-4.5
N4G2X25.Y5.5R10.
N5G1X0.M30
%
""",
}


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_corrected_program_is_what_rs274_runs(tmp_path, name):
    out = _corrected_matches(tmp_path, PROGRAMS[name], _wavy, name=name + ".ngc", max_segment=0.7)
    assert out.correction.blocks_changed > 0


@pytest.mark.parametrize("chord_tol", [CHORD_TOL, 1e-4])
def test_grid_field_corrected_program(tmp_path, examples, chord_tol):
    """The probed plate: its four arcs stay arcs where the field along them is a shift and a helix
    within the chord tolerance, and are cut into chords where it is not (a tolerance of 0.1 µm);
    either way rs274's motion of the output follows the displaced path."""
    field = fields.read(examples / "nc" / "plate_probe.csv")
    out = _corrected_matches(tmp_path, (examples / "nc" / "plate.ngc").read_text(), field, chord_tol=chord_tol)
    arcs = canonical(tmp_path / "c-p.ngc").kinds.count("arc")
    assert arcs + out.correction.arcs_linearised == 4
    assert arcs == (4 if chord_tol == CHORD_TOL else 0)


def test_shift_keeps_arcs_exact(tmp_path):
    """A constant shift of every move (rapids included) keeps arcs as arcs, moved by the shift."""
    src = PROGRAMS["absolute_mm"]
    (tmp_path / "a.ngc").write_text(src)
    shift = np.array([0.01, -0.02, 0.03])
    out = nc.read(tmp_path / "a.ngc").correct(fields.Shift(shift), rapids=True)
    assert out.correction.arcs_linearised == 0
    p = out.write(tmp_path / "b.ngc")
    a, b = canonical(tmp_path / "a.ngc"), canonical(p)
    assert a.kinds == b.kinds
    tol = TOL_MM
    assert np.abs(b.ends[:, :3] - a.ends[:, :3] - shift).max() <= tol
    plane_shift = {"CANON_PLANE_XY": (0, 1), "CANON_PLANE_XZ": (2, 0), "CANON_PLANE_YZ": (1, 2)}
    for ca, cb in zip(a.arcs, b.arcs):
        if ca is None:
            continue
        i, j = plane_shift[ca[3]]
        assert ca[0] == cb[0] and ca[3] == cb[3]
        assert abs(cb[1] - ca[1] - shift[i]) <= tol and abs(cb[2] - ca[2] - shift[j]) <= tol


# G28/G30 as shop programs write them: (program, axes unknown after the return)
RETURNS = {
    "g91_g28_z0": ("G21 G90 G0 X1 Y2 Z3\nG91 G28 Z0\nG90 G0 X5\nG1 Z-1 F100\nX8\nM2\n", "Z"),
    "g28_all": ("G21 G0 X1 Y2 Z3\nG28\nG0 X5 Y1 Z2\nM2\n", "XYZABCUVW"),
    "g28_xy_via": ("G21 G0 X1 Y2 Z3\nG28 X4 Y5\nG0 X5 Y1\nM2\n", "XY"),
    "g20_g28": ("G21 G0 X1 Y2 Z3\nG20 G28 Z0.1\nG0 X0.2 Z0.3\nM2\n", "Z"),
    "g55_g30": ("G21 G55 G0 X1 Y2 Z3\nG30 Z7\nG0 X5 Z1\nM2\n", "Z"),
    "g91_g30_x": ("G21 G0 X1 Y2 Z3\nG91 G30 X1\nG90 G0 X2\nM2\n", "X"),
    "g28_a": ("G21 G0 X1 Y2 Z3 A0\nG28 A10\nG0 A5\nM2\n", "A"),
}


@pytest.mark.parametrize("name", sorted(RETURNS))
def test_return_to_reference_is_traced_as_rs274(tmp_path, name):
    """G28/G30: the rapid to the intermediate point and the return make two moves, as rs274 prints;
    the intermediate point equals rs274's, the axes that return are unknown, the others are kept."""
    src, unknown = RETURNS[name]
    p = tmp_path / f"{name}.ngc"
    p.write_text(src)
    prog = nc.read(p)
    assert not prog.unsupported
    assert [n["line"] for n in prog.inspect()["notes"]] == [2]
    assert _compare_endpoints(prog, p) >= 3
    b = prog.blocks
    home = np.flatnonzero(b.line == 2)
    assert len(home) == 2 and np.isfinite(b.end[home[0], :3]).all()
    via, after = b.end[home[0]], b.end[home[1]]
    for k, axis in enumerate("XYZABCUVW"):
        if axis in unknown:
            assert np.isnan(after[k]), axis
        else:  # kept as it was at the intermediate point (NaN for an axis the program never set)
            assert after[k] == via[k] or np.isnan(after[k]) and np.isnan(via[k]), axis


def test_return_with_a_motion_code_is_an_error_as_in_rs274(tmp_path):
    p = tmp_path / "g28g1.ngc"
    p.write_text("G21 G0 X1 Y2 Z3\nG28 G1 X4 F100\nM2\n")
    assert "both use axis values" in canonical(p).error
    with pytest.raises(InputError, match=r":2:5: G28 and G1 in one block both use the axis words"):
        nc.read(p)


class _Tilt:
    """A plane tilted along X and shifted in X and Y: displaced by (0.01, -0.02, `g`·x) (closed form)."""

    def __init__(self, g: float):
        self.g = g

    def __call__(self, points):
        d = np.zeros_like(points)
        d[:, 0], d[:, 1] = 0.01, -0.02
        d[:, 2] = self.g * points[:, 0]
        return d


@pytest.mark.parametrize(
    "arc, g, dev",
    [
        # a full circle of r 0.25 on a slope of 0.002, starting at its highest point: z is 2·g·r
        # = 1 µm lower on the far side, a shift within the 2 µm chord tolerance: kept a circle
        ("G2 X10 Y0 I-0.25 J0", 0.002, 2 * 0.002 * 0.25),
        # a half circle of r 1 on a slope of 0.005, from x = 10 to 8: z = g·(9 + cos θ) against
        # the helix from g·10 to g·8, apart by g·max(cos θ − 1 + 2θ/π) = 0.2105·g: kept, a G3
        # with a Z word
        ("G3 X8 Y0 I-1 J0", 0.005, 0.005 * 0.21051),
        # the same, its centre absolute (G90.1) and R-format: the centre moves with it
        ("G90.1 G2 X10 Y0 I9.75 J0", 0.002, 2 * 0.002 * 0.25),
        ("G3 X8 Y0 R1", 0.005, 0.005 * 0.21051),
        # a full circle of r 5 on the same slope: 50 µm, no helix: cut into chords
        ("G2 X10 Y0 I-5 J0", 0.005, None),
    ],
)
def test_arc_kept_within_the_chord_tolerance(tmp_path, arc, g, dev):
    """An arc whose displacement is a shift and a helix within the chord tolerance stays an arc;
    rs274's arc of the output is then within the tolerance of the input's arc displaced by the
    field at every point (1000 points, not only where the engine sampled)."""
    src = f"G21 G90 G17 G0 X10 Y0 Z1\nG1 Z0 F100\n{arc}\nG1 X12\nM2\n"
    (tmp_path / "a.ngc").write_text(src)
    field = _Tilt(g)
    out = nc.read(tmp_path / "a.ngc").correct(field)
    p = out.write(tmp_path / "b.ngc")
    a, b = canonical(tmp_path / "a.ngc"), canonical(p)
    assert b.error is None
    kept = dev is not None
    assert ("arc" in b.kinds) == kept and out.correction.arcs_linearised == (0 if kept else 1)
    if not kept:
        return
    ma, mb = moves(a)[a.kinds.index("arc")], moves(b)[b.kinds.index("arc")]
    t = np.linspace(0, 1, 1001)
    pa = ma.at(t)
    want = pa + field(pa)
    got = mb.at(t)
    # the largest distance is the field's departure from a helix, within the chord tolerance
    # (rs274 prints 4 decimals: its centre and ends are rounded by 5e-5 mm)
    assert dev <= CHORD_TOL
    assert abs(np.abs(got - want).max() - dev) <= 1.5e-4


#: G92, G52, G92.1/.2/.3 and G10 L20 after the first move (G92.1 first, so the G92/G52 register
#: is known to be zero where the moves begin): rs274 prints each offset it sets
OFFSETS = """G21 G90 G17 G92.1
G0 X0 Y0 Z5
G1 Z-1 F300
X10 Y5
G92 X0 Y0
G1 X10 Y5
G2 X20 Y5 I5 J0
G52 X3 Y-2
G1 X5 Y5
G92.2
G1 X30 Y10
G92.3
G1 X0 Y0
G92.1
G1 X40 Y10
G10 L20 P0 X0 Y0
G1 X5 Y5
G91 G92 Z0
G90 G1 Z-0.5
G92.1
G1 X1 Y1
G92 X-5 Y-5 Z2
G98 G81 X1 Y1 Z-2 R3
X3 Y2
G80
G1 Z-1
G90.1 G3 X3 Y2 I1 J-1
M2
"""


@pytest.mark.parametrize("inch", [False, True])
def test_offsets_are_followed_as_rs274(tmp_path, inch):
    """Every move after G92, G52, G92.1/.2/.3 and G10 L20 is corrected where it is on the machine:
    rs274's motion of the output (program coordinates plus the offsets it prints) follows the
    input's displaced by a field of the machine position, and our reading of both programs ends
    every block where rs274 does."""
    src = OFFSETS.replace("G21", "G20") if inch else OFFSETS
    out = _corrected_matches(tmp_path, src, _Tilt(0.003), name="o.ngc", limit=5.0)
    assert "warning" not in " ".join(map(str, out.correction.notes)).lower()
    a = canonical(tmp_path / "o.ngc")
    # the field was evaluated on the machine: the arc of G92's frame is 10, 5 away from its numbers
    assert a.arcs[a.kinds.index("arc")][1:3] == pytest.approx(
        ((15 + 10) * (25.4 if inch else 1), 10 * (25.4 if inch else 1))
    )
    assert np.abs(out.correction.displacements[:, 2] - 0.003 * out.correction.points[:, 0]).max() < 1e-12


def test_offsets_the_program_does_not_tell_leave_moves_uncorrected(tmp_path):
    """G52 or G92.1 after the first move without a G92.1 before it: the G92/G52 register's value
    where the moves began is not known (LinuxCNC keeps it from program to program), nor where the
    moves after them are: they are copied unchanged with the warning; G10 L2 sets an origin in
    machine coordinates, the same."""
    for code in ("G52 X3", "G92.1", "G10 L2 P1 X3"):
        src = f"G21 G90 G0 X0 Y0 Z5\nG1 Z-1 F300\nX10\n{code}\nG1 X5 Y5\nM2\n"
        out = nc.parse(src).correct(fields.Shift((0, 0, 0.05)))
        assert out.text.splitlines()[4] == "G1 X5 Y5", code
        assert any("not corrected because the position is unknown" in w for w in out.correction.warnings), code


@pytest.mark.parametrize("r, kept", [(0.25, True), (5.0, False)])
def test_arcs_under_a_grid_field_in_the_engine(tmp_path, r, kept):
    """The engine's own grid evaluation (``correct_file``): a small circle after a cut, where the
    bilinear grid varies by less than the chord tolerance over its circle, is sampled at its end
    only and kept an arc; rs274's arc of the output is within the tolerance of the input's circle
    displaced by the field at 1,000 points. A large one is cut into chords as before."""
    xs = np.arange(0.0, 21.0)
    g = 0.002
    grid = fields.GridField(xs, xs, np.tile(g * xs, (len(xs), 1)) + 0.01, outside="error")
    src = f"G21 G90 G17 G0 X10 Y10 Z1\nG1 Z0 F100\nG2 X10 Y10 I-{r} J0\nG1 X12\nM2\n"
    (tmp_path / "a.ngc").write_text(src)
    c = nc.correct_file(tmp_path / "a.ngc", tmp_path / "b.ngc", grid)
    a, b = canonical(tmp_path / "a.ngc"), canonical(tmp_path / "b.ngc")
    assert b.error is None
    assert ("arc" in b.kinds) == kept and c.arcs_linearised == (0 if kept else 1)
    if kept:
        # the circle's end only, beside the plunge's and the last move's points
        assert c.n_points < 10
        ma, mb = moves(a)[a.kinds.index("arc")], moves(b)[b.kinds.index("arc")]
        t = np.linspace(0, 1, 1001)
        pa = ma.at(t)
        want = pa + np.column_stack([np.zeros((len(t), 2)), g * pa[:, 0] + 0.01])
        # the field varies by 2·g·r = 1 µm around the circle, which is how far the arc is from it
        assert np.abs(mb.at(t) - want).max() == pytest.approx(2 * g * r, abs=1.5e-4)


POLAR = """G21 G90 G17 G92.1
G0 X0 Y0 Z1
G1 Z0 F100
G1 @10 ^30
G1 ^60
G1 @5
G91 G1 @1 ^10
G1 ^10
G90 G0 X3 Y4
G0 @10
G1 Z-1
G1 @12
G2 @12 ^90 R12
G91 G0 ^10
G90 G1 X0 Y0
G92 X5 Y5
G1 @3 ^45
G92.1
M2
"""


@pytest.mark.parametrize("inch", [False, True])
@pytest.mark.parametrize("field", ["zero", "shift", "tilt"])
def test_polar_coordinates_as_rs274(tmp_path, inch, field):
    """LinuxCNC's polar words (@ distance, ^ angle about the program's origin; a word left out
    keeps the current point's, G91 adds to it): our reading ends every block where rs274 does; a
    zero correction leaves the program as it is; otherwise rs274's motion of the output follows
    the input's displaced, corrected blocks written in X and Y where their polar words would not
    reach the corrected end (a rapid from a point the correction moved, in G91, too)."""
    src = POLAR.replace("G21", "G20") if inch else POLAR
    (tmp_path / "p.ngc").write_text(src)
    prog = nc.read(tmp_path / "p.ngc")
    _compare_endpoints(prog, tmp_path / "p.ngc")
    if field == "zero":
        assert prog.correct(fields.Shift((0, 0, 0)), rapids=True).data == prog.data
        return
    f = fields.Shift((0.01, -0.02, 0.05)) if field == "shift" else _Tilt(0.002)
    out = _corrected_matches(tmp_path, src, f, name="q.ngc", limit=5.0)
    assert "@" in out.text  # the polar words that still reach their end stay


@pytest.mark.parametrize(
    "src",
    ["G21 G90 G0 X10 Y0 Z5 F100\nG91 G81 @-10 R-4 Z-5 L3\nM2\n", "G21 G90 G0 X0 Y0 Z5\nG91 G1 ^30 F100\nM2\n"],
    ids=["cycle", "move"],
)
@needs_rs274
def test_an_incremental_polar_step_from_the_origin_is_refused_as_rs274(tmp_path, src):
    (tmp_path / "p.ngc").write_text(src)
    assert "indeterminate when at the origin" in (canonical(tmp_path / "p.ngc").error or "")
    with pytest.raises(InputError, match="from the origin") as e:
        nc.parse(src)
    assert e.value.line == 2


def test_polar_words_with_x_are_refused_as_rs274_and_followed_in_a_cycle(tmp_path):
    with pytest.raises(InputError, match="polar coordinates"):
        nc.parse("G21 G90 G0 X1 Y1 Z1\nG1 X2 @3 ^4 F100\nM2\n")
    (tmp_path / "c.ngc").write_text("G21 G90 G0 X1 Y1 Z5\nG91 G81 R1 Z-1 ^60 L6 F10\nM2\n")
    prog = nc.read(tmp_path / "c.ngc")
    assert not prog.unsupported  # (tests/test_cycles.py checks the holes and their correction)
    _compare_endpoints(prog, tmp_path / "c.ngc")


TOOL_LENGTHS = """G21 G90 G17 G0 X0 Y0 Z5
G49
G1 Z1 F100
G43.1 Z2
G1 Z0
X5
G91 G1 Z-0.5
G90 G43.1 Z0.5
G1 X8
G49
G1 X10 Y2
G1 Z-1
M2
"""


def test_tool_lengths_move_the_tip_coordinates_as_rs274(tmp_path):
    """Program coordinates are the tool tip's: G43.1 Z2 makes the standing tip read 2 mm lower,
    G49 takes it back (rs274 prints the tip), so a G91 move after G43.1 starts there; our reading
    ends every block where rs274 does and the correction follows the displaced path."""
    (tmp_path / "t.ngc").write_text(TOOL_LENGTHS)
    prog = nc.read(tmp_path / "t.ngc")
    _compare_endpoints(prog, tmp_path / "t.ngc")
    assert not prog.unsupported
    _corrected_matches(tmp_path, TOOL_LENGTHS, _Tilt(0.002), name="u.ngc")


def test_a_tool_length_before_the_first_move_is_no_move(tmp_path):
    """G43.1's axis words are lengths, not a move in the work system: a G55 after it and before the
    first move is the system the moves are in (it used to count as a change after a move)."""
    src = "G21 G43.1 Z1.5\nG55\nG0 X0 Y0 Z5\nG1 Z0 F100\nG1 X10\nM2\n"
    (tmp_path / "l.ngc").write_text(src)
    prog = nc.read(tmp_path / "l.ngc")
    assert not prog.unsupported
    _compare_endpoints(prog, tmp_path / "l.ngc")
    _corrected_matches(tmp_path, src, _Tilt(0.002), name="lo.ngc")


def test_a_tool_table_length_leaves_the_tip_height_unknown():
    """G43 H takes the length from the tool table, which the program does not give: the tip's
    height is unknown until a move sets Z (a G91 Z move after it is left as written, with the
    warning), not read as if the length had not changed."""
    src = "G21 G90 G0 X0 Y0 Z5\nG43 H1\nG91 G1 Z-6 F100\nG90 G1 X5\nG1 Z-1\nX8\nM2\n"
    out = nc.parse(src).correct(fields.Shift((0, 0, 0.05)))
    lines = out.text.splitlines()
    assert lines[2] == "G91 G1 Z-6 F100" and lines[3] == "G90 G1 X5"
    assert any("position is unknown" in w for w in out.correction.warnings)
    assert lines[4] == "G1 Z-0.95" and lines[5] == "X8"


def test_probing_moves_are_copied_as_rs274_reads_them(tmp_path):
    """G38.2/G38.3 are copied (rs274 prints them as STRAIGHT_PROBE); the engine's block ends agree
    with rs274's where it knows them (the probe's axes are unknown after it), and the cut after the
    program sets Z again follows the displaced path."""
    src = "G21 G90 G0 X0 Y0 Z5\nG38.2 Z-10 F50\nG0 Z5\nG1 Z-1 F100\nX10\nG38.3 X12\nG1 X20\nG1 Y5\nM2\n"
    (tmp_path / "g.ngc").write_text(src)
    prog = nc.read(tmp_path / "g.ngc")
    assert canonical(tmp_path / "g.ngc").kinds.count("probe") == 2
    _compare_endpoints(prog, tmp_path / "g.ngc")
    out = _corrected_matches(tmp_path, src, fields.Shift((0.01, -0.02, 0.05)), name="h.ngc")
    assert "G38.2 Z-10 F50" in out.text and "G38.3 X12" in out.text
