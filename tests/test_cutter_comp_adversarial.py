"""Cutter radius compensation against LinuxCNC's own, on the cases a compensated contour is most
likely to be followed wrongly: reversals, turns too small for the controller to see as corners, a
tool table changed by the program, pieces of a large program, the dialects and the units.

The truth is ``rs274 -t TABLE``: the corrected program's tool-centre motion must be the input's
displaced by the field at rs274's tool-centre points, within 5 µm both ways (a symmetric
nearest-point distance between the two paths, sampled every 2 µm), or the program refused at a
line. The first three kinds were corrected wrongly once; they are refused now, at their line.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

import rs274
from ncadapt import RefusedError, constants, fields, nc
from ncadapt.errors import InputError
from test_cutter_comp import _dense, z_wave

needs_rs274 = pytest.mark.skipif(rs274.RS274 is None, reason="LinuxCNC rs274 not installed")

# rs274 without an INI file reads a tool table in inches: T3 0.1" (radius 1.27 mm), T7 1" (12.7 mm)
TABLE_INCH = "T1 P1 D0.25\nT3 P3 D0.1\nT5 P5 D0.2\nT7 P7 D1.0\nT8 P8 D0.5\n"
TOOLS_MM = {1: 6.35, 3: 2.54, 5: 5.08, 7: 25.4, 8: 12.7}
HEAD = "G21 G17 G90 F300\nG0 X-5 Y-5 Z2\nG1 Z-1\n"


def _motion(path, table):
    canon = rs274.canonical(path, tools=table)
    assert canon.error is None, canon.error
    return _dense([m for m in rs274.moves(canon) if m.kind in ("feed", "arc")])


def _distance(tmp_path, text, field, *, native=False, tools=TOOLS_MM, table=TABLE_INCH, **options):
    """The symmetric distance (mm) between the output's tool-centre motion and the input's
    displaced by `field`, both per rs274 -t (the rapids corrected too)."""
    tbl = tmp_path / "tool.tbl"
    tbl.write_text(table)
    src, out = tmp_path / "in.ngc", tmp_path / "out.ngc"
    src.write_text(text)
    if native:
        nc.correct_file(src, out, field, tools=tools, rapids=True, **options)
    else:
        dialect = options.pop("dialect", "linuxcnc")
        out.write_bytes(
            nc.parse(text, name="in.ngc", dialect=dialect).correct(field, tools=tools, rapids=True, **options).data
        )
    before, after = _motion(src, tbl), _motion(out, tbl)
    want = before + field(before)
    return max(cKDTree(want).query(after)[0].max(), cKDTree(after).query(want)[0].max())


# ------------------------------------------------------------------------------ refused
@needs_rs274
@pytest.mark.parametrize(
    "contour",
    [
        # G41 (tool outside the CW arc): +X, then a half circle starting along -X
        "G41 D3\nG1 X10 Y0\nG1 X20 Y0\nG2 X20 Y20 I0 J10\nG1 X40 Y20\nG40 G1 X50 Y30\n",
        # the mirror image with G42 and a CCW arc
        "G42 D3\nG1 X10 Y0\nG1 X20 Y0\nG3 X20 Y-20 I0 J-10\nG1 X40 Y-20\nG40 G1 X50 Y-30\n",
        # a full circle
        "G41 D3\nG1 X10 Y0\nG1 X20 Y0\nG2 X20 Y0 I0 J10\nG1 X30 Y0\nG40 G1 X40 Y-10\n",
    ],
)
def test_reversal_into_an_arc(tmp_path, contour):
    """rs274 on the input: the tool leaves the line's offset (Y 1.27) where it meets the arc's
    (X 12.873), so the bottom of the arc is never cut; on the output (the arc in chords, the first
    one along -X turning slightly left) it turned about the corner to Y -1.27 and cut the arc's
    bottom: 8.5 mm from any point of the input's tool path. A reversal is refused now."""
    with pytest.raises(RefusedError) as e:
        _distance(tmp_path, HEAD + contour + "M2\n", z_wave)
    assert "a reversal (a turn of more than 175°) under cutter compensation" in str(e.value.details)


def _x_bump(p):
    """10 µm rising over X 20 … 70 along X only (zero before X 20): a move along X is cut in pieces."""
    p = np.asarray(p, float)
    d = np.zeros_like(p)
    d[:, 2] = 0.01 * (1 - np.cos(np.maximum(p[:, 0] - 20, 0) / 15))
    return d


@needs_rs274
@pytest.mark.parametrize("turn", [0.0499, -0.0499, 0.04])
def test_small_turn_with_a_large_tool(tmp_path, turn):
    """A 1" tool (r 12.7 mm) and a turn of 0.05 rad: rs274 runs the input's tool from (100, 12.7)
    straight to the next move's offset end (no corner arc, no trim), r(1 - cos θ) = 15.8 µm off
    that move's offset line at its start; the output's next move was cut in pieces, and its first
    piece joined the offset line within a millimetre: 15.7 µm from the input's tool path. Such a
    move is written whole now, and refused where the field bends it; a shift leaves it straight."""
    y = 100 * math.tan(turn)
    text = (
        "G21 G17 G90 F300\nG0 X-20 Y0 Z2\nG1 Z-1\nG41 D7\nG1 X10 Y0\nG1 X100 Y0\n"
        f"G1 X200 Y{y:.4f}\nG40 G1 X210 Y{y - 40:.4f}\nM2\n"
    )
    with pytest.raises(InputError, match=r":7:1: .*follows a turn under 0\.05 rad"):
        _distance(tmp_path, text, _x_bump)
    assert _distance(tmp_path, text, lambda p: np.c_[0 * p[:, :2], 0.01 + 0 * p[:, 2]]) < 0.005


def _ramp(p):
    d = np.zeros_like(np.asarray(p, float))
    d[:, 2] = 0.0005 * p[:, 1] + 0.0003 * p[:, 0]
    return d


@needs_rs274
def test_radius_set_by_g10_l1(tmp_path):
    """G10 L1 P3 R5 makes tool 3's radius 5 mm for LinuxCNC; the engine followed the table's
    1.27 mm, cut the X30 Y20 move in pieces whose first was shorter than the 5 mm the tool stops
    short of the inside corner, and rs274 refused the output ("Straight feed in concave corner
    cannot be reached by the tool without gouging") where it ran the input. Now the tool's
    diameter is unknown after G10 L1: refused, and with --keep-unsupported the compensated moves
    and the move that ends the compensation are copied as written (rs274 runs them as the input)."""
    text = HEAD + "G10 L1 P3 R5\nG41 D3\nG1 X10 Y0\nG1 X30 Y0\nG1 X30 Y20\nG40 G1 X40 Y30\nM2\n"
    with pytest.raises(RefusedError) as e:
        nc.parse(text).correct(_ramp, tools=TOOLS_MM)
    assert "tool 3, which the tool table does not hold" in str(e.value.details)
    out = nc.parse(text).correct(_ramp, tools=TOOLS_MM, keep_unsupported=True, rapids=True)
    assert out.text.splitlines()[4:9] == text.splitlines()[4:9]
    tbl = tmp_path / "tool.tbl"
    tbl.write_text(TABLE_INCH)
    (tmp_path / "o.ngc").write_bytes(out.data)
    assert rs274.canonical(tmp_path / "o.ngc", tools=tbl).error is None


# ------------------------------------------------------------------------------ followed
@needs_rs274
@pytest.mark.parametrize(
    "contour",
    [
        # the tool inside a full circle and a two-turn helix (G41 on G3)
        "G41 D3\nG1 X10 Y0\nG1 X20 Y0\nG3 X20 Y0 I0 J10\nG1 X30 Y0\nG40 G1 X40 Y-10\n",
        "G41 D3\nG1 X10 Y0\nG1 X20 Y0\nG3 X20 Y0 Z-3 I0 J10 P2\nG1 X30 Y0\nG40 G1 X40 Y-10\n",
        # G91 under compensation, an arc in it
        "G41 D3\nG1 X10 Y0\nG91\nG1 X20\nG3 X10 Y10 I0 J10\nG1 Y20\nG90\nG40 G1 X50 Y50\n",
        # G42.1 with a negative diameter: the tool on the left
        "G42.1 D-2\nG1 X10 Y0\nG1 X30 Y0\nG1 X30 Y20\nG40 G1 X40 Y30\n",
        # G41 in the block of the first move; the tool loaded by M6 (T5 in the same block)
        "G41 D3 G1 X10 Y0\nG1 X30 Y0\nG1 X30 Y20\nG40 G1 X40 Y30\n",
        "M6 T5\nG41\nG1 X10 Y0\nG1 X30 Y0\nG1 X30 Y20\nG40 G1 X40 Y30\n",
        # Z moves and a rapid under compensation
        "G41 D3\nG1 X10 Y0\nG1 X30 Y0\nG1 Z-2\nG1 X30 Y20\nG1 Z-1\nG0 X10 Y20\nG40 G1 X0 Y30\n",
        # tangent arcs both ways, and turns of 1e-4 rad
        "G41 D3\nG1 X10 Y0\nG1 X20 Y0\nG3 X30 Y10 R10\nG2 X40 Y20 R10\nG3 X30 Y30 R10\nG1 X10 Y30\nG40 G1 X0 Y40\n",
        "G41 D3\nG1 X10 Y0\nG1 X20 Y0\nG1 X30 Y0.001\nG1 X40 Y0\nG1 X50 Y-0.001\nG40 G1 X60 Y-10\n",
    ],
)
def test_followed_as_rs274_runs_it(tmp_path, contour):
    assert _distance(tmp_path, HEAD + contour + "M2\n", z_wave) < 0.005


@needs_rs274
@pytest.mark.parametrize("d_word", ["G41 D3", "G41.1 D0.1"])
def test_inch_program(tmp_path, d_word):
    """An inch program: G41.1's D in inches, a table tool's diameter from the table."""
    text = (
        "G20 G17 G90 F10\nG0 X-0.2 Y-0.2 Z0.1\nG1 Z-0.04\n"
        f"{d_word}\nG1 X0.4 Y0\nG1 X1.2 Y0\nG3 X1.6 Y0.4 R0.4\nG1 X1.6 Y1.2\nG40 G1 X2 Y1.6\nM2\n"
    )
    assert _distance(tmp_path, text, z_wave) < 0.005


@needs_rs274
def test_fanuc_diameter_register(tmp_path):
    """Fanuc's G41 D01: register 1 given as tool 1 (rs274 reads the same program with T1)."""
    text = (
        "%\nO1000\nG21 G17 G90 F300.\nG0 X-5. Y-5. Z2.\nG1 Z-1.\nG41 D01\nG1 X10. Y0.\nG1 X30. Y0.\n"
        "G3 X40. Y10. R10.\nG1 X40. Y30.\nG40 G1 X50. Y40.\nM30\n%\n"
    )
    assert _distance(tmp_path, text, z_wave, dialect="fanuc", tools={1: 2.54}, table="T1 P1 D0.1\n") < 0.005


@needs_rs274
@pytest.mark.parametrize("back", [60, 120, 180])
def test_contour_across_pieces(tmp_path, back):
    """A compensated contour (204 bytes) that starts `back` bytes before the end of the first
    piece the engine reads, through the native grid path."""
    contour = (
        "G0 Z2\nG0 X-5 Y-5\nG1 Z-1\nG41 D3\nG1 X10 Y0\nG1 X30 Y0\nG3 X40 Y10 R10\nG1 X40 Y30\n"
        "G3 X30 Y40 I-10 J0\nG1 X20 Y35\nG1 X10 Y40\nG1 Z-0.5\nG1 X0 Y20\nG1 X0 Y5\nG40 G1 X-6 Y-6\n"
    )
    head, fill = "G21 G17 G90 F300\n", "(" + "x" * 98 + ")\n"
    n = (constants.PIECE_BYTES - back - len(head)) // len(fill)
    text = head + fill * n + contour + fill * 5 + contour + "M2\n"
    xs, ys = np.linspace(-20, 60, 321), np.linspace(-20, 70, 361)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    dz = z_wave(np.c_[X.ravel(), Y.ravel(), 0 * X.ravel()])[:, 2].reshape(X.shape).T
    grid = fields.GridField(xs, ys, dz)
    assert _distance(tmp_path, text, grid, native=True) < 0.005


def _quadrant_wave(p):
    """40 µm of waviness around the origin over the quadrant x > 0, y < 0 (sin² of twice the
    angle: zero, and flat, on the quadrant's edges), nothing elsewhere."""
    p = np.asarray(p, float)
    th = np.arctan2(p[:, 1], p[:, 0])
    d = np.zeros_like(p)
    d[:, 2] = np.where((th <= 0) & (th >= -np.pi / 2), 0.04 * np.sin(2 * th) ** 2, 0.0)
    return d


@needs_rs274
@pytest.mark.parametrize("native", [False, True])
def test_a_large_tool_outside_an_arc_cut_in_chords(tmp_path, native):
    """A ½" tool (r 6.35 mm) outside a quarter arc of radius 10 mm (G42 on G3, the lines before
    and after it tangent), cut in chords at a 3 µm chord tolerance: chords laid for the arc's own
    radius turn by 0.049 rad, which LinuxCNC neither rounds nor trims, so the tool would cut
    chords of the offset circle (radius 16.35 mm) 16.35 / 10 × 3 = 4.9 µm off it; they are laid
    for the offset circle (0.038 rad). With a 1" tool (r 12.7 mm) at 4 µm the chords would be
    0.374 mm long, shorter than the 12.7 × 2√2 × 0.00005 / 0.004 = 0.449 mm under which the
    rounding of the written numbers alone could turn the tool centre by more than 4 µm: refused."""
    text = (
        "G21 G17 G90 F300\nG0 X-40 Y-10 Z2\nG1 Z-1\nG42 D8\nG1 X-20 Y-10\nG1 X0 Y-10\n"
        "G3 X10 Y0 I0 J10\nG1 X10 Y10\nG40 G1 X30 Y30\nM2\n"
    )
    field = _quadrant_wave
    if native:
        xs, ys = np.linspace(-60, 60, 481), np.linspace(-60, 60, 481)
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        dz = _quadrant_wave(np.c_[X.ravel(), Y.ravel(), 0 * X.ravel()])[:, 2].reshape(X.shape).T
        field = fields.GridField(xs, ys, dz)
    assert _distance(tmp_path, text, field, native=native, chord_tol=0.003) < 0.005
    with pytest.raises(InputError, match=r":7:1: an arc under cutter compensation cut in chords as short as 0\.374"):
        _distance(tmp_path, text.replace("D8", "D7"), field, native=native, chord_tol=0.004)
