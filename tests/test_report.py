"""The freeform report made for review before cutting: the correction map and its extrapolated strip,
tolerance bands, callouts, sections, one histogram binning, the 3-D view drawn by a real browser.

The part: a measured grid (x 0…60, y 0…40 mm every 2 mm) on the bowl z = 1 + 0.002 (x − 30)² +
0.001 (y − 20)² with its exact normals; the deviation along them is a known smooth field plus seeded
3 µm noise. Every figure the report states is recomputed here from the input file, the
``--points-out`` CSV (the systematic part as the decomposition wrote it) or numpy, not read from the
report's own code."""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner
from lxml import html as lhtml

from ncadapt.cli import main
from ncadapt.report import freeform as rep

XS, YS = np.arange(0, 61, 2.0), np.arange(0, 41, 2.0)
TOL = 0.012  # mm


def _part(seed=7):
    X, Y = np.meshgrid(XS, YS, indexing="ij")
    x, y = X.ravel(), Y.ravel()
    z = 1 + 0.002 * (x - 30) ** 2 + 0.001 * (y - 20) ** 2
    n = np.column_stack([-0.004 * (x - 30), -0.002 * (y - 20), np.ones_like(x)])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    dev = 0.02 * np.sin(x / 12) * np.cos(y / 9) + 0.004 + np.random.default_rng(seed).normal(0, 0.003, len(x))
    return np.column_stack([x, y, z]), n, dev


def _write(tmp_path):
    p, n, dev = _part()
    f = tmp_path / "m.csv"
    f.write_text(
        "x,y,z,i,j,k,dev\n" + "".join(",".join(f"{v:.9f}" for v in (*a, *b, e)) + "\n" for a, b, e in zip(p, n, dev))
    )
    return f, p, n, np.array([float(f"{e:.9f}") for e in dev])


def _rows(doc, div_id):
    """The text of a table's cells, row by row, under the element ``div_id``."""
    el = doc.get_element_by_id(div_id)
    return [[c.text_content().strip() for c in tr.xpath("./td|./th")] for tr in el.iter("tr")]


def _num(s):
    return float(s.replace("−", "-").replace("+", ""))


@pytest.fixture(scope="module")
def grid_run(tmp_path_factory):
    """compensate on the measured grid: the surface grid is the measured one (no strip)."""
    tmp = tmp_path_factory.mktemp("grid")
    m, p, n, dev = _write(tmp)
    args = ["compensate", m, "--tolerance", TOL, "--section", "x=30", "--section", "y=21"]
    args += ["--report", tmp / "r.html", "--json", tmp / "r.json", "--points-out", tmp / "p.csv"]
    r = CliRunner().invoke(main, [str(a) for a in args])
    assert r.exit_code == 0, r.output
    pts = np.loadtxt(tmp / "p.csv", delimiter=",", skiprows=1)
    text = (tmp / "r.html").read_text()
    return {
        "dir": tmp,
        "p": p,
        "n": n,
        "dev": dev,
        "out": pts,
        "html": text,
        "doc": lhtml.fromstring(text),
        "stdout": r.output,
    }


def test_tolerance_shares_are_the_points_in_and_out(grid_run):
    g = grid_run
    dev, sysv = g["dev"], g["out"][:, 4]
    rows = {r[0]: r for r in _rows(g["doc"], "tolerance")[1:]}
    for name, v in (("measured", dev), ("predicted after (measured − systematic)", dev - sysv)):
        r = rows[name]
        inside = 100 * np.count_nonzero(np.abs(v) <= TOL) / len(v)
        above = 100 * np.count_nonzero(v > TOL) / len(v)
        below = 100 * np.count_nonzero(v < -TOL) / len(v)
        assert int(r[1]) == len(v) == len(XS) * len(YS)
        for got, want in zip(r[2:6], (inside, 100 - inside, above, below)):
            assert abs(_num(got) - want) <= 0.05 + 1e-9, (name, r, want)
        assert abs(_num(r[6]) - 1000 * np.abs(v).max()) <= 0.05 + 1e-9
    # both before and after are in the map's problem: the measurement is mostly out, the prediction in
    assert _num(rows["measured"][2]) < 70 < _num(rows["predicted after (measured − systematic)"][2])
    # the JSON and the summary say the same
    j = json.loads((g["dir"] / "r.json").read_text())["tolerance"]
    assert j["value"] == TOL and j["before"]["inside"] == pytest.approx(np.mean(np.abs(dev) <= TOL), abs=1e-12)
    assert j["predicted"]["below"] == pytest.approx(np.mean(dev - sysv < -TOL), abs=1e-12)
    assert (
        f"tolerance ±{TOL:g} mm: {100 * np.mean(np.abs(dev) <= TOL):.1f} % of the points inside before" in g["stdout"]
    )


def test_callouts_are_the_largest_deviations(grid_run):
    g = grid_run
    dev, p = g["dev"], g["p"]
    want = np.argsort(-np.abs(dev))[: rep.CALLOUTS]
    assert np.abs(dev[want[-1]]) - np.abs(dev[np.argsort(-np.abs(dev))[rep.CALLOUTS]]) > 1e-6  # no tie at the cut
    rows = _rows(g["doc"], "callouts-measured")
    assert rows[0] == ["#", "x, mm", "y, mm", "deviation, µm"]
    assert len(rows) == 1 + rep.CALLOUTS
    for k, (r, j) in enumerate(zip(rows[1:], want)):
        assert int(r[0]) == k + 1
        assert (_num(r[1]), _num(r[2])) == pytest.approx((p[j, 0], p[j, 1]), abs=5e-4)
        assert _num(r[3]) == pytest.approx(1000 * dev[j], abs=0.05 + 1e-9)


def _section(doc, key):
    el = doc.get_element_by_id(f"section-{key}")
    tables = el.xpath(".//table")
    prof = [[c.text_content().strip() for c in tr.xpath("./td")] for tr in tables[0].iter("tr")][1:]
    meas = [[c.text_content().strip() for c in tr.xpath("./td")] for tr in tables[1].iter("tr")][1:]
    return prof, meas


def test_sections_are_the_fields_along_the_line(grid_run):
    g = grid_run
    p, n, dev, out = g["p"], g["n"], g["dev"], g["out"]
    sysv = out[:, 4]
    comp = np.einsum("ij,ij->i", out[:, 6:9] - p, n)  # the compensated points' offset along the normal
    # x = 30 lies on a column of the grid: the profiles are the values at its points
    prof, meas = _section(g["doc"], "x=30")
    on = np.flatnonzero(np.isclose(p[:, 0], 30))
    on = on[np.argsort(p[on, 1])]
    assert len(prof) == len(YS) == len(on)
    col = np.array([[_num(c) for c in r[:4]] for r in prof])
    np.testing.assert_allclose(col[:, 0], YS, atol=5e-4)
    np.testing.assert_allclose(col[:, 1], p[on, 2], atol=5e-5)  # the nominal height: the input's z
    np.testing.assert_allclose(col[:, 2], 1000 * sysv[on], atol=0.005 + 1e-9)
    np.testing.assert_allclose(col[:, 3], 1000 * comp[on], atol=0.005 + 1e-6)
    assert all(r[4] == "" for r in prof)  # the surface is the measured grid: nothing extrapolated
    m = np.array([[_num(c) for c in r] for r in meas])
    np.testing.assert_allclose(m[:, 0], p[on, 1], atol=5e-4)
    np.testing.assert_allclose(m[:, 1], 1000 * dev[on], atol=0.005 + 1e-9)
    # y = 21 runs between the rows y = 20 and 22: the systematic profile is their linear blend, the
    # nominal the bicubic through the grid (here the exact quadratic bowl)
    prof, meas = _section(g["doc"], "y=21")
    row = np.array([[_num(c) for c in r[:4]] for r in prof])
    a, b = (np.flatnonzero(np.isclose(p[:, 1], y)) for y in (20, 22))
    a, b = a[np.argsort(p[a, 0])], b[np.argsort(p[b, 0])]
    np.testing.assert_allclose(row[:, 0], XS, atol=5e-4)
    np.testing.assert_allclose(row[:, 2], 1000 * 0.5 * (sysv[a] + sysv[b]), atol=0.005 + 1e-9)
    np.testing.assert_allclose(row[:, 1], 1 + 0.002 * (XS - 30) ** 2 + 0.001, atol=5e-4)
    # measured points within half the spacing of y = 21: both neighbouring rows (|Δy| = 1 = h/2)
    assert len(meas) == 2 * len(XS)


def test_correction_map_marks_the_strip_outside_the_measured_hull(tmp_path):
    from scipy.spatial import Delaunay

    m, p, n, dev = _write(tmp_path)
    args = ["compensate", m, "--extent", "-4,64,-4,44", "--extrapolate-nominal", "--report", tmp_path / "r.html"]
    args += ["--points-out", tmp_path / "p.csv"]
    r = CliRunner().invoke(main, [str(a) for a in args])
    assert r.exit_code == 0, r.output
    out = np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1)
    corr = -out[:, 4]  # the correction at the measured points: −dF
    doc = lhtml.fromstring((tmp_path / "r.html").read_text())
    rows = {r[0]: r[1] for r in _rows(doc, "correction")[1:]}
    assert rows["surface grid"] == "35 × 25 nodes"  # the extent at the 2 mm spacing
    u, v = np.linspace(-4, 64, 35), np.linspace(-4, 44, 25)
    U, V = np.meshgrid(u, v, indexing="ij")
    nodes = np.column_stack([U.ravel(), V.ravel()])
    outside = Delaunay(p[:, :2]).find_simplex(nodes) < 0
    assert abs(_num(rows["extrapolated strip: share of the grid, %"]) - 100 * outside.mean()) <= 0.05
    far = np.sqrt(((nodes[outside, None] - nodes[None, ~outside]) ** 2).sum(-1)).min(axis=1).max()
    assert _num(rows["extrapolated strip: farthest from a measured node, mm"]) == pytest.approx(far, abs=5e-4)
    # the grid's nodes inside are the measured points: the correction there is −dF at the points
    lo, hi = (_num(s) for s in rows["correction inside the measured area, µm"].split("…"))
    assert (lo, hi) == pytest.approx((1000 * corr.min(), 1000 * corr.max()), abs=0.05 + 1e-9)
    # the strip holds the nearest measured value (--border hold): the values on the hull's edge
    edge = np.isin(p[:, 0], (0, 60)) | np.isin(p[:, 1], (0, 40))
    lo, hi = (_num(s) for s in rows["correction in the extrapolated strip, µm"].split("…"))
    assert (lo, hi) == pytest.approx((1000 * corr[edge].min(), 1000 * corr[edge].max()), abs=0.05 + 1e-9)
    assert "in the hatched strip the correction is extrapolated" in doc.text_content()


def test_one_binning_for_every_series():
    rng = np.random.default_rng(3)
    series = [rng.normal(0.02, 0.01, 500), rng.normal(0, 0.003, 500), rng.uniform(-0.05, 0.08, 50)]
    e = rep.histogram_edges(series)
    w = np.diff(e)
    np.testing.assert_allclose(w, w[0], rtol=1e-9)
    assert w[0] in (1, 2, 2.5, 5) or w[0] / 10 ** np.floor(np.log10(w[0])) in (1, 2, 2.5, 5)
    for s in series:  # every value in a bin (µm)
        assert np.histogram(s * 1000, bins=e)[0].sum() == len(s)
    assert 20 <= len(w) <= 80


def test_numbers_carry_units(grid_run):
    doc = grid_run["doc"]
    for div in ("tolerance", "callouts-measured"):
        head = _rows(doc, div)[0]
        assert all(h in ("", "#", "points") or any(u in h for u in ("µm", "mm", "%")) for h in head), head
    assert "bins:" in grid_run["html"] and " µm wide" in grid_run["html"]
    # the gate's offset and the noise in µm
    text = doc.text_content()
    assert "mean offset, µm" in text and "random part: std, µm" in text and "mean offset, mm" not in text


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--section", "x=30"], "--section draws in the report"),
        (["--section", "x30", "--report", "{t}/r.html"], "expected AXIS=POSITION"),
        (["--section", "z=3", "--report", "{t}/r.html"], "the part's plane is (x, y)"),
        (["--section", "x=90", "--report", "{t}/r.html"], "outside the compensated surface, x 0 … 60 mm"),
        (["--tolerance", "0", "--report", "{t}/r.html"], "--tolerance"),
    ],
)
def test_bad_report_options_are_refused(tmp_path, extra, message):
    m, *_ = _write(tmp_path)
    r = CliRunner().invoke(main, ["compensate", str(m), *(a.format(t=tmp_path) for a in extra)])
    assert r.exit_code == 2 and message in r.output, r.output
    assert not (tmp_path / "r.html").exists()


def test_without_plotly_the_report_names_its_extra(tmp_path, monkeypatch):
    import sys

    m, *_ = _write(tmp_path)
    for name in [k for k in sys.modules if k == "plotly" or k.startswith("plotly.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "plotly", None)  # import raises ModuleNotFoundError
    r = CliRunner().invoke(
        main, ["compensate", str(m), "--report", str(tmp_path / "r.html"), "--json", str(tmp_path / "r.json")]
    )
    assert r.exit_code == 2 and "plotly" in r.output and "pip install 'ncadapt[report]'" in r.output, r.output
    assert not (tmp_path / "r.html").exists() and not (tmp_path / "r.json").exists()


# ------------------------------------------------------------------------------ a real browser
def _chromium():
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is missing on CI: make test installs it")
        pytest.skip("chromium not installed (make test installs it)")
    return [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--virtual-time-budget=15000"]


def test_the_report_is_self_contained_and_its_3d_view_draws_in_chromium(grid_run):
    text = grid_run["html"]
    # no network: no external script, stylesheet or image
    doc = grid_run["doc"]
    assert not doc.xpath("//script[@src] | //link[@href] | //img[not(starts-with(@src, 'data:'))]")
    assert "plotly" in text and len(text) > 3_000_000  # the library is inside
    dom = subprocess.run(
        [*_chromium(), "--dump-dom", (grid_run["dir"] / "r.html").as_uri()],
        check=True,
        capture_output=True,
        timeout=180,
        text=True,
    ).stdout
    drawn = lhtml.fromstring(dom).get_element_by_id("surface3d")
    # plotly drew: its SVG layers (axes, colour bar, menu) and the WebGL canvas of the 3-D scene
    assert drawn.xpath(".//svg[contains(@class, 'main-svg')]")
    assert drawn.xpath(".//div[contains(@class, 'gl-container')]//canvas")
    assert drawn.xpath(".//*[contains(@class, 'colorbar')]")
    assert "WebGL is not supported" not in drawn.text_content()


def test_the_3d_view_paints_the_deviations(tmp_path):
    """The scene itself has colour: a page holding only the 3-D view, screenshotted; the colour
    bar sits at the right, so the left three fifths are the WebGL canvas alone."""
    from matplotlib.image import imread

    from ncadapt.report import page

    p, _, dev = _part()
    f = tmp_path / "v.html"
    f.write_text(page("view", "", [("3-D", rep.surface_view(p, [("measured", dev)]))]))
    shot = tmp_path / "v.png"
    subprocess.run(
        [*_chromium(), "--window-size=1100,900", f"--screenshot={shot}", f.as_uri()],
        check=True,
        capture_output=True,
        timeout=180,
    )
    rgb = imread(shot)[..., :3]
    scene = rgb[:, : int(0.6 * rgb.shape[1])]
    red = (scene[..., 0] > 0.6) & (scene[..., 0] - scene[..., 2] > 0.3)
    blue = (scene[..., 2] > 0.5) & (scene[..., 2] - scene[..., 0] > 0.25)
    assert red.sum() > 2000 and blue.sum() > 2000, (red.sum(), blue.sum())
