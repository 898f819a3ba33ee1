"""Alignment of measured points to a CAD nominal: the best fit on the faces and the RPS / 3-2-1
alignment on datum points. The parts are built with OpenCASCADE and written as STEP; the truth is
the rigid transform the test applies (built with scipy's ``Rotation``, not with ncadapt), so the
solver is checked against something it did not compute."""

from __future__ import annotations

import doctest
import json

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import InputError, cad, measure
from ncadapt.cli import main
from ncadapt.measure import _align

pytest.importorskip("OCP")
Rotation = pytest.importorskip("scipy.spatial.transform").Rotation

L, W, H = 200.0, 150.0, 100.0  # the box, mm: faces x = 0, y = 0 and z = H are measured
NOISE = 0.005  # 5 µm standard deviation per coordinate, the figure
# the transform from the measurement's frame to the CAD frame: a part clamped 0.4 mm, −0.3 mm,
# 0.2 mm off and turned 0.3°, −0.2°, 0.5° (about the fixed X, Y, Z axes), a few times more than a
# careful setup leaves
T_TRUE = np.array([0.4, -0.3, 0.2])
ANGLES_TRUE = np.radians([0.3, -0.2, 0.5])


def _write_step(shape, path):
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    w = STEPControl_Writer()
    w.Transfer(shape, STEPControl_AsIs)
    w.Write(str(path))
    return path


def _box(path):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    return _write_step(BRepPrimAPI_MakeBox(L, W, H).Shape(), path)


def _plane(path, z=5.0):
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt

    return _write_step(
        BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0, 0, z), gp_Dir(0, 0, 1)), 0.0, 60.0, 0.0, 40.0).Face(), path
    )


def _cylinder(path):
    import math

    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    cyl = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 40.0, 50.0, math.radians(60))
    return _write_step(cyl.Shape(), path)


def _grid(a0, a1, b0, b1, n):
    a, b = np.meshgrid(np.linspace(a0, a1, n), np.linspace(b0, b1, n), indexing="ij")
    return a.ravel(), b.ravel()


def _box_points(n, margin=5.0):
    """n × n points on each of the faces z = H, y = 0 and x = 0, ``margin`` mm from their edges."""
    g = margin
    a, b = _grid(g, L - g, g, W - g, n)
    top = np.column_stack([a, b, np.full_like(a, H)])
    a, b = _grid(g, L - g, g, H - g, n)
    front = np.column_stack([a, np.zeros_like(a), b])
    a, b = _grid(g, W - g, g, H - g, n)
    left = np.column_stack([np.zeros_like(a), a, b])
    return np.vstack([top, front, left])


def _to_measurement(q, t=T_TRUE, angles=ANGLES_TRUE):
    """CAD points q moved into the measurement's frame: m = Rᵀ (q − t), so that R m + t = q."""
    r = Rotation.from_euler("xyz", angles).as_matrix()
    return (np.asarray(q) - t) @ r


def _csv(path, pts, ids=None):
    ids = ids or [f"P{k}" for k in range(len(pts))]
    path.write_text("id,x,y,z\n" + "".join(f"{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in zip(ids, pts.tolist())))
    return path


def test_the_rotation_convention_is_scipys_extrinsic_xyz():
    rng = np.random.default_rng(3)
    for a in rng.uniform(-3, 3, size=(20, 3)):
        np.testing.assert_allclose(measure.rotation_matrix(*a), Rotation.from_euler("xyz", a).as_matrix(), atol=1e-14)


def test_bestfit_recovers_a_known_transform_with_5um_noise(tmp_path):
    # 3 × 1600 points on three faces of a box (they fix all six degrees of freedom), moved by a known
    # transform, plus 5 µm Gaussian noise (seed 11): the best fit returns the transform within 1 µm
    # and 1e-5 rad (the expected errors from the noise are about 0.3 µm and 3e-6 rad; over seeds
    # 0–9 the largest were 0.6 µm and 4.4e-6 rad)
    faces = cad.faces(cad.read_shape(_box(tmp_path / "box.step")))
    q = _box_points(40)
    m = _to_measurement(q) + np.random.default_rng(11).normal(scale=NOISE, size=q.shape)
    a = measure.align_to_cad(m, faces)
    assert a.converged and a.mode == "bestfit" and a.dof == measure.DOF and a.points == len(q)
    assert np.abs(a.translation - T_TRUE).max() < 1e-3
    assert np.abs(np.radians(a.rotation) - ANGLES_TRUE).max() < 1e-5
    np.testing.assert_allclose(a.apply(m), q, atol=5 * NOISE)
    # the residual is the noise's normal component: its RMS is the noise's standard deviation
    assert a.rms == pytest.approx(NOISE, rel=0.05)
    # the reported uncertainty is that of the noise: the errors are within three of them
    assert np.all(np.abs(a.translation - T_TRUE) < 3 * a.std[:3])
    assert np.all(np.abs(a.rotation - np.degrees(ANGLES_TRUE)) < 3 * a.std[3:])


def _freeform(path):
    """A bicubic B-spline patch through z = 8 sin(x/25) cos(y/20) + 0.002 (x − 50)² on 100 × 80 mm
    (OpenCASCADE's interpolation), as STEP, and 25 × 25 points on it evaluated by OpenCASCADE."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.collections import Array2_gp_Pnt
    from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface
    from OCP.gp import gp_Pnt

    n = 21
    grid = Array2_gp_Pnt(1, n, 1, n)
    for i, x in enumerate(np.linspace(0, 100, n)):
        for j, y in enumerate(np.linspace(0, 80, n)):
            grid.SetValue(i + 1, j + 1, gp_Pnt(x, y, 8 * np.sin(x / 25) * np.cos(y / 20) + 0.002 * (x - 50) ** 2))
    face = BRepBuilderAPI_MakeFace(GeomAPI_PointsToBSplineSurface(grid, 3, 3).Surface(), 1e-6).Face()
    s = BRep_Tool.Surface_s(face)
    u0, u1, v0, v1 = s.Bounds()
    a, b = _grid(0.06, 0.94, 0.06, 0.94, 25)
    q = [s.Value(u0 + x * (u1 - u0), v0 + y * (v1 - v0)) for x, y in zip(a, b)]
    return _write_step(face, path), np.array([(p.X(), p.Y(), p.Z()) for p in q])


def test_bestfit_on_a_freeform_patch(tmp_path):
    # one curved face fixes all six degrees of freedom: without noise the transform comes back to
    # round-off; with 5 µm noise within three of the standard uncertainties it reports (on this
    # gently curved patch with 625 points: about 2 µm in x and y, 3e-5 rad about z)
    step, q = _freeform(tmp_path / "patch.step")
    faces = cad.faces(cad.read_shape(step))
    a = measure.align_to_cad(_to_measurement(q), faces)
    np.testing.assert_allclose(a.translation, T_TRUE, atol=1e-9)
    np.testing.assert_allclose(np.radians(a.rotation), ANGLES_TRUE, atol=1e-12)
    # from 20° and 5 mm off as well (the nearest minimum is the right one here)
    t, ang = np.array([5.0, -3.0, 2.0]), np.radians([10.0, -5.0, 20.0])
    a = measure.align_to_cad(_to_measurement(q, t, ang), faces)
    np.testing.assert_allclose(a.translation, t, atol=1e-9)
    np.testing.assert_allclose(np.radians(a.rotation), ang, atol=1e-12)
    m = _to_measurement(q) + np.random.default_rng(4).normal(scale=NOISE, size=q.shape)
    a = measure.align_to_cad(m, faces)
    assert np.all(np.abs(a.translation - T_TRUE) < 3 * a.std[:3])
    assert np.all(np.abs(a.rotation - np.degrees(ANGLES_TRUE)) < 3 * a.std[3:])
    assert a.std[0] > 1e-3  # the patch fixes x less well than the box: the uncertainty says so


def test_analyze_aligns_before_the_deviations(tmp_path):
    # through the command: the JSON's alignment is the applied transform, and the deviations after
    # it are the noise alone (mean 0, RMS 5 µm); without alignment the points are off the part
    step = _box(tmp_path / "box.step")
    q = _box_points(16)
    m = _to_measurement(q) + np.random.default_rng(5).normal(scale=NOISE, size=q.shape)
    a = _csv(tmp_path / "a.csv", m)
    out = tmp_path / "a.json"
    r = CliRunner().invoke(main, ["analyze", str(a), "--nominal", str(step), "--align", "bestfit", "--json", str(out)])
    assert r.exit_code == 0, r.output
    j = json.loads(out.read_text())
    assert np.abs(np.array(j["alignment"]["translation"]) - T_TRUE).max() < 3e-3
    assert np.abs(np.radians(j["alignment"]["rotation"]) - ANGLES_TRUE).max() < 3e-5
    assert j["alignment"]["rms"] == pytest.approx(NOISE, rel=0.15)
    assert j["deviation"]["rms"] == pytest.approx(NOISE, rel=0.15)
    assert abs(j["deviation"]["mean"]) < 1e-3
    assert "alignment (bestfit, x,y,z,rx,ry,rz; 768 points" in r.output and "translation (mm) +0.4" in r.output
    r = CliRunner().invoke(main, ["analyze", str(a), "--nominal", str(step)])
    assert r.exit_code == 2 and "farther than --max-distance" in r.output, r.output


def test_a_plane_cannot_fix_six_degrees_of_freedom(tmp_path):
    step = _plane(tmp_path / "plate.step")
    x, y = _grid(2, 58, 2, 38, 15)
    q = np.column_stack([x, y, np.full_like(x, 5.0)])
    t, ang = np.array([0.0, 0.0, 0.15]), np.radians([0.2, -0.1, 0.0])
    m = _to_measurement(q, t, ang) + np.random.default_rng(2).normal(scale=NOISE, size=q.shape)
    a = _csv(tmp_path / "a.csv", m)
    r = CliRunner().invoke(main, ["analyze", str(a), "--nominal", str(step), "--align", "bestfit"])
    assert r.exit_code == 2, r.output
    assert f"{a}: error: --align bestfit: the measured points on these faces do not determine x, y, rz" in r.output
    # the three it can fix: the tilt and the height, recovered within what 225 points allow
    out = tmp_path / "a.json"
    r = CliRunner().invoke(
        main,
        ["analyze", str(a), "--nominal", str(step), "--align", "bestfit", "--align-dof", "z,rx,ry", "--json", str(out)],
    )
    assert r.exit_code == 0, r.output
    j = json.loads(out.read_text())["alignment"]
    assert j["dof"] == ["z", "rx", "ry"] and j["translation"][:2] == [0.0, 0.0] and j["rotation"][2] == 0.0
    assert abs(j["translation"][2] - 0.15) < 3e-3
    assert np.abs(np.radians(j["rotation"][:2]) - ang[:2]).max() < 1e-4


def test_a_cylinder_cannot_fix_its_axis(tmp_path):
    # a cylinder about z through the origin: sliding along z and turning about it leave every
    # distance unchanged — both are named
    faces = cad.faces(cad.read_shape(_cylinder(tmp_path / "cyl.step")))
    th, z = _grid(0.2, 0.8, 5, 45, 8)
    m = np.column_stack([40 * np.cos(th), 40 * np.sin(th), z])
    with pytest.raises(InputError, match=r"do not determine z, rz \(--align-dof x,y,z,rx,ry,rz\)"):
        measure.align_to_cad(m, faces)
    a = measure.align_to_cad(m + [0.05, -0.02, 0.0], faces, dof="x,y,rx,ry")
    np.testing.assert_allclose(a.translation, [-0.05, 0.02, 0.0], atol=1e-7)


def test_bestfit_that_does_not_converge_is_refused(tmp_path, monkeypatch):
    faces = cad.faces(cad.read_shape(_box(tmp_path / "box.step")))
    m = _to_measurement(_box_points(5))
    monkeypatch.setattr(_align, "MAX_ITERATIONS", 1)
    with pytest.raises(InputError, match="did not converge in 1 iterations"):
        measure.align_to_cad(m, faces, source="a.csv")


# ------------------------------------------------------------------------------------ datums
# a 3-2-1 system on the box: three points on the bottom (z), two on the front (y), one on the left (x)
RPS = [
    ("A1", (20.0, 20.0, 0.0), "z"),
    ("A2", (180.0, 20.0, 0.0), "z"),
    ("A3", (100.0, 130.0, 0.0), "z"),
    ("B1", (30.0, 0.0, 50.0), "y"),
    ("B2", (170.0, 0.0, 50.0), "y"),
    ("C1", (0.0, 75.0, 50.0), "x"),
]


def _datums_toml(path, measured):
    text = "# 3-2-1 on the box\n"
    for (name, p, axes), mv in zip(RPS, measured):
        mtext = f'"{mv}"' if isinstance(mv, str) else "[" + ", ".join(repr(float(c)) for c in mv) + "]"
        text += f'\n[[datum]]\nname = "{name}"\nnominal = {list(p)}\nmeasured = {mtext}\nconstrains = "{axes}"\n'
    path.write_text(text)
    return path


def _touches():
    """Where the datum points are touched, CAD frame: on the datum planes but up to 0.3 mm beside
    the nominal points in the plane (a constraint holds only along its direction)."""
    slide = np.array([[0.3, -0.2, 0], [0, 0.3, 0], [-0.3, 0, 0], [0.2, 0, -0.3], [0, 0, 0.25], [0, -0.3, 0.2]])
    return np.array([p for _, p, _ in RPS]) + slide


def test_datums_give_the_exact_transform(tmp_path):
    path = _datums_toml(tmp_path / "d.toml", _to_measurement(_touches()))
    d = measure.read_datums(path)
    assert [x.name for x in d] == ["A1", "A2", "A3", "B1", "B2", "C1"] and d[0].line == 3
    a = measure.align_datums(d, source=str(path))
    np.testing.assert_allclose(a.translation, T_TRUE, atol=1e-9)
    np.testing.assert_allclose(np.radians(a.rotation), ANGLES_TRUE, atol=1e-12)
    assert a.rms < 1e-9 and a.mode == "datums" and a.points == 6


def test_analyze_with_datums_named_in_the_measurements(tmp_path):
    # the datum points are rows of the measurement (ids A1 … C1); the other rows are on the top face
    # with a known form error e along +z: after the 3-2-1 alignment the deviations are e exactly
    step = _box(tmp_path / "box.step")
    x, y = _grid(10, 190, 10, 140, 12)
    e = 0.02 * np.sin(x / 30) * np.cos(y / 25)
    top = np.column_stack([x, y, H + e])
    m = _to_measurement(np.vstack([_touches(), top]))
    ids = [n for n, _, _ in RPS] + [f"P{k}" for k in range(len(top))]
    a = _csv(tmp_path / "a.csv", m, ids)
    toml = _datums_toml(tmp_path / "d.toml", [n for n, _, _ in RPS])
    out = tmp_path / "a.json"
    args = ["analyze", str(a), "--nominal", str(step), "--face", "6", "--align", "datums", "--datums", str(toml)]
    r = CliRunner().invoke(main, [*args, "--json", str(out)])
    assert r.exit_code == 0, r.output
    j = json.loads(out.read_text())
    np.testing.assert_allclose(j["alignment"]["translation"], T_TRUE, atol=1e-9)
    np.testing.assert_allclose(np.radians(j["alignment"]["rotation"]), ANGLES_TRUE, atol=1e-12)
    assert j["deviation"]["rms"] == pytest.approx(np.sqrt(np.mean(e * e)), abs=1e-9)
    assert j["deviation"]["max"] == pytest.approx(e.max(), abs=1e-9)
    meas = measure.against_cad(a, step, faces=[6], align="datums", datums=toml)
    np.testing.assert_allclose(meas.deviation, e, atol=1e-9)
    assert meas.ids[0] == "P0" and meas.lines[0] == 8 and meas.alignment.mode == "datums"
    # the labelled points are probe-tip centres with --probe-radius: refused at the datum
    r = CliRunner().invoke(main, [*args, "--probe-radius", "1"])
    assert r.exit_code == 2 and f"{toml}:3:1: error: datum 'A1' names a measured point" in r.output, r.output


@pytest.mark.parametrize(
    ("change", "message"),
    [
        # three primary points on one line along x: the rotation about it is free
        ({"A3": (100.0, 20.0, 0.0)}, "do not determine .*rx"),
        # the tertiary constrains y again: x is free
        ({"C1": "y"}, "do not determine x"),
    ],
)
def test_datums_that_do_not_fix_six_degrees_of_freedom_are_refused(tmp_path, change, message):
    rows = []
    for name, p, axes in RPS:
        c = change.get(name)
        rows.append((name, c if isinstance(c, tuple) else p, c if isinstance(c, str) else axes))
    text = "".join(
        f'[[datum]]\nname = "{n}"\nnominal = {list(p)}\nmeasured = {list(p)}\nconstrains = "{ax}"\n'
        for n, p, ax in rows
    )
    (tmp_path / "d.toml").write_text(text)
    with pytest.raises(InputError, match=message):
        measure.align_datums(measure.read_datums(tmp_path / "d.toml"))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "no \\[\\[datum\\]\\] table"),
        ("units = 'mm'\n", "unknown key 'units'"),
        ('[[datum]]\nnominal = [0, 0, 0]\nmeasured = "P1"\n', ":1: datum 'datum 1': give constrains"),
        ('[[datum]]\nnominal = [0, 0]\nmeasured = "P1"\nconstrains = "z"\n', ":1: datum 'datum 1': nominal must be"),
        ('[[datum]]\nnominal = [0, 0, 0]\nmeasured = "P1"\nconstrains = "zz"\n', "constrains must name axes"),
        ('[[datum]]\nnominal = [0, 0, 0]\nmeasured = "P1"\ndirection = [0, 1, 1]\n', "direction must be a unit"),
        ('[[datum]]\nnominal = [0, 0, 0]\nmeasured = "P1"\nconstrains = "z"\nside = 1\n', "unknown key 'side'"),
        (
            '[[datum]]\nname = "A"\nnominal = [0, 0, 0]\nmeasured = "P1"\nconstrains = "z"\n\n'
            '[[datum]]\nname = "A"\nnominal = [1, 0, 0]\nmeasured = "P2"\nconstrains = "z"\n',
            ":7: datum 'A' repeats the one at line 1",
        ),
        ("[[datum]\n", "not valid TOML"),
    ],
)
def test_datum_files_that_are_refused(tmp_path, text, message):
    (tmp_path / "d.toml").write_text(text)
    with pytest.raises(InputError, match=message):
        measure.read_datums(tmp_path / "d.toml")


def test_datums_must_be_as_many_as_the_degrees_of_freedom(tmp_path):
    path = _datums_toml(tmp_path / "d.toml", _to_measurement(_touches()))
    d = measure.read_datums(path)
    with pytest.raises(InputError, match="5 constraints for 6 degrees of freedom"):
        measure.align_datums(d[:5])
    with pytest.raises(InputError, match="no measured point with id 'A1'"):
        measure.align_datums(measure.read_datums(_datums_toml(tmp_path / "l.toml", ["A1"] * 6)), ids=["X"])
    # three on the primary plane fix z, rx, ry
    flat = [measure.Datum(x.name, x.nominal, x.nominal - [0, 0, 0.1], None, x.directions, 0) for x in d[:3]]
    np.testing.assert_allclose(measure.align_datums(flat, dof="z,rx,ry").translation, [0, 0, 0.1], atol=1e-12)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--align", "bestfit"], "--align needs --nominal"),
        (["--align-dof", "z"], "--align-dof needs --align bestfit or datums"),
        (["--nominal", "{step}", "--align", "datums"], "--align datums needs --datums FILE.toml"),
        (["--nominal", "{step}", "--datums", "{a}"], "--datums needs --align datums"),
        (["--nominal", "{step}", "--align", "bestfit", "--align-dof", "z,w"], "'w' is not one of x, y, z, rx, ry, rz"),
        (["--nominal", "{step}", "--align", "bestfit", "--align-dof", "z,z"], "repeats a degree of freedom"),
    ],
)
def test_alignment_options_that_are_refused(tmp_path, args, message):
    step = _plane(tmp_path / "plate.step")
    a = _csv(tmp_path / "a.csv", np.array([[1.0, 1.0, 5.0], [2.0, 1.0, 5.0], [1.0, 3.0, 5.0]]))
    args = [s.format(step=step, a=a) for s in args]
    r = CliRunner().invoke(main, ["analyze", str(a), *args])
    assert r.exit_code == 2 and message in r.output, r.output


def test_the_examples_run():
    assert doctest.testmod(_align, optionflags=doctest.NORMALIZE_WHITESPACE).failed == 0


# ------------------------------------------------------------------------- compensate --align
def _box_form_error(p, n):
    """A smooth form error on each measured face of the box (mm, along the outward normal n)."""
    x, y, z = p.T
    top = 0.05 + 0.10 * np.sin(x / 40) * np.cos(y / 35)
    front = 0.08 * np.cos(x / 45) * np.sin(z / 35) - 0.04
    left = 0.06 * np.sin(y / 35) + 0.04 * np.cos(z / 25)
    return np.where(n[:, 2] > 0.5, top, np.where(n[:, 1] < -0.5, front, left))


def _rigid_rows(p, n):
    """The normal displacement of a small rigid motion (t, θ) at p: n·t + (p × n)·θ, as rows [n, p × n]."""
    return np.column_stack([n, np.cross(p, n)])


def _box_normals(q):
    return np.where(
        np.isclose(q[:, 2], H)[:, None],
        [0.0, 0.0, 1.0],
        np.where(np.isclose(q[:, 1], 0)[:, None], [0, -1.0, 0], [-1.0, 0, 0]),
    )


MARGIN = 2.5  # mm: the unmeasured border strip of each face in the test below


def test_compensate_aligns_then_compensates_the_form(tmp_path):
    # the box's three faces with a form error E moved by the known transform, 5 µm noise per
    # coordinate: compensate --align bestfit returns the transform within 1 µm and 1e-5 rad, and the
    # compensated part meets the truth targets of tests/test_cad_compensate.py. A best fit cannot
    # tell a rigid motion of the part from the same motion in the form error, so E is made free of
    # rigid motions over the measured points (least squares with numpy: E − [n, p × n] c); E keeps
    # 9-18 µm RMS per face
    from OCP.TopAbs import TopAbs_FACE

    step = _box(tmp_path / "box.step")
    q = _box_points(40, MARGIN)
    nq = _box_normals(q)
    c = np.linalg.lstsq(_rigid_rows(q, nq), _box_form_error(q, nq), rcond=None)[0]

    def truth(p, n):
        return _box_form_error(p, n) - _rigid_rows(p, n) @ c

    e = truth(q, nq)
    assert np.abs(_rigid_rows(q, nq).T @ e).max() < 1e-9
    m = _to_measurement(q + e[:, None] * nq) + np.random.default_rng(6).normal(scale=NOISE, size=q.shape)
    a = _csv(tmp_path / "a.csv", m)
    out, js = tmp_path / "box_c.step", tmp_path / "c.json"
    r = CliRunner().invoke(
        main,
        ["compensate", str(a), "--nominal", str(step), "--align", "bestfit", "--part", str(out), "--json", str(js)],
    )
    assert r.exit_code == 0, r.output
    assert "alignment (bestfit, x,y,z,rx,ry,rz; 4,800 points" in r.output
    j = json.loads(js.read_text())
    assert np.abs(np.array(j["alignment"]["translation"]) - T_TRUE).max() < 1e-3
    assert np.abs(np.radians(j["alignment"]["rotation"]) - ANGLES_TRUE).max() < 1e-5
    assert j["alignment"]["rms"] == pytest.approx(np.sqrt(np.mean(e**2) + NOISE**2), rel=0.1)
    assert sorted(j["faces"]) == [1, 3, 6]  # x = 0, y = 0, z = H in OpenCASCADE's order
    # the written part, read back with OpenCASCADE and cut along the faces' normals (as in
    # tests/test_cad_compensate.py): the form error left, E − dF, against E
    from helpers import along as _along
    from helpers import read_step
    from test_cad_compensate import _count, _truth_figures, _valid

    back = read_step(out)
    assert _valid(back) and _count(back, TopAbs_FACE) == 6
    rs = np.random.default_rng(9)
    ps, ns, inner = [], [], []
    for axes, size, fixed, normal in (
        ((0, 1), (L, W), (2, H), (0, 0, 1.0)),
        ((0, 2), (L, H), (1, 0.0), (0, -1.0, 0)),
        ((1, 2), (W, H), (0, 0.0), (-1.0, 0, 0)),
    ):
        p = np.zeros((800, 3))
        p[:, axes[0]] = rs.uniform(0.5, size[0] - 0.5, 800)
        p[:, axes[1]] = rs.uniform(0.5, size[1] - 0.5, 800)
        p[:, fixed[0]] = fixed[1]
        ps.append(p)
        ns.append(np.tile(normal, (800, 1)))
        inner.append(np.all((p[:, axes] >= MARGIN) & (p[:, axes] <= np.array(size) - MARGIN), axis=1))
    p, n, measured = np.vstack(ps), np.vstack(ns), np.concatenate(inner)
    t = _along(back, p, n, reach=0.3)
    assert np.isfinite(t).all()
    f = _truth_figures(truth(p, n), t, measured)
    assert f["inside"] <= 0.10 and f["border"] <= 0.20 and f["inside_rms"] <= 0.002, f


def test_compensate_alignment_options_are_checked(tmp_path):
    step = _plane(tmp_path / "plate.step")
    a = _csv(tmp_path / "a.csv", np.array([[1.0, 1.0, 5.0], [2.0, 1.0, 5.0], [1.0, 3.0, 5.0]]))
    for args, message in (
        (["--align", "bestfit"], "--align needs --nominal"),
        (["--nominal", str(step), "--align-dof", "z"], "--align-dof needs --align bestfit or datums"),
        (["--nominal", str(step), "--align", "datums"], "--align datums needs --datums FILE.toml"),
    ):
        r = CliRunner().invoke(main, ["compensate", str(a), *args])
        assert r.exit_code == 2 and message in r.output, r.output
