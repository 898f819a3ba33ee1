"""The report's correction map, callouts and 3-D view with a CAD nominal (``compensate --nominal …
--report R.html``), checked against closed forms.

The part is built with OpenCASCADE here: the solid sixth of a cylinder (R 40 mm, height 50 mm,
0…60°), measured on its curved face (θ 6…54°, z 5…44 mm) and its top (r 4…36 mm, θ 6…54°). The
"measured" points are nominal points moved along the face's outward normal by a chosen error E,
without noise, linear in the face's (u, v): on the side E = 0.001 (z − 25.2) + 0.01 (θ − 0.5)
(u = θ rad, v = z), on the top E = −0.0006 x + 0.0003 y (its (u, v) an affine map of (x, y)). The
smoothing spline reproduces a linear field exactly (nothing to penalise) and ``--border cubic``
extrapolates it exactly (a cubic fitted to a straight line is that line; the bound of the measured
range widened by 25 % is not reached on these faces), so the correction −dF over each face's whole
(u, v) is −E evaluated at the point of the face, and the measured hull and its strip are the
rectangle of θ and z measured (on the side).
"""

from __future__ import annotations

import base64
import json
import math
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner
from lxml import html as lhtml

from ncadapt import measure
from ncadapt.cli import main
from ncadapt.processes import freeform as pf
from ncadapt.report import cad_maps

pytest.importorskip("OCP")

R, H, ANGLE = 40.0, 50.0, 60.0
K = 5  # callouts, the report's default


def _side_error(theta, z):
    return 0.001 * (z - 25.2) + 0.01 * (theta - 0.5)


def _top_error(x, y):
    return -0.0006 * x + 0.0003 * y


def _write_step(shape, path):
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    w = STEPControl_Writer()
    w.Transfer(shape, STEPControl_AsIs)
    w.Write(str(path))
    return path


def _num(s):
    return float(s.replace("−", "-").replace("+", ""))


def _rows(doc, div_id):
    el = doc.get_element_by_id(div_id)
    return [[c.text_content().strip() for c in tr.xpath("./td|./th")] for tr in el.iter("tr")]


@pytest.fixture(scope="module")
def part(tmp_path_factory):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    tmp = tmp_path_factory.mktemp("cadmaps")
    solid = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), R, H, math.radians(ANGLE)).Shape()
    step = _write_step(solid, tmp / "cyl.step")
    th, z = np.meshgrid(np.radians(np.arange(6, 54.1, 1.5)), np.arange(5, 45.1, 1.5), indexing="ij")
    th, z = th.ravel(), z.ravel()
    e_side = _side_error(th, z)
    side = np.column_stack([R * np.cos(th), R * np.sin(th), z])  # the nominal points
    side_n = np.column_stack([np.cos(th), np.sin(th), np.zeros_like(th)])
    rr, tt = np.meshgrid(np.arange(4, 36.1, 1.5), np.radians(np.arange(6, 54.1, 2.0)), indexing="ij")
    tx, ty = (rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel()
    e_top = _top_error(tx, ty)
    top = np.column_stack([tx, ty, np.full_like(tx, H)])
    nominal = np.vstack([side, top])
    error = np.concatenate([e_side, e_top])
    normal = np.vstack([side_n, np.tile([0.0, 0.0, 1.0], (len(top), 1))])
    csv = tmp / "two.csv"
    m = nominal + error[:, None] * normal
    csv.write_text("x,y,z\n" + "".join(f"{float(a)!r},{float(b)!r},{float(c)!r}\n" for a, b, c in m))
    args = ["compensate", csv, "--nominal", step, "--filter", "spline", "--border", "cubic", "--report", tmp / "r.html"]
    r = CliRunner().invoke(main, [str(a) for a in args])
    assert r.exit_code == 0, r.output
    proj = measure.project_on_cad(csv, step)
    pc = pf.compensate_cad(proj, "spline", border="cubic")
    text = (tmp / "r.html").read_text()
    return {
        "dir": tmp,
        "nominal": nominal,
        "error": error,
        "n_side": len(side),
        "proj": proj,
        "pc": pc,
        "html": text,
        "doc": lhtml.fromstring(text),
    }


def _face_points(face, u, v):
    """Points of an OpenCASCADE face at (u, v), from its surface (OCP directly)."""
    from OCP.BRep import BRep_Tool

    s = BRep_Tool.Surface_s(face)
    return np.array([[c for c in (lambda p: (p.X(), p.Y(), p.Z()))(s.Value(float(a), float(b)))] for a, b in zip(u, v)])


def test_the_correction_map_is_minus_the_known_error_over_each_whole_face(part):
    pc, proj = part["pc"], part["proj"]
    fcs = cad_maps.face_corrections(pc)
    assert [fc.face for fc in fcs] == [1, 2]
    rng = np.random.default_rng(0)
    for fc in fcs:
        ok = np.isfinite(fc.correction)
        i, j = np.nonzero(ok)
        pick = rng.choice(len(i), size=min(400, len(i)), replace=False)
        i, j = i[pick], j[pick]
        p = _face_points(proj.faces[fc.face - 1], fc.u[i], fc.v[j])
        if fc.face == 1:
            # the side: (u, v) = (θ, z), and the point is at radius R there
            np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), R, atol=1e-9)
            want = -_side_error(np.arctan2(p[:, 1], p[:, 0]), p[:, 2])
        else:
            np.testing.assert_allclose(p[:, 2], H, atol=1e-9)
            want = -_top_error(p[:, 0], p[:, 1])
        got = fc.correction[i, j]
        # in the strip as well as inside the hull: within 1 µm of the closed form
        assert fc.strip[i, j].any() and (~fc.strip[i, j]).any()
        np.testing.assert_allclose(got, want, atol=1e-3)
        assert np.abs(got - want).max() < 1e-5  # in fact within 10 nm
    # outside the trimmed top (θ > 60°, or beyond r = 40) no correction is drawn
    top = fcs[1]
    U, V = np.meshgrid(top.u, top.v, indexing="ij")
    p = _face_points(proj.faces[1], U.ravel(), V.ravel())
    ang, r = np.degrees(np.arctan2(p[:, 1], p[:, 0])), np.hypot(p[:, 0], p[:, 1])
    off = ((ang > ANGLE + 1) | (r > R + 1)).reshape(U.shape)
    assert off.any() and np.isnan(top.correction[off]).all()


def test_the_strip_is_where_the_side_extends_beyond_its_measured_rectangle(part):
    (side, _) = cad_maps.face_corrections(part["pc"])
    # the side's scale along u: the mean chord length of the 16 chords of its 0…60° span per radian
    d = math.radians(ANGLE) / 16
    su = 16 * 2 * R * math.sin(d / 2) / math.radians(ANGLE)
    np.testing.assert_allclose(side.u_mm, side.u * su, rtol=1e-12)
    np.testing.assert_allclose(side.v_mm, side.v, rtol=1e-12)
    # the measured hull: θ 6…54°, z 5…44 (the last row of 5 + 1.5 k below 45)
    t0, t1, z0, z1 = math.radians(6), math.radians(54), 5.0, 44.0
    lo, hi = side.hull.min(axis=0), side.hull.max(axis=0)
    assert (lo[0], hi[0], lo[1], hi[1]) == pytest.approx((t0 * su, t1 * su, z0, z1), abs=1e-6)
    T, Z = np.meshgrid(side.u, side.v, indexing="ij")
    eps = 1e-7
    outside = (T < t0 - eps) | (T > t1 + eps) | (Z < z0 - eps) | (Z > z1 + eps)
    inside = (T > t0 + eps) & (T < t1 - eps) & (Z > z0 + eps) & (Z < z1 - eps)
    assert side.strip[outside].all() and not side.strip[inside].any()
    # the farthest strip node from the rectangle: a corner of the face, (0, 0) or (60°, 50), its
    # distance to the rectangle's nearest corner
    want = max(math.hypot(t0 * su, z0), math.hypot((math.radians(ANGLE) - t1) * su, H - z1))
    assert side.strip_distance == pytest.approx(want, abs=1e-9)
    # its share of the face's nodes: between the nodes surely outside and all but those surely inside
    assert side.strip.shape == T.shape and outside.mean() <= side.strip_fraction <= 1 - inside.mean()
    assert 1 - inside.mean() - outside.mean() < 0.1
    # the report's table says it, face by face
    rows = {r[0]: r for r in _rows(part["doc"], "correction")[1:]}
    assert set(rows) == {"1", "2"}
    r = rows["1"]
    assert _num(r[6]) == pytest.approx(want, abs=5e-4)
    assert _num(r[5]) == pytest.approx(100 * side.strip_fraction, abs=0.05)
    # the correction over the hull's nodes (µm): the extremes of −E there (the nodes on the hull's
    # edge, either side by rounding, taken as the map marks them)
    e_hull = _side_error(T[~side.strip], Z[~side.strip])
    lo_c, hi_c = (_num(s) for s in r[4].split("…"))
    assert (lo_c, hi_c) == pytest.approx((-1000 * e_hull.max(), -1000 * e_hull.min()), abs=0.05 + 1e-9)


def test_the_callouts_are_the_largest_known_deviations_with_face_and_place(part):
    err, nominal, n_side = part["error"], part["nominal"], part["n_side"]
    rows = _rows(part["doc"], "callouts-measured")
    assert rows[0] == [
        "#",
        "face",
        "u (face parameter)",
        "v (face parameter)",
        "x, mm",
        "y, mm",
        "z, mm",
        "deviation, µm",
    ]
    want = np.argsort(-np.abs(err), kind="stable")[:K]
    assert len(rows) == K + 1
    for k, (row, j) in enumerate(zip(rows[1:], want)):
        assert int(row[0]) == k + 1
        assert _num(row[7]) == pytest.approx(1000 * err[j], abs=0.05 + 1e-9)
        assert [_num(c) for c in row[4:7]] == pytest.approx(list(nominal[j]), abs=5e-4 + 1e-9)
        face = 1 if j < n_side else 2
        assert row[1] == str(face)
        if face == 1:  # (u, v) = (θ, z)
            th = math.atan2(nominal[j, 1], nominal[j, 0])
            assert (_num(row[2]), _num(row[3])) == pytest.approx((th, nominal[j, 2]), rel=1e-4)
    # the known field's k largest |E| are not ties: the k + 1-th is smaller
    s = np.sort(np.abs(err))[::-1]
    assert s[K - 1] > s[K] + 1e-7


def _plotly_data(text, div_id="surface3d"):
    """The traces plotly is given in the page: the JSON after ``Plotly.newPlot("id",``, its typed
    arrays decoded."""
    start = text.index(f'Plotly.newPlot({" " * 24}"{div_id}",')
    start = text.index("[", start)
    data, _ = json.JSONDecoder().raw_decode(text[start:])

    def arr(a):
        if isinstance(a, dict) and "bdata" in a:
            return np.frombuffer(base64.b64decode(a["bdata"]), dtype=np.dtype(a["dtype"]))
        return np.asarray(a, float)

    return [{k: arr(t[k]) if k in ("x", "y", "z", "intensity") else t.get(k) for k in (*t, "visible")} for t in data]


def test_the_3d_view_draws_the_points_at_their_place_on_the_part(part):
    traces = _plotly_data(part["html"])
    names = [t["name"] for t in traces]
    assert names == ["face 1, points", "face 2, points", "face 1, correction", "face 2, correction"]
    nominal, err, n_side = part["nominal"], part["error"], part["n_side"]
    for t, sl in zip(traces[:2], (slice(0, n_side), slice(n_side, None))):
        p = np.column_stack([t["x"], t["y"], t["z"]])
        want, e = nominal[sl], err[sl]
        # every point drawn, at its closed-form place on the CAD face (not at a flat layout)
        assert len(p) == len(want)
        d, i = _nearest(p, want)
        assert d.max() < 1e-6 and len(np.unique(i)) == len(want)
        np.testing.assert_allclose(t["intensity"], 1000 * e[i], atol=1e-6)
        assert t["visible"] in (None, True)
    # the correction on the faces: nodes on the nominal surfaces, coloured by −E there (µm)
    for t, face in zip(traces[2:], (1, 2)):
        p = np.column_stack([t["x"], t["y"], t["z"]])
        if face == 1:
            np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), R, atol=1e-9)
            want = -_side_error(np.arctan2(p[:, 1], p[:, 0]), p[:, 2])
        else:
            np.testing.assert_allclose(p[:, 2], H, atol=1e-9)
            want = -_top_error(p[:, 0], p[:, 1])
        np.testing.assert_allclose(t["intensity"], 1000 * want, atol=1e-2)
        assert t["visible"] is False
    # the projection onto the CAD faces puts the points where the closed form does
    np.testing.assert_allclose(part["proj"].measurements.nominal, nominal, atol=1e-6)


def _nearest(p, q):
    from scipy.spatial import cKDTree

    return cKDTree(q).query(p)


def test_the_cad_report_is_self_contained_and_its_3d_view_draws_in_chromium(part):
    from test_report import _chromium

    doc = part["doc"]
    assert not doc.xpath("//script[@src] | //link[@href] | //img[not(starts-with(@src, 'data:'))]")
    dom = subprocess.run(
        [*_chromium(), "--dump-dom", (part["dir"] / "r.html").as_uri()],
        check=True,
        capture_output=True,
        timeout=180,
        text=True,
    ).stdout
    drawn = lhtml.fromstring(dom).get_element_by_id("surface3d")
    assert drawn.xpath(".//svg[contains(@class, 'main-svg')]")
    assert drawn.xpath(".//div[contains(@class, 'gl-container')]//canvas")
    assert drawn.xpath(".//*[contains(@class, 'colorbar')]")
    assert "WebGL is not supported" not in drawn.text_content()
