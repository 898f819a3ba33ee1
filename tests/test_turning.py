"""Turning slender shafts: the workpiece compliance against a finite-element beam, the 6 × 6
per-revolution system against its steady closed form, the plan's targets on the paper's example,
the lathe program read by LinuxCNC's rs274, and the virtual lathe."""

from __future__ import annotations

import copy
import dataclasses
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
        k = (
            EI
            / h**3
            * np.array(
                [
                    [12, 6 * h, -12, 6 * h],
                    [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                    [-12, -6 * h, 12, -6 * h],
                    [6 * h, 2 * h * h, -6 * h, 4 * h * h],
                ]
            )
        )
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
        L**3 / (48 * m.EI) + (1 / c.chuck[0, 0] + 1 / c.tail[0, 0]) / 4, rel=1e-12
    )


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
    d = m.nominal_deflection(x3, s, 2000)
    np.testing.assert_allclose(m.feed_for(x3, 2000, d), s, rtol=1e-9)
    # the feed for δ with the program offset by −δ: the closed form with the offset gives δ back
    np.testing.assert_allclose(m.deflection(x3, s, 2000, -d), d, rtol=1e-9)


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
    feeds = feeds[feeds > 0][1:]  # the first is the radial plunge's, at the smallest feed of the bounds
    assert "T1 M6 G43" in text and "M8" in text and "M9" in text
    cuts = c.ends[np.array(c.kinds) == "feed"]
    # the entry revolutions, one block each (ending where the next starts, at its X), then the stations
    e = feed_plan.entry
    r0 = (cfg.diameter / 2 - cfg.depth) * 1e3
    ne = len(e.x3)
    np.testing.assert_allclose(cuts[0, 0], r0 + e.offset[0] * 1e3, atol=1e-4)  # G7: X words are diameters
    np.testing.assert_allclose(cuts[1:ne, 0], r0 + e.offset[1:] * 1e3, atol=1e-4)
    np.testing.assert_allclose(cuts[1 : ne + 1, 2], -(e.x3 + e.feed) * 1e3, atol=c.resolution_mm)
    r_final = r0 + feed_plan.x1_offset[0] * 1e3
    np.testing.assert_allclose(cuts[ne:, 0], r_final, atol=1e-4)  # (4 decimals)
    stations = feed_plan.x3[feed_plan.x3 > e.x3[-1] + e.feed[-1]]
    np.testing.assert_allclose(cuts[ne + 1 :, 2], -stations * 1e3, atol=c.resolution_mm)
    expect = np.minimum(feed_plan.feed[:-1], feed_plan.feed[1:]) * 1e3
    assert len(feeds) >= 10
    # every feed rs274 sets is one of the schedule's block feeds (4 decimals), in mm/rev
    assert np.all(np.min(np.abs(feeds[:, None] - expect[None, :]), axis=1) <= 6e-5)
    assert feeds.max() == pytest.approx(expect.max(), abs=1e-4) and feeds.min() == pytest.approx(expect.min(), abs=1e-4)


def test_virtual_lathe_barrel_and_corrections(cfg, feed_plan, tmp_path):
    path = tu.plan(cfg, "path")
    const = path.constant_feed_plan()
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
    r = CliRunner().invoke(
        main,
        [
            "turning",
            "plan",
            str(CONFIG),
            "--mode",
            "feed",
            "-o",
            str(tmp_path / "p.ngc"),
            "--json",
            str(tmp_path / "p.json"),
        ],
        catch_exceptions=False,
    )
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "p.json").read_text())
    assert {
        "mode",
        "diameter_error_max",
        "diameter_error_constant_feed",
        "machining_time_s",
        "machining_time_constant_feed_s",
        "profile",
    } <= set(d)
    assert {"x3", "feed", "spindle_rpm", "deflection"} <= set(d["profile"][0])
    assert d["diameter_error_max"] <= 0.05 * d["diameter_error_constant_feed"]
    bad = tmp_path / "bad.toml"
    bad.write_text("[shaft]\ndiameter = 20\n")
    r = CliRunner().invoke(main, ["turning", "plan", str(bad)])
    assert r.exit_code == 2 and "bad.toml" in r.output and "missing" in r.output


@pytest.mark.parametrize(
    "old,new,line,says",
    [
        ("step = 1.0 ", "step = nan ", 39, "[plan] step must be finite"),
        ("step = 1.0 ", "step = 1e-9 ", 39, "at most 100,000 stations"),
        ("speeds = 21 ", "speeds = 100000000000000000000000 ", 40, "[plan] speeds must be within 2..1000"),
        ("speeds = 21 ", 'speeds = "x" ', 40, "[plan] speeds must be a whole number"),
        ("diameter = 20.0 ", 'diameter = "twenty" ', 8, "[shaft] diameter must be a number"),
        ("depth = 2.0 ", "depth = [1, 2] ", 13, "[cut] depth must be a number"),
        ("depth = 2.0 ", "depth = 12.0 ", 13, "[cut] depth must be < 10 mm, the bar's radius"),
        ("depth = 2.0 ", "depth = 10.0 ", 13, "[cut] depth must be < 10 mm, the bar's radius"),
        ("step = 1.0 ", "step = 0 ", 39, "[plan] step must be > 0"),
        ("step = 1.0 ", "step = -1 ", 39, "[plan] step must be > 0"),
        ("step = 1.0 ", "step = 500 ", 39, "[plan] step must be at most end - start"),
        ("diameter = 20.0 ", "diameter = -20.0 ", 8, "[shaft] diameter must be > 0"),
        ("youngs_modulus = 2.1e5 ", "youngs_modulus = nan ", 10, "[shaft] youngs_modulus must be finite"),
        ("lambda = [0.4, 1.0, 0.25]", "lambda = [0.0, 1.0, 0.25]", 0, "[cut] lambda must be (radial > 0"),
        ("lambda = [0.4, 1.0, 0.25]", "lambda = [-0.4, 1.0, 0.25]", 0, "[cut] lambda must be (radial > 0"),
        ("rho = [290.0, 250.0, 220.0, 210.0]", "rho = [290.0, 250.0, 220.0, 1e25]", 0, "[cut] rho must be <= 5000"),
        ("feed = [0.05, 0.8]", "feed = [0.05, 80]", 0, "[bounds] feed must be <= 5"),
        ("feed_change = 0.05 ", "feed_change = -0.05 ", 0, "[bounds] feed_change must be > 0"),
    ],
)
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


# ------------------------------------------------------------------ the inverse problem (issue 20, 1)
def test_path_mode_keeps_the_nominal_depth(cfg):
    """X₁ = R − g ρ (S t_p − ζ S²) (no feedback factor): then the depth of cut of eq. 5,
    t_p − o − w, is t_p again, the deflection w is the nominal one and the radius R + o + w = R."""
    p = tu.plan(cfg, "path")
    m = tu.Model(cfg)
    g, rho, s = m.radial_compliance(p.x3), m.rho(p.rpm), p.feed
    expect = g * rho * (s * cfg.depth - m.zeta * s * s)  # by hand, eq. 2 and 4 at the nominal depth
    np.testing.assert_allclose(-p.x1_offset, expect, rtol=1e-12)
    w = m.deflection(p.x3, p.feed, p.rpm, p.x1_offset)  # the closed form with the program's offset
    np.testing.assert_allclose(w, -p.x1_offset, rtol=1e-9)
    # the form with the feedback factor is 1/(1 + ρSg) smaller: ρSg ≈ 0.4 mid-span (the figure)
    mid = np.argmin(np.abs(p.x3 - cfg.length / 2))
    assert 0.3 < rho[mid] * s[mid] * g[mid] < 0.5


def test_virtual_lathe_catches_a_wrong_path(cfg, tmp_path):
    """The virtual lathe (depth from the programmed X, eq. 5) leaves the old pre-distortion — with
    the feedback factor — about 0.3 mm barrelled (the issue reproduced 307 µm) and the right one
    within 2 µm."""
    import dataclasses

    p = tu.plan(cfg, "path")
    m = tu.Model(cfg)
    wrong = dataclasses.replace(p, x1_offset=-m.deflection(p.x3, p.feed, p.rpm))
    res = {}
    for name, q in (("right", p), ("wrong", wrong)):
        f = tmp_path / f"{name}.ngc"
        f.write_text(tu.program(q, cfg))
        res[name] = st.simulate(cfg, f)
    assert res["right"].variation < 0.002 and res["right"].error_max < 0.002
    assert 0.25 < res["wrong"].variation < 0.35


def test_virtual_lathe_depth_from_the_programmed_x(cfg, tmp_path):
    """X26 on a Ø20 bar touches nothing: the surface stays Ø20 and the run says where. X18 (1 mm
    deep) leaves D = 2 (X₁ + w) with w from eq. 5 in the steady state, by hand:
    w = gρ(S t − ζS²)/(1 + gρS)."""
    f = tmp_path / "x26.ngc"
    f.write_text("G18 G21 G90 G7 G95\nG97 S1000 M3\nG0 X30 Z-20\nG1 X26 F0.2\nG1 Z-400\nG0 X30\nM2\n")
    pr = st.simulate(cfg, f)
    assert pr.diameter.min() == pytest.approx(20.0) and pr.diameter.max() == pytest.approx(20.0)
    assert len(pr.no_contact) == 1 and pr.no_contact[0][0] == pytest.approx(20.0) and pr.no_contact[0][1] > 399
    f.write_text("G18 G21 G90 G7 G95\nG97 S1000 M3\nG0 X30 Z-20\nG1 X18 F0.2\nG1 Z-400\nG0 X30\nM2\n")
    pr = st.simulate(cfg, f)
    m = tu.Model(cfg)
    for a in (100.0, 215.0, 330.0):
        k = int(np.argmin(np.abs(pr.x3 - a)))
        x3 = pr.x3[k] * 1e-3
        g = float(m.radial_compliance(x3)[0])
        rho = float(np.interp(np.pi * 0.020 * 1000, cfg.rho_speed, cfg.rho))
        s, t = 0.2e-3, 1e-3
        w = g * rho * (s * t - m.zeta * s * s) / (1 + g * rho * s)
        assert pr.diameter[k] == pytest.approx(18.0 + 2 * w * 1e3, abs=2e-4)
    assert not pr.no_contact


def test_chip_area_of_a_shallow_cut():
    """Below the trailing triangle's height 2ζS the chip is a triangle of height t and base
    t (cot φ + cot φ₁) = t/(2ζ): area t²/(4ζ); above it S t − ζ S² (eq. 4); continuous."""
    zeta = np.sqrt(3) / 8  # φ = 60°, φ₁ = 30°
    cot = 1 / np.tan(np.radians(60)) + 1 / np.tan(np.radians(30))
    t, s = 0.05e-3, 0.4e-3
    assert st._area(s, t, zeta)[0] == pytest.approx(t * t * cot / 2, rel=1e-12)
    h = 2 * zeta * s
    assert st._area(s, h * (1 - 1e-12), zeta)[0] == pytest.approx(st._area(s, h, zeta)[0], rel=1e-9)
    assert st._area(s, 2e-3, zeta)[0] == pytest.approx(s * 2e-3 - zeta * s * s, rel=1e-12)
    assert st._area(s, -1e-3, zeta)[0] == 0.0


def test_comparisons_are_diameter_ranges_on_the_model_and_the_lathe(cfg, feed_plan, tmp_path):
    """One measure: the plan's variation (max D − min D) at the constant feed agrees with the
    virtual lathe's (an independent solver) to 3 %, and is twice the radial deflection's range."""
    q = feed_plan.constant_feed_plan()
    f = tmp_path / "c.ngc"
    f.write_text(tu.program(q, cfg))
    pr = st.simulate(cfg, f)
    assert pr.variation == pytest.approx(feed_plan.diameter_variation_constant_feed * 1e3, rel=0.03)
    m = tu.Model(cfg)
    w = m.deflection(q.x3, q.feed, q.rpm, q.x1_offset)
    assert feed_plan.diameter_variation_constant_feed == pytest.approx(2 * np.ptp(w), rel=1e-9)
    d = feed_plan.as_dict()
    assert d["diameter_variation_ratio"] == pytest.approx(
        d["diameter_variation"] / d["diameter_variation_constant_feed"]
    )


def _blocks(p):
    """The cutting blocks a program of plan ``p`` must hold, after the plunge (x3 at the end, mm;
    program offset there, mm; feed, mm/rev; rpm): one per entry revolution, ending where the next
    starts at its X (the last at the stations' X), then one per station beyond."""
    e = p.entry
    ends = e.x3 + e.feed
    offs = np.append(e.offset[1:], np.interp(ends[-1], p.x3, p.x1_offset))
    j = np.flatnonzero(p.x3 > ends[-1] + 1e-12)
    return (
        np.concatenate([ends, p.x3[j]]) * 1e3,
        np.concatenate([offs, p.x1_offset[j]]) * 1e3,
        np.concatenate([e.feed, np.minimum(p.feed[j - 1], p.feed[j])]) * 1e3,
        np.concatenate([e.rpm, np.maximum(p.rpm[j - 1], p.rpm[j])]),
    )


def test_css_keeps_the_planned_speeds(cfg, feed_plan, tmp_path):
    """--css: G96 with a D limit and an S (m/min) per block at the tool's own diameter: the spindle
    speed 1000·V/(π d) is the plan's block speed, and the lathe turns the same part in the same time
    as with G97."""
    text = tu.program(feed_plan, cfg, css=True)
    assert re.search(r"^G96 D2860 S[\d.]+ M3$", text, re.M)
    blocks = [ln for ln in text.splitlines() if ln.startswith("G1 ") and " Z" in ln]
    s_now = float(re.search(r"G96 D\d+ S([\d.]+)", text).group(1))
    ns = []
    for ln in blocks:
        m = re.search(r" S([\d.]+)", ln)
        s_now = float(m.group(1)) if m else s_now
        d = float(re.search(r"X([\d.]+)", ln).group(1))
        ns.append(1000 * s_now / (np.pi * d))
    np.testing.assert_allclose(ns, _blocks(feed_plan)[3], rtol=2e-4)
    assert sum(" S" in ln for ln in blocks) > 5  # not one S word for the whole cut
    (tmp_path / "css.ngc").write_text(text)
    (tmp_path / "rpm.ngc").write_text(tu.program(feed_plan, cfg))
    a, b = st.simulate(cfg, tmp_path / "css.ngc"), st.simulate(cfg, tmp_path / "rpm.ngc")
    assert a.variation == pytest.approx(b.variation, abs=5e-4)
    assert a.time_s == pytest.approx(b.time_s, rel=0.005)


@needs_rs274
def test_css_program_is_accepted_by_rs274(cfg, feed_plan, tmp_path):
    from rs274 import canonical

    f = tmp_path / "css.ngc"
    f.write_text(tu.program(feed_plan, cfg, css=True))
    assert canonical(f).error is None


HEAD = "G18 G21 G90 G7 G95\nG97 S1000 M3\nG0 X30 Z-20\nG1 X16 F0.2\n"


@pytest.mark.parametrize(
    "body,line,says",
    [
        (HEAD + "G1 Z-100 F0\n", 5, "feed F0 mm/rev must be > 0"),
        (HEAD + "G1 Z-100 F-0.2\n", 5, "must be > 0"),
        ("G18 G21 G90 G7 G98\nG97 S1000 M3\nG0 X30 Z-20\nG1 X16 F150\nG1 Z-100\n", 1, "G98: feed per minute"),
        ("G18 G21 G90 G7 G94\nG97 S1000 M3\nG0 X30 Z-20\nG1 X16 F150\nG1 Z-100\n", 1, "feed per minute (G94)"),
        ("G18 G21 G90 G7\nG97 S1000 M3\nG0 X30 Z-20\nG1 X16 F0.2\nG1 Z-100\n", 4, "feed per revolution (G95)"),
        (HEAD + "G1 Z-500\n", 5, "Z-500 is beyond the chuck face (Z-430)"),
        ("G18 G21 G90 G95\nG97 S1000 M3\nG0 X30 Z-20\n", 3, "before G7 (diameter) or G8 (radius)"),
        ("G18 G20 G90 G7 G95\n", 1, "inch units (G20)"),
        ("G18 G21 G91 G7 G95\n", 1, "incremental distances (G91)"),
        (
            "G18 G21 G90 G7 G95\nG96 S100 M3\nG0 X30 Z-20\nG1 X16 F0.2\nG1 Z-100\n",
            4,
            "G96 without a spindle-speed limit (D)",
        ),
        (HEAD + "G1 Z-400 F0.0001\n", 0, "at most 2,000,000"),
        ("G18 G21 G90 G7 G95\nG97 S1000 M3\nG0 X16 Z-20\nG1 Z-100 F0.2\n", 3, "a rapid move (G0) into the stock"),
        (HEAD + "G76 P1\n", 5, "G76 is not simulated"),
        (HEAD + "G1 X-2\n", 5, "below the axis"),
    ],
)
def test_lathe_program_checks(cfg, tmp_path, body, line, says):
    from ncadapt.errors import InputError

    f = tmp_path / "p.ngc"
    f.write_text(body)
    with pytest.raises(InputError) as e:
        st.simulate(cfg, f)
    assert says in e.value.message
    assert e.value.line == line


def test_simulate_cli_bounds_and_seed(cfg, tmp_path):
    f = tmp_path / "p.ngc"
    f.write_text(tu.program(tu.plan(cfg, "path"), cfg))
    run = CliRunner().invoke
    for opt, v in (
        ("--rho-sigma", "1e20"),
        ("--stiffness-sigma", "1e308"),
        ("--rho-sigma", "nan"),
        ("--stiffness-sigma", "-0.1"),
    ):
        r = run(main, ["turning", "simulate", str(CONFIG), str(f), opt, v])
        assert r.exit_code == 2 and opt in r.output, r.output
    out = []
    for _ in range(2):
        r = run(
            main,
            [
                "turning",
                "simulate",
                str(CONFIG),
                str(f),
                "--rho-sigma",
                "0.5",
                "--stiffness-sigma",
                "0.5",
                "--seed",
                "7",
                "--json",
                "-",
            ],
        )
        assert r.exit_code == 0, r.output
        d = json.loads(r.stdout)
        assert all(np.isfinite(v) for v in (d["diameter_min"], d["diameter_max"], d["diameter_error_max"]))
        out.append(d)
    assert out[0] == out[1]
    bad = tmp_path / "f0.ngc"
    bad.write_text(HEAD + "G1 Z-100 F0\n")
    r = run(main, ["turning", "simulate", str(CONFIG), str(bad)])
    assert r.exit_code == 2 and f"{bad}:5:10: error: feed F0 mm/rev must be > 0" in r.output, r.output


def test_plan_cli_refuses_bad_configurations(tmp_path, examples):
    text = (examples / "turning" / "shaft_d20_l430.toml").read_text()
    for old, new in (
        ("step = 1.0 ", "step = 0 "),
        ("step = 1.0 ", "step = -1 "),
        ("rho = [290.0, 250.0, 220.0, 210.0]", "rho = [290.0, 250.0, 220.0, 1e25]"),
        ("youngs_modulus = 2.1e5 ", "youngs_modulus = nan "),
    ):
        p = tmp_path / "c.toml"
        p.write_text(text.replace(old, new, 1))
        r = CliRunner().invoke(main, ["turning", "plan", str(p)])
        assert r.exit_code == 2 and f"{p}:" in r.output and "error:" in r.output, r.output


# ------------------------------------------------------------------ controllers (issue 20, 8)
GOLDEN = EXAMPLES / "turning" / "golden"


@pytest.mark.parametrize("css,name", [(False, "short_cut_path_fanuc.nc"), (True, "short_cut_path_fanuc_css.nc")])
def test_fanuc_program_matches_the_golden_file(css, name):
    """The golden files were checked by hand against the Fanuc lathe manual's rules (see
    examples/turning/golden/README.md); the program must stay byte for byte what was checked."""
    c = tu.load(GOLDEN / "short_cut.toml")
    text = tu.program(tu.plan(c, "path"), c, css=css, dialect="fanuc")
    assert text == (GOLDEN / name).read_text()
    lines = text.splitlines()
    assert lines[0] == lines[-1] == "%" and lines[1].startswith("O1000 (")
    assert not re.search(r"\bG(90|7|8|95|94)\b", text)  # system A: G90 is a cycle; G7/G8/G95 are not Fanuc's
    first_cut = next(i for i, ln in enumerate(lines) if ln.startswith("G1 "))
    assert any("G99" in ln for ln in lines[:first_cut])
    g50 = next(i for i, ln in enumerate(lines) if ln.startswith("G50 S"))
    speed = next(i for i, ln in enumerate(lines) if ln.startswith(("G96", "G97")))
    assert g50 < speed and "T0101" in lines
    assert all(len(w.split(".")[1]) == 3 for w in re.findall(r"[XZ]-?\d+\.\d+", text))  # IS-B, 0.001 mm


def test_programs_of_every_dialect_turn_the_same_part(cfg, feed_plan, tmp_path):
    res = {}
    for d in ("linuxcnc", "fanuc", "sinumerik"):
        f = tmp_path / f"{d}.nc"
        f.write_text(tu.program(feed_plan, cfg, css=True, dialect=d))
        res[d] = st.simulate(cfg, f, dialect=d)
    for d in ("fanuc", "sinumerik"):
        assert res[d].variation == pytest.approx(res["linuxcnc"].variation, abs=1e-3)  # Fanuc rounds X to 1 µm
        assert res[d].time_s == pytest.approx(res["linuxcnc"].time_s, rel=1e-3)
    with pytest.raises(Exception, match="G99: feed per revolution on a Fanuc lathe"):
        st.simulate(cfg, tmp_path / "fanuc.nc")  # a Fanuc program read as LinuxCNC's is refused, not misread
    from ncadapt.errors import InputError

    with pytest.raises(InputError, match="Fanuc lathe programs X as a diameter"):
        tu.program(feed_plan, cfg, diameter_mode=False, dialect="fanuc")


def test_sinumerik_program_read_by_nc_gcode_interpreter(cfg, feed_plan):
    """nc-gcode-interpreter (a Sinumerik-flavoured interpreter) reads the program and reports every
    block's end position: the plan's X (diameter, DIAMON), Z and F."""
    nci = pytest.importorskip("nc_gcode_interpreter")
    import io

    text = tu.program(feed_plan, cfg, dialect="sinumerik")
    df, state = nci.nc_to_dataframe(io.StringIO(text))
    rows = df.to_dicts()
    cuts = [r for r in rows if r.get("gg01_motion") == "G1" and r.get("Z") is not None]
    r_final = (cfg.diameter / 2 - cfg.depth) * 1e3
    z = np.array([r["Z"] for r in cuts])
    x = np.array([r["X"] for r in cuts])
    f = np.array([r["F"] for r in cuts])
    # the first G1 is the plunge at x3[0]; then one block per entry revolution and per station
    bz, bo, bf, _ = _blocks(feed_plan)
    np.testing.assert_allclose(z[1:], -bz, atol=1e-4)
    np.testing.assert_allclose(x[1:], 2 * (r_final + bo), atol=1e-4)
    np.testing.assert_allclose(f[1:], bf, atol=1e-4)
    assert state["symbol_table"]["LIMS"] == pytest.approx(cfg.rpm_bounds[1])


# ------------------------------------------------------------------ baselines (issue 20, 6)
def test_roughness_bound_and_baselines(tmp_path, examples):
    """rz_max caps the feed by Rz = S²/(8 r_ε) (0.8 mm nose, 25 µm: √(8·0.8·0.025) = 0.4 mm/rev);
    the rough + finish baseline's closed form agrees with the virtual lathe turning both passes."""
    c = tu.load(examples / "turning" / "shaft_d20_l430_finish.toml")
    assert c.feed_bounds[1] * 1e3 == pytest.approx(np.sqrt(8 * 0.8 * 0.025), rel=1e-12)
    assert tu.roughness(0.4, 0.8) == pytest.approx(0.025)
    p = tu.plan(c, "feed")
    assert p.feed.max() <= c.feed_bounds[1] * (1 + 1e-9)
    rf = next(b for b in p.baselines if b["name"] == "rough + finish")
    m = tu.Model(c)
    n = p.constant_rpm
    R = (c.diameter / 2 - c.depth) * 1e3
    cr, _ = m.constant_offset(p.x3, rf["feed"] * 1e-3, n, depth=c.depth - c.finish_depth)
    wr = m.deflection(p.x3, rf["feed"] * 1e-3, n, -cr, c.depth - c.finish_depth)
    cf, _ = m.constant_offset(p.x3, rf["finish_feed"] * 1e-3, n, depth=c.finish_depth, left=wr - cr)
    lines = ["G18 G21 G90 G7 G95", f"G97 S{n:.0f} M3", "G0 X24", f"G0 Z{-p.x3[0] * 1e3:.4f}"]
    for r, f in ((R + c.finish_depth * 1e3 - cr * 1e3, rf["feed"]), (R - cf * 1e3, rf["finish_feed"])):
        lines += [
            f"G1 X{2 * r:.4f} F0.05",
            f"G1 Z{-p.x3[-1] * 1e3:.4f} F{f:.4f}",
            "G0 X24",
            f"G0 Z{-p.x3[0] * 1e3:.4f}",
        ]
    prog = tmp_path / "rf.ngc"
    prog.write_text("\n".join(lines + ["M2"]) + "\n")
    pr = st.simulate(c, prog)
    assert pr.variation == pytest.approx(rf["diameter_variation"], rel=0.1)
    # honest figures: the schedule is not 20× better than a sensible finish, only about 2.5× the
    # constant feed at the same mean (the issue measured 41 %)
    assert 0.3 < p.diameter_variation / p.diameter_variation_constant_feed < 0.5
    bad = tmp_path / "c.toml"
    bad.write_text(
        (examples / "turning" / "shaft_d20_l430_finish.toml").read_text().replace("rz_max = 25.0", "rz_max = 1.0")
    )
    from ncadapt.errors import InputError

    with pytest.raises(InputError, match=r"\[bounds\] rz_max allows feeds up to 0.0800 mm/rev"):
        tu.load(bad)


# ------------------------------------------------------------------ the workpiece model (issue 20, 7)
def _fe_beam_general(L, ei_of, a, kc=None, kt=None, clamped=False, n=200, nodes=()):
    """Deflection under a unit load at a (from the tailstock) of an Euler–Bernoulli beam with EI
    per element (``ei_of(x_mid)``), on translational springs (None: rigid) at the tailstock (x = 0)
    and the chuck (x = L), the chuck end clamped (rotation fixed) or pinned; finite elements
    (cubic Hermite), the load node at a."""
    k = max(2, int(round(n * a / L)))
    xs = np.r_[np.linspace(0, a, k + 1), np.linspace(a, L, n - k + 2)[1:]]
    xs = np.unique(np.r_[xs, [v for v in nodes if 0 < v < L]])  # a node at every step of EI
    nn = len(xs)
    K = np.zeros((2 * nn, 2 * nn))
    for e in range(nn - 1):
        h = xs[e + 1] - xs[e]
        EI = ei_of(0.5 * (xs[e] + xs[e + 1]))
        ke = (
            EI
            / h**3
            * np.array(
                [
                    [12, 6 * h, -12, 6 * h],
                    [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                    [-12, -6 * h, 12, -6 * h],
                    [6 * h, 2 * h * h, -6 * h, 4 * h * h],
                ]
            )
        )
        idx = [2 * e, 2 * e + 1, 2 * e + 2, 2 * e + 3]
        K[np.ix_(idx, idx)] += ke
    fixed = []
    if kt is None:
        fixed.append(0)
    else:
        K[0, 0] += kt
    if kc is None:
        fixed.append(2 * (nn - 1))
    else:
        K[2 * (nn - 1), 2 * (nn - 1)] += kc
    if clamped:
        fixed.append(2 * (nn - 1) + 1)
    free = np.setdiff1d(np.arange(2 * nn), fixed)
    f = np.zeros(2 * nn)
    j = int(np.argmin(np.abs(xs - a)))
    f[2 * j] = 1.0
    u = np.zeros(2 * nn)
    u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
    return u[2 * j]


@pytest.mark.parametrize("stepped,chuck", [(True, "pinned"), (False, "clamped"), (True, "clamped")])
def test_workpiece_options_match_a_finite_element_beam(cfg, stepped, chuck):
    """[model] stepped (the part already turned, from the start of the cut to the tool, at the
    turned diameter) and chuck = "clamped": the bending compliance against FE with the same
    assumptions; with springs, the pinned stepped beam's lever rule is exact (FE with springs)."""
    import dataclasses

    c = dataclasses.replace(
        cfg, stepped=stepped, chuck_support=chuck, chuck=np.diag(np.diag(cfg.chuck)), tail=np.diag(np.diag(cfg.tail))
    )
    m = tu.Model(c)
    for a in (0.05, 0.15, 0.215, 0.3, 0.39):

        def ei(x, a=a):
            return m.EI_f if (stepped and c.start <= x < a) else m.EI

        fe = _fe_beam_general(c.length, ei, a, clamped=chuck == "clamped", nodes=(c.start,))
        assert m._bending(a)[0] == pytest.approx(fe, rel=1e-6)
        if chuck == "pinned":
            fe = _fe_beam_general(c.length, ei, a, kc=c.chuck[0, 0], kt=c.tail[0, 0], nodes=(c.start,))
            assert m.workpiece_compliance(a)[0, 0, 0] == pytest.approx(fe, rel=1e-6)
    # the propped cantilever at mid-span by hand: δ = 7L³/768EI (clamped at one end, pinned at the other)
    if chuck == "clamped" and not stepped:
        assert m._bending(c.length / 2)[0] == pytest.approx(7 * c.length**3 / (768 * m.EI), rel=1e-12)


def test_workpiece_options_change_the_plan(cfg, tmp_path, examples):
    text = (examples / "turning" / "shaft_d20_l430.toml").read_text()
    p = tmp_path / "c.toml"
    p.write_text(text + '\n[model]\nstepped = true\nchuck = "clamped"\n')
    c = tu.load(p)
    assert c.stepped and c.chuck_support == "clamped"
    q = tu.plan(c, "path")
    f = tmp_path / "p.ngc"
    f.write_text(tu.program(q, c))
    assert st.simulate(c, f).variation < 0.002  # the lathe turns with the same workpiece model
    p.write_text(text + '\n[model]\nchuck = "welded"\n')
    from ncadapt.errors import InputError

    with pytest.raises(InputError, match=r'\[model\] chuck must be "pinned" or "clamped"'):
        tu.load(p)


def test_entry_transient_costs_one_revolution_and_the_entry_x_takes_it_out(cfg, tmp_path):
    """The virtual lathe turns the entry transient: the revolution that enters the stock has no
    axial deflection before it, so its feed is S − a instead of S, the force and the radial
    deflection are smaller and the diameter there is smaller. Turned with and without it
    (``entry_transient=False``: the steady state S_p = S from the first revolution), a program
    with the stations' X alone loses 0.97 µm on the first revolution (the second: 1.5 % of it),
    almost the whole of what the path program leaves; the plan's entry X (its own revolution
    model) takes it out."""
    p = tu.plan(cfg, "path")
    f, g = tmp_path / "stations.ngc", tmp_path / "entry.ngc"
    f.write_text(tu.program(dataclasses.replace(p, entry=None), cfg))
    g.write_text(tu.program(p, cfg))
    a = st.simulate(cfg, f)
    b = st.simulate(cfg, f, entry_transient=False)
    c = st.simulate(cfg, g)
    assert np.array_equal(a.x3, b.x3)
    diff = (a.diameter - b.diameter) * 1000  # µm
    x = a.x3 - a.x3.min()
    feed = float(p.feed[0]) * 1e3  # mm/rev (0.425; the plan holds SI)
    first = x < feed - 1e-9
    assert np.all(diff[first] < -0.9) and np.all(diff[first] > -1.05)  # 0.97 µm smaller
    assert np.abs(diff[~first]).max() < 0.02
    assert np.abs(diff[x > 2 * feed]).max() < 1e-3
    va, vb = (a.diameter.max() - a.diameter.min()) * 1000, (b.diameter.max() - b.diameter.min()) * 1000
    assert 0.9 < va < 1.1 and vb < 0.15
    # with the entry X: the first revolutions within 0.05 µm of the transient-free lathe, the range its range
    dc = (np.interp(b.x3, c.x3, c.diameter) - b.diameter) * 1000
    assert np.abs(dc[x < 3 * feed]).max() < 0.05 and np.abs(dc[(x >= 3 * feed) & (x < x.max() - 2)]).max() < 0.01
    assert c.variation * 1000 == pytest.approx(vb, abs=0.01)


def test_entry_offsets_solve_the_revolution_and_reach_the_steady_state(cfg):
    """Model.entry against a root found by brentq on the revolution's force balance
    F = ρ((S + a_prev − g₃F) t − ζ(S + a_prev − g₃F)²), t = t_p − e, and, revolution after
    revolution at one place, against the steady closed form (the nominal deflection at depth t)."""
    from scipy.optimize import brentq

    m = tu.Model(cfg)
    x, s, n = 0.2, 0.4e-3, 1900.0
    g, g3, rho = float(m.radial_compliance(x)[0]), float(m.axial_compliance(x)[0]), float(m.rho(n))
    assert g3 > 0
    e = np.array([0.0, 3e-6, -2e-6, 0.0, 0.0, 0.0, 0.0, 0.0])
    off, w = m.entry(np.full(len(e), x), s, n, e)
    a_prev = 0.0
    for k in range(len(e)):
        t = cfg.depth - e[k]

        def balance(f, t=t, a_prev=a_prev):
            sp = s + a_prev - g3 * f
            return f - rho * (sp * t - m.zeta * sp * sp)

        f0 = brentq(balance, 0.0, 1e5, xtol=1e-12, rtol=1e-14)
        assert w[k] == pytest.approx(g * f0, rel=1e-10) and off[k] == pytest.approx(e[k] - g * f0, rel=1e-10)
        a_prev = g3 * f0
    # the first revolution cuts less (no axial deflection before it); the transient dies out
    off, w = m.entry(np.full(8, x), s, n, 0.0)
    steady = float(m.nominal_deflection(x, s, n)[0])
    assert w[0] < steady * (1 - 1e-3)
    assert w[-1] == pytest.approx(steady, rel=1e-12) and off[-1] == pytest.approx(-steady, rel=1e-12)
    assert abs(w[1] - steady) < abs(w[0] - steady) / 20  # a factor of about 60 a revolution


def test_entering_on_a_compliant_span_the_transient_is_ten_microns(tmp_path):
    """The golden short cut starts at mid-shaft (x3 = 100 mm), where the shaft is compliant: the
    stations' X alone leave the first revolution 10.5 µm under the target diameter on the virtual
    lathe; the entry X leaves it within 0.1 µm (LinuxCNC, 0.1 µm on the diameter) or within the
    X increment (Fanuc IS-B, 1 µm on the diameter)."""
    c = tu.load(GOLDEN / "short_cut.toml")
    p = tu.plan(c, "path")
    res = {}
    for d in ("linuxcnc", "fanuc"):
        for name, q in (("stations", dataclasses.replace(p, entry=None)), ("entry", p)):
            f = tmp_path / f"{name}_{d}.nc"
            f.write_text(tu.program(q, c, dialect=d))
            r = st.simulate(c, f, dialect=d)
            x = r.x3 - r.x3.min()
            err = np.abs(r.diameter - r.target) * 1000
            res[name, d] = (err[x < 0.425 - 1e-9].max(), r.variation * 1000)
    assert 10 < res["stations", "linuxcnc"][0] < 11 and 10 < res["stations", "fanuc"][0] < 11
    assert res["entry", "linuxcnc"][0] < 0.1 and res["entry", "linuxcnc"][1] < 0.1
    assert res["entry", "fanuc"][0] < 0.5 and res["entry", "fanuc"][1] < 1.0
