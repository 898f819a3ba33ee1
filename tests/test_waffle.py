"""Waffle shells: the tilt formulas on hand-computed cases, the backlash model against closed forms
and scipy, the program correction read back by LinuxCNC's rs274, and the testbed's targets."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import needs_rs274
from ncadapt.cli import main
from ncadapt.processes import waffle as pw
from ncadapt.sim import waffle as sw
from rs274 import canonical


def _cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


# ------------------------------------------------------------------------------ tilt
def test_least_squares_line_by_hand():
    # B = 0, 1, 2; V = 0, 1, 3: nΣBV = 3·7 = 21, ΣBΣV = 3·4 = 12, nΣB² = 15, (ΣB)² = 9
    k, t = pw.fit_segments([0, 1, 2], [0, 1, 3], [(0, 3)])
    assert k[0] == pytest.approx(9 / 6, abs=1e-12)  # (21 − 12)/(15 − 9)
    assert t[0] == pytest.approx((4 - 1.5 * 3) / 3, abs=1e-12)  # −1/6
    rng = np.random.default_rng(1)
    b, v = rng.uniform(0, 10, 17), rng.normal(0, 1, 17)
    k, t = pw.fit_segments(b, v, [(0, 17)])
    np.testing.assert_allclose([k[0], t[0]], np.polyfit(b, v, 1), rtol=1e-10)  # numpy's own fit


def test_tilt_error_closed_form():
    # a wall rising 0.02 mm per degree on a D = 1000 mm shell, R = 12.5 mm:
    # tan α = 0.02·360/(π·1000) = 0.0022918…, E = R tan α = 0.028648 mm
    b = np.arange(0.0, 10.0, 0.5)
    t = pw.tilt(b, np.zeros_like(b), 0.1 + 0.02 * b, tool_radius=12.5, diameter=1000.0, segment=5)
    tan_a = 0.02 * 360 / (math.pi * 1000)
    np.testing.assert_allclose(t.tan_alpha, tan_a, rtol=0, atol=1e-12)
    np.testing.assert_allclose(t.error, 12.5 * tan_a, rtol=0, atol=1e-9)
    assert 12.5 * tan_a == pytest.approx(0.0286478897565, abs=1e-12)
    # a falling wall: the signed error flips, the web is thinner by |E| either way
    t2 = pw.tilt(b, np.zeros_like(b), -0.02 * b, tool_radius=12.5, diameter=1000.0, segment=5)
    np.testing.assert_allclose(t2.error, -12.5 * tan_a, atol=1e-12)
    np.testing.assert_allclose(t2.correction, t.correction, atol=1e-15)
    assert (t.correction < 0).all()


def test_segments_follow_the_rule():
    assert pw.segments(np.zeros(10), 4) == [(0, 4), (4, 8), (8, 10)]  # 2 points = N/2: kept
    assert pw.segments(np.zeros(9), 4) == [(0, 4), (4, 9)]  # 1 point < N/2: joins the previous
    assert pw.segments([0] * 6 + [5] * 5, 3) == [(0, 3), (3, 6), (6, 9), (9, 11)]  # restart where Z changes


def test_tilt_cli_json_rows_in_input_order(tmp_path):
    # two segments of 4 with different slopes, by hand: k = 0.1 and −0.3 mm/deg
    b = [0, 1, 2, 3, 4, 5, 6, 7]
    v = [0.0, 0.1, 0.2, 0.3, 1.0, 0.7, 0.4, 0.1]
    (tmp_path / "log.csv").write_text("B,Z,V\n" + "".join(f"{x},{-50},{y}\n" for x, y in zip(b, v)))
    r = _cli(
        "waffle",
        "tilt",
        "--tracking",
        tmp_path / "log.csv",
        "--tool-radius",
        10,
        "--diameter",
        2000,
        "--segment",
        4,
        "--json",
        tmp_path / "t.json",
    )
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "t.json").read_text())
    s = 360 / (math.pi * 2000)
    assert [p["B"] for p in d["points"]] == b
    assert [p["tan_alpha"] for p in d["points"]] == pytest.approx([0.1 * s] * 4 + [-0.3 * s] * 4, abs=1e-12)
    assert [p["error"] for p in d["points"]] == pytest.approx([1.0 * s] * 4 + [-3.0 * s] * 4, abs=1e-9)
    assert d["max_abs_error"] == pytest.approx(3 * s, abs=1e-9)
    assert d["rms_error"] == pytest.approx(math.sqrt((1 + 9) / 2) * s, abs=1e-9)


def test_tilt_cli_names_the_bad_line(tmp_path):
    (tmp_path / "log.csv").write_text("B,Z,V\n0,0,0\n1,0,x\n")
    r = _cli("waffle", "tilt", "--tracking", tmp_path / "log.csv", "--tool-radius", 10, "--diameter", 2000)
    assert r.exit_code == 2 and "log.csv:3:" in r.output


# ------------------------------------------------------------------------------ backlash
def test_play_shelf_and_lag_closed_form():
    # a ramp up then down at 0.01 mm per sample through a gap g = 0.04: one way the output lags
    # by g/2; after the reversal it stays flat for g/0.01 = 4 samples (the shelf)
    x = np.r_[np.arange(0, 1.0001, 0.01), np.arange(0.99, 0.4999, -0.01)]
    y = pw.play(x, 0.04)
    np.testing.assert_allclose(y[10:101], x[10:101] - 0.02, atol=1e-12)
    top = 101
    assert np.all(y[top : top + 3] == y[100])  # flat while the input crosses the gap
    np.testing.assert_allclose(y[top + 4 :], x[top + 4 :] + 0.02, atol=1e-12)


def test_drive_matches_scipy_lsim_with_held_input():
    from scipy.signal import lsim

    rng = np.random.default_rng(2)
    u = np.cumsum(rng.normal(0, 0.01, 300))
    tau, dt = 0.05, 0.0393
    t = np.arange(len(u)) * dt
    # 1/(τs + 1) driven by the input held over each sample; the drive reacts to sample k at once
    # (w_k uses y_k), lsim's output at t_k to the input held from t_k−1: shift by one sample
    _, y, _ = lsim(([1.0], [tau, 1.0]), u - u[0], t, interp=False)
    w = pw.drive(u, tau, dt)
    np.testing.assert_allclose(w[:-1], y[1:] + u[0], atol=1e-10)


def test_backlash_estimated_from_the_pair_of_signals():
    vi, vm, dt = sw.backlash_pair(seed=3, noise=0.002)
    r = pw.estimate_backlash(vi, vm, dt)
    # the testbed's chain is a gap and a second-order drive; the estimator's first-order drive
    # recovers the gap, and leaves little beyond the noise
    assert r.gap == pytest.approx(sw.GAP, rel=0.05)
    assert 0.5 * sw.TAU < r.tau < 2 * sw.TAU  # an equivalent lag, not a parameter of the truth
    assert r.residual_rms == pytest.approx(0.002, rel=0.15)


# ------------------------------------------------------------------------------ the program
def _tracking(path, slope):
    b = np.arange(0.0, 15.01, 0.25)
    z = np.arange(-230.0, -129.0, 5.0)
    with open(path, "w") as f:
        f.write("B,Z,V\n")
        for zz in z:
            for bb in b:
                f.write(f"{bb},{zz},{slope * bb:.12g}\n")


@needs_rs274
def test_correct_moves_the_depth_axis_only_and_keeps_b(tmp_path):
    # constant wall slope 0.05 mm/deg: K_dist = −R|tan α| everywhere; a constant thickness map
    # T_ref + b + 0.02 adds K_fb = +0.02
    prog = tmp_path / "cell.ngc"
    prog.write_text(sw.cell_program(0, 0))
    _tracking(tmp_path / "log.csv", 0.05)
    bt, zt = np.meshgrid(np.arange(0.0, 15.01, 1.0), np.arange(-230.0, -129.0, 10.0))
    (tmp_path / "map.csv").write_text(
        "B,Z,thickness\n" + "".join(f"{b},{z},2.32\n" for b, z in zip(bt.ravel(), zt.ravel()))
    )
    r = _cli(
        "waffle",
        "correct",
        prog,
        "--tracking",
        tmp_path / "log.csv",
        "--tool-radius",
        10,
        "--diameter",
        1500,
        "--thickness",
        tmp_path / "map.csv",
        "--target",
        2.0,
        "--allowance",
        0.3,
        "-o",
        tmp_path / "out.ngc",
        "--json",
        tmp_path / "out.json",
    )
    assert r.exit_code == 0, r.output
    k = -10 * 0.05 * 360 / (math.pi * 1500) + 0.02
    before, after = canonical(prog), canonical(tmp_path / "out.ngc")
    assert before.error is None and after.error is None
    cut_b = before.ends[np.array(before.kinds) == "feed"]
    cut_a = after.ends[np.array(after.kinds) == "feed"]
    deep_b, deep_a = cut_b[cut_b[:, 1] > 1], cut_a[cut_a[:, 1] > 1]
    # every programmed B end is still reached, exactly
    assert set(np.round(deep_b[:, 4], 4)) <= set(np.round(deep_a[:, 4], 4))
    np.testing.assert_allclose(deep_a[:, 1], 8.0 + k, atol=after.resolution_mm)
    np.testing.assert_allclose(deep_a[:, [0, 3, 5]], 0.0, atol=0)
    d = json.loads((tmp_path / "out.json").read_text())
    assert d["max_displacement"] == pytest.approx(abs(k), abs=1e-9)


def test_depth_field_follows_b_along_split_moves():
    from ncadapt import nc

    f = pw.DepthField([0, 20, 0, 20], [0, 0, 30, 30], [0.0, 0.2, 0.0, 0.2], diameter=1000)  # K = 0.01·B
    p = nc.parse("G21 G90 G94\nG0 X0 Y0 Z10 B0\nG1 Y5 F500\nG1 B10 Z20\nM2\n").correct(f, max_segment=1.0)
    c = p.correction
    b = c.points[:, 2] - 10  # B = Z − 10 along the last move
    last = c.line == 4
    np.testing.assert_allclose(c.displacements[last, 1], 0.01 * b[last], atol=1e-12)
    assert "B10" in p.text.splitlines()[3] or "B10.0" in p.text


def test_correct_refuses_points_outside_the_measurement(tmp_path):
    prog = tmp_path / "cell.ngc"
    prog.write_text(sw.cell_program(0, 5))  # B 75..90, the log covers 0..15
    _tracking(tmp_path / "log.csv", 0.05)
    r = _cli(
        "waffle",
        "correct",
        prog,
        "--tracking",
        tmp_path / "log.csv",
        "--tool-radius",
        10,
        "--diameter",
        1500,
        "-o",
        tmp_path / "out.ngc",
    )
    assert r.exit_code == 1 and "outside" in r.output
    assert not (tmp_path / "out.ngc").exists()


# ------------------------------------------------------------------------------ self-tuning and the testbed
def test_self_tuning_retunes_on_either_side_of_the_band():
    s = pw.SelfTuning(2.0, 0.3, 1.97, 2.03)
    assert s.needs_semi_finish
    np.testing.assert_allclose(s.tune(np.array([2.35, 2.31])), [0.05, 0.01])
    assert not s.finished([2.0, 2.02])
    assert s.finished([2.0, 2.031])  # only the max leaves the band: retune (the paper's "and" would not)
    s.tune([2.3, 2.3])
    assert s.finished([1.969, 2.0])
    assert s.retunes == 2


def test_testbed_targets_on_three_seeds():
    """make bench runs the twenty seeds."""
    for seed in (1, 2, 3):
        r = {st: sw.simulate(st, seed).as_dict() for st in sw.STRATEGIES}
        assert r["combined"]["rms_error"] <= 0.3 * r["none"]["rms_error"]
        assert r["combined"]["retunes"] <= 0.55 * r["combined"]["cells_total"]  # 49 of 96 at most over 20 seeds
        assert r["combined"]["rms_error"] < min(r["disturbance"]["rms_error"], r["self-tuning"]["rms_error"])
        assert r["none"]["rms_error"] == pytest.approx(r["combined"]["rms_error_uncorrected"])


def test_simulate_cli_json_and_report(tmp_path):
    r = _cli(
        "waffle",
        "simulate",
        "--strategy",
        "combined",
        "--seed",
        2,
        "--json",
        tmp_path / "w.json",
        "--report",
        tmp_path / "w.html",
    )
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "w.json").read_text())
    assert {"strategy", "rms_error", "max_abs_error", "retunes", "cells"} <= set(d)
    assert len(d["cells"]) == sw.ROWS * sw.CELLS and d["rms_error"] == sw.simulate("combined", 2).as_dict()["rms_error"]
    html = (tmp_path / "w.html").read_text()
    assert html.count("data:image/png") == 2 and "self-tuning" in html


@pytest.mark.parametrize("layout", ["pass", "grid", "scattered"])
def test_depth_field_extrapolates_a_plane_as_the_plane(layout):
    """outside="extrapolate": a correction linear in (s, Z) continues as that plane beyond the
    measured area (a single pass: along B only)."""
    from ncadapt.processes.waffle import DepthField

    D = 360 / np.pi  # 1 mm of arc per degree
    if layout == "pass":
        b = np.linspace(0, 10, 6)
        z = np.full_like(b, 5.0)
    elif layout == "grid":
        B, Z = np.meshgrid(np.linspace(0, 10, 6), np.linspace(0, 4, 5))
        b, z = B.ravel(), Z.ravel()
    else:
        rng = np.random.default_rng(3)
        b, z = rng.uniform(0, 10, 40), rng.uniform(0, 4, 40)
    k = 0.01 * b - 0.02 * z + 0.1
    f = DepthField(b, z, k, diameter=D, outside="extrapolate")
    qb, qz = np.array([-2.0, 12.0, 5.0]), np.array([5.0, 5.0, 5.0]) if layout == "pass" else np.array([-1.0, 6.0, 2.0])
    want = 0.01 * qb - 0.02 * qz + 0.1
    np.testing.assert_allclose(f.values(qb, qz), want, atol=1e-6 if layout != "scattered" else 2e-4)
    with pytest.raises(Exception, match="measured area"):
        DepthField(b, z, k, diameter=D, outside="error").values(qb, qz)
