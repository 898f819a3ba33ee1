"""Correction fields against closed forms and scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from ncadapt import InputError, RefusedError, fields


def _grid(tmp_path, rows, name="g.csv"):
    p = tmp_path / name
    p.write_text("x,y,dz\n" + "\n".join(rows) + "\n")
    return p


def test_bilinear_equals_scipy_and_any_row_order(tmp_path):
    rng = np.random.default_rng(1)
    xs, ys = np.array([0.0, 1.0, 3.0, 7.0]), np.array([-2.0, 0.0, 5.0])
    dz = rng.normal(size=(3, 4)) * 0.01
    rows = [f"{x},{y},{float(dz[j, i])!r}" for j, y in enumerate(ys) for i, x in enumerate(xs)]
    rng.shuffle(rows)
    f = fields.read(_grid(tmp_path, rows))
    pts = np.column_stack([rng.uniform(0, 7, 500), rng.uniform(-2, 5, 500), rng.normal(size=500)])
    ref = RegularGridInterpolator((xs, ys), dz.T)(pts[:, :2])
    d = f(pts)
    np.testing.assert_allclose(d[:, 2], ref, rtol=0, atol=1e-15)
    assert (d[:, :2] == 0).all()


def test_bicubic_reproduces_a_cubic_polynomial(tmp_path):
    xs, ys = np.linspace(0, 10, 6), np.linspace(0, 8, 5)
    poly = lambda x, y: 1e-4 * (x**3 - 2 * x * y**2 + 3 * y**3) + 0.01  # noqa: E731
    X, Y = np.meshgrid(xs, ys)
    f = fields.GridField(xs, ys, poly(X, Y), method="cubic")
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(0, 10, 200), rng.uniform(0, 8, 200), np.zeros(200)])
    np.testing.assert_allclose(f(pts)[:, 2], poly(pts[:, 0], pts[:, 1]), atol=1e-12)


def test_outside_policies():
    f = fields.GridField([0, 10], [0, 10], [[0.0, 0.1], [0.2, 0.3]])
    pts = np.array([[5.0, 5.0, 0], [12.0, 5.0, 0], [-1.0, 11.0, 0]])
    with pytest.raises(fields.OutsideError) as e:
        f(pts)
    assert e.value.indices.tolist() == [1, 2]
    assert isinstance(e.value, RefusedError)
    clamp = fields.GridField([0, 10], [0, 10], [[0.0, 0.1], [0.2, 0.3]], outside="clamp")(pts)[:, 2]
    np.testing.assert_allclose(clamp, [0.15, 0.2, 0.2])  # (10, 5) and (0, 10)
    # the plane through the four corners: dz = 0.01 x + 0.02 y, continued outside
    ext = fields.GridField([0, 10], [0, 10], [[0.0, 0.1], [0.2, 0.3]], outside="extrapolate")(pts)[:, 2]
    np.testing.assert_allclose(ext, 0.01 * pts[:, 0] + 0.02 * pts[:, 1], atol=1e-15)
    with pytest.raises(ValueError, match='"outside" must be one of error, clamp, extrapolate'):
        fields.GridField([0, 1], [0, 1], np.zeros((2, 2)), outside="wrap")


@pytest.mark.parametrize(
    "rows, line, message",
    [
        (["0,0,0", "1,0,0", "0,1,nan", "1,1,0"], 4, "not finite"),
        (["0,0,0", "1,0,0", "0,1,abc", "1,1,0"], 4, "expected a number"),
        (["0,0,0", "1,0,0", "0,1,0"], 0, "not a rectangular grid: 1 of 4 points missing"),
        (["0,0,0", "1,0,0", "0,0,0.1", "0,1,0", "1,1,0"], 4, "duplicate grid point x=0 y=0 (first on line 2)"),
        (["0,0", "1,0,0"], 2, "expected 3 fields"),
    ],
)
def test_grid_csv_errors(tmp_path, rows, line, message):
    with pytest.raises(InputError) as e:
        fields.read(_grid(tmp_path, rows))
    assert message in e.value.message
    assert e.value.line == line


def test_missing_column(tmp_path):
    p = tmp_path / "g.csv"
    p.write_text("x,y,z\n0,0,0\n")
    with pytest.raises(InputError, match="missing column"):
        fields.read(p)


def test_scattered_thin_plate_reproduces_data_and_planes(tmp_path):
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 50, size=(40, 2))
    plane = lambda x, y: 0.002 * x - 0.001 * y + 0.05  # noqa: E731
    rows = ["x,y,z,dx,dy,dz"] + [f"{float(x)!r},{float(y)!r},0,0.001,0,{float(plane(x, y))!r}" for x, y in xy]
    p = tmp_path / "s.csv"
    p.write_text("\n".join(rows) + "\n")
    f = fields.read(p)
    assert isinstance(f, fields.ScatteredField)
    pts = np.column_stack([xy, np.zeros(40)])
    np.testing.assert_allclose(f(pts)[:, 2], plane(xy[:, 0], xy[:, 1]), atol=1e-9)
    # a thin-plate spline reproduces planes exactly everywhere inside the hull
    c = np.array([[xy[:, 0].mean(), xy[:, 1].mean(), 0.0]])
    assert f(c)[0, 2] == pytest.approx(plane(c[0, 0], c[0, 1]), abs=1e-9)
    assert f(c)[0, 0] == pytest.approx(0.001, abs=1e-12)
    with pytest.raises(fields.OutsideError):
        f(np.array([[-10.0, -10.0, 0.0]]))


def test_bcnc_probe_file(tmp_path):
    # written the way bCNC's Probe.save writes it: three header lines, blank lines, "x y z" rows
    p = tmp_path / "map.probe"
    rows = ["0 20 3", "0 10 2", "-0.1 0.1 100", "", ""]
    for j, y in enumerate((0, 10)):
        for i, x in enumerate((0, 10, 20)):
            rows.append(f"{x:g} {y:g} {0.01 * i + 0.02 * j:g}")
        rows.append("")
    p.write_text("\n".join(rows))
    f = fields.read(p)
    assert isinstance(f, fields.GridField)
    assert f(np.array([[15.0, 5.0, 0]]))[0, 2] == pytest.approx(0.015 + 0.01)


def test_linuxcnc_probe_log(tmp_path):
    # (PROBEOPEN) logs: one line per G38 trip point, X Y Z A B C U V W
    p = tmp_path / "probe.txt"
    lines = []
    for y in (0.0, 5.0):
        for x in (0.0, 5.0, 10.0):
            lines.append(" ".join(f"{v:.6f}" for v in (x, y, 0.001 * x + 0.002 * y, 0, 0, 0, 0, 0, 0)))
    p.write_text("\n".join(lines) + "\n")
    f = fields.read(p)
    assert isinstance(f, fields.GridField)
    assert f(np.array([[2.5, 2.5, -1]]))[0, 2] == pytest.approx(0.0025 + 0.005)
