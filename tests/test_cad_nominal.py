"""A CAD model as the nominal (issue: freeform on real parts, §1): actual points projected onto the
part's faces through OpenCASCADE, the deviation along the face's outward normal. The parts are
built with OpenCASCADE here and the deviations are known in closed form."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import InputError, measure
from ncadapt.cli import main

pytest.importorskip("OCP")


def _write_step(shape, path):
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    w = STEPControl_Writer()
    w.Transfer(shape, STEPControl_AsIs)
    w.Write(str(path))
    return path


def _cylinder(path, radius=40.0, height=50.0):
    """A solid sixth of a cylinder about z: its curved face is a cylinder segment from 0 to 60°."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    return _write_step(
        BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), radius, height, math.radians(60)).Shape(),
        path,
    )


def _plane(path, z=5.0):
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt

    return _write_step(
        BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0, 0, z), gp_Dir(0, 0, 1)), 0.0, 60.0, 0.0, 40.0).Face(), path
    )


def _csv(path, pts):
    path.write_text(
        "id,x,y,z\n" + "".join(f"P{k},{float(x)!r},{float(y)!r},{float(z)!r}\n" for k, (x, y, z) in enumerate(pts))
    )
    return path


def test_deviations_along_a_cylinder_segments_outward_normal(tmp_path):
    # actual points at radius 40 + e: the deviation is e (material left on an outer surface), the
    # normal radial outward, the nominal point at radius 40 — whatever the height field
    step = _cylinder(tmp_path / "cyl.step")
    th, z = np.meshgrid(np.radians(np.arange(6, 55, 4.0)), np.arange(6, 45, 4.0), indexing="ij")
    th, z = th.ravel(), z.ravel()
    e = 0.02 * np.sin(3 * th) * np.cos(z / 9)
    r = 40.0 + e
    m = measure.against_cad(_csv(tmp_path / "a.csv", np.column_stack([r * np.cos(th), r * np.sin(th), z])), step)
    np.testing.assert_allclose(m.deviation, e, atol=1e-7)
    np.testing.assert_allclose(m.normal, np.column_stack([np.cos(th), np.sin(th), 0 * th]), atol=1e-7)
    np.testing.assert_allclose(np.hypot(m.nominal[:, 0], m.nominal[:, 1]), 40.0, atol=1e-7)
    assert m.ids[0] == "P0" and m.lines[0] == 2


def test_analyze_with_a_cad_nominal(tmp_path):
    # a plane z = 5 and actual points with a smooth pattern plus noise: the JSON's deviation
    # statistics are those of the pattern (closed form), and a point 3 mm off is refused at its line
    step = _plane(tmp_path / "plate.step")
    x, y = np.meshgrid(np.arange(2.0, 59, 3), np.arange(2.0, 39, 3), indexing="ij")
    x, y = x.ravel(), y.ravel()
    e = 0.01 + 0.0003 * x + 0.001 * np.random.default_rng(1).normal(size=len(x))
    a = _csv(tmp_path / "a.csv", np.column_stack([x, y, 5.0 + e]))
    r = CliRunner().invoke(main, ["analyze", str(a), "--nominal", str(step), "--json", str(tmp_path / "a.json")])
    assert r.exit_code == 0, r.output
    j = json.loads((tmp_path / "a.json").read_text())
    assert j["deviation"]["mean"] == pytest.approx(e.mean(), abs=1e-9)
    assert j["deviation"]["rms"] == pytest.approx(np.sqrt((e * e).mean()), abs=1e-9)
    assert j["verdict"]["systematic"] is True
    pts = np.column_stack([x, y, 5.0 + e])
    pts[4, 2] = 8.0
    bad = _csv(tmp_path / "bad.csv", pts)
    r = CliRunner().invoke(main, ["analyze", str(bad), "--nominal", str(step)])
    assert r.exit_code == 2 and f"{bad}:6:" in r.output and "3 mm from the nearest face" in r.output, r.output
    r = CliRunner().invoke(main, ["analyze", str(a), "--nominal", str(step), "--face", "2"])
    assert r.exit_code == 2 and "faces 1 to 1" in r.output
    r = CliRunner().invoke(main, ["analyze", str(a), "--face", "1"])
    assert r.exit_code == 2 and "--face needs --nominal" in r.output
    (tmp_path / "m.csv").write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="header must name x,y,z"):
        measure.read_actuals(tmp_path / "m.csv")
