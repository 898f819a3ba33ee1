"""Property tests over generated programs (hypothesis)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st

from conftest import needs_rs274
from helpers import match_path
from ncadapt import fields, nc
from ncadapt.constants import CHORD_TOL
from ncadapt.errors import RefusedError

PLANES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
CENTRE_LETTERS = {0: "I", 1: "J", 2: "K"}
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def moves(draw, n_max=12, r_min=1000):
    """Absolute moves on a 1 µm grid: (kind, plane, end (3,) µm, centre offset (2,) µm or None, turns)."""
    pos = [0, 0, 0]
    out = []
    for _ in range(draw(st.integers(1, n_max))):
        kind = draw(st.sampled_from(["G0", "G1", "G2", "G3"]))
        if kind in ("G0", "G1"):
            end = [pos[k] + draw(st.integers(-20000, 20000)) for k in range(3)]
            out.append((kind, 17, end, None, 1))
        else:
            plane = draw(st.sampled_from([17, 18, 19]))
            a1, a2, an = PLANES[plane]
            r = draw(st.integers(r_min, 15000))
            phi0 = draw(st.floats(0, 2 * math.pi))
            centre = (pos[a1] - round(r * math.cos(phi0)), pos[a2] - round(r * math.sin(phi0)))
            full = draw(st.booleans()) and draw(st.booleans())
            end = list(pos)
            if not full:
                phi1 = draw(st.floats(0, 2 * math.pi))
                end[a1] = centre[0] + round(r * math.cos(phi1))
                end[a2] = centre[1] + round(r * math.sin(phi1))
            end[an] = pos[an] + draw(st.integers(-3000, 3000))
            turns = draw(st.integers(1, 2)) if full else 1
            out.append((kind, plane, end, (centre[0] - pos[a1], centre[1] - pos[a2]), turns))
        pos = out[-1][2]
    return out


def um(v, unit=1.0):
    return f"{v / 1000 / unit:.6f}".rstrip("0").rstrip(".") or "0"


def program(mv, incremental=False, inch=False, crlf=False, compact=False):
    """Write moves as a program; inch programs use values that are exact in inches."""
    unit = 25.4 if inch else 1.0
    sep = "" if compact else " "
    lines = [f"G{20 if inch else 21}{sep}G90{sep}G0{sep}X0{sep}Y0{sep}Z0"]
    if incremental:
        lines.append("G91")
    pos = [0, 0, 0]
    plane = 17
    for kind, pl, end, centre, turns in mv:
        words = []
        if pl != plane:
            words.append(f"G{pl}")
            plane = pl
        words.append(kind)
        for k, a in enumerate("XYZ"):
            v = end[k] - pos[k] if incremental else end[k]
            words.append(f"{a}{um(v, unit)}")
        if centre is not None:
            a1, a2, _ = PLANES[pl]
            words.append(f"{CENTRE_LETTERS[a1]}{um(centre[0], unit)}")
            words.append(f"{CENTRE_LETTERS[a2]}{um(centre[1], unit)}")
            if turns > 1:
                words.append(f"P{turns}")
        if kind != "G0":
            words.append("F500")
        lines.append(sep.join(words))
        pos = end
    lines.append("M2")
    eol = "\r\n" if crlf else "\n"
    return eol.join(lines) + eol


def wavy(p):
    d = np.zeros_like(p)
    d[:, 2] = 0.01 * np.sin(p[:, 0] / 9.0) + 0.005 * np.cos(p[:, 1] / 7.0)
    d[:, 0] = 0.002 * np.sin(p[:, 1] / 5.0)
    return d


def corrected(*progs):
    """Each program corrected by ``wavy``. Where the field lifts the surface above a rapid's end just
    before a short plunge, the correction is refused (the rapid would end in the part): then every
    program must be refused alike, and the example is set aside."""
    outs, refusals = [], []
    for p in progs:
        try:
            outs.append(p.correct(wavy))
        except RefusedError as e:
            assert "would end inside the part" in str(e), e
            refusals.append(e)
    assert len(refusals) in (0, len(progs)), refusals
    if refusals:
        reject()
    return outs


#: How far a written path may be from the predicted one, per axis: half a unit of the last written
#: digit for the rounding of a written end, and as much again where pieces on one straight line
#: (within half a unit) are written as one move: one unit of 4 decimals in mm, of 5 in inches.
TOL_MM = 1e-4 + 1e-6
TOL_INCH = 1e-5 * 25.4 + 1e-6


def assert_follows(out, tol):
    """The corrected program, read back, runs its feed moves through the predicted points; where it
    keeps an arc an arc, within the chord tolerance of them (read back in 0.01 µm chords)."""
    c = out.correction
    tp = nc.parse(out.data).toolpath(chord_tol=1e-5, max_segment=1e9, rapids=False)
    sel = tp.motion != 0
    chords = tp.motion[sel] >= 2
    match_path(c.points + c.displacements, tp.starts[sel], tp.points[sel], tol, chords, tol + CHORD_TOL + 1e-5)


def as_inch_grid(mv):
    """Round the moves to a 0.0001 inch grid (2.54 µm) so they are exact in both units."""

    def q(v):
        return round(v / 2.54) * 2.54

    out = []
    for kind, pl, end, centre, turns in mv:
        out.append((kind, pl, [q(v) for v in end], None if centre is None else tuple(q(c) for c in centre), turns))
    return out


@SETTINGS
@given(moves(), st.booleans(), st.booleans(), st.booleans())
def test_zero_field_identity(mv, inc, crlf, compact):
    prog = nc.parse(program(mv, incremental=inc, crlf=crlf, compact=compact))
    out = prog.correct(fields.Shift((0, 0, 0)), rapids=True)
    assert out.data == prog.data


@SETTINGS
@given(moves())
def test_absolute_and_incremental_are_the_same_path(mv):
    a = nc.parse(program(mv))
    b = nc.parse(program(mv, incremental=True))
    ta, tb = a.toolpath(), b.toolpath()
    np.testing.assert_allclose(ta.points, tb.points, atol=1e-9)
    ca, cb = corrected(a, b)
    pa = ca.correction.points + ca.correction.displacements
    pb = cb.correction.points + cb.correction.displacements
    np.testing.assert_allclose(pa, pb, atol=1e-9)
    # both corrected programs, read back, follow that path to the written digits
    assert_follows(ca, TOL_MM)
    assert_follows(cb, TOL_MM)
    assert "G91" in cb.text


@SETTINGS
@given(moves(r_min=5000))
def test_inch_and_mm_are_the_same_path(mv):
    mv = as_inch_grid(mv)
    a = nc.parse(program(mv))
    b = nc.parse(program(mv, inch=True))
    np.testing.assert_allclose(a.toolpath().points, b.toolpath().points, atol=1e-9)
    assert b.units == "inch"
    ca, cb = corrected(a, b)
    pa = ca.correction.points + ca.correction.displacements
    pb = cb.correction.points + cb.correction.displacements
    np.testing.assert_allclose(pa, pb, atol=1e-9)
    # corrected inch programs stay in inches and follow the path to 5 inch decimals (1.3e-4 mm)
    assert cb.text.startswith("G20")
    assert_follows(ca, TOL_MM)
    assert_follows(cb, TOL_INCH)


@SETTINGS
@given(
    st.sampled_from([17, 18, 19]),
    st.sampled_from(["G2", "G3"]),
    st.integers(1000, 20000),
    st.floats(0.05, math.pi - 0.05),
    st.floats(0, 2 * math.pi),
    st.booleans(),
)
def test_arc_ijk_and_r_forms_agree(plane, kind, r_um, sweep, phi0, long_way):
    """The same arc written with I/J/K and with R traces the same points."""
    a1, a2, an = PLANES[plane]
    sign = -1 if kind == "G2" else 1
    if long_way:
        sweep = 2 * math.pi - sweep
    r = r_um / 1000
    start = np.zeros(3)
    centre = np.array([-r * math.cos(phi0), -r * math.sin(phi0)])
    phi1 = phi0 + sign * sweep
    end = np.zeros(3)
    end[a1], end[a2] = centre[0] + r * math.cos(phi1), centre[1] + r * math.sin(phi1)
    e = {"XYZ"[k]: f"{end[k]:.9f}" for k in range(3)}
    head = f"G21 G90 G{plane} G0 X0 Y0 Z0\n{kind} X{e['X']} Y{e['Y']} Z{e['Z']} "
    ijk = f"{CENTRE_LETTERS[a1]}{centre[0]:.9f} {CENTRE_LETTERS[a2]}{centre[1]:.9f}\n"
    rr = f"R{-r if long_way else r:.9f}\n"
    ta = nc.parse(head + ijk).toolpath(rapids=False)
    tb = nc.parse(head + rr).toolpath(rapids=False)
    assert len(ta) == len(tb)
    np.testing.assert_allclose(ta.points, tb.points, atol=1e-6)
    _ = start


@needs_rs274
@pytest.mark.rs274
@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)
@given(moves(), st.booleans(), st.booleans())
def test_generated_programs_match_rs274(tmp_path, mv, inc, inch):
    from test_rs274 import _compare_endpoints

    if inch:
        mv = as_inch_grid([m for m in mv if m[3] is None])
    p = tmp_path / "g.ngc"
    p.write_text(program(mv, incremental=inc, inch=inch))
    prog = nc.read(p)
    _compare_endpoints(prog, p)
    (out,) = corrected(prog)
    q = out.write(tmp_path / "c.ngc")
    _compare_endpoints(nc.read(q), q)
