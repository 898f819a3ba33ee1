"""Face sets: faces of a CAD part analysed and decomposed together in the (u, v) of the plane their
normals fit, so that the correction is one field across their common edges.

Testbed: a part whose top is one cylinder of radius 100 mm (axis along y, z up) split into two faces
along its crest x = 0 (two 20° sectors fused by OpenCASCADE: 70…90° and 90…110° from +x), 40 mm
long. The "measured" points are the nominal points moved along the outward normal by a smooth error
field of their position — a 10 µm offset plus a Gaussian bump of 40 µm, σ 6 mm, centred at
x = 5 mm, y = −20 mm, so that it crosses the common edge with a slope of
40 · (5 / 36) · exp(−25 / 72) ≈ 3.9 µm/mm there — plus seeded normal noise of 5 µm. The points lie
on a 2 mm grid in x (±1, ±3, … ±29 mm) and y (−36 … −4 mm): the nearest points are 1 mm from the
common edge on either side. The truth at any point is the closed form E below."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from helpers import along, read_step, rms, write_step, xyz_csv
from ncadapt import cad, measure
from ncadapt.cli import main
from ncadapt.errors import InputError
from ncadapt.processes import freeform as pf

pytest.importorskip("OCP")

NOISE = 0.005  # mm
RB, L = 100.0, 40.0  # the top's radius and the part's length, mm


def E(p):
    """The error field (mm) of a point's position (n, 3)."""
    return 0.01 + 0.04 * np.exp(-((p[:, 0] - 5.0) ** 2 + (p[:, 1] + 20.0) ** 2) / (2 * 6.0**2))


def _on_top(x, y):
    """Points of the top at (x, y) and their outward normals."""
    z = np.sqrt(RB**2 - x**2)
    return np.column_stack([x, y, z]), np.column_stack([x, 0 * x, z]) / RB


@pytest.fixture(scope="module")
def crest(tmp_path_factory):
    """The part, its measurement and the ids of its two top faces (x > 0, x < 0)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Fuse
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    def sector(a0, a1):
        a = math.radians(a0)
        # axis −y, angles from (cos a0, 0, sin a0) towards +z
        ax = gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, -1, 0), gp_Dir(math.cos(a), 0, math.sin(a)))
        return BRepPrimAPI_MakeCylinder(ax, RB, L, math.radians(a1 - a0)).Shape()

    fuse = BRepAlgoAPI_Fuse(sector(70, 90), sector(90, 110))
    fuse.Build()
    d = tmp_path_factory.mktemp("crest")
    step = write_step(fuse.Shape(), d / "crest.step")
    part = cad.read_part(step)
    top = {}
    for k, f in enumerate(part.faces, 1):
        u0, u1, v0, v1 = cad.face_uv_bounds(f)
        p, n, _ = cad.face_evaluate(f, [(u0 + u1) / 2], [(v0 + v1) / 2])
        if n[0, 2] > 0.9:
            top["right" if p[0, 0] > 0 else "left"] = k
    assert len(part.faces) == 8 and set(top) == {"right", "left"}
    x, y = np.meshgrid(np.arange(-29.0, 29.1, 2.0), np.arange(-36.0, -3.9, 2.0), indexing="ij")
    p, n = _on_top(x.ravel(), y.ravel())
    m = p + (E(p) + NOISE * np.random.default_rng(1).normal(size=len(p)))[:, None] * n
    return step, xyz_csv(d / "crest.csv", m), top["right"], top["left"], d


def _edge(ys, side):
    """Points of the top at x = side (mm) along y, and their normals."""
    return _on_top(np.full(len(ys), float(side)), ys)


def _df_at(pc, proj, fid, points) -> np.ndarray:
    """dF (mm) of face ``fid`` at points of its surface (their parameters found by OpenCASCADE's
    ``GeomAPI_ProjectPointOnSurf``, edges included)."""
    from OCP.BRep import BRep_Tool
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.gp import gp_Pnt

    s = BRep_Tool.Surface_s(proj.faces[fid - 1])
    uv = []
    for x, y, z in points:
        pr = GeomAPI_ProjectPointOnSurf(gp_Pnt(float(x), float(y), float(z)), s)
        assert pr.LowerDistance() < 1e-6
        uv.append(pr.LowerDistanceParameters())
    uv = np.array(uv)
    return next(f for f in pc.faces if f.face == fid).df(uv[:, 0], uv[:, 1])


def test_a_set_carries_one_field_across_the_common_edge(crest):
    step, csv, right, left, _ = crest
    own = pf.compensate_cad(measure.project_on_cad(csv, step))
    proj = measure.project_on_cad(csv, step, face_sets=[[right, left]])
    assert proj.sets == ((right, left),)
    pc = pf.compensate_cad(proj)
    assert [f.face_set for f in pc.faces] == [0, 0] and [f.face_set for f in own.faces] == [None, None]
    (fs,) = pc.sets
    # the set's plane: the crest is seen from +z, (u, v) = (x, y)
    np.testing.assert_allclose(fs.frame.axes, np.eye(3), atol=1e-12)
    ys = np.linspace(-34.0, -6.0, 57)
    errors = {}
    for name, c in (("set", pc), ("own", own)):
        err = []
        for fid, sign in ((right, 1), (left, -1)):
            for dx in (0.0, 0.5, 1.0):
                q, _ = _edge(ys, sign * dx)
                err.append(_df_at(c, proj, fid, q) - E(q))
        errors[name] = rms(np.concatenate(err))
    # along the common edge (within 1 mm of it), the set's dF is nearer the truth than the faces' own
    # (2.5 against 5.0 µm RMS)
    assert errors["set"] < 0.7 * errors["own"] and errors["set"] <= 0.003, errors
    # on the edge itself both faces give the same dF, and near the truth (the bilateral filter's
    # σ_c = 3 mm rounds the bump's top a little: 6.2 µm at most there)
    q, _ = _edge(ys, 0.0)
    a, b = _df_at(pc, proj, right, q), _df_at(pc, proj, left, q)
    assert np.abs(a - b).max() <= 0.001
    assert rms(a - E(q)) <= 0.003 and np.abs(a - E(q)).max() <= 0.0075
    a_own, b_own = _df_at(own, proj, right, q), _df_at(own, proj, left, q)
    assert np.abs(a_own - b_own).max() > 0.005  # each face on its own: a step at the edge
    # over the whole measured area the set compensates as well as the faces on their own
    x, y = np.meshgrid(np.linspace(-28.5, 28.5, 40), np.linspace(-35.5, -4.5, 20), indexing="ij")
    q, _ = _on_top(x.ravel(), y.ravel())
    right_side = q[:, 0] > 0
    df = np.zeros(len(q))
    df[right_side] = _df_at(pc, proj, right, q[right_side])
    df[~right_side] = _df_at(pc, proj, left, q[~right_side])
    assert rms(df - E(q)) <= 0.1 * rms(E(q)) and rms(df - E(q)) <= 0.003


def test_the_written_part_lies_minus_df_from_the_nominal(crest):
    step, csv, right, left, d = crest
    out, js = d / "crest_c.step", d / "crest.json"
    r = CliRunner().invoke(
        main,
        [
            "compensate",
            str(csv),
            "--nominal",
            str(step),
            "--face-set",
            f"{right},{left}",
            "--part",
            str(out),
            "--json",
            str(js),
        ],
    )
    assert r.exit_code == 0, r.output
    assert f"face set {right}, {left}: 510 points in one (u, v)" in r.output
    j = json.loads(js.read_text())
    assert j["faces"] == sorted([right, left]) and j["face_names"] == [None, None]
    assert [b["face_set"] for b in j["by_face"]] == [0, 0]
    (fs,) = j["face_sets"]
    assert fs["faces"] == [right, left] and fs["names"] == [None, None] and fs["n_points"] == 510
    assert fs["method"] == "bilateral" and fs["verdict"]["systematic"] and "rms" in fs["systematic"]
    assert j["part"]["valid"] and j["part"]["check"]["max_error"] <= 1e-3
    # read back by OpenCASCADE: the faces lie −dF from the nominal along its normal, within 1 µm,
    # up to the common edge from both sides
    from OCP.BRepCheck import BRepCheck_Analyzer

    back = read_step(out)
    assert BRepCheck_Analyzer(back).IsValid()
    proj = measure.project_on_cad(csv, step, face_sets=[[right, left]])
    pc = pf.compensate_cad(proj)
    ys = np.linspace(-38.0, -2.0, 19)
    for fid, xs in ((right, (0.05, 1.0, 15.0, 33.0)), (left, (-0.05, -1.0, -15.0, -33.0))):
        for x in xs:
            q, n = _edge(ys, x)
            np.testing.assert_allclose(along(back, q, n), -_df_at(pc, proj, fid, q), atol=1e-3)


def test_analyze_gives_the_sets_statistics(crest):
    step, csv, right, left, d = crest
    js = d / "a.json"
    r = CliRunner().invoke(
        main, ["analyze", str(csv), "--nominal", str(step), "--face-set", f"{right},{left}", "--json", str(js)]
    )
    assert r.exit_code == 0, r.output
    j = json.loads(js.read_text())
    assert [f["face_set"] for f in j["faces"]] == [0, 0]
    (fs,) = j["face_sets"]
    assert fs["faces"] == [right, left] and fs["n_points"] == 510 and fs["verdict"]["systematic"]
    # the deviations of the set's points are the figures of all its points (every point is on it)
    assert fs["deviation"] == pytest.approx(j["deviation"])


# ---------------------------------------------------------------------------------- refusals
def _cylinder_with_cap(tmp_path):
    """A 60° sector of a cylinder (radius 40, height 50 mm) measured on its curved side and its cap,
    with a 20 µm offset along the normals and 5 µm noise."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    shape = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 40.0, 50.0, math.radians(60)).Shape()
    step = write_step(shape, tmp_path / "cyl.step")
    th, z = np.meshgrid(np.radians(np.arange(6, 54.1, 3.0)), np.arange(5, 45.1, 3.0), indexing="ij")
    side = np.column_stack([40 * np.cos(th.ravel()), 40 * np.sin(th.ravel()), z.ravel()])
    rr, tt = np.meshgrid(np.arange(4, 36.1, 3.0), np.radians(np.arange(6, 54.1, 4.0)), indexing="ij")
    top = np.column_stack([(rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel(), np.full(rr.size, 50.0)])
    n = np.vstack([side * [1 / 40, 1 / 40, 0], np.tile([0.0, 0.0, 1.0], (len(top), 1))])
    e = 0.02 + NOISE * np.random.default_rng(6).normal(size=len(n))
    return step, xyz_csv(tmp_path / "cyl.csv", np.vstack([side, top]) + e[:, None] * n)


def test_a_cylinder_and_its_cap_are_not_one_height_field(tmp_path):
    step, csv = _cylinder_with_cap(tmp_path)
    faces = measure.project_on_cad(csv, step).faces_used()
    assert [f["id"] for f in faces] == [1, 2]  # the side, the cap
    # the direction the set is seen along: the area-weighted mean normal, closed form: the side's
    # (area 40 · π/3 · 50) mean normal is (3/π)(cos 30°, sin 30°, 0), the cap's (area π/6 · 40²) is z;
    # the cap's normal is arccos(w_z) from it
    a_side, a_cap = 40 * math.pi / 3 * 50, math.pi / 6 * 40**2
    m = np.array([a_side * 3 / math.pi * math.cos(math.pi / 6), a_side * 3 / math.pi * 0.5, a_cap])
    deg = math.degrees(math.acos(m[2] / np.linalg.norm(m)))
    assert 60 < deg < 75
    out, js = tmp_path / "out.step", tmp_path / "out.json"
    for cmd in (["analyze"], ["compensate", "--part", str(out)]):
        r = CliRunner().invoke(
            main, [cmd[0], str(csv), "--nominal", str(step), "--face-set", "1,2", "--json", str(js), *cmd[1:]]
        )
        assert r.exit_code == 2, r.output
        assert f"cyl.step: error: face set 1,2: the normals of face 2 turn up to {deg:.0f}°" in r.output, r.output
        assert "more than 45°: the set is not a height field over one plane" in r.output
        assert not out.exists() and not js.exists()
    # each face in its own (u, v): compensated
    r = CliRunner().invoke(main, ["compensate", str(csv), "--nominal", str(step), "--part", str(out)])
    assert r.exit_code == 0, r.output


def test_a_set_that_folds_over_its_plane_is_refused():
    # a C-shaped profile (x, z) extruded 30 mm along y: its top (z = 20, x 0…60) lies over the top
    # of its lower jaw (z = 5, x 0…40): both normals +z, the projection on z folds
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakePolygon
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Pnt, gp_Vec

    poly = BRepBuilderAPI_MakePolygon()
    for x, z in ((0, 0), (60, 0), (60, 20), (0, 20), (0, 15), (40, 15), (40, 5), (0, 5)):
        poly.Add(gp_Pnt(x, 0, z))
    poly.Close()
    solid = BRepPrimAPI_MakePrism(BRepBuilderAPI_MakeFace(poly.Wire()).Face(), gp_Vec(0, 30, 0)).Shape()
    faces = cad.faces(solid)
    up = {}
    for k, f in enumerate(faces, 1):
        u0, u1, v0, v1 = cad.face_uv_bounds(f)
        p, n, _ = cad.face_evaluate(f, [(u0 + u1) / 2], [(v0 + v1) / 2])
        if n[0, 2] > 0.9:
            up[round(float(p[0, 2]))] = k
    top, jaw = up[20], up[5]
    with pytest.raises(InputError, match=r"folds over its plane: .* crosses face \d+ again 15 mm away"):
        pf.face_set_frame({top: faces[top - 1], jaw: faces[jaw - 1]}, "c.step")
    # the top alone: no fold
    assert np.allclose(pf.face_set_frame({top: faces[top - 1]}).axes[2], [0, 0, 1])


@pytest.mark.parametrize(
    "sets, message",
    [
        (["1,9"], "--face-set 9: the CAD file has faces 1 to 8"),
        (["1,nope"], "--face-set 'nope': no face has that name. The CAD file names none of its faces"),
        (["1,3", "3"], "--face-set: face 3 is in two sets (1,3 and 3)"),
        (["1,,3"], "expected face ids or names separated by commas"),
    ],
)
def test_face_sets_naming_unknown_faces_or_a_face_twice_are_refused(crest, tmp_path, sets, message):
    step, csv, _, _, _ = crest
    out = tmp_path / "out.step"
    args = [a for s in sets for a in ("--face-set", s)]
    for cmd in (["analyze"], ["compensate", "--part", str(out)]):
        r = CliRunner().invoke(main, [cmd[0], str(csv), "--nominal", str(step), *args, *cmd[1:]])
        assert r.exit_code == 2 and message in r.output, r.output
        assert not out.exists()


def test_face_set_needs_a_nominal(crest):
    _, csv, _, _, _ = crest
    for cmd in ("analyze", "compensate"):
        r = CliRunner().invoke(main, [cmd, str(csv), "--face-set", "1,3"])
        assert r.exit_code == 2 and "--face-set needs --nominal" in r.output, r.output


def test_the_report_outlines_the_sets_hull(crest):
    """A face of a set is extrapolated beyond the hull of the set's points (x within ±29 mm, y
    within −36…−4 mm on the top), not its own: the farthest strip node of each face is its outer
    corner (θ = 70° or 110°, y = 0 or −40), 100 mm × (acos 0.29 − 70°) = 5.48 mm along the arc and
    4 mm along y from that hull's corner: 6.79 mm (the report measures it to the nearest grid node
    inside the hull, at most a cell farther)."""
    from ncadapt.report import cad_maps

    step, csv, right, left, d = crest
    pc = pf.compensate_cad(measure.project_on_cad(csv, step, face_sets=[[right, left]]))
    want = math.hypot(RB * (math.acos(0.29) - math.radians(70.0)), 4.0)
    for fc in cad_maps.face_corrections(pc):
        cell = math.hypot(np.diff(fc.u_mm).max(), np.diff(fc.v_mm).max())
        assert fc.in_set and want - 1e-3 <= fc.strip_distance <= want + cell, (fc.strip_distance, want, cell)
    r = CliRunner().invoke(
        main,
        [
            "compensate",
            str(csv),
            "--nominal",
            str(step),
            "--face-set",
            f"{right},{left}",
            "--report",
            str(d / "r.html"),
        ],
    )
    assert r.exit_code == 0, r.output
    assert "hatched strip" in (d / "r.html").read_text()


def test_a_second_round_with_a_set(crest, tmp_path):
    """Round 2 measures the part cut with round 1's compensation: its error is E − dF₁ (the testbed's
    truth). The total dF = dF₁ + the new systematic part comes nearer E than dF₁ alone, and both
    faces still give one dF on their common edge."""
    step, csv, right, left, _ = crest
    proj1 = measure.project_on_cad(csv, step, face_sets=[[right, left]])
    pc1 = pf.compensate_cad(proj1)
    x, y = np.meshgrid(np.arange(-29.0, 29.1, 2.0), np.arange(-36.0, -3.9, 2.0), indexing="ij")
    p, n = _on_top(x.ravel(), y.ravel())
    df1 = np.empty(len(p))
    side = p[:, 0] > 0
    df1[side] = _df_at(pc1, proj1, right, p[side])
    df1[~side] = _df_at(pc1, proj1, left, p[~side])
    m2 = p + (E(p) - df1 + NOISE * np.random.default_rng(2).normal(size=len(p)))[:, None] * n
    proj2 = measure.project_on_cad(xyz_csv(tmp_path / "round2.csv", m2), step, face_sets=[[right, left]])
    pc2 = pf.compensate_cad(proj2, previous={f.face: f.df for f in pc1.faces}, gain=1.0)
    assert [f.face_set for f in pc2.faces] == [0, 0]
    xs, ys = np.meshgrid(np.linspace(-28.5, 28.5, 40), np.linspace(-35.5, -4.5, 20), indexing="ij")
    q, _ = _on_top(xs.ravel(), ys.ravel())
    r = q[:, 0] > 0

    def err(pc, proj):
        df = np.empty(len(q))
        df[r] = _df_at(pc, proj, right, q[r])
        df[~r] = _df_at(pc, proj, left, q[~r])
        return rms(df - E(q))

    assert err(pc2, proj2) < err(pc1, proj1)
    e, _ = _edge(np.linspace(-34.0, -6.0, 29), 0.0)
    assert np.abs(_df_at(pc2, proj2, right, e) - _df_at(pc2, proj2, left, e)).max() <= 0.001
