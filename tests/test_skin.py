"""Skin mirror milling: the compensators on closed-form plants, the testbed's calibration and
targets, and the loop over a real OPC UA server."""

from __future__ import annotations

import asyncio
import csv
import json
import threading

import numpy as np
import pytest

from conftest import needs_rs274
from helpers import skin_server
from ncadapt import loop as lp
from ncadapt.errors import InputError
from ncadapt.processes import skin as ps
from ncadapt.sim import skin as sk
from rs274 import canonical

A_G = 0.5


def _linear(kappa):
    """δ(a_p) for f = κ a_p: δ = a_g − (1 − κ) a_p."""
    return lambda a: A_G - (1 - kappa) * a


def test_mirror_converges_linearly_by_f_prime():
    plant, c = _linear(0.4), ps.MirrorCompensator(A_G)
    d = plant(A_G)
    for _ in range(4):
        d_next = plant(c.step(d))
        assert d_next == pytest.approx(0.4 * d, rel=1e-12)  # δ_i+1 = f' δ_i
        d = d_next
    assert c.w1_offset == pytest.approx(c.depth - A_G)


def test_secant_is_exact_on_a_linear_plant_after_two_points():
    plant, c = _linear(0.45), ps.SecantCompensator(A_G, noise=0.0)
    a2 = c.step(plant(A_G))
    assert a2 == pytest.approx(A_G + plant(A_G))  # the second point is the mirror step
    a3 = c.step(plant(a2))
    assert plant(a3) == pytest.approx(0.0, abs=1e-15)
    assert a3 == pytest.approx(A_G / (1 - 0.45))
    assert c.fallbacks == 0


def test_secant_falls_back_and_bounds_its_steps():
    c = ps.SecantCompensator(A_G, noise=0.005)
    c.step(0.1)
    c.step(0.101)  # |Δδ| below 3σ: the mirror step
    assert c.fallbacks == 1
    c = ps.SecantCompensator(A_G, noise=0.0)
    c.step(0.1)
    c.step(0.2)  # δ grew as a_p grew: a slope of the wrong sign
    assert c.fallbacks == 1
    c = ps.MirrorCompensator(A_G, max_step=0.05)
    assert c.step(1.0) == pytest.approx(A_G + 0.05) and c.fallbacks == 1


def test_kalman_identifies_the_compliance_in_one_reading():
    plant, c = _linear(0.48), ps.KalmanCompensator(A_G, noise=0.0)
    a = c.step(plant(A_G))
    assert a == pytest.approx(A_G / (1 - 0.48), rel=1e-9) and plant(a) == pytest.approx(0, abs=1e-12)


def test_tracking_a_moving_root_the_secant_falls_back_to_the_mirror():
    """Along the path the root moves: with the supports' push growing, the deflection is
    f = s a_p − r i and δ_i = a_g − r i − (1 − s) a_p. The mirror's error then settles at
    −r/(1 − s) (δ_i+1 = −r + s δ_i); a secant through consecutive readings sees δ stop changing
    while a_p moves, a slope of 0, and falls back to the mirror step on every reading — both end
    at −r/(1 − s). Ours tracks it to round-off (a constant-velocity filter on the root has no
    steady error on a ramp), though its slope — the chord through the origin, here below s — is
    wrong for this wall: the slope scales only the correction, which vanishes."""
    s, r = 0.48, 0.002
    for comp in (ps.MirrorCompensator(A_G), ps.SecantCompensator(A_G, noise=0.0)):
        a, d = A_G, []
        for i in range(60):
            d.append(A_G - r * i - (1 - s) * a)
            a = comp.step(d[-1])
        assert d[-1] == pytest.approx(-r / (1 - s), rel=1e-12)
    assert comp.fallbacks >= comp.steps - 5
    for comp in (ps.KalmanCompensator(A_G, noise=1e-4), ps.MirrorCompensator(A_G)):
        a = A_G
        for i in range(100):
            d = A_G - r * i - (1 - s) * a
            a = comp.step(d)
        if comp.name == "kalman":
            assert abs(d) < 1e-12 and comp.fallbacks == 0
        else:
            assert d == pytest.approx(-r / (1 - s), rel=1e-9)


def test_ours_never_oversteps_on_a_wall_that_does_not_deflect_without_a_cut():
    """The chord f(a_p)/a_p is at most the slope f'(a_p) when f is convex with f(0) ≤ 0, so the
    correction δ/(1 − κ) never exceeds the Newton step δ/(1 − s): on affine walls f = c + s a_p
    with c ≤ 0 the loop converges to the root (a_g + c)/(1 − s), whatever c and s, and no later
    error exceeds the first."""
    for c in (0.0, -0.05, -0.2):
        for s in (0.1, 0.48, 0.8):
            comp = ps.KalmanCompensator(A_G, noise=1e-4)
            a, ds = A_G, []
            for _ in range(80):
                ds.append(A_G - (a - c - s * a))  # δ = a_g − a_r, a_r = a − f(a)
                a = comp.step(ds[-1])
            root = (A_G + c) / (1 - s)
            assert a == pytest.approx(root, abs=1e-10), (c, s)
            assert max(abs(d) for d in ds[1:]) <= abs(ds[0]), (c, s, ds[:6])


def test_csv_replay(tmp_path):
    """Recorded readings through the mirror: the offsets are the running sums of δ; a rejected
    (empty) reading leaves an empty row and no step."""
    src = tmp_path / "gauge.csv"
    src.write_text("thickness\n1.52\n\n1.51\n1.495\n")
    sink = lp.CsvSink(tmp_path / "w1.csv")
    n = lp.run(lp.CsvSource(src), sink, ps.MirrorCompensator(A_G), 1.5)
    sink.close()
    assert n == 3
    rows = [r[0] for r in csv.reader((tmp_path / "w1.csv").read_text().splitlines())]
    assert rows[0] == "w1_offset" and rows[2] == ""
    assert [float(r) for r in rows[1:] if r] == pytest.approx([0.02, 0.03, 0.025], abs=1e-12)
    src.write_text("t,thickness\n0,1.5\n1,abc\n")
    with pytest.raises(InputError, match=r"gauge.csv:3:3: .*column thickness.*'abc'"):
        lp.run(lp.CsvSource(src), lp.CsvSink(tmp_path / "x.csv"), ps.MirrorCompensator(A_G), 1.5)


@pytest.mark.parametrize("a, table", [(200.0, 0.00560), (400.0, 0.00722)])
def test_clamped_plate_matches_timoshenkos_table(a, table):
    """Centre deflection of a clamped rectangular plate under a central load, w = α P b²/D:
    Timoshenko and Woinowsky-Krieger, Table 35 (b/a = 1: 0.00560, 2: 0.00722; Roark's
    0.0611 and 0.0787 for ν = 0.3 give the same). The 5 mm grid is within 1.5 %; Richardson
    extrapolation from 10 and 5 mm (second-order scheme) within 0.5 %."""
    coarse = sk.plate_coefficients(a, 200.0, 10.0)[2].max()
    x, y, fine = sk.plate_coefficients(a, 200.0, 5.0)
    assert fine.max() == pytest.approx(table, rel=0.015)
    assert fine.max() + (fine.max() - coarse) / 3 == pytest.approx(table, rel=0.005)
    assert fine[np.argmin(abs(x)), np.argmin(abs(y))] == fine.max()  # largest at the centre
    assert not fine[0].any() and not fine[:, 0].any() and not fine[-1].any()  # clamped edges
    np.testing.assert_allclose(fine, fine[::-1, ::-1], rtol=1e-9)  # symmetric


@pytest.mark.parametrize("a, table", [(200.0, 0.00126), (300.0, 0.00220), (400.0, 0.00254)])
def test_clamped_plate_under_a_uniform_load_matches_timoshenkos_table(a, table):
    """Every column of the Green's function at once: the centre deflection of a clamped plate under
    a uniform load q is Σ_k α(centre; k) q h² b²/D = α' q b⁴/D, Timoshenko and Woinowsky-Krieger,
    Table 35 (b/a = 1: 0.00126, 1.5: 0.00220, 2: 0.00254); within 2 % on the 5 mm grid, 0.5 %
    after Richardson extrapolation from 10 and 5 mm."""

    def centre(h):
        x, y, g = sk.plate_green(a, 200.0, h)
        return g[np.argmin(abs(x)), np.argmin(abs(y))].sum() * h**2 / 200.0**2

    fine, coarse = centre(5.0), centre(10.0)
    assert fine == pytest.approx(table, rel=0.02)
    assert fine + (fine - coarse) / 3 == pytest.approx(table, rel=0.005)


def _navier(a, b, x, y, xi, eta, terms=400):
    """α = w D/(P b²) of a simply supported a × b plate, load at (ξ, η), deflection at (x, y)
    (centred coordinates): Navier's double series, Timoshenko and Woinowsky-Krieger § 34."""
    m = np.arange(1, terms + 1)[:, None]
    n = np.arange(1, terms + 1)[None, :]
    s = (
        np.sin(m * np.pi * (x + a / 2) / a)
        * np.sin(n * np.pi * (y + b / 2) / b)
        * np.sin(m * np.pi * (xi + a / 2) / a)
        * np.sin(n * np.pi * (eta + b / 2) / b)
        / ((m / a) ** 2 + (n / b) ** 2) ** 2
    )
    return 4 / (np.pi**4 * a * b) * s.sum() / b**2


@pytest.mark.parametrize(
    "load, at", [((0.0, 0.0), (50.0, -30.0)), ((-60.0, 20.0), (40.0, 50.0)), ((0.0, 0.0), (0.0, 0.0))]
)
def test_simply_supported_green_function_matches_navier(load, at):
    """Off the diagonal too: the finite-difference Green's function with simply supported edges
    against Navier's series on the pocket's 300 × 200 mm; within 1.5 % on the 5 mm grid, 0.3 % after
    Richardson extrapolation (the diagonal converges slower: 3 % and 1 %)."""

    def value(h):
        x, y, g = sk.plate_green(300.0, 200.0, h, "simple")
        i, j = (int(np.argmin(abs(x - v))) for v in (at[0], load[0]))
        k, m = (int(np.argmin(abs(y - v))) for v in (at[1], load[1]))
        return g[i, k, j, m]

    exact = _navier(300.0, 200.0, *at, *load)
    fine, coarse = value(5.0), value(10.0)
    tol = (0.03, 0.01) if load == at else (0.015, 0.003)
    assert fine == pytest.approx(exact, rel=tol[0])
    assert fine + (fine - coarse) / 3 == pytest.approx(exact, rel=tol[1])
    with pytest.raises(ValueError, match="edges must be"):
        sk.plate_green(300.0, 200.0, 10.0, "free")


def test_constant_force_supports_shift_the_deflection_and_leave_its_slope(monkeypatch):
    """Six supports of a constant 12.5 N, not a spring. With θ = 0 the cut is linear, and the real
    depth in closed form: a_r = (a_p + P_s ΣC_s)/(1 + K C) (K = dF/da, C and C_s the plate's
    compliances under the tool and from the supports): its slope does not depend on the supports'
    force; removing them deepens nothing but shifts every depth by the same P_s ΣC_s/(1 + K C)."""
    sk.support_radius()  # calibrated (and cached) with the testbed's θ
    monkeypatch.setattr(sk, "THETA", 0.0)
    x, y = 30.0, -20.0
    c, cs = sk.compliance(sk.alpha(x, y), 2.0), sk.compliance(sk.support_alpha(x, y), 2.0)
    k = float(sk.force(1.0))
    for a in (0.3, 0.5, 0.8):
        expected = (a + 12.5 * cs) / (1 + k * c)
        assert a - sk.deflection(x, y, a) == pytest.approx(expected, rel=1e-12)
    with_support = sk.deflection(x, y, 0.8) - sk.deflection(x, y, 0.5)
    monkeypatch.setattr(sk, "SUPPORT_FORCE", 0.0)
    assert sk.deflection(x, y, 0.8) - sk.deflection(x, y, 0.5) == pytest.approx(with_support, rel=1e-12)
    assert sk.deflection(x, y, 0.5) == pytest.approx(0.5 * k * c / (1 + k * c), rel=1e-12)
    assert sk.SUPPORTS * 12.5 == pytest.approx(6 * 0.05 * 250.0)  # 0.05 MPa on a piston of 250 mm²
    pts = sk.support_points(40.0)
    np.testing.assert_allclose(np.hypot(*pts.T), 40.0)
    assert len(pts) == 6 and sk.support_alpha(150.0 - 1e-9, 0.0) == pytest.approx(0.0, abs=1e-12)  # at the wall


def test_thirteen_checkpoints_per_pocket_largest_at_the_centre():
    """13 per pocket, point 7 the centre; without compensation and in the paper's protocol with the
    mirror the largest error is at point 7 of each pocket, the smallest at a corner point."""
    assert len(sk.POINTS) == 13 and sk.POINTS[sk.CENTRE_POINT - 1] == (0.0, 0.0)
    assert len(sk.CHECKPOINTS) == 26 and len(set(sk.POINTS)) == 13
    none = sk.run("none", seed=1).as_dict()
    for pocket in (1, 2):
        cps = [c for c in none["checkpoints"] if c["pocket"] == pocket]
        assert [c["point"] for c in cps] == list(range(1, 14))
        assert max(cps, key=lambda c: abs(c["error"]))["point"] == 7
        assert min(cps, key=lambda c: abs(c["error"]))["point"] in (1, 5, 9, 13)
    mirror = sk.protocol("mirror")["checkpoints"]
    last = [abs(r["errors"][-1]) for r in mirror]
    assert mirror[int(np.argmax(last))]["point"] == 7 and len(mirror) == 26
    first = [abs(r["errors"][0]) for r in mirror]
    assert mirror[int(np.argmax(first))]["point"] == 7


def test_calibration_and_the_papers_protocol():
    """The two calibrated constants reproduce the paper's finite-element protocol at point 7: the
    mirror 32.2 µm after the second compensation (the ring radius, exact by construction), the
    secant 0.213 µm (θ = 0.031, rounded: within 1 %). The uncompensated error at the centre is
    0.142 mm, not the paper's 0.24 (documented): the bare plate without supports would give at most
    0.236 mm."""
    assert sk.support_radius() == pytest.approx(56.8, abs=0.1)
    mirror, secant = sk.protocol("mirror"), sk.protocol("secant")
    assert mirror["max_abs_error"] == pytest.approx(0.0322, rel=1e-6)
    assert secant["max_abs_error"] == pytest.approx(0.000213, rel=0.01)
    assert sk.error(0, 0, A_G) == pytest.approx(0.142, abs=0.001)
    assert abs(sk.error(150, 0, A_G)) < 1e-12
    assert sk.force(0.5) == pytest.approx(2 * 0.5 * (642.5 * 0.09375 / np.pi + 128.29 / 2))
    assert sk.deflection(0, 0, 1.0) > 2 * sk.deflection(0, 0, 0.5)  # the supports' push matters less


@pytest.mark.parametrize("noise, latency_ms, seeds", [(0.005, 45.0, 5), (0.010, 60.0, 3)])
def test_ours_beats_mirror_and_secant_on_the_testbed(noise, latency_ms, seeds):
    """The default (5 µm noise, 45 ms dead time; make bench runs twenty seeds) and the worst
    conditions ours is meant for (10 µm, 60 ms)."""
    res = {
        m: [sk.run(m, seed=s, noise=noise, latency_ms=latency_ms).as_dict() for s in range(1, seeds + 1)]
        for m in ("mirror", "secant", "kalman")
    }
    mx = {m: np.mean([r["max_abs_error"] for r in v]) for m, v in res.items()}
    mean = {m: np.mean([r["mean_abs_error"] for r in v]) for m, v in res.items()}
    assert mx["kalman"] < min(mx["mirror"], mx["secant"])
    assert mean["kalman"] < min(mean["mirror"], mean["secant"])


def test_uncompensated_run():
    none = sk.run("none", seed=1).as_dict()
    assert none["max_abs_error"] == pytest.approx(0.142, abs=0.02)  # uncompensated: point 7, ± the roughed variation
    assert none["fallbacks"] == 0 and none["compensator_steps"] == 0


def test_no_divergence_over_1e5_noisy_steps():
    rng = np.random.default_rng(3)
    kappa = 0.3 + 0.2 * np.sin(np.arange(100_000) / 500)
    noise = rng.normal(0, 0.005, 100_000)
    for method in ("mirror", "secant", "kalman"):
        c = ps.make(method, A_G, noise=0.005)
        a = A_G
        worst = 0.0
        for k in range(100_000):
            d = A_G - (1 - kappa[k]) * a
            if k > 100:
                worst = max(worst, abs(d))
            a = c.step(d + noise[k])
        assert worst < 0.1, method
        if method == "secant":
            assert c.fallbacks > 0


def test_opcua_loop_equals_the_in_process_run():
    """A real asyncua server on loopback plays the controller (the testbed's machines); the
    compensator runs as an OPC UA client. Same seed, same thicknesses, step for step."""
    pytest.importorskip("asyncua")
    ref = sk.run("kalman", seed=4)
    ms = sk.machines(seed=4)
    url = "opc.tcp://127.0.0.1:48411/ncadapt/"
    ready = threading.Event()
    errors = []

    def server():
        try:
            asyncio.run(lp.serve_machine(ms, sk.A_G, endpoint=url, ready=ready))
        except Exception as err:  # pragma: no cover - shown by the assertion below
            errors.append(err)
            ready.set()

    th = threading.Thread(target=server, daemon=True)
    th.start()
    assert ready.wait(20)
    lat: list = []
    steps = asyncio.run(
        lp.run_opcua(
            url,
            lambda: sk.compensator("kalman"),
            sk.T_TARGET,
            pockets=len(ms),
            latencies=lat,
            make_guard=lambda: ps.Interlocks(sk.T_TARGET, sk.A_G),
        )
    )
    th.join(20)
    assert not errors
    assert steps == ref.steps
    for m, err in zip(ms, ref.path_errors):
        np.testing.assert_array_equal(m.thickness - sk.T_TARGET, err)


def test_secant_stays_in_the_gauges_band_without_noise():
    # a noise-free loop: the spatial change of the compliance pollutes the two-point slope; the
    # slope bound (≥ 10 % of the mirror's gain) keeps the secant from stepping out of the gauge's band
    r = sk.run("secant", noise=0.0, seed=1).as_dict()
    m = sk.run("mirror", noise=0.0, seed=1).as_dict()
    assert r["rejected_readings"] == 0
    # inside the paper's ±0.1 mm, but on constant-force supports 3.9× the mirror's (67.7 vs 17.5 µm):
    # without noise every corrupted two-point slope passes the guard (docs/skin.md)
    assert r["max_abs_error"] < 0.1 and m["max_abs_error"] < r["max_abs_error"]


# ------------------------------------------------------------------------------ offline mode
def _skin_map(path, xs, ys, thickness):
    with open(path, "w") as f:
        f.write("x,y,thickness\n")
        for x in xs:
            for y in ys:
                f.write(f"{x},{y},{thickness(x, y)!r}\n")


def _cli(*args):
    from click.testing import CliRunner

    from ncadapt.cli import main

    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@needs_rs274
def test_skin_correct_constant_map_shifts_every_cut_by_the_excess(tmp_path):
    prog = tmp_path / "finish.ngc"
    prog.write_text(sk.finishing_program(0, 0.5))
    _skin_map(tmp_path / "map.csv", range(300, 601, 50), range(500, 701, 50), lambda x, y: 1.5 + 0.2 + 0.1)
    r = _cli(
        "skin",
        "correct",
        prog,
        "--thickness",
        tmp_path / "map.csv",
        "--target",
        1.5,
        "--allowance",
        0.2,
        "-o",
        tmp_path / "out.ngc",
        "--json",
        tmp_path / "out.json",
    )
    assert r.exit_code == 0, r.output
    before, after = canonical(prog), canonical(tmp_path / "out.ngc")
    assert before.error is None and after.error is None
    cut = after.ends[np.array(after.kinds) == "feed"]
    orig = before.ends[np.array(before.kinds) == "feed"]
    assert len(cut) == len(orig) == 30  # a constant shift keeps straight moves straight: nothing split
    np.testing.assert_allclose(cut[:, :2], orig[:, :2], atol=after.resolution_mm)
    np.testing.assert_allclose(cut[:, 2], orig[:, 2] - 0.1, atol=after.resolution_mm)  # 0.1 mm deeper
    d = json.loads((tmp_path / "out.json").read_text())
    assert d["excess_max"] == pytest.approx(0.1) and d["max_displacement"] == pytest.approx(0.1)


@needs_rs274
def test_skin_correct_scattered_linear_map_is_reproduced(tmp_path):
    # a thin-plate spline reproduces a linear map exactly: Z = −0.5 − (t − T) along the path
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(290, 610, 80), rng.uniform(490, 710, 80)])
    pts = np.vstack([pts, [[290, 490], [610, 490], [290, 710], [610, 710]]])
    t = lambda x, y: 1.5 + 1e-4 * (x - 300) - 5e-5 * (y - 600)  # noqa: E731
    with open(tmp_path / "map.csv", "w") as f:
        f.write("x,y,thickness\n" + "".join(f"{x:.17g},{y:.17g},{t(x, y):.17g}\n" for x, y in pts))
    prog = tmp_path / "finish.ngc"
    prog.write_text(sk.finishing_program(0, 0.5))
    r = _cli("skin", "correct", prog, "--thickness", tmp_path / "map.csv", "--target", 1.5, "-o", tmp_path / "out.ngc")
    assert r.exit_code == 0, r.output
    after = canonical(tmp_path / "out.ngc")
    cut = after.ends[np.array(after.kinds) == "feed"]
    np.testing.assert_allclose(cut[:, 2], -0.5 - (t(cut[:, 0], cut[:, 1]) - 1.5), atol=1e-4)


def test_skin_correct_errors_name_the_file_and_line(tmp_path):
    prog = tmp_path / "finish.ngc"
    prog.write_text(sk.finishing_program(0, 0.5))
    (tmp_path / "map.csv").write_text("x,y,thickness\n300,500,1.6\n600,500,abc\n")
    r = _cli("skin", "correct", prog, "--thickness", tmp_path / "map.csv", "--target", 1.5, "-o", tmp_path / "out.ngc")
    assert r.exit_code != 0 and "map.csv:3:" in r.output and "thickness" in r.output
    assert not (tmp_path / "out.ngc").exists()
    r = _cli("skin", "correct", prog, "--thickness", tmp_path / "map.csv", "--target", 1.5, "-o", prog)
    assert r.exit_code != 0 and "overwrite" in r.output


def test_simulate_cli_json_and_report(tmp_path):
    r = _cli(
        "skin",
        "simulate",
        "--method",
        "mirror",
        "--seed",
        2,
        "--json",
        tmp_path / "r.json",
        "--report",
        tmp_path / "r.html",
    )
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "r.json").read_text())
    ref = sk.run("mirror", seed=2).as_dict()
    assert d["max_abs_error"] == ref["max_abs_error"] and d["checkpoints"] == ref["checkpoints"]
    assert {"method", "max_abs_error", "min_abs_error", "mean_abs_error", "checkpoints", "fallbacks"} <= set(d)
    assert len(d["checkpoints"]) == 26 and {"x", "y", "error"} <= set(d["checkpoints"][0])
    html = (tmp_path / "r.html").read_text()
    assert all(f"<th>{m}</th>" in html for m in ("none", "mirror", "secant", "kalman"))


def test_loop_cli_replays_a_recording(tmp_path):
    """`skin loop --replay`: the mirror's offsets are the running sums of δ (closed form); a
    rejected reading leaves an empty offset; the log's other columns are kept as written, and a
    replayed output's w1_offset column is replaced."""
    gauge = tmp_path / "gauge.csv"
    gauge.write_text('t,thickness,note\n0.00,1.52,"a, b"\n0.05,,\n0.10,1.51,\n0.15,nan,\n0.20,1.495,x\n')
    r = _cli(
        "skin",
        "loop",
        "--method",
        "mirror",
        "--target",
        1.5,
        "--depth",
        A_G,
        "--replay",
        gauge,
        "-o",
        tmp_path / "w1.csv",
        "--json",
        tmp_path / "w1.json",
    )
    assert r.exit_code == 0, r.output
    rows = list(csv.reader((tmp_path / "w1.csv").read_text().splitlines()))
    assert rows[0] == ["t", "thickness", "note", "w1_offset"]
    assert [r[:3] for r in rows[1:]] == list(csv.reader(gauge.read_text().splitlines()))[1:]
    offsets = [r[3] for r in rows[1:]]
    assert offsets[1] == offsets[3] == ""
    assert [float(v) for v in offsets if v] == pytest.approx([0.02, 0.03, 0.025], abs=1e-12)
    r = _cli(
        "skin",
        "loop",
        "--method",
        "mirror",
        "--target",
        1.49,
        "--depth",
        A_G,
        "--replay",
        tmp_path / "w1.csv",
        "-o",
        tmp_path / "w1b.csv",
    )
    rows = list(csv.reader((tmp_path / "w1b.csv").read_text().splitlines()))
    assert rows[0] == ["t", "thickness", "note", "w1_offset"]
    assert [float(r[3]) for r in rows[1:] if r[3]] == pytest.approx([0.03, 0.05, 0.055], abs=1e-12)
    d = json.loads((tmp_path / "w1.json").read_text())
    assert (d["steps"], d["fallbacks"], d["method"]) == (3, 0, "mirror")
    assert d["w1_offset_min"] == pytest.approx(0.02) and d["w1_offset_max"] == pytest.approx(0.03)
    r = _cli("skin", "loop", "--target", 1.5, "--depth", A_G)
    assert r.exit_code == 2 and "exactly one of --replay FILE or --opcua URL" in r.output
    r = _cli("skin", "loop", "--target", 1.5, "--depth", A_G, "--replay", gauge)
    assert r.exit_code == 2 and "--replay and -o go together" in r.output


def test_serve_and_loop_clis_over_opcua_equal_the_in_process_run(tmp_path):
    """`skin serve` (a separate process playing the controller) and `skin loop --opcua` (the
    client): the checkpoint errors and the compensator's steps equal the in-process run."""

    pytest.importorskip("asyncua")
    url = "opc.tcp://127.0.0.1:48412/ncadapt/"
    srv = skin_server("--endpoint", url, "--seed", "4", "--insecure", "--json", tmp_path / "srv.json")
    try:
        line = srv.stderr.readline()
        assert line.startswith(f"serving the skin testbed at {url}"), line + srv.stderr.read()
        r = _cli(
            "skin",
            "loop",
            "--opcua",
            url,
            "--pockets",
            2,
            "--target",
            sk.T_TARGET,
            "--depth",
            sk.A_G,
            "--insecure",
            "--json",
            tmp_path / "cl.json",
        )
        assert r.exit_code == 0, r.output
        out, err = srv.communicate(timeout=60)
    finally:
        srv.kill()
    assert srv.returncode == 0, err
    ref = sk.run("kalman", seed=4).as_dict()
    served = json.loads((tmp_path / "srv.json").read_text())
    assert served["checkpoints"] == ref["checkpoints"]
    assert out.startswith(f"client: |error| at 2 × 13 checkpoints max {ref['max_abs_error'] * 1000:.1f} µm")
    client = json.loads((tmp_path / "cl.json").read_text())
    assert (client["steps"], client["fallbacks"]) == (ref["compensator_steps"], ref["fallbacks"])
    assert 0 < client["latency_median_ms"] <= client["latency_p99_ms"]


def test_loop_cli_names_an_unreachable_controller():
    url = "opc.tcp://127.0.0.1:48413/ncadapt/"  # nothing listens here
    r = _cli("skin", "loop", "--opcua", url, "--target", 1.5, "--depth", A_G, "--connect-timeout", 0, "--insecure")
    assert r.exit_code == 2 and r.output.startswith(f"{url}: error: cannot reach the controller")
