"""RPS / 3-2-1 alignment on datum features (plane, line, circle, cylinder, sphere) and over-determined
datums. The truths are independent of the solver: the rigid transform the test applies (scipy's
``Rotation.from_rotvec``), points generated on known elements, the closed-form circumcircle of
three points, and scipy's ``least_squares`` on the geometric distances for noisy fits."""

from __future__ import annotations

import doctest
import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import InputError, measure
from ncadapt.cli import main
from ncadapt.measure import _fit

Rotation = pytest.importorskip("scipy.spatial.transform").Rotation
least_squares = pytest.importorskip("scipy.optimize").least_squares

NOISE = 0.005  # 5 µm standard deviation per coordinate, the figure
# the transform from the measurement's frame to the CAD frame: 0.2° about a skew axis and 0.5 mm
# along a skew direction
AXIS = np.array([1.0, -2.0, 0.7]) / np.linalg.norm([1.0, -2.0, 0.7])
R_TRUE = Rotation.from_rotvec(np.radians(0.2) * AXIS).as_matrix()
T_TRUE = 0.5 * np.array([0.6, -0.48, 0.64]) / np.linalg.norm([0.6, -0.48, 0.64])
L, W, H = 200.0, 150.0, 100.0  # the box, mm


def _to_measurement(q):
    """CAD points q in the measurement's frame: m = Rᵀ (q − t), so that R m + t = q."""
    return (np.asarray(q) - T_TRUE) @ R_TRUE


def _grid(a0, a1, b0, b1, n):
    a, b = np.meshgrid(np.linspace(a0, a1, n), np.linspace(b0, b1, n), indexing="ij")
    return a.ravel(), b.ravel()


def _errors(a):
    """The alignment's translation error (largest component, mm) and rotation error (the angle of
    R_est R_trueᵀ, rad)."""
    rot = Rotation.from_matrix(a.matrix[:3, :3] @ R_TRUE.T).as_rotvec()
    return float(np.abs(a.translation - T_TRUE).max()), float(np.linalg.norm(rot))


def _box_features(n, k, seed=0):
    """CAD-frame points: n × n on the bottom (z = 0), front (y = 0) and left (x = 0) faces of the box,
    k on a tooling ball (centre (220, 75, 30), radius 10, upper half) and k in a hole (axis
    x = 100, y = 75 along z, radius 8, z 60 … 95)."""
    a, b = _grid(20, 180, 20, 130, n)
    bottom = np.column_stack([a, b, 0 * a])
    a, b = _grid(20, 180, 10, 90, n)
    front = np.column_stack([a, 0 * a, b])
    a, b = _grid(20, 130, 10, 90, n)
    left = np.column_stack([0 * a, a, b])
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(k, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    u[:, 2] = np.abs(u[:, 2])
    ball = np.array([220.0, 75.0, 30.0]) + 10 * u
    th, z = rng.uniform(0, 2 * np.pi, k), rng.uniform(60, 95, k)
    hole = np.column_stack([100 + 8 * np.cos(th), 75 + 8 * np.sin(th), z])
    return bottom, front, left, ball, hole


def _fmt(v):
    return "[" + ", ".join(repr(float(c)) for c in v) + "]"


def _table(name, feature, nominal, measured, **keys):
    """One [[datum]] table; ``measured`` a list of ids or an (n, 3) array."""
    if isinstance(measured, list):
        mtext = "[" + ", ".join(f'"{s}"' for s in measured) + "]"
    else:
        mtext = "[" + ", ".join(_fmt(p) for p in measured) + "]"
    text = f'\n[[datum]]\nname = "{name}"\nfeature = "{feature}"\nnominal = {_fmt(nominal)}\nmeasured = {mtext}\n'
    for k, v in keys.items():
        text += f"{k} = {v!r}\n" if isinstance(v, (str, int, float)) else f"{k} = {_fmt(v)}\n"
    return text


def _features_toml(path, bottom, front, left, ball, hole, top=""):
    text = top
    text += _table("A", "plane", (0, 0, 0), bottom, normal=(0, 0, -1.0))
    text += _table("B", "plane", (0, 0, 0), front, normal=(0, -1.0, 0))
    text += _table("C", "plane", (0, 0, 0), left, normal=(-1.0, 0, 0))
    text += _table("S", "sphere", (220, 75, 30), ball, radius=10.0)
    text += _table("H", "cylinder", (100, 75, 0), hole, axis=(0, 0, 1.0), radius=8.0)
    path.write_text(text)
    return path


# ------------------------------------------------------------------------------------ the fits
def _circumcircle(a, b, c):
    """The circle through three points (closed form): centre a + ((|u|² v − |v|² u) × w) … with
    u = b − a, v = c − a, w = u × v; radius |u| |v| |u − v| / (2 |w|)."""
    u, v = b - a, c - a
    w = np.cross(u, v)
    centre = a + np.cross(u @ u * v - v @ v * u, w) / (2 * w @ w)
    return centre, np.linalg.norm(u) * np.linalg.norm(v) * np.linalg.norm(u - v) / (2 * np.linalg.norm(w))


def test_a_circle_through_three_points_is_the_circumcircle():
    rng = np.random.default_rng(1)
    for _ in range(20):
        p = rng.uniform(-50, 50, size=(3, 3))
        centre, radius = _circumcircle(*p)
        f = measure.fit_feature("circle", p)
        np.testing.assert_allclose(f.centre, centre, atol=1e-9)
        assert f.radius == pytest.approx(radius, abs=1e-9) and f.form_max < 1e-9
        assert abs(f.direction @ np.cross(p[1] - p[0], p[2] - p[0])) == pytest.approx(
            np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]))
        )


def _frame(n):
    e1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def test_a_noisy_circle_is_scipys_least_squares_circle_in_the_fitted_plane():
    # 40 points on a 120° arc of radius 12 in a tilted plane, 5 µm noise: the centre and radius are
    # those scipy's least_squares finds minimising Σ (|q − q0| − r)² in the least-squares plane
    # (the plane: numpy's SVD of the centred points)
    rng = np.random.default_rng(2)
    n = np.array([0.2, -0.3, 1.0]) / np.linalg.norm([0.2, -0.3, 1.0])
    e1, e2 = _frame(n)
    th = rng.uniform(0, 2 * np.pi / 3, 40)
    p = np.array([5.0, -7.0, 3.0]) + 12 * (np.outer(np.cos(th), e1) + np.outer(np.sin(th), e2))
    p += rng.normal(scale=NOISE, size=p.shape)
    c = p.mean(axis=0)
    pn = np.linalg.svd(p - c)[2][2]
    f1, f2 = _frame(pn)
    q = np.column_stack([(p - c) @ f1, (p - c) @ f2])
    ref = least_squares(lambda x: np.hypot(*(q - x[:2]).T) - x[2], [0, 0, 1], xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    f = measure.fit_feature("circle", p)
    np.testing.assert_allclose(f.centre, c + ref[0] * f1 + ref[1] * f2, atol=1e-7)
    assert f.radius == pytest.approx(ref[2], abs=1e-7)
    assert f.form_rms == pytest.approx(NOISE, rel=0.4)


def test_a_sphere_and_a_cylinder_on_known_elements_and_against_scipy():
    rng = np.random.default_rng(3)
    # exact points on a sphere of centre (1, 2, 3), radius 7 and a cylinder through (3, 4, 5) along
    # a skew axis, radius 12: the fit returns them to round-off
    u = rng.normal(size=(30, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    s = measure.fit_feature("sphere", np.array([1.0, 2.0, 3.0]) + 7 * u)
    np.testing.assert_allclose(s.centre, [1, 2, 3], atol=1e-9)
    assert s.radius == pytest.approx(7, abs=1e-9)
    a = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    e1, e2 = _frame(a)
    th, z = rng.uniform(0, 2 * np.pi, 60), rng.uniform(-20, 20, 60)
    x0 = np.array([3.0, 4.0, 5.0])
    p = x0 + 12 * (np.outer(np.cos(th), e1) + np.outer(np.sin(th), e2)) + np.outer(z, a)
    c = measure.fit_feature("cylinder", p)
    assert c.radius == pytest.approx(12, abs=1e-9) and abs(c.direction @ a) == pytest.approx(1, abs=1e-12)
    off = (c.centre - x0) - ((c.centre - x0) @ a) * a  # the fitted axis point is on the true axis
    assert np.linalg.norm(off) < 1e-9
    assert c.centre @ a - x0 @ a == pytest.approx(z.mean(), abs=1e-9)  # … at the points' mid-height
    # with 5 µm noise: scipy's least_squares on the geometric distances, from the truth
    pn = p + rng.normal(scale=NOISE, size=p.shape)

    def dist(x):
        d = np.array([np.cos(x[4]) * np.sin(x[3]), np.sin(x[4]) * np.sin(x[3]), np.cos(x[3])])
        return np.linalg.norm(np.cross(pn - x[:3], d), axis=1) - x[5]

    start = [*x0, np.arccos(a[2]), np.arctan2(a[1], a[0]), 12.0]
    ref = least_squares(dist, start, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    d = np.array([np.cos(ref.x[4]) * np.sin(ref.x[3]), np.sin(ref.x[4]) * np.sin(ref.x[3]), np.cos(ref.x[3])])
    c = measure.fit_feature("cylinder", pn)
    assert c.radius == pytest.approx(ref.x[5], abs=1e-7)
    assert np.linalg.norm(np.cross(c.direction, d)) < 1e-8
    off = (c.centre - ref.x[:3]) - ((c.centre - ref.x[:3]) @ d) * d
    assert np.linalg.norm(off) < 1e-7
    assert np.sqrt(np.mean(c.residuals**2)) == pytest.approx(np.sqrt(np.mean(ref.fun**2)), rel=1e-6)
    us = np.array([1.0, 2.0, 3.0]) + 7 * u + rng.normal(scale=NOISE, size=u.shape)
    ref = least_squares(lambda x: np.linalg.norm(us - x[:3], axis=1) - x[3], [1, 2, 3, 7], xtol=1e-15, ftol=1e-15)
    s = measure.fit_feature("sphere", us)
    np.testing.assert_allclose(s.centre, ref.x[:3], atol=1e-8)
    assert s.radius == pytest.approx(ref.x[3], abs=1e-8)


@pytest.mark.parametrize(
    ("kind", "points", "message"),
    [
        ("plane", [[0, 0, 0], [1, 1, 1], [3, 3, 3]], "lie on one line"),
        ("plane", [[0, 0, 0], [1, 1, 1]], "a plane needs at least 3 points, got 2"),
        ("line", [[1, 2, 3], [1, 2, 3]], "coincide"),
        ("circle", [[0, 0, 0], [1, 0, 0], [2, 0, 0]], "lie on one line"),
        ("sphere", [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [3, 2, 0]], "lie in one plane"),
        # one ring of points across the axis: the axis's tilt is not fixed
        ("cylinder", [[8 * np.cos(t), 8 * np.sin(t), 0] for t in np.linspace(0, 6, 12)], "do not determine the cyl"),
        ("cone", [[0, 0, 0]] * 5, "a feature is one of"),
    ],
)
def test_fits_that_are_refused(kind, points, message):
    with pytest.raises(InputError, match=message):
        measure.fit_feature(kind, points)


# ------------------------------------------------------------------------- 3-2-1 on features
def test_plane_line_point_gives_the_exact_transform(tmp_path):
    # primary: the bottom plane (16 points); secondary: a line on the front face at z = 50 (5
    # points); tertiary: a point on the left face. Six equations for six unknowns, no noise: the
    # transform comes back to round-off, and each datum's residual is 0
    a, b = _grid(20, 180, 20, 130, 4)
    bottom = np.column_stack([a, b, 0 * a])
    x = np.linspace(20, 180, 5)
    line = np.column_stack([x, 0 * x, np.full(5, 50.0)])
    text = _table("A", "plane", (0, 0, 0), _to_measurement(bottom), normal=(0, 0, -1.0))
    text += _table("B", "line", (0, 0, 50.0), _to_measurement(line), axis=(1.0, 0, 0), constrains="y")
    text += (
        f'\n[[datum]]\nname = "C"\nnominal = [0.0, 75.0, 50.0]\n'
        f'measured = {_fmt(_to_measurement([[0.0, 70.0, 52.0]])[0])}\nconstrains = "x"\n'
    )
    path = tmp_path / "d.toml"
    path.write_text(text)
    d = measure.read_datums(path)
    assert [(x.name, x.feature, x.constraints, x.line) for x in d] == [
        ("A", "plane", 3, 2),
        ("B", "line", 2, 9),
        ("C", "point", 1, 17),
    ]
    al = measure.align_datums(d, source=str(path))
    t_err, r_err = _errors(al)
    assert t_err < 1e-9 and r_err < 1e-12 and al.points == 6 and al.rms < 1e-9
    assert [r.name for r in al.datums] == ["A", "B", "C"] and max(r.residual for r in al.datums) < 1e-9
    assert al.datums[0].points == 16 and al.datums[0].form_max < 1e-9
    np.testing.assert_allclose(al.apply(_to_measurement(bottom)), bottom, atol=1e-9)


def test_over_determined_features_recover_the_transform_with_5um_noise(tmp_path):
    # three planes of the box (1600 points each), a tooling ball and a hole (800 points each): 14
    # equations for 6 unknowns, 5 µm Gaussian noise per coordinate (seed 0). The weighted least
    # squares returns the transform within 1 µm and 1e-5 rad (the target); over seeds 0–19
    # the largest errors were 0.82 µm and 8.7e-6 rad. Each datum's residual is the noise's trace
    # (below 2 µm), the fits' form RMS the noise's standard deviation
    feats = _box_features(40, 800)
    rng = np.random.default_rng(0)
    noisy = [_to_measurement(q) + rng.normal(scale=NOISE, size=q.shape) for q in feats]
    path = _features_toml(tmp_path / "d.toml", *noisy)
    al = measure.align_datums(measure.read_datums(path), source=str(path))
    t_err, r_err = _errors(al)
    assert t_err < 1e-3 and r_err < 1e-5, (t_err, r_err)
    assert al.points == 14 and al.dof == measure.DOF
    res = {r.name: r for r in al.datums}
    assert list(res) == ["A", "B", "C", "S", "H"] and all(r.residual < 2e-3 for r in res.values())
    for r in res.values():
        assert r.form_rms == pytest.approx(NOISE, rel=0.1)
    assert res["S"].radius == pytest.approx(10, abs=2e-3) and res["S"].radius_nominal == 10
    assert res["H"].radius == pytest.approx(8, abs=2e-3)
    # the reported uncertainty covers the error
    assert np.all(al.std[:3] > 0) and t_err < 5 * al.std[:3].max()


def test_a_contradicting_datum_is_refused_by_name(tmp_path):
    # the tooling ball measured 0.2 mm off in y (a ball moved on its holder): the others agree, the
    # ball does not — refused at its table's line, naming it. The least squares shares the 0.2 mm
    # between the ball and the front plane that also fixes y (and tilts): the plane is left
    # farther off than the ball, so the largest residual would blame the wrong datum; leaving each
    # out in turn finds the one without which the others agree
    feats = list(_box_features(10, 60))
    feats[3] = feats[3] + [0.0, 0.2, 0.0]
    path = _features_toml(tmp_path / "d.toml", *(_to_measurement(q) for q in feats))
    with pytest.raises(InputError, match=r"datum 'S' contradicts the others \(without it they agree within") as e:
        measure.align_datums(measure.read_datums(path), source=str(path))
    assert e.value.line == measure.read_datums(path)[3].line
    assert re.search(
        r"leaves 'B' 0\.075\d* mm \(tolerance 0\.05\), 'S' 0\.073\d* mm \(tolerance 0\.05\)", e.value.message
    )
    # its own wider tolerance is not enough: it still pulls the front plane off
    text = path.read_text().replace("radius = 10.0\n", "radius = 10.0\ntolerance = 0.5\n")
    path.write_text(text)
    with pytest.raises(InputError, match=r"datum 'S' contradicts the others"):
        measure.align_datums(measure.read_datums(path))
    # … with a small weight as well the others hold the frame and the ball's residual says how
    # far it is (0.2 mm, less the little it pulls)
    path.write_text(text.replace("tolerance = 0.5\n", "tolerance = 0.5\nweight = 1e-6\n"))
    al = measure.align_datums(measure.read_datums(path))
    assert al.datums[3].residual == pytest.approx(0.2, abs=1e-4) and al.datums[1].residual < 1e-4
    # a file-wide tolerance of 1 µm refuses the noise-free datums? No: they are exact to round-off
    clean = _features_toml(
        tmp_path / "c.toml", *(_to_measurement(q) for q in _box_features(10, 60)), "tolerance = 1e-6\n"
    )
    t_err, r_err = _errors(measure.align_datums(measure.read_datums(clean)))
    assert t_err < 1e-9 and r_err < 1e-12


def test_weights_pull_the_solution_towards_the_heavier_datum(tmp_path):
    # two contradicting datums along x (a plane x = 0 and a sphere 0.01 mm off in x): the least
    # squares puts x where the weights say — the weighted mean of the two positions (closed form
    # for two equations in one unknown: x = (w₁·0 + w₂·0.01) / (w₁ + w₂))
    feats = _box_features(10, 60)
    ball = feats[3] + [0.01, 0.0, 0.0]
    text = _table("A", "plane", (0, 0, 0), feats[0], normal=(0, 0, 1.0))
    text += _table("B", "plane", (0, 0, 0), feats[1], normal=(0, 1.0, 0))
    text += _table("C", "plane", (0, 0, 0), feats[2], normal=(1.0, 0, 0), weight=3.0)
    text += _table("S", "sphere", (220, 75, 30), ball, constrains="x")
    path = tmp_path / "d.toml"
    path.write_text(text)
    al = measure.align_datums(measure.read_datums(path), dof="x")
    assert al.translation[0] == pytest.approx(-(1 * 0.01) / (3 + 1), abs=1e-12)
    assert al.points == 10 and al.datums[3].residual == pytest.approx(0.01 * 3 / 4, abs=1e-12)


def test_under_determined_features_name_the_free_degrees_of_freedom(tmp_path):
    a, b = _grid(20, 180, 20, 130, 4)
    x = np.linspace(20, 180, 5)
    text = _table("A", "plane", (0, 0, 0), np.column_stack([a, b, 0 * a]), normal=(0, 0, 1.0))
    text += _table("B", "line", (0, 0, 50), np.column_stack([x, 0 * x, 50 + 0 * x]), axis=(1.0, 0, 0), constrains="y")
    path = tmp_path / "d.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=r"5 constraints for 6 degrees of freedom .*do not determine x;"):
        measure.align_datums(measure.read_datums(path))
    # two parallel planes fix z, rx, ry twice over and nothing else
    text = _table("A", "plane", (0, 0, 0), np.column_stack([a, b, 0 * a]), normal=(0, 0, 1.0))
    text += _table("T", "plane", (0, 0, H), np.column_stack([a, b, H + 0 * a]), normal=(0, 0, 1.0))
    path.write_text(text)
    with pytest.raises(InputError, match=r"do not determine x, y, rz"):
        measure.align_datums(measure.read_datums(path))


def _plane_rows(n):
    return "[" + ", ".join(f"[{i}.0, {i * i % 7}.0, 0.0]" for i in range(n)) + "]"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            '# a plane\n\n[[datum]]\nname = "A"\nfeature = "plane"\nnominal = [0, 0, 0]\nnormal = [0, 0, 1]\n'
            'measured = ["P1", "P2"]\n',
            ":3: datum 'A': a plane needs at least 3 measured points, got 2",
        ),
        ('[[datum]]\nfeature = "plane"\nnominal = [0, 0, 0]\nmeasured = ["P1", "P2", "P3"]\n', "a plane needs normal"),
        (
            '[[datum]]\nfeature = "plane"\nnominal = [0, 0, 0]\nnormal = [0, 0, 1]\nmeasured = ["P1", "P2", "P3"]\n'
            'constrains = "z"\n',
            "a plane does not take constrains",
        ),
        (
            '[[datum]]\nfeature = "cone"\nnominal = [0, 0, 0]\nmeasured = ["P1"]\n',
            "feature must be one of point, plane",
        ),
        (
            '[[datum]]\nfeature = "line"\nnominal = [0, 0, 0]\naxis = [1, 0, 0]\nmeasured = ["P1", "P2"]\n'
            "direction = [0.6, 0.8, 0]\n",
            "must be square to its axis",
        ),
        (
            '[[datum]]\nfeature = "line"\nnominal = [0, 0, 0]\naxis = [1, 0, 0]\nmeasured = ["P1", "P2"]\n',
            "a line needs the one direction it fixes",
        ),
        (
            '[[datum]]\nfeature = "line"\nnominal = [0, 0, 0]\naxis = [1, 0, 0]\nmeasured = ["P1", "P2"]\n'
            'constrains = "yz"\n',
            "a line fixes one direction, got 2",
        ),
        (
            '[[datum]]\nfeature = "sphere"\nnominal = [0, 0, 0]\nmeasured = ["P1", "P2", "P3", "P1"]\n',
            "names point 'P1' twice",
        ),
        (
            '[[datum]]\nfeature = "sphere"\nnominal = [0, 0, 0]\nmeasured = ["P1", [0, 0, 0], "P3", "P4"]\n',
            "measured \\(a list of point ids or of \\[x, y, z\\]\\) must be",
        ),
        (
            '[[datum]]\nfeature = "circle"\nnominal = [0, 0, 0]\nnormal = [0, 0, 2]\nmeasured = ["P1", "P2", "P3"]\n',
            "normal must be a unit vector",
        ),
        (
            '[[datum]]\nnominal = [0, 0, 0]\nmeasured = "P1"\nconstrains = "z"\nweight = -1\n',
            "weight must be a positive",
        ),
        ("tolerance = 0\n[[datum]]\n", "tolerance \\(mm\\) must be a positive number"),
        (
            '[[datum]]\nnominal = [0, 0, 0]\nmeasured = "P1"\nconstrains = "z"\nradius = 3\n',
            "a point does not take radius",
        ),
    ],
)
def test_feature_datum_files_that_are_refused(tmp_path, text, message):
    (tmp_path / "d.toml").write_text(text)
    with pytest.raises(InputError, match=message):
        measure.read_datums(tmp_path / "d.toml")


def test_a_degenerate_feature_is_refused_at_its_line(tmp_path):
    # three plane points on one line (the file reads; the fit refuses, naming the datum and line)
    text = '# A\n\n[[datum]]\nname = "A"\nfeature = "plane"\nnominal = [0, 0, 0]\nnormal = [0, 0, 1]\n'
    text += "measured = [[0, 0, 0], [10, 10, 0], [20, 20, 0]]\n"
    (tmp_path / "d.toml").write_text(text)
    d = measure.read_datums(tmp_path / "d.toml")
    with pytest.raises(InputError, match=r"d.toml:3: datum 'A': the plane's points lie on one line"):
        measure.align_datums(d, source=str(tmp_path / "d.toml"))


# ------------------------------------------------------------------------------- the commands
def _csv(path, pts, ids):
    path.write_text("id,x,y,z\n" + "".join(f"{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in zip(ids, pts.tolist())))
    return path


def _box_step(path):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    w = STEPControl_Writer()
    w.Transfer(BRepPrimAPI_MakeBox(L, W, H).Shape(), STEPControl_AsIs)
    w.Write(str(path))
    return path


def test_compensate_with_feature_datums_reports_each_datum(tmp_path):
    # the box's three planes (6 × 6 points each) and the ball are datums named by id in ACTUALS;
    # the other rows are on the top face with a known form error e along +z. The alignment (12
    # equations, no noise) is exact, the datum rows are left out of the deviations (which are then
    # e exactly), and compensate --json's alignment lists each datum with its residual
    pytest.importorskip("OCP")
    step = _box_step(tmp_path / "box.step")
    bottom, front, left, ball, _ = _box_features(6, 12)
    x, y = _grid(10, 190, 10, 140, 12)
    e = 0.02 * np.sin(x / 30) * np.cos(y / 25)
    top = np.column_stack([x, y, H + e])
    groups = {"A": bottom, "B": front, "C": left, "S": ball}
    ids, pts = [], []
    for g, q in groups.items():
        ids += [f"{g}{k}" for k in range(len(q))]
        pts.append(q)
    ids += [f"P{k}" for k in range(len(top))]
    a = _csv(tmp_path / "a.csv", _to_measurement(np.vstack([*pts, top])), ids)
    text = _table("A", "plane", (0, 0, 0), [f"A{k}" for k in range(36)], normal=(0, 0, -1.0))
    text += _table("B", "plane", (0, 0, 0), [f"B{k}" for k in range(36)], normal=(0, -1.0, 0))
    text += _table("C", "plane", (0, 0, 0), [f"C{k}" for k in range(36)], normal=(-1.0, 0, 0))
    text += _table("S", "sphere", (220, 75, 30), [f"S{k}" for k in range(12)], radius=10.0)
    toml = tmp_path / "d.toml"
    toml.write_text(text)
    out = tmp_path / "c.json"
    args = ["--nominal", str(step), "--face", "6", "--align", "datums", "--datums", str(toml)]
    r = CliRunner().invoke(main, ["compensate", str(a), *args, "--json", str(out)])
    assert r.exit_code == 0, r.output
    assert "least squares: 12 constraints for 6 degrees of freedom" in r.output
    assert "datum S (sphere, 3): residual 0.0000 mm, 12 points" in r.output
    j = json.loads(out.read_text())["alignment"]
    R = np.array(j["matrix"])[:3, :3]
    assert np.abs(np.array(j["translation"]) - T_TRUE).max() < 1e-9
    assert np.linalg.norm(Rotation.from_matrix(R @ R_TRUE.T).as_rotvec()) < 1e-12
    assert len(j["rotation"]) == 3 and j["rms"] < 1e-9
    assert [(d["name"], d["feature"], d["constraints"], d["points"]) for d in j["datums"]] == [
        ("A", "plane", 3, 36),
        ("B", "plane", 3, 36),
        ("C", "plane", 3, 36),
        ("S", "sphere", 3, 12),
    ]
    assert all(d["residual_mm"] < 1e-9 for d in j["datums"]) and j["datums"][3]["radius_nominal_mm"] == 10
    meas = measure.against_cad(a, step, faces=[6], align="datums", datums=toml)
    np.testing.assert_allclose(meas.deviation, e, atol=1e-9)
    assert meas.ids[0] == "P0"
    # the ball moved 0.2 mm: refused (exit 2) at its table, nothing written
    a2 = _csv(tmp_path / "b.csv", _to_measurement(np.vstack([bottom, front, left, ball + [0, 0.2, 0], top])), ids)
    out2 = tmp_path / "c2.json"
    r = CliRunner().invoke(main, ["compensate", str(a2), *args, "--json", str(out2)])
    line = measure.read_datums(toml)[3].line
    assert (
        r.exit_code == 2 and f"{toml}:{line}:1: error: --align datums: datum 'S' contradicts the others" in r.output
    ), r.output
    assert not out2.exists()


def test_the_examples_run():
    assert doctest.testmod(_fit, optionflags=doctest.NORMALIZE_WHITESPACE).failed == 0


def test_the_sample_file_of_the_docs_reads(tmp_path):
    from pathlib import Path

    doc = (Path(__file__).resolve().parent.parent / "docs" / "freeform.md").read_text()
    block = doc.split("```toml\n# 3-2-1 on features")[1].split("```")[0]
    (tmp_path / "d.toml").write_text("# 3-2-1 on features" + block)
    d = measure.read_datums(tmp_path / "d.toml")
    assert [(x.name, x.feature, x.constraints) for x in d] == [
        ("A", "plane", 3),
        ("B", "line", 2),
        ("C", "point", 1),
        ("H", "cylinder", 2),
    ]
    assert [x.tolerance for x in d] == [0.02, 0.02, 0.02, 0.01] and d[3].weight == 2.0 and d[3].labels[0] == "H1"
