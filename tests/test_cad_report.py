"""Tolerance bands and sections with a CAD nominal (``compensate --nominal … --tolerance T --section
x=…``): the shares of points in tolerance by face and over the part, and the planes cut through
the compensated faces, checked against closed forms.

The parts are built with OpenCASCADE here: a plate z = 5 (60 × 40 mm) and the solid sixth of a
cylinder (R 40 mm, height 50 mm, 0…60°). The "measured" points are nominal points moved along the
face's outward normal by a chosen error E, without noise: E is linear in the face's (u, v) (a ramp
along x on the plate, along z on the cylinder's side, along x on its top), which the smoothing spline
reproduces exactly (a straight line has no curvature to penalise), so the systematic part is E
itself and the closed forms below hold: the share of points with |E| ≤ T counted from the grid, and
along a cut dF = E of the cut's points, the compensation −dF, the cut's shape (a straight line or the
arc of radius R) and length."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from lxml import html as lhtml

from ncadapt import measure
from ncadapt.cli import main
from ncadapt.errors import InputError
from ncadapt.processes import freeform as pf
from ncadapt.report import cad_sections

pytest.importorskip("OCP")

T = 0.01  # mm, the profile tolerance
R, H, ANGLE = 40.0, 50.0, 60.0


def _write_step(shape, path):
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    w = STEPControl_Writer()
    w.Transfer(shape, STEPControl_AsIs)
    w.Write(str(path))
    return path


def _csv(path, pts):
    path.write_text("x,y,z\n" + "".join(f"{float(x)!r},{float(y)!r},{float(z)!r}\n" for x, y, z in pts))
    return path


def _num(s):
    return float(s.replace("−", "-").replace("+", ""))


# ------------------------------------------------------------------------------------- the plate
XS, YS = np.arange(2, 58.1, 2.0), np.arange(2, 38.1, 2.0)  # the measured grid: a 2 mm strip unmeasured


def _plate_error(x):
    """E on the plate: a ramp from −30 µm at x = 2 to +30 µm at x = 58."""
    return -0.03 + 0.06 * (x - 2) / 56


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt

    tmp = tmp_path_factory.mktemp("plate")
    face = BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0, 0, 5), gp_Dir(0, 0, 1)), 0.0, 60.0, 0.0, 40.0).Face()
    step = _write_step(face, tmp / "plate.step")
    X, Y = np.meshgrid(XS, YS, indexing="ij")
    x, y = X.ravel(), Y.ravel()
    csv = _csv(tmp / "plate.csv", np.column_stack([x, y, 5 + _plate_error(x)]))
    args = ["compensate", csv, "--nominal", step, "--filter", "spline", "--tolerance", T]
    args += ["--section", "y=20", "--section", "x=31", "--json", tmp / "p.json", "--report", tmp / "p.html"]
    r = CliRunner().invoke(main, [str(a) for a in args])
    assert r.exit_code == 0, r.output
    return {
        "dir": tmp,
        "step": step,
        "csv": csv,
        "out": r.output,
        "json": json.loads((tmp / "p.json").read_text()),
        "doc": lhtml.fromstring((tmp / "p.html").read_text()),
    }


def test_tolerance_shares_on_a_plate_are_counted_from_the_ramp(plate):
    # |E| ≤ T where 18.67 ≤ x − 2 ≤ 37.33: the columns x = 22 … 38 (9 of 29); above +T: x ≥ 40 (10);
    # below −T: x ≤ 20 (10). After: E − dF = 0 everywhere.
    n = len(XS) * len(YS)
    want = {"points": n, "inside": 9 / 29, "above": 10 / 29, "below": 10 / 29}
    j = plate["json"]
    for tol in (j["tolerance"], j["by_face"][0]["tolerance"]):
        assert tol["value"] == T and set(tol) == {"value", "before", "predicted"}
        assert tol["before"] == pytest.approx(want, abs=1e-12)
        assert tol["predicted"] == pytest.approx({"points": n, "inside": 1.0, "above": 0.0, "below": 0.0}, abs=1e-12)
    assert "face 1: tolerance ±0.01 mm: 31.0 % of its points inside before, 100.0 % predicted after" in plate["out"]
    rows = {r[0]: r for r in _rows(plate["doc"], "tolerance")[1:]}
    r = rows["face 1, measured"]
    assert int(r[1]) == n and [_num(c) for c in r[2:6]] == pytest.approx(
        [100 * 9 / 29, 100 * 20 / 29] + [100 * 10 / 29] * 2, abs=0.05
    )
    assert _num(rows["all faces, predicted after (measured − systematic)"][2]) == 100.0


def _rows(doc, div_id):
    el = doc.get_element_by_id(div_id)
    return [[c.text_content().strip() for c in tr.xpath("./td|./th")] for tr in el.iter("tr")]


def test_a_section_of_the_plate_is_the_ramp_along_it(plate):
    proj = measure.project_on_cad(plate["csv"], plate["step"])
    pc = pf.compensate_cad(proj, "spline")
    sec = cad_sections.cad_section(pc, proj.measurements.nominal, "y", 20.0)
    (c,) = sec.cuts
    # the cut: the segment y = 20, z = 5 across the whole face, x 0 … 60, its arc length x
    np.testing.assert_allclose(c.points[:, 1:], np.tile([20.0, 5.0], (len(c.points), 1)), atol=1e-9)
    x = c.points[:, 0]
    assert x[0] == pytest.approx(0, abs=1e-9) and x[-1] == pytest.approx(60, abs=1e-9)
    np.testing.assert_allclose(c.position, x, atol=1e-9)
    # dF = E over the measured x 2 … 58, held at the edge values beyond; the compensation −dF
    want = _plate_error(np.clip(x, 2, 58))
    np.testing.assert_allclose(c.systematic, want, atol=1e-6)
    np.testing.assert_allclose(c.compensated, -want, atol=1e-6)
    np.testing.assert_array_equal(c.extrapolated, (x < 2 - 1e-9) | (x > 58 + 1e-9))
    # the measured points on it: the row y = 20, at their x
    np.testing.assert_allclose(c.measured_position, XS, atol=1e-9)
    np.testing.assert_allclose(proj.measurements.deviation[c.measured], _plate_error(XS), atol=1e-9)
    # the report's table of x = 31: along y at the constant E(31)
    el = plate["doc"].get_element_by_id("section-x=31")
    prof = [[td.text_content().strip() for td in tr.xpath("./td")] for tr in el.xpath(".//table")[0].iter("tr")][1:]
    v = np.array([[_num(s) for s in r[:5]] for r in prof])
    np.testing.assert_allclose(v[:, 0], v[:, 1], atol=5e-4)  # along the cut = y
    assert v[0, 1] == pytest.approx(0, abs=5e-4) and v[-1, 1] == pytest.approx(40, abs=5e-4)
    np.testing.assert_allclose(v[:, 3], 1000 * _plate_error(31.0), atol=0.005 + 1e-9)
    np.testing.assert_allclose(v[:, 4], -1000 * _plate_error(31.0), atol=0.005 + 1e-9)


# ---------------------------------------------------------------------------------- the cylinder
def _side_error(z):
    return 0.02 * (z - 25.2) / 20  # −20.2 µm at z = 5, +19.8 µm at z = 45; no point on ±T


def _top_error(x):
    return -0.0006 * x  # 0 … −21.7 µm over x 0 … 36


@pytest.fixture(scope="module")
def cylinder(tmp_path_factory):
    """The cylinder segment measured on its curved face (6…54°, z 5…45 mm) and its top (r 4…36 mm)."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    tmp = tmp_path_factory.mktemp("cyl")
    solid = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), R, H, math.radians(ANGLE)).Shape()
    step = _write_step(solid, tmp / "cyl.step")
    th, z = np.meshgrid(np.radians(np.arange(6, 54.1, 1.5)), np.arange(5, 45.1, 1.5), indexing="ij")
    th, z = th.ravel(), z.ravel()
    side = np.column_stack([(R + _side_error(z)) * np.cos(th), (R + _side_error(z)) * np.sin(th), z])
    rr, tt = np.meshgrid(np.arange(4, 36.1, 1.5), np.radians(np.arange(6, 54.1, 2.0)), indexing="ij")
    tx, ty = (rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel()
    top = np.column_stack([tx, ty, H + _top_error(tx)])
    csv = _csv(tmp / "two.csv", np.vstack([side, top]))
    return {"step": step, "csv": csv, "dir": tmp, "side_z": z, "top_x": tx}


def test_tolerance_by_face_on_a_two_face_part(cylinder):
    js = cylinder["dir"] / "t.json"
    args = ["compensate", cylinder["csv"], "--nominal", cylinder["step"], "--filter", "spline", "--tolerance", T]
    r = CliRunner().invoke(main, [str(a) for a in [*args, "--json", js]])
    assert r.exit_code == 0, r.output
    j = json.loads(js.read_text())
    assert j["faces"] == [1, 2]
    side, top = (b["tolerance"] for b in j["by_face"])
    # the side: |E| ≤ T for 15.2 ≤ z ≤ 35.2, the rows z = 5 + 1.5k, k = 7 … 20: 14 of 27, 33 angles each
    assert side["before"] == pytest.approx(
        {"points": 33 * 27, "inside": 14 / 27, "above": 6 / 27, "below": 7 / 27}, abs=1e-12
    )
    # the top: |E| ≤ T for x ≤ 16.67 mm, counted from the grid's x
    x = cylinder["top_x"]
    n_in = int(np.count_nonzero(x <= T / 0.0006))
    assert top["before"] == pytest.approx(
        {"points": len(x), "inside": n_in / len(x), "above": 0.0, "below": 1 - n_in / len(x)}, abs=1e-12
    )
    both = (33 * 14 + n_in) / (33 * 27 + len(x))
    assert j["tolerance"]["before"]["inside"] == pytest.approx(both, abs=1e-12)
    for t in (side, top, j["tolerance"]):
        assert t["predicted"]["inside"] == 1.0


def test_sections_through_the_cylinder_are_its_arc_and_its_lines(cylinder):
    proj = measure.project_on_cad(cylinder["csv"], cylinder["step"])
    pc = pf.compensate_cad(proj, "spline")
    nominal = proj.measurements.nominal
    # z = 29 cuts the curved face in the arc of radius R over 0…60°: length R·π/3, dF = E(29) = 3.8 µm
    # along the whole arc
    sec = cad_sections.cad_section(pc, nominal, "z", 29.0)
    (c,) = sec.cuts
    assert c.face == 1
    np.testing.assert_allclose(np.hypot(c.points[:, 0], c.points[:, 1]), R, atol=1e-6)
    np.testing.assert_allclose(c.points[:, 2], 29.0, atol=1e-7)
    assert c.position[-1] == pytest.approx(R * math.radians(ANGLE), rel=2e-4)  # the chords of the arc
    np.testing.assert_allclose(c.systematic, _side_error(29.0), atol=1e-6)
    np.testing.assert_allclose(c.compensated, -_side_error(29.0), atol=1e-6)
    ang = np.degrees(np.arctan2(c.points[:, 1], c.points[:, 0]))
    # extrapolated outside the measured 6…54° (on its edge, either)
    assert c.extrapolated[(ang < 6 - 1e-6) | (ang > 54 + 1e-6)].all()
    assert not c.extrapolated[(ang > 6 + 1e-6) & (ang < 54 - 1e-6)].any()
    # y = 20 cuts both faces: the side along the line θ = 30° (x = √(R² − 400)), z 0 … 50, where dF is
    # the ramp along z (held beyond 5…45); the top along y = 20, x 20/tan 60° … √(R² − 400), dF = E(x)
    sec = cad_sections.cad_section(pc, nominal, "y", 20.0)
    assert [c.face for c in sec.cuts] == [1, 2]
    s, t = sec.cuts
    np.testing.assert_allclose(s.points[:, 0], math.sqrt(R * R - 400), atol=1e-6)
    assert (s.points[0, 2], s.points[-1, 2]) == pytest.approx((0.0, H), abs=1e-9)
    np.testing.assert_allclose(s.position, s.points[:, 2], atol=1e-9)
    ok = ~s.extrapolated  # inside the measured hull; the strip holds the value of the grid's last node inside
    assert ok.sum() > 30 and s.extrapolated[(s.points[:, 2] < 5 - 1e-6) | (s.points[:, 2] > 45 + 1e-6)].all()
    np.testing.assert_allclose(s.systematic[ok], _side_error(s.points[ok, 2]), atol=1e-6)
    np.testing.assert_allclose(s.systematic[:3], s.systematic[0], atol=1e-12)
    np.testing.assert_allclose(t.points[:, 2], H, atol=1e-9)
    x0, x1 = 20 / math.tan(math.radians(ANGLE)), math.sqrt(R * R - 400)
    assert (t.points[0, 0], t.points[-1, 0]) == pytest.approx((x0, x1), abs=1e-6)
    np.testing.assert_allclose(t.position, t.points[:, 0] - x0, atol=1e-6)  # the edge found within 1e-7
    # the top's measured hull: inside it dF = E(x) (linear; within 10 nm: next to the hull's edge the
    # bicubic spline through the grid feels the held strip); the strip is held, not asserted
    ok = ~t.extrapolated
    assert ok.sum() > 5
    np.testing.assert_allclose(t.systematic[ok], _top_error(t.points[ok, 0]), atol=1e-5)
    # a plane that misses the compensated faces, an axis of (u, v)
    with pytest.raises(InputError, match=r"--section z=80: the plane cuts none of the compensated faces \(z 0 … 50"):
        cad_sections.cad_section(pc, nominal, "z", 80.0)
    with pytest.raises(InputError, match="a section is a plane x=…, y=… or z=…"):
        cad_sections.cad_section(pc, nominal, "u", 1.0)


def test_cad_section_options_are_checked(plate, tmp_path):
    base = ["compensate", str(plate["csv"]), "--nominal", str(plate["step"])]
    for extra, message in (
        (["--section", "u=3", "--report", str(tmp_path / "r.html")], "with --nominal a section is the plane x=…"),
        (["--section", "x=3"], "--section draws in the report"),
        (["--section", "z=9", "--report", str(tmp_path / "r.html")], "the plane cuts none of the compensated faces"),
    ):
        r = CliRunner().invoke(main, [*base, *extra])
        assert r.exit_code == 2 and message in r.output, r.output
        assert not (tmp_path / "r.html").exists()


def test_analyze_counts_the_points_in_tolerance(cylinder, tmp_path):
    """``analyze --tolerance T``: the shares of the measured deviations inside ±T, above and below,
    over the part and by face (the same closed-form counts as compensate's before), and the
    report's banded maps."""
    js, rp = tmp_path / "a.json", tmp_path / "a.html"
    args = ["analyze", cylinder["csv"], "--nominal", cylinder["step"], "--tolerance", T, "--json", js]
    r = CliRunner().invoke(main, [str(a) for a in [*args, "--report", rp]])
    assert r.exit_code == 0, r.output
    j = json.loads(js.read_text())
    side, top = (f["tolerance"] for f in j["faces"])
    assert side == pytest.approx({"points": 33 * 27, "inside": 14 / 27, "above": 6 / 27, "below": 7 / 27}, abs=1e-12)
    x = cylinder["top_x"]
    n_in = int(np.count_nonzero(x <= T / 0.0006))
    assert top["inside"] == pytest.approx(n_in / len(x), abs=1e-12)
    assert j["tolerance"]["value"] == T
    assert j["tolerance"]["before"]["inside"] == pytest.approx((33 * 14 + n_in) / (33 * 27 + len(x)), abs=1e-12)
    assert f"tolerance ±{T:g} mm" in r.output
    assert "Tolerance" in rp.read_text()
