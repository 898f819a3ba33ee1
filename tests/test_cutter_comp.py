"""Cutter radius compensation (G41/G42, G41.1/G42.1): the field is evaluated where the tool
centre is, and the corrected program keeps compensation on.

The truth is LinuxCNC's own compensation: ``rs274 -t TABLE`` turns the input and the output into
tool-centre motion, and the output's must be the input's displaced by the field (an analytic
function here, evaluated at rs274's tool-centre points), within 5 µm both ways (a symmetric
distance between the two paths, densely sampled).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial import cKDTree

import rs274
from ncadapt import RefusedError, fields, nc, tooltable
from ncadapt.cli import main
from ncadapt.errors import InputError

needs_rs274 = pytest.mark.skipif(rs274.RS274 is None, reason="LinuxCNC rs274 not installed")

# rs274 without an INI file reads a tool table in inches: T1 is 1/4", T3 0.1" (radius 1.27 mm)
TABLE_INCH = "T1 P1 D0.25 ;quarter inch\nT3 P3 D0.1\nT5 P5 D0.2\n"
TOOLS_MM = {1: 6.35, 3: 2.54, 5: 5.08}

# a contour with outside and inside corners, arcs both ways, a Z move under compensation, both
# sides, G41.1 with its own diameter; the plunges come before compensation is turned on
PROGRAM = """G21 G17 G90
F300
G0 X-5 Y-5 Z2
G1 Z-1
G41 D3
G1 X10 Y0
G1 X30 Y0
G3 X40 Y10 R10
G1 X40 Y30
G3 X30 Y40 I-10 J0
G1 X20 Y35
G1 X10 Y40
G1 Z-0.5
G1 X0 Y20
G1 X0 Y5
G40 G1 X-6 Y-6
G42 D5
G1 X5 Y5
G1 X25 Y8
G3 X25 Y20 I0 J6
G1 X15 Y25
G40 G1 X0 Y30
G41.1 D3
G1 X10 Y45
G1 X35 Y45
G40 G1 X45 Y50
M2
"""


def z_wave(p):
    """A Z field of its own: 20 µm of waviness over 25 mm (|∇f| ≤ 8e-4)."""
    p = np.asarray(p, float)
    d = np.zeros_like(p)
    d[:, 2] = 0.01 * np.sin(p[:, 0] / 25.0) + 0.01 * np.cos(p[:, 1] / 25.0)
    return d


def _dense(moves, step=0.002):
    """Points along rs274's moves at most `step` mm apart (arcs along their length)."""
    out = []
    for m in moves:
        if m.arc is None:
            length = float(np.linalg.norm(m.end[:3] - m.start[:3]))
        else:
            a1, a2, an = m.axes
            length = float(np.hypot(m.sweep * max(m.rs, m.re), m.end[an] - m.start[an]))
        out.append(m.at(np.linspace(0.0, 1.0, int(np.ceil(length / step)) + 2)))
    return np.concatenate(out)


def _motion(path, table):
    canon = rs274.canonical(path, tools=table)
    assert canon.error is None, canon.error
    mv = rs274.moves(canon)
    return _dense([m for m in mv if m.kind in ("feed", "arc")])


def _corrected(tmp_path, text, field, **options):
    out = nc.parse(text, name="comp.ngc").correct(field, tools=TOOLS_MM, **options)
    p = tmp_path / "out.ngc"
    p.write_bytes(out.data)
    return p


@needs_rs274
@pytest.mark.parametrize("native", [False, True])
def test_compensated_motion_is_the_displaced_tool_path(tmp_path, native):
    table = tmp_path / "tool.tbl"
    table.write_text(TABLE_INCH)
    src = tmp_path / "in.ngc"
    src.write_text(PROGRAM)
    if native:
        # the engine's own bilinear grid (fine enough that it is the wave within 0.1 µm)
        xs, ys = np.linspace(-20, 60, 321), np.linspace(-20, 70, 361)
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        dz = z_wave(np.c_[X.ravel(), Y.ravel(), 0 * X.ravel()])[:, 2].reshape(X.shape).T
        field = fields.GridField(xs, ys, dz)
        out = tmp_path / "out.ngc"
        nc.correct_file(src, out, field, tools=TOOLS_MM, rapids=True)
    else:
        field = z_wave
        out = _corrected(tmp_path, PROGRAM, field, rapids=True)
    text = out.read_text()
    assert len(text.splitlines()) > 3 * len(PROGRAM.splitlines())  # long moves cut in pieces
    assert text.count("G41 D3") == 1 and "G42 D5" in text and "G41.1 D3" in text  # compensation kept on
    before = _motion(src, table)
    after = _motion(out, table)
    want = before + z_wave(before)
    # both ways: every output point is on the displaced tool path and every displaced point on
    # the output's, within 5 µm
    d_out = cKDTree(want).query(after)[0]
    d_in = cKDTree(after).query(want)[0]
    assert d_out.max() < 0.005 and d_in.max() < 0.005, (d_out.max(), d_in.max())
    # and the correction is not nothing: the tool centre's Z moved by the field there
    assert np.abs(after[:, 2] - before[cKDTree(before[:, :2]).query(after[:, :2])[1], 2]).max() > 0.01


@needs_rs274
def test_evaluated_at_the_tool_centre_not_the_contour(tmp_path):
    """A field that changes fast across the contour: evaluated on the programmed contour, the
    output would be off by the field's change over the tool radius (3.2 mm for T1 here)."""
    table = tmp_path / "tool.tbl"
    table.write_text(TABLE_INCH)

    def ramp(p):  # 10 µm per mm in Y only: along the X line it is constant
        d = np.zeros_like(p)
        d[:, 2] = 0.01 * p[:, 1]
        return d

    text = "G21 G17 G90 F100\nG0 X-10 Y-10 Z1\nG1 Z-1\nG41 D1\nG1 X0 Y0\nG1 X40 Y0\nG40 G1 X50 Y-10\nM2\n"
    src = tmp_path / "in.ngc"
    src.write_text(text)
    out = _corrected(tmp_path, text, ramp, chord_tol=0.05)
    after = rs274.moves(rs274.canonical(out, tools=table))
    # the tool centre runs along Y = +3.175 (left of +X): the field there is 31.75 µm
    line = [m for m in after if m.kind == "feed" and abs(m.end[1] - 3.175) < 1e-3 and m.end[0] > 30]
    assert line, [m.end for m in after]
    assert line[0].end[2] == pytest.approx(-1 + 0.03175, abs=1e-4)


@needs_rs274
def test_zero_field_is_byte_identical(tmp_path):
    out = nc.parse(PROGRAM).correct(fields.Shift((0, 0, 0)), tools=TOOLS_MM)
    assert out.text == PROGRAM


def test_steep_corner_refused_with_its_line():
    # a slope of 5 µm/mm in X: at the first corner (line 7: the entry along (15, 5), then +X) the
    # tool turns about the corner from the normal (-5, 15)/√250 to (0, 1), its centre moving by
    # 1.27 × 5/√250 mm in X: 5 µm/mm × 0.4016 mm = 2.0 µm, over the 2 µm chord tolerance
    def slope(p):
        d = np.zeros_like(p)
        d[:, 2] = 0.005 * p[:, 0]
        return d

    with pytest.raises(RefusedError, match=r"line 7: cutter compensation corner: the field varies by 2\.0 µm"):
        nc.parse(PROGRAM).correct(slope, tools=TOOLS_MM, rapids=True)


def test_xy_displacement_refused():
    with pytest.raises(RefusedError, match="moves X or Y .* under cutter compensation"):
        nc.parse(PROGRAM).correct(fields.Shift((0.01, 0, 0)), tools=TOOLS_MM)


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("G41 D3\nG1 X10\nG40 G1 X20\n", None),  # accepted
        ("G41 D1\nG1 X10\nG40 G1 X20\n", "its diameter is not known; give the tool table"),
        ("G41 D9\nG1 X10\nG40 G1 X20\n", "tool 9, which the tool table does not hold"),
        ("G41\nG1 X10\nG40 G1 X20\n", "no D word and no tool loaded"),
        ("G18 G41 D3\nG1 X10\nG40 G1 X20\n", None),  # in G18: by its bound (test_g18_...)
        ("G41 D3\nG2 X10 R5\nG40 G1 X20\n", None),  # an arc starts it: LinuxCNC's entry arc
        ("G41 D3\nG1 X10\nG40\nG2 X20 R5\n", "an arc as the move after G40"),
        ("G41 D3\nG1 X1\nG40 G1 X20\n", "not longer than the tool radius"),
        ("G41 D3\nG1 X10\nG81 X20 Y0 Z-1 R1\nG80\nG40 G1 X20\n", "a canned cycle"),
    ],
)
def test_what_is_followed_and_what_is_refused(text, why):
    p = nc.parse("G0 X0 Y0 Z1\nG1 Z0 F100\n" + text)
    tools = None if "D1" in text else {3: 2.54}
    if why is None:
        out = p.correct(fields.Shift((0, 0, 0.1)), tools=tools)
        assert out.text.splitlines()[2:] == text.splitlines()  # compensation kept, Z already moved
        return
    with pytest.raises(RefusedError) as e:
        p.correct(fields.Shift((0, 0, 0.1)), tools=tools)
    assert why in str(e.value.details)


def test_entry_move_kept_whole():
    """The move after G41 goes from the programmed point to the offset one: cut in two, the
    controller would take its first piece as that move; a field that bends it is refused."""
    text = "G21 G0 X0 Y0 Z1\nG41 D3\nG1 X10 Y0 Z-1 F100\nG1 X20\nG40 G1 X30\n"

    def bump(p):
        d = np.zeros_like(p)
        d[:, 2] = 0.1 * np.exp(-(((p[:, 0] - 5) / 2) ** 2))
        return d

    with pytest.raises(InputError, match="must stay one move"):
        nc.parse(text).correct(bump, tools={3: 2.54}, rapids=True)


def test_tool_table_units_and_errors(tmp_path):
    p = tmp_path / "t.tbl"
    p.write_text("; a comment line\nT1 P1 D0.25 Z1.0 ;1/4\nT2 P2\nT7 P7 X0 D-0.5\n")
    assert tooltable.read(p, "inch") == {1: 6.35, 2: 0.0, 7: -12.7}
    assert tooltable.read(p, "mm") == {1: 0.25, 2: 0.0, 7: -0.5}
    for bad, where in (
        ("T1 D1\nT1 D2\n", ":2:"),
        ("T1 D1\nP1 D2\n", ":2:"),
        ("T1.5 D1\n", ":1:"),
        ("T1 D1e9\n", ":1:"),
    ):
        p.write_text(bad)
        with pytest.raises(InputError) as e:
            tooltable.read(p, "mm")
        assert where in str(e.value)


def test_cli_tool_table(tmp_path):
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G0 X0 Y0 Z1\nG1 Z0 F100\nG41 D3\nG1 X10\nG1 Y10\nG40 G1 X20\nM2\n")
    table = tmp_path / "t.tbl"
    table.write_text(TABLE_INCH)
    r = CliRunner().invoke(main, ["correct", str(prog), "--shift", "0,0,0.1", "-o", str(tmp_path / "o.ngc")])
    assert r.exit_code == 1 and "give the tool table (--tool-table)" in r.output and "line 3" in r.output
    r = CliRunner().invoke(
        main, ["correct", str(prog), "--shift", "0,0,0.1", "-o", str(tmp_path / "o.ngc"), "--tool-table", str(table)]
    )
    assert r.exit_code == 2 and "--tool-units" in r.output
    r = CliRunner().invoke(
        main,
        ["correct", str(prog), "--shift", "0,0,0.1", "-o", str(tmp_path / "o.ngc")]
        + ["--tool-table", str(table), "--tool-units", "inch"],
    )
    assert r.exit_code == 0, r.output
    assert (tmp_path / "o.ngc").read_text().splitlines()[1] == "G1 Z0.1 F100"


def _bend(p):
    """A 40 µm bump at X15 (flat within 0.05 µm beyond X28): a straight move over it is cut in
    pieces, the corners at X40 see no change."""
    d = np.zeros_like(p)
    d[:, 2] = 0.04 * np.exp(-(((p[:, 0] - 15.0) / 5.0) ** 2))
    return d


# G41 with a 1/4" tool (r 3.175 mm): a 40 mm move along +X, then an inside turn of 150°, where
# the tool stops r·tan(75°) = 11.85 mm short of the corner
SHARP = "G21 G0 X-10 Y-10 Z1\nG1 Z0 F100\nG41 D1\nG1 X0 Y0\nG1 X40 Y0\nG1 X22.6795 Y10\nG40 G1 X10 Y30\nM2\n"


@needs_rs274
def test_pieces_clear_of_inside_corners(tmp_path):
    """A move cut in pieces keeps its last piece 2 tool radii long, so the controller reaches an
    inside corner up to 126.9°; the 150° one here is refused after a cut move (rs274 would refuse
    the corrected program), accepted after a whole one."""
    with pytest.raises(InputError, match=r":6:1: an inside corner under cutter compensation: the tool stops 11\.849"):
        nc.parse(SHARP).correct(_bend, tools=TOOLS_MM, chord_tol=0.01)
    table = tmp_path / "tool.tbl"
    table.write_text(TABLE_INCH)
    out = tmp_path / "out.ngc"
    out.write_bytes(nc.parse(SHARP).correct(fields.Shift((0, 0, 0.05)), tools=TOOLS_MM).data)
    assert rs274.canonical(out, tools=table).error is None
    # a 90° inside corner (r·tan 45° = r) after the same cut move is reached
    square = SHARP.replace("G1 X22.6795 Y10", "G1 X40 Y20").replace("G40 G1 X10 Y30", "G40 G1 X50 Y30")
    out.write_bytes(nc.parse(square).correct(_bend, tools=TOOLS_MM, chord_tol=0.01).data)
    canon = rs274.canonical(out, tools=table)
    assert canon.error is None, canon.error
    assert out.read_text().count("\n") > square.count("\n") + 5  # the 40 mm move was cut


# ------------------------------------------------------------------------------ real programs
def _comp_programs():
    import corpus

    if not corpus.CORPUS.is_dir():
        return []
    return [e for e in corpus.manifest() if re.search(rb"\bG0*4[12](?![\d.])", e.path.read_bytes(), re.I)]


@needs_rs274
@pytest.mark.parametrize("entry", _comp_programs(), ids=lambda e: e.file)
def test_corpus_compensated_contours(entry, tmp_path):
    """The corpus programs with cutter compensation, with a 0.01" tool (a radius rs274 reaches
    every corner of theirs with) and the corpus's gentle grid field: refused at a line, or their
    compensated motion (rs274 -t, the moves under compensation and the move leaving it) is the
    input's displaced by the field at rs274's tool centre, within 5 µm both ways (9 µm in inch
    programs: rs274 prints 4 decimals of an inch)."""
    import corpus
    from ncadapt import dialects

    diameter = 0.01
    table = tmp_path / "tool.tbl"
    table.write_text("".join(f"T{t} P{t} Z0 D{diameter} ;\n" for t in range(1, 100)))
    tools = {t: diameter * 25.4 for t in range(1, 100)}
    try:
        prog = nc.read(entry.path, dialect=dialects.resolve(entry.path).name, tools=tools)
    except InputError as e:
        assert e.line > 0
        return
    if prog.unsupported:
        assert all(u.line > 0 for u in prog.unsupported)
        return
    grid = corpus.gentle_field(prog.inspect()["extents"]["feed"])
    try:
        out = prog.correct(grid, rapids=True)
    except (RefusedError, InputError) as e:
        assert re.search(r"line \d+|:\d+:\d+:", str(e)), e
        return
    src = tmp_path / ("in" + entry.path.suffix)
    src.write_bytes(corpus.adjust(entry.path.read_bytes(), list(corpus.ADJUSTMENTS)))
    dst = tmp_path / ("out" + entry.path.suffix)
    dst.write_bytes(corpus.adjust(out.data, list(corpus.ADJUSTMENTS)))

    def comp_motion(path):
        canon = rs274.canonical(path, tools=table)
        assert canon.error is None, canon.error
        mv = rs274.moves(canon)
        sel = [m for m, c in zip(mv, canon.comp) if c and m.kind in ("feed", "arc")]
        assert sel
        return _dense(sel)

    before, after = comp_motion(src), comp_motion(dst)
    want = before + grid(before)
    tol = 0.005 if prog.units == "mm" else 0.009
    assert cKDTree(want).query(after)[0].max() < tol
    assert cKDTree(after).query(want)[0].max() < tol


# ------------------------------------------------------------------ compensation in G18 (ZX plane)
#: A contour in the ZX plane at Y = 7, cut by a mill: lines, arcs both ways, an outside and an
#: inside corner.
G18_PROGRAM = """G21 G18 G90
F300
G0 X-5 Y7 Z5
G41 D3
G1 X0 Z0
G1 X20 Z0
G3 X30 Z-10 I0 K-10
G1 X30 Z-25
G2 X40 Z-35 I10 K0
G1 X60 Z-35
G1 X60 Z-20
G40 G1 X70 Z-15
M2
"""


def xz_wave(p):
    """A field of its own in X and Z: 10 µm over 25 mm (|∇f| ≤ 4e-4: under 0.6 µm within the
    tool's 1.27 mm radius)."""
    p = np.asarray(p, float)
    d = np.zeros_like(p)
    d[:, 0] = 0.01 * np.sin(p[:, 2] / 25.0)
    d[:, 2] = 0.01 * np.cos(p[:, 0] / 25.0)
    return d


@needs_rs274
def test_g18_compensation_offsets_the_corrected_contour(tmp_path):
    """LinuxCNC compensates in G18 too: rs274 -t offsets the output's contour by the tool radius,
    and that path is the input's offset path moved by a shift exactly, and by a field that
    changes little within the radius within the chord tolerance (rs274's 4 decimals besides)."""
    table = tmp_path / "tool.tbl"
    table.write_text(TABLE_INCH)
    src = tmp_path / "in.ngc"
    src.write_text(G18_PROGRAM)
    before = _motion(src, table)
    # rs274 compensates: the tool centre is off the programmed line Z0 by the radius
    on_z0 = (before[:, 0] > 3) & (before[:, 0] < 12) & (np.abs(before[:, 2]) < 2)
    np.testing.assert_allclose(np.abs(before[on_z0, 2]), 1.27, atol=1e-3)
    shift = (0.03, 0.0, -0.02)
    after = _motion(_corrected(tmp_path, G18_PROGRAM, fields.Shift(shift), rapids=True), table)
    d = max(cKDTree(before + shift).query(after)[0].max(), cKDTree(after).query(before + shift)[0].max())
    assert d < 0.0012, d  # (the paths are sampled every 2 µm)
    # (an arc's chords take half the tolerance, the field's change within the radius the other)
    out = _corrected(tmp_path, G18_PROGRAM, xz_wave, rapids=True, chord_tol=0.003)
    text = out.read_text()
    assert text.count("G41 D3") == 1 and len(text.splitlines()) > 3 * len(G18_PROGRAM.splitlines())
    after = _motion(out, table)
    want = before + xz_wave(before)
    d = max(cKDTree(want).query(after)[0].max(), cKDTree(after).query(want)[0].max())
    assert d <= 0.003 + 0.0006, d
    # the entry move stays one move; the next is cut in pieces
    lines = text.splitlines()
    k = lines.index("G41 D3")
    assert lines[k + 1].startswith("G1 X0") and lines[k + 2].startswith("G1 X1"), lines[k : k + 3]


def test_g18_compensation_refused_where_the_field_changes_within_the_radius():
    def steep(p):  # 10 µm over 1 mm
        d = np.zeros_like(np.asarray(p, float))
        d[:, 2] = 0.01 * np.sin(np.asarray(p, float)[:, 0])
        return d

    with pytest.raises(RefusedError, match=r"line \d+: radius compensation in G18/G19 .*: the field changes"):
        nc.parse(G18_PROGRAM).correct(steep, tools=TOOLS_MM)
    (u,) = nc.parse(G18_PROGRAM).unsupported  # (no tool table: the radius is not known)
    assert u.line == 4 and "give the tool table" in u.construct
    # a reversal: the arc turns back along the line (G2 from X20 Z0 about X20 Z-10 heads to -X),
    # where the control meets the offset paths of the exact arc but may go round those of its
    # pieces
    back = G18_PROGRAM.replace("G3 X30 Z-10", "G2 X30 Z-10")
    (u,) = nc.parse(back, tools=TOOLS_MM).unsupported
    assert u.line == 7 and "a reversal" in u.construct


#: A V groove in the ZX plane (turns of 75° and 150°), compensated with G41.
VEE = "G21 G18 G90\nF300\nG0 X-5 Y0 Z5\nG41 D3\nG1 X0 Z0\nG1 X20 Z0\nG1 X25 Z-18.66\nG1 X30 Z0\nG1 X50 Z0\nG40 G1 X55 Z5\nM2\n"


def grow(p):
    """A field that grows the part about the groove's bottom: 2 µm within the 1.27 mm radius."""
    p = np.asarray(p, float)
    d = np.zeros_like(p)
    d[:, 0] = 0.0016 * (p[:, 0] - 25.0)
    d[:, 2] = 0.0016 * (p[:, 2] + 18.66)
    return d


@needs_rs274
def test_a_sharp_inside_corner_multiplies_the_bound(tmp_path):
    """Where the contour turns sharply into an inside corner, the control meets the two offset
    paths at a point an error of theirs moves up to 1/cos(turn/2) times as far. A V groove
    (turns of 75° and 150°) under a field that grows the part about the groove's bottom (2 µm
    within the 1.27 mm radius): rs274 finds the tool centre off the displaced path by more than
    twice that at the bottom, within the corner's bound; so a tolerance under it is refused
    there, and the contour without the groove is taken."""
    vee = VEE.replace("G41", "G42")
    flat = vee.replace("G1 X25 Z-18.66\n", "")

    corrected = nc.parse(vee).correct(grow, tools=TOOLS_MM, chord_tol=0.016, rapids=True).data
    before, after = _before_after(tmp_path, vee, corrected)
    want = before + grow(before)
    d = max(cKDTree(want).query(after)[0].max(), cKDTree(after).query(want)[0].max())
    assert 2 * 0.00203 < d < 2 * 0.00203 * 3.86, d
    with pytest.raises(RefusedError, match=r"line 8: .*times 3.86 where it meets the move before, 150°"):
        nc.parse(vee).correct(grow, tools=TOOLS_MM, chord_tol=0.006, rapids=True)
    nc.parse(flat).correct(grow, tools=TOOLS_MM, chord_tol=0.006, rapids=True)


@needs_rs274
@pytest.mark.parametrize(
    ("text", "line", "says"),
    [
        # LinuxCNC compensates in G17 and G18 only, and refuses a change of plane under it
        ("G19 G41 D3\nG1 Y10 Z-1\nG40 G1 Y20\n", 3, "LinuxCNC compensates in G17 and G18 only"),
        ("G18 G41 D3\nG1 X10 Z-1\nG17\nG40 G1 X20\n", 5, "a change of plane with cutter compensation on"),
        ("G41 D3\nG1 X10 Y5\nG18 G1 X20\nG40 G1 X30\n", 4, "a change of plane with cutter compensation on"),
        # the move after G41 is the entry move: not along Y in G18, nor shorter than the radius
        ("G18 G41 D3\nG1 Y5\nG1 X10 Z-1\nG40 G1 X20\n", 4, "not longer than the tool radius in its plane"),
        ("G18 G41 D3\nG1 X1 Z0.5\nG1 X10 Z-1\nG40 G1 X20\n", 4, "not longer than the tool radius in its plane"),
    ],
)
def test_compensation_planes_rs274_refuses_are_refused(tmp_path, text, line, says):
    prog = "G21 G0 X0 Y0 Z1 F100\n" + text.replace("G19 G41", "G19\nG41").replace("G18 G41", "G18\nG41") + "M2\n"
    p = tmp_path / "p.ngc"
    p.write_text(prog)
    (tmp_path / "tool.tbl").write_text(TABLE_INCH)
    assert rs274.canonical(p, tools=tmp_path / "tool.tbl").error is not None
    with pytest.raises(InputError) as e:
        nc.parse(prog, tools=TOOLS_MM)
    assert (e.value.line, says in e.value.message) == (line, True), e.value


@needs_rs274
@pytest.mark.parametrize("move", ["G1 Z-1", "G0 Z0.5", "G0 X0 Y0 Z0.5"])
def test_an_entry_move_going_nowhere_in_the_plane_is_refused_as_rs274_refuses_it(tmp_path, move):
    """LinuxCNC's entry is the next move after G41/G42, whatever axes it moves: one that stays
    where it is in the plane is not longer than the radius (rs274: "Length of cutter compensation
    entry move is not greater than the tool radius"). A Fanuc control starts the offset at the
    first move in the plane, so there it is followed."""
    prog = f"G21 G0 X0 Y0 Z1 F100\nG41 D3\n{move}\nG1 X10 Y0\nG1 Y10\nG40 G1 X0\nM2\n"
    p = tmp_path / "p.ngc"
    p.write_text(prog)
    (tmp_path / "tool.tbl").write_text(TABLE_INCH)
    assert "entry move" in rs274.canonical(p, tools=tmp_path / "tool.tbl").error
    with pytest.raises(RefusedError) as e:
        nc.parse(prog, tools=TOOLS_MM).correct(fields.Shift((0, 0, 0.1)))
    [d] = e.value.details
    assert d["line"] == 3 and "not longer than the tool radius" in d["construct"]
    fanuc = "%\nO1\nG21 G90 G17\nG0 X0. Y0. Z1.\nG41 D3\nG1 Z-1. F100.\nG1 X10. Y0.\nG1 Y10.\nG40 G1 X0.\nM30\n%\n"
    prog = nc.parse(fanuc, dialect="fanuc", tools=TOOLS_MM)
    assert prog.unsupported == ()


def test_fanuc_compensates_in_g19_by_the_bound():
    """A Fanuc mill compensates in G19 too (LinuxCNC does not): the contour in the YZ plane is
    corrected where it is, compensation kept; a shift moves its points by the shift."""
    text = "%\nO1\nG21 G90 G19\nG0 X5. Y-5. Z5.\nG41 D3 G1 Y0. Z0. F100.\nG1 Y20.\nG2 Y30. Z-10. J0. K-10.\nG40 G1 Y40. Z-5.\nM30\n%\n"
    prog = nc.parse(text, dialect="fanuc", tools=TOOLS_MM)
    assert prog.unsupported == ()
    out = prog.correct(fields.Shift((0.0, 0.02, -0.01)), rapids=True).text
    assert "G41 D3" in out and "G1 Y20.02" in out and "G2 Y30.02 Z-10.01" in out, out


def _both_ways(want, got):
    return max(cKDTree(want).query(got)[0].max(), cKDTree(got).query(want)[0].max())


def _dz(of_x):
    """A Z field of X alone."""

    def field(p):
        p = np.asarray(p, float)
        d = np.zeros_like(p)
        d[:, 2] = of_x(p[:, 0])
        return d

    return field


def _before_after(tmp_path, text, corrected: bytes):
    """rs274's compensated motion of the input and of its correction (TABLE_INCH's tools)."""
    table = tmp_path / "tool.tbl"
    table.write_text(TABLE_INCH)
    src, out = tmp_path / "in.ngc", tmp_path / "out.ngc"
    src.write_text(text)
    out.write_bytes(corrected)
    return _motion(src, table), _motion(out, table)


@needs_rs274
def test_g18_pieces_next_to_an_inside_corner_are_longer_than_the_trim(tmp_path):
    """At an inside corner the control stops the tool R·tan(turn/2) short of it on both moves: a
    piece next to it shorter than that makes rs274 refuse ("cannot be reached by the tool
    without gouging"). Such pieces are refused at their line; with longer pieces the output runs,
    and follows the displaced path."""
    text = "G21 G18 G90 F100\nG0 X-5 Y0 Z-5\nG41 D3\nG1 X0 Z0\nG1 X20 Z0\nG1 X20 Z-10\nG40 G1 X25 Z-15\nM2\n"

    bowl = _dz(lambda x: 1e-5 * x**2)
    with pytest.raises(
        InputError, match=r":6:1: an inside corner under radius compensation in G18/G19: the tool stops 1.2700 mm"
    ):
        nc.parse(text).correct(bowl, tools=TOOLS_MM, rapids=True)
    corrected = nc.parse(text).correct(bowl, tools=TOOLS_MM, rapids=True, max_segment=4).data
    before, after = _before_after(tmp_path, text, corrected)
    assert _both_ways(before + bowl(before), after) <= 0.002 + 0.0006


@needs_rs274
def test_g18_compensation_ends_after_a_straight_move_or_a_whole_arc(tmp_path):
    """G40's move starts where the control's offset of the move before ends: after an arc written
    in chords that is the last chord's normal, not the arc's (13 µm off here): refused; an arc a
    shift keeps whole ends it exactly."""
    text = "G21 G18 G90 F100\nG0 X-5 Y0 Z5\nG41 D3\nG1 X0 Z0\nG1 X20 Z0\nG3 X30 Z-10 I0 K-10\nG40 G1 X35 Z-20\nM2\n"

    lean = _dz(lambda x: 1e-5 * x)
    with pytest.raises(
        InputError, match=r":7:1: the move that ends radius compensation in G18/G19 comes right after an arc"
    ):
        nc.parse(text).correct(lean, tools=TOOLS_MM, rapids=True)
    shift = (0.01, 0.0, 0.02)
    corrected = nc.parse(text).correct(fields.Shift(shift), tools=TOOLS_MM, rapids=True).data
    assert b"G3 X30.01 Z-9.98" in corrected
    before, after = _before_after(tmp_path, text, corrected)
    assert _both_ways(before + shift, after) < 0.0012
    # a helical arc cut in chords: the control's corners between them hold Y still
    helix = text.replace("G3 X30 Z-10 I0 K-10", "G3 X30 Y5 Z-10 I0 K-10")
    with pytest.raises(InputError, match=r":6:1: a helical arc under radius compensation"):
        nc.parse(helix).correct(lean, tools=TOOLS_MM, rapids=True)


def test_g18_entry_move_stays_longer_than_the_radius_once_corrected():
    # the input's entry is 1.2705 mm long, the tool radius 1.27 mm: a field that shortens it
    text = "G21 G18 G90 F100\nG0 X0 Y0 Z0\nG41 D3\nG1 X1.2705 Z0\nG1 X20 Z0\nG40 G1 X25 Z5\nM2\n"

    def shrink(p):
        return -0.0009 * np.asarray(p, float)

    with pytest.raises(InputError, match=r":4:1: the move that starts cutter compensation, corrected, is 1.269"):
        nc.parse(text).correct(shrink, tools=TOOLS_MM, rapids=True, chord_tol=0.01)


def test_g18_outside_corners_are_not_multiplied():
    """LinuxCNC goes round an outside corner on an arc about it: the offset paths do not meet, and
    the corner's factor is for inside corners only (G41 in G18's (Z, X) frame: the tool left of
    the path, so a turn to the right is an outside corner)."""
    vee = VEE

    # G42 makes the groove's bottom an inside corner (refused at 6 µm: test above); G41 an outside one
    nc.parse(vee).correct(grow, tools=TOOLS_MM, chord_tol=0.006, rapids=True)


#: LinuxCNC's comp311_2.ngc's compensated contour: compensation starts on an arc.
ARC_ENTRY = """G20 G17 G90
F10
T3 M6
G0 X1 Y4 Z0.1
G1 Z0
G41
G3 X2 Y3 I1
G2 X3 Y2 J-1
G1 Y-1
G2 X2 Y-2 I-1
G1 X-2
G2 X-2.6 Y-0.2 J1
G1 X1.4 Y2.8
G2 X2 Y3 I.6 J-.8
G40
G1 X1 Y4
M2
"""


@needs_rs274
def test_an_arc_that_starts_compensation_is_the_controller_s_entry_arc(tmp_path):
    """LinuxCNC starts compensation on an arc with an arc of its own, from the programmed start
    to the end's offset point (convert_arc_comp1): the field is read along it, and the corrected
    program, run by rs274 -t, follows the input's tool path displaced within 5 µm (9 µm: inch);
    the arc stays an arc (a helix), or is refused where the field bends it more."""
    corrected = nc.parse(ARC_ENTRY).correct(z_wave, tools=TOOLS_MM, rapids=True).data
    lines = corrected.decode().splitlines()
    assert lines[lines.index("G41") + 1].startswith("G3 X2 Y3 ")  # one arc
    before, after = _before_after(tmp_path, ARC_ENTRY, corrected)
    assert _both_ways(before + z_wave(before), after) < 0.009

    def bump(p):
        p = np.asarray(p, float)
        d = np.zeros_like(p)
        d[:, 2] = 0.05 * np.exp(-(((p[:, 0] - 38.0) / 3.0) ** 2))
        return d

    with pytest.raises(InputError, match=r":7:1: an arc that starts cutter compensation"):
        nc.parse(ARC_ENTRY).correct(bump, tools=TOOLS_MM, rapids=True)


@needs_rs274
def test_compensation_ends_on_the_first_move_naming_x_or_y(tmp_path):
    """After G40 LinuxCNC's current point is the tool's: the first move naming X or Y goes from the
    offset point to the programmed one, even when the programmed point stays (gmoccapy's program
    returns so to the centre); compensation may then start again."""
    text = (
        "G21 G17 G90\nF300\nG0 X20 Y50 Z1\nG1 Z-1\nG41 D3\nG1 X50 Y50\nG1 X50 Y20\nG40\nG0 Z5\nG0 X50 Y20\n"
        "G1 Z-1\nG42 D3\nG1 X20 Y20\nG1 X20 Y40\nG40 G1 X15 Y45\nM2\n"
    )
    corrected = nc.parse(text).correct(z_wave, tools=TOOLS_MM, rapids=True).data
    before, after = _before_after(tmp_path, text, corrected)
    assert _both_ways(before + z_wave(before), after) < 0.005


def test_entry_arcs_the_engine_does_not_follow_are_refused():
    head = "G21 G17 G90 F100\nG0 X0 Y0 Z1\nG1 Z0\n"
    # P turns: LinuxCNC's entry arc takes them all
    (u,) = nc.parse(head + "G41 D3\nG3 X20 Y0 I10 P2\nG1 X20 Y20\nG40 G1 X30 Y30\nM2\n", tools=TOOLS_MM).unsupported
    assert (u.line, "more than one turn (P)" in u.construct) == (5, True)
    # an inside corner after it: LinuxCNC trims it from the entry arc's own centre
    text = head + "G41 D1\nG3 X8 Y0 R20\nG1 X11.165 Y9.486\nG40 G1 X14.331 Y18.972\nM2\n"
    (u,) = nc.parse(text, tools={1: 6.0}).unsupported
    assert (u.line, "an inside corner right after the arc that starts" in u.construct) == (6, True)


@needs_rs274
def test_an_entry_arc_is_sampled_along_the_tool_s_own_arc(tmp_path):
    """A 30° programmed arc whose entry arc is a 333° loop of 5.5 mm: a bump of the field on the
    loop, between the programmed arc's samples, is seen (refused, or followed within 5 µm)."""
    text = "G21 G17 G90 F100\nG0 X-5 Y0 Z1\nG1 Z0\nG41 D3\nG3 X-4.3301 Y-2.5 I5 J0\nG1 X0 Y-5\nG40 G1 X5 Y-10\nM2\n"

    def bump(p):
        p = np.asarray(p, float)
        d = np.zeros_like(p)
        d[:, 2] = 0.02 * np.exp(-((p[:, 0] + 9.610) ** 2 + (p[:, 1] - 0.648) ** 2) / (2 * 0.6**2))
        return d

    try:
        corrected = nc.parse(text).correct(bump, tools=TOOLS_MM, rapids=True).data
    except (RefusedError, InputError):
        return
    before, after = _before_after(tmp_path, text, corrected)
    assert _both_ways(before + bump(before), after) < 0.005


@needs_rs274
@pytest.mark.parametrize(
    "text",
    [
        # an arc, then an inside corner (the controller meets the arc's offset circle)
        "G21 G17 G90 F100\nG0 X-5 Y0 Z1\nG1 Z0\nG42 D3\nG1 X0 Y0\nG2 X20 Y0 R-10\nG1 X0 Y15\nG40 G1 X-5 Y20\nM2\n",
        # an arc, then the move after G40
        "G21 G17 G90 F100\nG0 X-5 Y-5 Z1\nG1 Z0\nG41 D3\nG1 X0 Y0\nG1 X20 Y0\nG3 X30 Y10 I0 J10\nG40 G1 X35 Y20\nM2\n",
    ],
)
def test_arcs_next_to_corners_and_exits_are_refused_or_followed(tmp_path, text):
    """Where an arc is cut in chords before G40's move, or a move next to an inside corner with an
    arc would be cut in pieces, the controller's path is another: refused at the line; else rs274
    follows the input's displaced path within 5 µm."""
    slope = _dz(lambda x: 0.0008 * x)
    try:
        corrected = nc.parse(text).correct(slope, tools=TOOLS_MM, rapids=True).data
    except (RefusedError, InputError) as e:
        assert re.search(r":\d+:1: ", str(e)), e
        return
    before, after = _before_after(tmp_path, text, corrected)
    assert _both_ways(before + slope(before), after) < 0.005
