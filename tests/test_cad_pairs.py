"""Files with nominal points of their own given with a CAD nominal (``--nominal``): the actual points are
projected onto the CAD as those of an actual-only file, and the file's nominals must lie on the CAD.

The parts are built here by OpenCASCADE: a sixth of a cylinder (R 40 mm, 50 mm high) and a plate
63.5 × 38.1 × 25.4 mm. On the cylinder the file's nominal of a point at angle θ and height z is
(40 cos θ, 40 sin θ, z), its normal the radial (cos θ, sin θ, 0), its actual point 40 + e along it:
the deviation along the CAD's outward normal is e exactly (closed form), the nominal's distance to
the face 0, and a nominal moved 0.5 mm along its normal is 0.5 mm off the face."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import InputError, measure
from ncadapt.cli import main

pytest.importorskip("OCP")

R = 40.0


def _write_step(shape, path: Path) -> Path:
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    w = STEPControl_Writer()
    w.Transfer(shape, STEPControl_AsIs)
    w.Write(str(path))
    return path


@pytest.fixture(scope="module")
def cylinder(tmp_path_factory):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    shape = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), R, 50.0, math.radians(60)).Shape()
    return _write_step(shape, tmp_path_factory.mktemp("cyl") / "cyl.step")


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    return _write_step(BRepPrimAPI_MakeBox(63.5, 38.1, 25.4).Shape(), tmp_path_factory.mktemp("plate") / "plate.step")


def _on_cylinder():
    """Nominal points on the cylinder's side, their radial normals and offsets e (mm)."""
    th, z = np.meshgrid(np.radians(np.arange(8, 53, 6.0)), np.arange(8, 43, 7.0), indexing="ij")
    th, z = th.ravel(), z.ravel()
    n = np.column_stack([np.cos(th), np.sin(th), 0 * th])
    e = 0.03 * np.sin(th * 5) + 0.0004 * (z - 25)
    return np.column_stack([R * n[:, :2], z]), n, e


def _csv(path: Path, header: str, rows) -> Path:
    path.write_text(header + "\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in rows))
    return path


def _analyze(tmp_path, path, step, *extra):
    out = tmp_path / f"{path.stem}.json"
    r = CliRunner().invoke(main, ["analyze", str(path), "--nominal", str(step), "--json", str(out), *extra])
    return r, (json.loads(out.read_text()) if out.exists() else None)


def test_paired_csv_gives_the_deviations_of_its_actual_points(cylinder, tmp_path):
    p, n, e = _on_cylinder()
    m = p + e[:, None] * n
    pairs = _csv(tmp_path / "pairs.csv", "x,y,z,i,j,k,mx,my,mz", np.column_stack([p, n, m]))
    actuals = _csv(tmp_path / "actuals.csv", "x,y,z", m)
    with_pairs = measure.project_on_cad(pairs, cylinder, faces=[1])
    alone = measure.against_cad(actuals, cylinder, faces=[1])
    np.testing.assert_allclose(with_pairs.measurements.deviation, alone.deviation, atol=1e-12)
    np.testing.assert_allclose(with_pairs.measurements.deviation, e, atol=1e-9)
    np.testing.assert_allclose(with_pairs.measurements.measured, m, atol=1e-12)
    assert with_pairs.file_nominals["points"] == len(e)
    assert with_pairs.file_nominals["max_distance"] < 1e-9
    assert with_pairs.file_nominals["from_deviation"] is False
    r, j = _analyze(tmp_path, pairs, cylinder)
    assert r.exit_code == 0, r.output
    assert j["deviation"]["rms"] == pytest.approx(np.sqrt(np.mean(e**2)), abs=1e-9)
    assert j["file_nominals"]["points"] == len(e) and j["file_nominals"]["max_distance"] < 1e-9
    assert f"its {len(e)} nominals checked against the CAD" in r.output
    r, j = _analyze(tmp_path, actuals, cylinder)
    assert r.exit_code == 0 and "file_nominals" not in j


def test_deviations_along_the_file_normals_give_nominal_plus_deviation(cylinder, tmp_path):
    p, n, e = _on_cylinder()
    path = _csv(tmp_path / "dev.csv", "x,y,z,i,j,k,dev", np.column_stack([p, n, e]))
    a = measure.read_actuals(path)
    assert a.from_deviation
    np.testing.assert_allclose(a.points, p + e[:, None] * n, atol=1e-12)
    r, j = _analyze(tmp_path, path, cylinder)
    assert r.exit_code == 0, r.output
    assert j["deviation"]["mean"] == pytest.approx(e.mean(), abs=1e-9)
    assert j["file_nominals"]["from_deviation"] is True
    assert "the actual points are the file's nominals + deviation x normal" in r.output
    # XYZIJK text (x y z i j k mx my mz) is read the same way
    xyz = tmp_path / "pairs.txt"
    xyz.write_text(
        "".join(" ".join(f"{v:.12f}" for v in row) + "\n" for row in np.column_stack([p, n, p + e[:, None] * n]))
    )
    np.testing.assert_allclose(measure.against_cad(xyz, cylinder, faces=[1]).deviation, e, atol=1e-9)


def test_a_nominal_off_the_cad_is_refused_with_its_line(cylinder, tmp_path):
    p, n, e = _on_cylinder()
    m = p + e[:, None] * n
    off = p.copy()
    off[4] += 0.5 * n[4]  # 0.5 mm out along the normal: 0.5 mm off the face
    path = _csv(tmp_path / "off.csv", "x,y,z,i,j,k,mx,my,mz", np.column_stack([off, n, m]))
    r, j = _analyze(tmp_path, path, cylinder, "--max-distance", "0.3")
    assert r.exit_code == 2 and j is None, r.output
    assert f"{path}:6:" in r.output, r.output
    assert "the file's nominal point is 0.5 mm off the CAD: another frame or another part?" in r.output
    # within --max-distance it is accepted, and the largest distance is reported: 0.5 mm, line 6
    r, j = _analyze(tmp_path, path, cylinder)
    assert r.exit_code == 0, r.output
    assert j["file_nominals"]["max_distance"] == pytest.approx(0.5, abs=1e-9)
    assert j["file_nominals"]["line"] == 6
    np.testing.assert_allclose(measure.against_cad(path, cylinder).deviation, e, atol=1e-9)  # the actuals decide


def test_a_paired_csv_missing_its_normals_is_refused(cylinder, tmp_path):
    # x,y,z with dev but no normals: neither actual points nor a paired file
    p, _, e = _on_cylinder()
    path = _csv(tmp_path / "bad.csv", "x,y,z,dev", np.column_stack([p, e]))
    with pytest.raises(InputError, match="header must name x,y,z,i,j,k and mx,my,mz or dev") as err:
        measure.read_actuals(path)
    assert err.value.line == 1


def _plate_points():
    """Points on the plate's top (z = 25.4), side (x = 63.5) and front (y = 0) faces (mm) and their
    outward normals."""
    top = [[x, y, 25.4] for x in (8.0, 31.0, 55.0) for y in (6.0, 19.0, 32.0)]
    side = [[63.5, y, z] for y in (6.0, 32.0) for z in (5.0, 20.0)]
    front = [[x, 0.0, z] for x in (8.0, 55.0) for z in (5.0, 20.0)]
    p = np.array(top + side + front)
    n = np.array([[0, 0, 1]] * 9 + [[1, 0, 0]] * 4 + [[0, -1, 0]] * 4, float)
    return p, n


def test_the_file_nominals_are_checked_after_the_alignment(plate, tmp_path):
    from scipy.spatial.transform import Rotation

    p, n = _plate_points()
    # the actual points 0.05 mm out of their nominals along the normals everywhere: the best fit
    # takes them back onto the faces by the true transform then 0.05 mm along each face's normal
    # (-x, +y, -z, a rigid motion since the three faces are orthogonal), so the aligned actuals
    # lie on the faces (deviation 0) and every aligned nominal is 0.05 mm inside its face
    m = p + 0.05 * n
    # the file is in the measuring machine's frame: CAD point = rot(file point) + t
    rot = Rotation.from_euler("xyz", [0.1, -0.05, 0.2], degrees=True)
    t = np.array([0.6, -0.4, 0.3])
    to_file = lambda q: rot.inv().apply(q - t)  # noqa: E731
    path = _csv(
        tmp_path / "machine.csv", "x,y,z,i,j,k,mx,my,mz", np.column_stack([to_file(p), rot.inv().apply(n), to_file(m)])
    )
    # without the alignment the file's nominals are off the CAD: another frame
    r, _ = _analyze(tmp_path, path, plate, "--max-distance", "0.3")
    assert r.exit_code == 2 and "off the CAD: another frame or another part?" in r.output, r.output
    proj = measure.project_on_cad(path, plate, align="bestfit", max_distance=0.3)
    np.testing.assert_allclose(proj.measurements.deviation, 0.0, atol=1e-6)
    np.testing.assert_allclose(proj.measurements.alignment.translation, t + [-0.05, 0.05, -0.05], atol=1e-6)
    assert proj.file_nominals["points"] == len(p)
    assert proj.file_nominals["max_distance"] == pytest.approx(0.05, abs=1e-6)
    r, j = _analyze(tmp_path, path, plate, "--max-distance", "0.3", "--align", "bestfit")
    assert r.exit_code == 0, r.output
    assert j["file_nominals"]["max_distance"] == pytest.approx(0.05, abs=1e-6)
    # a stricter --max-distance refuses them: the file's nominals are 0.05 mm off after the alignment
    with pytest.raises(InputError, match="nominal point is 0.05 mm off the CAD after the alignment"):
        measure.project_on_cad(path, plate, align="bestfit", max_distance=0.04)


def test_compensate_with_a_paired_file_is_the_actual_only_run(cylinder, tmp_path):
    th, z = np.meshgrid(np.radians(np.linspace(5, 55, 18)), np.linspace(6, 44, 12), indexing="ij")
    th, z = th.ravel(), z.ravel()
    n = np.column_stack([np.cos(th), np.sin(th), 0 * th])
    p = np.column_stack([R * n[:, :2], z])
    e = 0.02 + 0.01 * np.sin(3 * th) * np.cos(z / 15)
    m = p + e[:, None] * n
    runs = {}
    for name, header, rows in (
        ("pairs", "x,y,z,i,j,k,mx,my,mz", np.column_stack([p, n, m])),
        ("actuals", "x,y,z", m),
    ):
        path = _csv(tmp_path / f"{name}.csv", header, rows)
        js = tmp_path / f"{name}.json"
        r = CliRunner().invoke(
            main, ["compensate", str(path), "--nominal", str(cylinder), "--face", "1", "--json", str(js)]
        )
        assert r.exit_code == 0, r.output
        runs[name] = json.loads(js.read_text())
    a, b = runs["pairs"], runs["actuals"]
    assert a["deviation"] == b["deviation"] and a["by_face"] == b["by_face"]
    assert a["deviation"]["mean"] == pytest.approx(e.mean(), abs=1e-9)
    assert a["file_nominals"]["points"] == len(e) and a["file_nominals"]["max_distance"] < 1e-9
    assert "file_nominals" not in b
