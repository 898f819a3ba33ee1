"""LinuxCNC's splines G5 (cubic) and G5.1 (quadratic), followed and corrected.

The truth is LinuxCNC 2.9: its interpreter (``convert_spline``) makes a G5 the cubic NURBS of the
start, start + (I, J), end + (P, Q) and the end (without I and J the first control point is the
start minus the last G5's (P, Q)), a G5.1 the quadratic one through start + (I, J); its canon layer
(``emccanon.cc`` NURBS_FEED) moves along biarcs of it, not the curve, which stray from the curve
by about 5e-6 of its size (5 µm on a metre). The expected motion here is that, written out in Python from
LinuxCNC's source (:func:`linuxcnc_motion`) for the control points the test writes, displaced by
the field; it is itself checked against scipy's Bernstein polynomials (the curve, within what the
biarcs stray). rs274 runs every output (its spline moves, ``NURBS_FEED``, print no points, so an
output written in pieces is compared through its straight moves) and refuses what the engine
refuses.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.interpolate import BPoly
from scipy.spatial import cKDTree

import rs274
from ncadapt import RefusedError, fields, nc
from ncadapt.errors import InputError

needs_rs274 = pytest.mark.skipif(rs274.RS274 is None, reason="LinuxCNC rs274 not installed")

#: The blocks after ``G21 G17 G90 F100 / G0 X0 Y0 Z1 / G1 Z0``: (text, control points in mm).
#: The second G5 has no I J (its first control point: its start minus the first's P Q).
BLOCKS = [
    ("G5 X10 Y0 I3 J4 P-3 Q4", [(0, 0), (3, 4), (7, 4), (10, 0)]),
    ("G5 X20 Y0 P-3 Q-4", [(10, 0), (13, -4), (17, -4), (20, 0)]),
    ("G5.1 X30 Y5 I5 J8", [(20, 0), (25, 8), (30, 5)]),
    ("G1 X31", [(30, 5), (31, 5)]),
    ("G91 G5.1 X4 Y-5 I2 J0", [(31, 5), (33, 5), (35, 0)]),
    ("G5 X5 Y0 I1 J-1 P-1 Q-1", [(35, 0), (36, -1), (39, -1), (40, 0)]),
    ("G90 G1 X41", [(40, 0), (41, 0)]),
]
HEAD = "G21 G17 G90 F100\nG0 X0 Y0 Z1\nG1 Z0\n"


def program(blocks=BLOCKS, units="G21") -> str:
    return HEAD.replace("G21", units) + "".join(t + "\n" for t, _ in blocks) + "M2\n"


def linuxcnc_motion(cp: np.ndarray, step: float = 0.002, small: float = 1e-6) -> np.ndarray:
    """Points along LinuxCNC's motion of the spline of control points ``cp`` (mm), as its canon
    layer makes it (``emccanon.cc`` NURBS_FEED of LinuxCNC 2.9, written out here from its
    source): the NURBS (weights 1, order the number of points, clamped uniform knots) at 4
    parameters per point, its tangents by a difference of 1e-5, and a biarc (``biarc``, ``arc``)
    over each span; ``small`` is its straightness threshold, 1e-6 program units, in mm. Written
    for well-conditioned splines (LinuxCNC skips a span where its construction fails)."""
    k = n1 = len(cp)
    n = n1 - 1
    kv = [0.0 if i < k else float(i - k + 1) if i <= n else float(n - k + 2) for i in range(n + k + 1)]

    def nmix(i, k, u):
        if k == 1:
            return 1.0 if kv[i] <= u <= kv[i + 1] else 0.0
        a, b = kv[i + k - 1] - kv[i], kv[i + k] - kv[i + 1]
        left = (u - kv[i]) * nmix(i, k - 1, u) / a if a else 0.0
        right = (kv[i + k] - u) * nmix(i + 1, k - 1, u) / b if b else 0.0
        return left + right

    def point(u):
        w = np.array([nmix(i, k, u) for i in range(n1)])
        return (w[:, None] * cp).sum(axis=0) / w.sum()

    umax = n - k + 2

    def tangent(u):
        lo, hi = max(0.0, u - 1e-5), min(umax, u + 1e-5)
        d = (point(hi) - point(lo)) / (hi - lo)
        return d / np.hypot(*d)

    def arc(p0, p1, d):
        x, y = p1 - p0
        den = 2 * (y * d[0] - x * d[1])
        if abs(den) <= small:
            return np.linspace(p0, p1, max(2, int(np.hypot(x, y) / step) + 2))
        r = -(x * x + y * y) / den
        c = p0 + np.array([d[1] * r, -d[0] * r])
        a0, a1 = (np.arctan2(*(q - c)[::-1]) for q in (p0, p1))
        sweep = (a1 - a0) % (2 * np.pi) if r < 0 else -((a0 - a1) % (2 * np.pi))
        th = a0 + np.linspace(0, sweep, max(2, int(abs(r * sweep) / step) + 2))
        return c + abs(r) * np.c_[np.cos(th), np.sin(th)]

    out, p0, t0 = [], point(0.0), tangent(0.0)
    div = n1 * 4
    for i in range(1, div + 1):
        u = umax * i / div
        p4, te = point(u), tangent(u)
        c = p0 - p4
        b = 2 * (c @ (t0 + te))
        a = 2 * (t0 @ te - 1)
        disq = np.sqrt(b * b - 4 * a * c @ c)
        beta = max((-b - disq) / 2 / a, (-b + disq) / 2 / a)
        p1, p3 = p0 + beta * t0, p4 - beta * te
        p2 = (p1 + p3) / 2
        tm = (p3 - p2) / np.hypot(*(p3 - p2))
        out += [arc(p0, p2, t0), arc(p2, p4, tm)]
        p0, t0 = p4, te
    return np.vstack(out)


def expected(blocks, field, step=0.002, scale=1.0) -> np.ndarray:
    """Points along the displaced motion of `blocks` (XYZ, mm; the numbers times `scale`), no
    more than about `step` apart: a spline's as LinuxCNC moves along it, a line's straight."""
    out = []
    for _, cp in blocks:
        cp = np.asarray(cp, float) * scale
        if len(cp) == 2:
            n = int(np.ceil(np.hypot(*(cp[1] - cp[0])) / step)) + 1
            xy = cp[0] + np.linspace(0, 1, n)[:, None] * (cp[1] - cp[0])
        else:
            xy = linuxcnc_motion(cp, step, 1e-6 * scale)
        p = np.c_[xy, np.zeros(len(xy))]
        out.append(p + field(p))
    return np.vstack(out)


def output_path(path) -> np.ndarray:
    """rs274's straight moves of the output from where Z reaches the part: dense XYZ (mm)."""
    canon = rs274.canonical(path)
    assert canon.error is None, canon.error
    assert "traverse" not in canon.kinds[2:]
    pts = [m.dense(step=0.002) for m in rs274.moves(canon)[2:]]
    return np.vstack(pts)


def wave(p):
    """A field of its own: 30 µm of waviness in Z over 8 mm, a shear of X by Y."""
    p = np.asarray(p, float)
    d = np.zeros_like(p)
    d[:, 2] = 0.03 * np.sin(p[:, 0] / 8.0) * np.cos(p[:, 1] / 6.0)
    d[:, 0] = 0.002 * p[:, 1]
    return d


@needs_rs274
@pytest.mark.parametrize(("units", "scale"), [("G21", 1.0), ("G20", 25.4)])
def test_splines_bent_by_the_field_are_written_as_pieces_along_the_displaced_curve(tmp_path, units, scale):
    src = tmp_path / "in.ngc"
    src.write_text(program(units=units))
    assert rs274.canonical(src).error is None
    out = nc.parse(program(units=units)).correct(wave, max_segment=2.0)
    assert "G5" not in out.text and out.correction.splines_linearised == 5
    dst = tmp_path / "out.ngc"
    dst.write_text(out.text)
    got, want = output_path(dst), expected(BLOCKS, wave, scale=scale)
    # both ways: every point of the displaced curve near the output's path, and back (the chord
    # tolerance, 2 µm, the written digits, and rs274's 4 decimals: of an inch, 1.3 µm)
    tol = 0.003 if units == "G21" else 0.005
    assert cKDTree(got).query(want)[0].max() < tol
    assert cKDTree(want).query(got)[0].max() < tol


def test_a_shift_keeps_the_splines():
    text = program()
    assert nc.parse(text).correct(fields.Shift((0, 0, 0))).text == text
    # a Z shift moves the plunge; the splines, in the plane, stay as written
    out = nc.parse(text).correct(fields.Shift((0, 0, 0.05))).text.splitlines()
    assert out[2] == "G1 Z0.05" and out[3:] == text.splitlines()[3:]
    # a shift in X moves their ends; I J P Q are offsets, the same
    out = nc.parse(text).correct(fields.Shift((0.1, 0, 0))).text.splitlines()
    assert out[3:6] == ["G5 X10.1 Y0 I3 J4 P-3 Q4", "G5 X20.1 Y0 P-3 Q-4", "G5.1 X30.1 Y5 I5 J8"]


@needs_rs274
def test_a_g5_without_i_and_j_after_one_written_in_pieces_is_written_in_pieces(tmp_path):
    """The field bends the first G5 and is still (zero) over the second, which has no I J: kept
    as written it would read LinuxCNC's register, which the output's pieces did not set."""

    def left(p):
        d = np.zeros_like(p)
        d[:, 2] = 0.04 * np.clip(1.0 - p[:, 0] / 9.0, 0.0, None) ** 2
        return d

    blocks = BLOCKS[:2]
    out = nc.parse(program(blocks)).correct(left)
    assert "G5" not in out.text
    dst = tmp_path / "out.ngc"
    dst.write_text(out.text)
    got, want = output_path(dst), expected(blocks, left)
    assert cKDTree(got).query(want)[0].max() < 0.003
    assert cKDTree(want).query(got)[0].max() < 0.003


@needs_rs274
@pytest.mark.parametrize(
    ("block", "says"),
    [
        ("G18 G5 X10 Z0 I1 J1 P-1 Q1", "XY plane"),
        ("G5 X10 Y0 Z-1 I1 J1 P-1 Q1", "motion in Z"),
        ("G5 X10 Y0 I1 P-1 Q1", "both I and J, or neither"),
        ("G5 X10 Y0 I1 J1", "both P and Q"),
        ("G5.1 X10 Y0 I1", "both I and J with G5.1"),
        ("G41.1 D1\nG1 X5 Y0\nG5 X10 Y0 I1 J1 P-1 Q1", "cutter radius compensation"),
        ("G5.1 Q1", "All axes missing"),
        ("G5.1 X1 I1 J1 P1 Q1", "P and Q on G5.1"),
        ("G5 X1 Y1 I1 J1 P1 Q1 K1", "K word"),
        # its P Q (I J) go with a G5 (G5.1) in the block: a modal spline block is refused
        ("G5 X1 Y1 I1 J1 P1 Q1\nX2 Y2 P1 Q1", "P word"),
        ("G5.1 X1 Y1 I1 J1\nX2 Y2 I1 J1", "I word"),
    ],
)
def test_what_rs274_refuses_is_refused_at_its_line(tmp_path, block, says):
    text = HEAD + block + "\nM2\n"
    p = tmp_path / "p.ngc"
    p.write_text(text)
    assert rs274.canonical(p).error is not None
    with pytest.raises(InputError) as e:
        nc.parse(text)
    assert says in e.value.message and e.value.line == text.count("\n") - 1


def test_a_g5_without_i_and_j_the_program_has_not_set_is_refused():
    """rs274 starts its register at 0, a machine holds what the last program left: the first
    control point is not known."""
    with pytest.raises(RefusedError) as e:
        nc.parse(HEAD + "G5 X10 Y0 P-3 Q4\nM2\n").correct(fields.Shift((0, 0, 0.05)))
    [d] = e.value.details
    assert d["line"] == 4 and "register" in d["construct"]


def test_inspect_counts_them():
    info = nc.parse(program()).inspect()
    assert (info["motions"]["spline"], info["motions"]["spline_quadratic"]) == (3, 2)


@needs_rs274
def test_a_g5_without_i_and_j_after_a_canned_cycle_continues_the_last_g5(tmp_path):
    """In LinuxCNC only G87 writes the register a G5 without I J reads (its I J): after G81 it
    still holds the last G5's P Q, and written in pieces after that one, the second G5 is too."""

    def left(p):
        d = np.zeros_like(p)
        d[:, 2] = 0.04 * np.clip(1.0 - p[:, 0] / 9.0, 0.0, None) ** 2
        return d

    text = HEAD + "G5 X10 Y0 I3 J4 P-3 Q4\nG81 X12 Y0 Z-1 R1\nG80\nG1 X10 Y0 Z0\nG5 X20 Y0 P-3 Q-4\nM2\n"
    src = tmp_path / "in.ngc"
    src.write_text(text)
    assert rs274.canonical(src).error is None
    out = nc.parse(text).correct(left, rapids=True)
    assert "G5" not in out.text
    dst = tmp_path / "out.ngc"
    dst.write_text(out.text)
    got = np.vstack([m.dense(step=0.002) for m in rs274.moves(rs274.canonical(dst))])
    want = expected(BLOCKS[1:2], left)
    assert cKDTree(got).query(want)[0].max() < 0.003


@pytest.mark.parametrize("codes", ["G64 P0.5 Q0.2", "M19 R90", "M53 P0", "G4 P1", "M66 P1 L0"])
def test_a_spline_written_in_pieces_keeps_the_words_of_the_other_codes_of_its_block(codes):
    """Its P Q go with it: a code of the block that reads P, Q or R would lose its own (G64's
    tolerances, M19's angle): refused; kept a spline (a shift), the block stays as written."""
    text = HEAD + f"{codes.split()[0]} G5 X10 Y0 I3 J4 P-3 Q4\nM2\n"
    with pytest.raises(InputError, match="put that code on a line of its own"):
        nc.parse(text).correct(wave)
    assert nc.parse(text).correct(fields.Shift((0, 0, 0))).text == text


def test_pieces_are_no_longer_than_the_max_segment():
    """Equal steps of the parameter are not equal lengths: a G5 whose control points crowd at its
    ends runs fast in its middle."""
    out = nc.parse(HEAD + "G5 X400 Y0 I0 J100 P0 Q100\nM2\n").correct(wave, max_segment=1.0)
    xy = [(0.0, 0.0)]
    for line in out.text.splitlines()[3:-1]:
        x = float(re.search(r"X(-?[\d.]+)", line).group(1)) if "X" in line else xy[-1][0]
        y = float(re.search(r"Y(-?[\d.]+)", line).group(1)) if "Y" in line else xy[-1][1]
        xy.append((x, y))
    step = np.hypot(*np.diff(np.array(xy), axis=0).T)
    assert step.max() <= 1.0 + 1e-4 and len(step) > 400


@pytest.mark.parametrize(
    "block",
    [
        "G5 X10 Y0 I1 J1 P1 Q1 R1",
        "G5.1 X10 Y0 I1 J1 L1",
        "G5 X10 Y0 I1 J1 P1 Q1 H1",
        "G53 G5 X10 Y0 I1 J1 P1 Q1",
        "G5.09 X10 Y0 I1 J1",
    ],
)
def test_words_and_codes_rs274_refuses_on_a_spline(block):
    with pytest.raises(InputError):
        nc.parse(HEAD + block + "\nM2\n")


def test_linuxcnc_s_motion_is_near_the_curve():
    """The model of LinuxCNC's biarcs against scipy's Bernstein polynomial of the same control
    points: within 1e-5 of the spline's size, exact at its ends; and they do stray (0.46 µm on
    this 100 mm one, sampled finely enough to tell)."""
    cp = np.array([(0, 0), (30, 40), (70, 40), (100, 0)], float)
    m = linuxcnc_motion(cp, 2e-4)
    curve = BPoly(cp[:, None, :], [0, 1])(np.linspace(0, 1, 2_000_001))
    d = cKDTree(curve).query(m)[0]
    assert d.max() < 1e-3 and np.abs(m[-1] - cp[-1]).max() < 1e-9
    assert 3e-4 < cKDTree(m).query(curve)[0].max() < 1e-3


@needs_rs274
def test_a_large_spline_follows_linuxcnc_s_arcs_not_the_curve(tmp_path):
    """On a 1 m G5 LinuxCNC's biarcs stray 4.6 µm from the curve: the output's pieces follow the
    arcs, displaced, within 3 µm."""
    blocks = [("G5 X1000 Y0 I300 J400 P-300 Q400", [(0, 0), (300, 400), (700, 400), (1000, 0)])]

    def slow_wave(p):
        d = np.zeros_like(p)
        d[:, 2] = 0.03 * np.sin(p[:, 0] / 80.0) * np.cos(p[:, 1] / 60.0)
        return d

    out = nc.parse(program(blocks)).correct(slow_wave, max_segment=5.0)
    dst = tmp_path / "out.ngc"
    dst.write_text(out.text)
    got, want = output_path(dst), expected(blocks, slow_wave)
    assert cKDTree(got).query(want)[0].max() < 0.003
    assert cKDTree(want).query(got)[0].max() < 0.003


def test_an_ill_conditioned_spline_is_refused():
    """Tangents nearly parallel across a span: LinuxCNC's biarc there runs 17 m away (its
    arithmetic's rounding decides where): refused at its line, not followed."""
    with pytest.raises(InputError, match="ill-conditioned") as e:
        nc.parse(HEAD + "G5 X1 Y20 I0 J2 P-2 Q2\nM2\n").correct(wave)
    assert e.value.line == 4


def test_a_nurbs_is_refused_as_one_construct():
    """LinuxCNC's NURBS (G5.2 with its control points on the lines after it, to G5.3) is not
    followed: one construct at its first line, its control points (X Y P) part of it, not words
    with no code to use them; with --keep-unsupported it is copied and the position after it is
    unknown until a move gives it."""
    text = HEAD + "G5.2 X3.53 Y-1.5 P2 L3\nX5.33 Y-11.01 P1\nX3.52 Y-24 P1\nG5.3\nG1 X0 Y0\nM2\n"
    [u] = nc.parse(text).unsupported
    assert (u.line, u.construct, u.blocks) == (4, "spline G5.2", 4)
    out = nc.parse(text).correct(fields.Shift((0, 0, 0.05)), keep_unsupported=True)
    lines = out.text.splitlines()
    # (Z not given again: the move after it is left as written, and the correction says so)
    assert lines[3:8] == text.splitlines()[3:8]
    assert any("not corrected" in w for w in out.correction.warnings)
