"""Turning slender shafts: the workpiece compliance against a finite-element beam, the 6 × 6
per-revolution system against its steady closed form, the plan's targets on the paper's example,
the lathe program read by LinuxCNC's rs274, and the virtual lathe."""

from __future__ import annotations

import copy
import json
import re

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import EXAMPLES, needs_rs274

from ncadapt.cli import main
from ncadapt.processes import turning as tu
from ncadapt.sim import turning as st

CONFIG = EXAMPLES / "turning" / "shaft_d20_l430.toml"


@pytest.fixture(scope="module")
def cfg():
    return tu.load(CONFIG)


@pytest.fixture(scope="module")
def feed_plan(cfg):
    return tu.plan(cfg, "feed")


def _fe_beam(L, EI, kc, kt, a, n=400):
    """Deflection under a unit load at a (from the tailstock) of an Euler–Bernoulli beam on two
    translational springs (chuck at x = L, tailstock at x = 0), by finite elements (cubic
    Hermite elements, the load node placed exactly at a)."""
    k = max(2, int(round(n * a / L)))
    xs = np.r_[np.linspace(0, a, k + 1), np.linspace(a, L, n - k + 2)[1:]]
    nn = len(xs)
    K = np.zeros((2 * nn, 2 * nn))
    for e in range(nn - 1):
        h = xs[e + 1] - xs[e]
        k = EI / h ** 3 * np.array([[12, 6 * h, -12, 6 * h], [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                                    [-12, -6 * h, 12, -6 * h], [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
        idx = [2 * e, 2 * e + 1, 2 * e + 2, 2 * e + 3]
        K[np.ix_(idx, idx)] += k
    K[0, 0] += kt
    K[2 * (nn - 1), 2 * (nn - 1)] += kc
    f = np.zeros(2 * nn)
    j = int(np.argmin(np.abs(xs - a)))
    f[2 * j] = 1.0
    return np.linalg.solve(K, f)[2 * j]


def test_units_are_converted_to_si(cfg):
    assert cfg.chuck[0, 0] == pytest.approx(8.0e4 * 9806.65)  # kgf/mm → N/m
    assert cfg.tool[1, 0] == pytest.approx(0.08e4 * 9806.65)
    assert cfg.rho[0] == pytest.approx(290 * 9.80665e6)  # kgf/mm² → Pa
    assert cfg.diameter == pytest.approx(0.020) and cfg.depth == pytest.approx(0.002)


def test_workpiece_compliance_matches_a_finite_element_beam(cfg):
    c = copy.deepcopy(cfg)
    c.chuck = np.diag(np.diag(cfg.chuck))
    c.tail = np.diag(np.diag(cfg.tail))
    m = tu.Model(c)
    for a in (0.02, 0.1, 0.215, 0.33, 0.41):
        fe = _fe_beam(c.length, m.EI, c.chuck[0, 0], c.tail[0, 0], a)
        assert m.workpiece_compliance(a)[0, 0, 0] == pytest.approx(fe, rel=1e-6)
    # mid-span closed form: L³/(48 EI) + (1/kc + 1/kt)/4
    L = c.length
    assert m.workpiece_compliance(L / 2)[0, 0, 0] == pytest.approx(
        L ** 3 / (48 * m.EI) + (1 / c.chuck[0, 0] + 1 / c.tail[0, 0]) / 4, rel=1e-12)


def test_six_by_six_steady_state_equals_the_closed_form(cfg):
    m = tu.Model(cfg)
    for a, s, n in ((0.05, 0.3e-3, 1000), (0.215, 0.1e-3, 2500), (0.39, 0.6e-3, 1500)):
        x = m.solve_revolution(a, s, n, 0.0)
        for _ in range(200):  # the previous revolution's axial deflection converges
            x = m.solve_revolution(a, s, n, x[2] + x[5])
        assert x[0] + x[3] == pytest.approx(float(m.deflection(a, s, n)[0]), rel=1e-9)
        # and the subsystems see the force: c^(X) x = λ F₀, c^(Y) y = λ F₀
        f0 = float(m.rho(n)) * (cfg.depth * s - m.zeta * s * s - s * (x[0] + x[3]))
        np.testing.assert_allclose(cfg.tool @ x[:3], cfg.lam * f0, rtol=1e-9)
        np.testing.assert_allclose(m.workpiece_stiffness(a)[0] @ x[3:], cfg.lam * f0, rtol=1e-9)


def test_chip_area_and_inverse(cfg):
    m = tu.Model(cfg)
    # ζ = ½ tan φ tan φ₁ / (tan φ + tan φ₁), φ = 60°, φ₁ = 30°: ½·√3·(1/√3)/(√3 + 1/√3) = √3/8
    assert m.zeta == pytest.approx(np.sqrt(3) / 8, rel=1e-12)
    x3 = np.linspace(0.05, 0.4, 8)
    s = np.full_like(x3, 0.2e-3)
    d = m.deflection(x3, s, 2000)
    np.testing.assert_allclose(m.feed_for(x3, 2000, d), s, rtol=1e-9)


def test_feed_plan_meets_the_target_and_its_bounds(cfg, feed_plan):
    p = feed_plan
    assert p.diameter_error_max <= 0.05 * p.diameter_error_constant_feed
    smin, smax = cfg.feed_bounds
    assert p.feed.min() >= smin * (1 - 1e-9) and p.feed.max() <= smax * (1 + 1e-9)
    assert p.rpm.min() >= cfg.rpm_bounds[0] and p.rpm.max() <= cfg.rpm_bounds[1]
    revs = np.diff(p.x3) / np.maximum(p.feed[1:], p.feed[:-1])
    assert np.all(np.abs(np.diff(p.feed)) <= cfg.feed_change * revs + 1e-12)
    assert np.all(np.abs(np.diff(p.rpm)) <= cfg.rpm_change * revs + 1e-9)
    # the schedule is slower than the same mean feed (which barrels) but much faster than a
    # constant feed as accurate
    assert p.machining_time_same_error_s > 5 * p.machining_time_s


@needs_rs274
def test_program_is_accepted_by_rs274_and_carries_the_schedule(cfg, feed_plan, tmp_path):
    from rs274 import canonical

    f = tmp_path / "shaft.ngc"
    f.write_text(tu.program(feed_plan, cfg))
    c = canonical(f)
    assert c.error is None, c.error
    text = (tmp_path / "shaft.ngc").read_text()
    assert "G7" in text and "G95" in text and "G18" in text
    out = f.with_suffix(".canon")
    import subprocess

    from rs274 import RS274

    subprocess.run([RS274, "-g", str(f), str(out)], capture_output=True, check=False)
    canon = out.read_text()
    feeds = np.array([float(v) for v in re.findall(r"SET_FEED_RATE\(([-\d.]+)\)", canon)])
    feeds = feeds[feeds > 0]
    cuts = c.ends[np.array(c.kinds) == "feed"]
    r_final = (cfg.diameter / 2 - cfg.depth) * 1e3 + feed_plan.x1_offset[0] * 1e3
    np.testing.assert_allclose(cuts[1:, 0], r_final, atol=1e-4)  # G7: X words are diameters (4 decimals)
    np.testing.assert_allclose(cuts[1:, 2], -feed_plan.x3[1:] * 1e3, atol=c.resolution_mm)
    expect = np.minimum(feed_plan.feed[:-1], feed_plan.feed[1:]) * 1e3
    assert len(feeds) >= 10
    # every feed rs274 sets is one of the schedule's block feeds (4 decimals), in mm/rev
    assert np.all(np.min(np.abs(feeds[:, None] - expect[None, :]), axis=1) <= 6e-5)
    assert feeds.max() == pytest.approx(expect.max(), abs=1e-4) and feeds.min() == pytest.approx(expect.min(), abs=1e-4)


def test_virtual_lathe_barrel_and_corrections(cfg, feed_plan, tmp_path):
    path = tu.plan(cfg, "path")
    const = tu.plan(cfg, "path")
    const.x1_offset = np.zeros_like(const.x1_offset)
    res = {}
    for name, q in (("constant", const), ("path", path), ("feed", feed_plan)):
        f = tmp_path / f"{name}.ngc"
        f.write_text(tu.program(q, cfg))
        res[name] = st.simulate(cfg, f)
    c = res["constant"]
    k = int(np.argmax(c.diameter))
    assert 0.3 < c.x3[k] / (cfg.length * 1e3) < 0.7  # the barrel: thickest near mid-span
    assert np.ptp(res["path"].diameter) < 0.01 * np.ptp(c.diameter)
    assert np.ptp(res["feed"].diameter) < 0.1 * np.ptp(c.diameter)
    # noise in ρ and stiffness is seeded
    a = st.simulate(cfg, tmp_path / "feed.ngc", rho_sigma=0.05, stiffness_sigma=0.05, seed=4)
    b = st.simulate(cfg, tmp_path / "feed.ngc", rho_sigma=0.05, stiffness_sigma=0.05, seed=4)
    np.testing.assert_array_equal(a.diameter, b.diameter)


def test_plan_cli_json(tmp_path):
    r = CliRunner().invoke(main, ["turning", "plan", str(CONFIG), "--mode", "feed", "-o", str(tmp_path / "p.ngc"),
                                  "--json", str(tmp_path / "p.json")], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "p.json").read_text())
    assert {"mode", "diameter_error_max", "diameter_error_constant_feed", "machining_time_s",
            "machining_time_constant_feed_s", "profile"} <= set(d)
    assert {"x3", "feed", "spindle_rpm", "deflection"} <= set(d["profile"][0])
    assert d["diameter_error_max"] <= 0.05 * d["diameter_error_constant_feed"]
    bad = tmp_path / "bad.toml"
    bad.write_text("[shaft]\ndiameter = 20\n")
    r = CliRunner().invoke(main, ["turning", "plan", str(bad)])
    assert r.exit_code == 2 and "bad.toml" in r.output and "missing" in r.output


@pytest.mark.parametrize("old,new,line,says", [
    ("step = 1.0 ", "step = nan ", 39, "[plan] step must be finite"),
    ("step = 1.0 ", "step = 1e-9 ", 39, "at most 100,000 stations"),
    ("speeds = 21 ", "speeds = 100000000000000000000000 ", 40, "[plan] speeds must be within 2..1000"),
    ("speeds = 21 ", 'speeds = "x" ', 40, "[plan] speeds must be a whole number"),
    ("diameter = 20.0 ", 'diameter = "twenty" ', 8, "[shaft] diameter must be a number"),
    ("depth = 2.0 ", "depth = [1, 2] ", 13, "[cut] depth must be a number"),
    ("depth = 2.0 ", "depth = 12.0 ", 13, "[cut] depth must be <= 10"),
    ("feed_change = 0.05 ", "feed_change = -0.05 ", 0, "[bounds] feed_change must be > 0"),
])
def test_a_bad_configuration_value_is_located(tmp_path, examples, old, new, line, says):
    from ncadapt.errors import InputError

    text = (examples / "turning" / "shaft_d20_l430.toml").read_text()
    assert old in text
    p = tmp_path / "c.toml"
    p.write_text(text.replace(old, new, 1))
    with pytest.raises(InputError) as e:
        tu.load(p)
    assert says in e.value.message
    if line:
        assert e.value.line == line
    else:
        assert e.value.line > 0
