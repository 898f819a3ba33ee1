"""The compensated CAD part: measured faces decomposed in their own (u, v), the compensated faces
P − dF·n put in the part, the part written as STEP and read back.

Testbed: the parts are built with OpenCASCADE here; the "measured" points are the nominal face's
points moved along its normal by a chosen smooth error field E (closed forms below, in mm, of the
point's position) plus seeded normal noise of 5 µm. The written part is read back with
OpenCASCADE's own STEP reader and intersected with the lines P + t n from nominal points P along
their normals n (``IntCurvesFace_ShapeIntersector``): t is the compensation there, to be −dF
(the compensation's own dF, within 1 µm) and near −E (the truth: after compensation the
systematic error left, E + t, has an RMS ≤ 10 % of E's in the measured area and ≤ 20 % in the
unmeasured border strip, and ≤ 2 µm in the measured area)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from helpers import along, read_step, rms, write_step, xyz_csv
from ncadapt import measure
from ncadapt.cli import main
from ncadapt.processes import freeform as pf

pytest.importorskip("OCP")

NOISE = 0.005  # mm, the measurement noise (normal, seeded)


def _valid(shape) -> bool:
    from OCP.BRepCheck import BRepCheck_Analyzer

    return BRepCheck_Analyzer(shape).IsValid()


def _count(shape, kind) -> int:
    from OCP.TopExp import TopExp_Explorer

    n, ex = 0, TopExp_Explorer(shape, kind)
    while ex.More():
        n, _ = n + 1, ex.Next()
    return n


# --------------------------------------------------------------------------------- the parts
R, H, ANGLE = 40.0, 50.0, 60.0  # the cylinder segment: radius, height mm, opening deg


def _cylinder_solid(angle=ANGLE):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    return BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), R, H, math.radians(angle)).Shape()


def _cylinder_error(p):
    """E on the curved face: an offset, a taper along z and a waviness (a deflection pattern)."""
    th, z = np.arctan2(p[:, 1], p[:, 0]), p[:, 2]
    return 0.025 + 0.012 * (z / H) + 0.008 * np.cos(3 * th) * np.sin(z / 16)


def _cylinder_points(th_deg, z, rng):
    th = np.radians(th_deg)
    p = np.column_stack([R * np.cos(th), R * np.sin(th), z])
    n = np.column_stack([np.cos(th), np.sin(th), 0 * th])
    return p, n, p + (_cylinder_error(p) + NOISE * rng.normal(size=len(p)))[:, None] * n


def _cylinder_case(tmp_path, seed=7):
    """The solid sixth of a cylinder, measured on its curved face over 6…54° and z 5…45 mm: a
    border strip of 6° (4.2 mm) and 5 mm unmeasured."""
    step = write_step(_cylinder_solid(), tmp_path / "cyl.step")
    th, z = np.meshgrid(np.arange(6, 54.1, 1.5), np.arange(5, 45.1, 1.5), indexing="ij")
    _, _, m = _cylinder_points(th.ravel(), z.ravel(), np.random.default_rng(seed))
    return step, xyz_csv(tmp_path / "cyl.csv", m)


def _cylinder_samples(n=1500, seed=3):
    rng = np.random.default_rng(seed)
    th, z = rng.uniform(0.5, ANGLE - 0.5, n), rng.uniform(0.5, H - 0.5, n)
    p = np.column_stack([R * np.cos(np.radians(th)), R * np.sin(np.radians(th)), z])
    n_ = np.column_stack([np.cos(np.radians(th)), np.sin(np.radians(th)), 0 * th])
    measured = (th >= 6) & (th <= 54) & (z >= 5) & (z <= 45)
    return p, n_, np.radians(th), z, measured


def _truth_figures(truth, t, measured):
    left = truth + t  # the systematic error after compensation: E − dF
    return {
        "inside": rms(left[measured]) / rms(truth[measured]),
        "border": rms(left[~measured]) / rms(truth[~measured]),
        "inside_rms": rms(left[measured]),
    }


def test_a_cylinder_segment_is_compensated_in_its_own_uv(tmp_path):
    step, csv = _cylinder_case(tmp_path)
    proj = measure.project_on_cad(csv, step)
    pc = pf.compensate_cad(proj)
    assert pc.ids == [1] and pc.summary == {"solids": 1, "shells": 1, "faces": 5, "closed": True}
    # the face's (u, v) scaled to mm: u is the angle (R mm per rad), v the height (1 mm per mm)
    assert pc.faces[0].scale == pytest.approx((R, 1.0), rel=1e-3)
    from ncadapt import cad

    cad.write_shape(pc.part, tmp_path / "out.step")
    back = read_step(tmp_path / "out.step")
    from OCP.TopAbs import TopAbs_FACE, TopAbs_SOLID

    assert _valid(back) and _count(back, TopAbs_SOLID) == 1 and _count(back, TopAbs_FACE) == 5
    p, n, th, z, measured = _cylinder_samples()
    t = along(back, p, n)
    assert np.isfinite(t).all()
    # the written face lies −dF from the nominal along its normal, within 1 µm
    np.testing.assert_allclose(t, -pc.faces[0].df(th, z), atol=1e-3)
    f = _truth_figures(_cylinder_error(p), t, measured)
    assert f["inside"] <= 0.10 and f["border"] <= 0.20 and f["inside_rms"] <= 0.002, f


def _patch_face():
    """A blade-like B-spline patch (not a height field: its normals turn through 195°): OpenCASCADE's
    approximation of P(a, b) = ((30 + 5a) cos a, (30 + 5a) sin a, b + 3 sin a), a 0…3.4 rad, b 0…40 mm."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.collections import Array2_gp_Pnt as TColgp_Array2OfPnt
    from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface
    from OCP.gp import gp_Pnt

    na, nb = 27, 9
    arr = TColgp_Array2OfPnt(1, na, 1, nb)
    for i, a in enumerate(np.linspace(0, 3.4, na)):
        for j, b in enumerate(np.linspace(0, 40, nb)):
            r = 30 + 5 * a
            arr.SetValue(i + 1, j + 1, gp_Pnt(r * math.cos(a), r * math.sin(a), b + 3 * math.sin(a)))
    return BRepBuilderAPI_MakeFace(GeomAPI_PointsToBSplineSurface(arr).Surface(), 1e-6).Face()


def _patch_eval(face, u, v):
    """Points and face normals of the patch at its own (u, v) (OpenCASCADE's GeomLProp)."""
    from OCP.BRep import BRep_Tool
    from OCP.GeomLProp import GeomLProp_SLProps

    s = BRep_Tool.Surface_s(face)
    props = GeomLProp_SLProps(s, 1, 1e-9)
    p, n = [], []
    for a, b in zip(u, v):
        props.SetParameters(float(a), float(b))
        q, d = props.Value(), props.Normal()
        p.append((q.X(), q.Y(), q.Z()))
        n.append((d.X(), d.Y(), d.Z()))
    return np.array(p), np.array(n)


def _patch_error(p):
    """E on the patch, of the position: an offset and two waves (mm)."""
    return 0.02 + 0.01 * np.sin(p[:, 0] / 15) * np.cos(p[:, 2] / 20) + 0.006 * p[:, 1] / 40


def test_a_blade_like_bspline_patch(tmp_path):
    from OCP.BRepTools import BRepTools

    face = _patch_face()
    u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
    step = write_step(face, tmp_path / "patch.step")
    # measured over the inner 84 % of each parameter: the rest is the border strip
    lo_u, hi_u, lo_v, hi_v = u0 + 0.08 * (u1 - u0), u1 - 0.08 * (u1 - u0), v0 + 0.08 * (v1 - v0), v1 - 0.08 * (v1 - v0)
    uu, vv = np.meshgrid(np.linspace(lo_u, hi_u, 40), np.linspace(lo_v, hi_v, 24), indexing="ij")
    p, n = _patch_eval(face, uu.ravel(), vv.ravel())
    rng = np.random.default_rng(11)
    m = p + (_patch_error(p) + NOISE * rng.normal(size=len(p)))[:, None] * n
    csv = xyz_csv(tmp_path / "patch.csv", m)
    # the normals turn through 195°: not a height field over one plane
    r = CliRunner().invoke(main, ["analyze", str(csv), "--nominal", str(step)])
    assert r.exit_code == 2 and "not a height field" in r.output, r.output
    out, js = tmp_path / "patch_c.step", tmp_path / "c.json"
    r = CliRunner().invoke(
        main, ["compensate", str(csv), "--nominal", str(step), "--part", str(out), "--json", str(js)]
    )
    assert r.exit_code == 0, r.output
    j = json.loads(js.read_text())
    assert (
        j["faces"] == [1]
        and j["face_names"] == [None]
        and j["part"]["valid"]
        and j["part"]["check"]["max_error"] <= 1e-3
    )
    back = read_step(out)
    assert _valid(back)
    rs = np.random.default_rng(5)
    su, sv = rs.uniform(u0, u1, 1200), rs.uniform(v0, v1, 1200)
    ps, ns = _patch_eval(face, su, sv)
    t = along(back, ps, ns)
    ok = np.isfinite(t)
    assert ok.mean() > 0.99  # a line through the very edge may miss the face
    measured = (su >= lo_u) & (su <= hi_u) & (sv >= lo_v) & (sv <= hi_v)
    f = _truth_figures(_patch_error(ps)[ok], t[ok], measured[ok])
    assert f["inside"] <= 0.10 and f["border"] <= 0.20 and f["inside_rms"] <= 0.002, f


def test_a_two_face_part_names_its_faces(tmp_path):
    # the cylinder segment measured on its curved face and on its top (a 60° sector, trimmed by an
    # arc in its (u, v)); the top's error is a tilt of its own
    from OCP.TopAbs import TopAbs_FACE, TopAbs_SOLID

    step, _ = _cylinder_case(tmp_path)
    rng = np.random.default_rng(8)
    th, z = np.meshgrid(np.arange(6, 54.1, 1.5), np.arange(5, 45.1, 1.5), indexing="ij")
    _, _, side = _cylinder_points(th.ravel(), z.ravel(), rng)
    rr, tt = np.meshgrid(np.arange(4, 36.1, 1.5), np.radians(np.arange(6, 54.1, 2.0)), indexing="ij")
    top_p = np.column_stack([(rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel(), np.full(rr.size, H)])

    def top_error(p):
        return -0.03 - 0.0006 * p[:, 0] + 0.008 * np.sin(p[:, 1] / 7)

    top = top_p + np.column_stack(
        [0 * top_p[:, 0], 0 * top_p[:, 0], top_error(top_p) + NOISE * rng.normal(size=len(top_p))]
    )
    csv = xyz_csv(tmp_path / "two.csv", np.vstack([side, top]))
    out, surf, js = tmp_path / "two_c.step", tmp_path / "faces.igs", tmp_path / "two.json"
    r = CliRunner().invoke(
        main,
        ["compensate", str(csv), "--nominal", str(step), "--part", str(out), "--surface", str(surf), "--json", str(js)],
    )
    assert r.exit_code == 0, r.output
    j = json.loads(js.read_text())
    shape = measure.project_on_cad(csv, step).faces
    assert len(shape) == 5 and j["faces"] == [1, 2] and [b["face"] for b in j["by_face"]] == [1, 2]
    back = read_step(out)
    assert _valid(back) and _count(back, TopAbs_SOLID) == 1 and _count(back, TopAbs_FACE) == 5
    # the side, as for the cylinder alone
    p, n, _, _, measured = _cylinder_samples(600)
    f = _truth_figures(_cylinder_error(p), along(back, p, n), measured)
    assert f["inside"] <= 0.10 and f["border"] <= 0.20 and f["inside_rms"] <= 0.002, f
    # the top: normal +z; the measured area r 4…36 mm, 6…54°
    rs = np.random.default_rng(4)
    r_, a_ = rs.uniform(0.5, R - 0.5, 600), np.radians(rs.uniform(0.5, ANGLE - 0.5, 600))
    p = np.column_stack([r_ * np.cos(a_), r_ * np.sin(a_), np.full(600, H)])
    t = along(back, p, np.tile([0.0, 0.0, 1.0], (600, 1)))
    measured = (r_ >= 4) & (r_ <= 36) & (a_ >= np.radians(6)) & (a_ <= np.radians(54))
    f = _truth_figures(top_error(p), t, measured)
    assert f["inside"] <= 0.10 and f["border"] <= 0.20 and f["inside_rms"] <= 0.002, f
    # the faces alone, as IGES: two faces
    from OCP.IGESControl import IGESControl_Reader

    rd = IGESControl_Reader()
    rd.ReadFile(str(surf))
    rd.TransferRoots()
    assert _count(rd.OneShape(), TopAbs_FACE) == 2


def _refused(tmp_path, args, match):
    out = tmp_path / "refused.step"
    r = CliRunner().invoke(
        main, ["compensate", *map(str, args), "--part", str(out), "--json", str(tmp_path / "r.json")]
    )
    assert r.exit_code == 2 and match in r.output, r.output
    assert not out.exists() and not (tmp_path / "r.json").exists()


def test_refusals(tmp_path, monkeypatch):
    step, csv = _cylinder_case(tmp_path)
    rng = np.random.default_rng(2)
    side = np.loadtxt(csv, delimiter=",", skiprows=1)
    # a few points on the top face as well: too few to decompose it
    few = xyz_csv(tmp_path / "few.csv", np.vstack([side, [[10.0 + k, 5.0, H + 0.01] for k in range(4)]]))
    _refused(tmp_path, [few, "--nominal", step], "face 2: 4 measured point(s)")
    # points over a small corner of the face: too little of it to compensate
    th, z = np.meshgrid(np.arange(2, 14.1, 1.0), np.arange(2, 12.1, 1.0), indexing="ij")
    _, _, m = _cylinder_points(th.ravel(), z.ravel(), rng)
    _refused(tmp_path, [xyz_csv(tmp_path / "corner.csv", m), "--nominal", step], "the measured points cover")
    # a full turn (a seam edge): no B-spline face keeps its trimming
    full = write_step(_cylinder_solid(360.0), tmp_path / "full.step")
    _refused(tmp_path, [csv, "--nominal", full], "closes on itself")
    # a part that fails OpenCASCADE's check after the replacement: refused, nothing written
    from ncadapt import cad

    monkeypatch.setattr(cad, "is_valid", lambda shape: False)
    _refused(tmp_path, [csv, "--nominal", step], "not valid after the faces were replaced (BRepCheck_Analyzer)")
    monkeypatch.undo()
    # usage
    for args, match in (
        ([csv, "--face", "1"], "--face needs --nominal"),
        ([csv, "--nominal", step, "--extent", "0,1,0,1"], "--extent is for a nominal rebuilt"),
        ([csv, "--nominal", step, "--section", "u=1", "--report", tmp_path / "r.html"], "a section is the plane x="),
    ):
        r = CliRunner().invoke(main, ["compensate", *map(str, args)])
        assert r.exit_code == 2 and match in r.output, r.output
    r = CliRunner().invoke(main, ["compensate", str(csv), "--nominal", str(step), "--part", str(tmp_path / "p.igs")])
    assert r.exit_code == 2 and "written as STEP" in r.output


def test_a_program_is_corrected_from_a_cad_nominal(tmp_path):
    # a plate z = 5 (one face, 60 x 40 mm) measured with E = 20 µm + 0.5 µm/mm along x; a program
    # along y = 20 at the surface is moved by −E along +z (the face normal) where it was measured
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt

    step = write_step(
        BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0, 0, 5), gp_Dir(0, 0, 1)), 0.0, 60.0, 0.0, 40.0).Face(),
        tmp_path / "plate.step",
    )
    x, y = np.meshgrid(np.arange(2.0, 58.1, 1.5), np.arange(2.0, 38.1, 1.5), indexing="ij")
    x, y = x.ravel(), y.ravel()
    e = 0.02 + 0.0005 * x
    csv = xyz_csv(
        tmp_path / "a.csv", np.column_stack([x, y, 5.0 + e + NOISE * np.random.default_rng(3).normal(size=x.size)])
    )
    prog = tmp_path / "p.ngc"
    prog.write_text(
        "G21 G90\nG0 X10 Y20 Z10\nG1 Z5 F500\n" + "".join(f"G1 X{k}\n" for k in range(12, 51, 2)) + "G0 Z10\nM2\n"
    )
    out = tmp_path / "out.ngc"
    r = CliRunner().invoke(
        main,
        ["compensate", str(csv), "--nominal", str(step), "--program", str(prog), "-o", str(out), "--tool-radius", "0"],
    )
    assert r.exit_code == 0, r.output
    zs = {}
    for line in out.read_text().splitlines():
        if line.startswith("G1 X"):
            parts = dict((w[0], float(w[1:])) for w in line.split()[1:])
            if "Z" in parts:
                zs[parts["X"]] = parts["Z"]
    xs = np.array(sorted(zs))
    assert len(xs) >= 10
    np.testing.assert_allclose([zs[k] for k in xs], 5.0 - (0.02 + 0.0005 * xs), atol=0.003)
