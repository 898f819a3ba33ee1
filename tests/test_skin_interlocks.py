"""The live loop's interlocks (issue 21 item 1), fallbacks counted once per step (item 4), the
offline mode's limits and second round (item 6), and option bounds found by the CLI fuzzer."""

from __future__ import annotations

import asyncio
import csv
import json
import threading

import numpy as np
import pytest
from click.testing import CliRunner

from helpers import skin_server
from ncadapt import loop as lp
from ncadapt.processes import skin as ps
from ncadapt.sim import skin as sk

T_G, A_G = 1.5, 0.5
METHODS = ("mirror", "secant", "kalman")


def _cli(*args):
    from ncadapt.cli import main

    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _gauge(path, readings):
    path.write_text("thickness\n" + "".join(f"{r}\n" for r in readings))
    return path


def _offsets(path):
    rows = list(csv.reader(path.read_text().splitlines()))
    assert rows[0][-1] == "w1_offset"
    return [r[-1] for r in rows[1:]]


# ------------------------------------------------------------------------------ the cases
@pytest.mark.parametrize("method", METHODS)
def test_six_readings_of_2mm_command_nothing(tmp_path, method):
    """Issue 21: six readings of 2.0 mm (0.5 mm above the target, outside the gauge's 0.3 mm
    tolerance) used to command W1 +0.5 … +3.0 mm. They are rejected: no command, W1 stays 0."""
    g = _gauge(tmp_path / "g.csv", [2.0] * 6)
    r = _cli(
        "skin",
        "loop",
        "--method",
        method,
        "--replay",
        g,
        "-o",
        tmp_path / "w.csv",
        "--target",
        T_G,
        "--depth",
        A_G,
        "--json",
        tmp_path / "w.json",
    )
    assert r.exit_code == 0, r.output
    assert _offsets(tmp_path / "w.csv") == [""] * 6
    d = json.loads((tmp_path / "w.json").read_text())
    assert (d["steps"], d["rejected"], d["max_abs_w1"]) == (0, 6, 0.0)


@pytest.mark.parametrize("method", METHODS)
def test_negative_and_huge_readings_are_rejected(tmp_path, method):
    """A reading of −1 gave W1 −0.5 mm and one of 100 gave +0.4 mm: both rejected, the command
    in force is held; the good readings step as the mirror would (closed form for the mirror)."""
    g = _gauge(tmp_path / "g.csv", [-1, 1.52, 100, "nan", "inf", 0, 1.51])
    r = _cli(
        "skin",
        "loop",
        "--method",
        method,
        "--replay",
        g,
        "-o",
        tmp_path / "w.csv",
        "--target",
        T_G,
        "--depth",
        A_G,
        "--json",
        tmp_path / "w.json",
    )
    assert r.exit_code == 0, r.output
    off = _offsets(tmp_path / "w.csv")
    assert [i for i, v in enumerate(off) if v] == [1, 6]
    d = json.loads((tmp_path / "w.json").read_text())
    assert (d["steps"], d["rejected"]) == (2, 5)
    assert d["max_abs_w1"] <= 0.25 + 1e-12  # the default step bound, twice at most from 0... and far below 0.5
    if method == "mirror":
        assert [float(v) for v in off if v] == pytest.approx([0.02, 0.03], abs=1e-12)
        assert d["max_abs_w1"] == pytest.approx(0.03)


def test_stuck_gauge(tmp_path):
    """N identical readings in a row: the N-th and later are rejected (default N = 5)."""
    g = _gauge(tmp_path / "g.csv", [1.6] * 7 + [1.55])
    r = _cli(
        "skin",
        "loop",
        "--method",
        "mirror",
        "--replay",
        g,
        "-o",
        tmp_path / "w.csv",
        "--target",
        T_G,
        "--depth",
        A_G,
        "--json",
        tmp_path / "w.json",
    )
    assert r.exit_code == 0, r.output
    off = _offsets(tmp_path / "w.csv")
    assert [float(v) for v in off[:4]] == pytest.approx([0.1, 0.2, 0.3, 0.4])
    assert off[4:7] == ["", "", ""] and float(off[7]) == pytest.approx(0.45)
    assert json.loads((tmp_path / "w.json").read_text())["rejected"] == 3


def test_w1_and_its_step_are_bounded(tmp_path):
    """Readings 0.29 mm too thick, over and over (varying, so not stuck): the mirror would
    command 0.29, 0.58, 0.87 … mm; with --w1-step-max 0.1 and --w1-max 0.35 it commands 0.1, 0.2,
    0.3, 0.35, 0.35."""
    g = _gauge(tmp_path / "g.csv", [1.79, 1.789, 1.79, 1.789, 1.79])
    r = _cli(
        "skin",
        "loop",
        "--method",
        "mirror",
        "--replay",
        g,
        "-o",
        tmp_path / "w.csv",
        "--target",
        T_G,
        "--depth",
        A_G,
        "--w1-max",
        0.35,
        "--w1-step-max",
        0.1,
        "--json",
        tmp_path / "w.json",
    )
    assert r.exit_code == 0, r.output
    assert [float(v) for v in _offsets(tmp_path / "w.csv")] == pytest.approx([0.1, 0.2, 0.3, 0.35, 0.35])
    d = json.loads((tmp_path / "w.json").read_text())
    # the step bound is the compensator's own (a fallback per bounded step), |W1| the guard's
    assert d["max_abs_w1"] == pytest.approx(0.35) and (d["fallbacks"], d["clamped"]) == (5, 2)
    # the default bound: min(2 a_g, T_g / 2) = 0.75 mm, and a bound that would cut through is refused
    r = _cli("skin", "loop", "--replay", g, "-o", tmp_path / "w.csv", "--target", T_G, "--depth", A_G, "--w1-max", 1.5)
    assert r.exit_code == 2 and "--w1-max" in r.output and "cut through" in r.output


def test_the_compensator_continues_from_the_bounded_command():
    """The guard sets the compensator's depth to the bounded command: the mirror's next step
    starts from what the machine does (a_p = a_g + W1 held), not from its own unbounded value."""
    g = ps.Interlocks(T_G, A_G, w1_step_max=0.1)
    c = ps.MirrorCompensator(A_G)
    c.step(0.25)
    assert g.bound(c) == pytest.approx(0.1) and c.depth == pytest.approx(A_G + 0.1)
    c.step(0.0)
    assert g.bound(c) == pytest.approx(0.1)


@pytest.mark.parametrize("method", METHODS)
def test_persistent_faults_stop_the_loop_and_write_nothing(tmp_path, method):
    """--max-faults rejected readings in a row stop the loop: exit 1 (a safety refusal) naming
    the line, W1 held, nothing written."""
    g = _gauge(tmp_path / "g.csv", [1.52, 1.51, 2.0, 2.0, 2.0, 1.5])
    out = tmp_path / "w.csv"
    r = _cli(
        "skin",
        "loop",
        "--method",
        method,
        "--replay",
        g,
        "-o",
        out,
        "--target",
        T_G,
        "--depth",
        A_G,
        "--max-faults",
        3,
        "--json",
        tmp_path / "w.json",
    )
    assert r.exit_code == 1, r.output
    assert f"{g}:6: loop stopped after 3 rejected readings in a row" in r.output
    assert "W1 held at +0.0" in r.output
    assert not out.exists() and not (tmp_path / "w.json").exists()


def test_in_process_testbed_runs_behind_the_same_interlocks():
    """The testbed's loop goes through the defaults and never needs them to bind (no clamped
    command; |W1| below the default 0.75 mm)."""
    d = sk.run("kalman", seed=2).as_dict()
    assert d["clamped"] == 0 and 0.3 < d["max_abs_w1"] < ps.default_w1_max(sk.T_TARGET, sk.A_G)


def test_a_gauge_gone_wild_in_the_testbed_stops_the_loop():
    """A machine whose gauge reads 100 mm from the 40th reading on (lost coupling): the loop stops
    after 10 faults with W1 held at the last good command."""
    m = sk.machines(seed=1)[0]
    readings = iter(range(10**6))
    real = m.advance

    def advance():
        t = real()
        return 100.0 if next(readings) >= 40 else t

    m.advance = advance
    g = ps.Interlocks(sk.T_TARGET, sk.A_G)
    c = sk.compensator("kalman")
    with pytest.raises(ps.LoopStopped) as e:
        lp.run_in_process(m, c, sk.T_TARGET, sk.A_G, guard=g)
    assert e.value.faults == 10 and e.value.index == 49
    assert e.value.w1 == pytest.approx(c.w1_offset) and g.rejected == 10


def test_opcua_fault_reaches_the_controller():
    """Over OPC UA the same guard stops the loop and sets Fault on the controller, which holds W1
    and stops feeding."""
    pytest.importorskip("asyncua")
    ms = sk.machines(seed=1)
    real = ms[0].advance
    count = iter(range(10**6))
    ms[0].advance = lambda: 100.0 if next(count) >= 20 else real()
    url = "opc.tcp://127.0.0.1:48415/ncadapt/"
    ready, status, errors = threading.Event(), {}, []

    def server():
        try:
            asyncio.run(lp.serve_machine(ms, sk.A_G, endpoint=url, ready=ready, status=status))
        except Exception as err:  # pragma: no cover
            errors.append(err)
            ready.set()

    th = threading.Thread(target=server, daemon=True)
    th.start()
    assert ready.wait(20)
    info: dict = {}
    with pytest.raises(ps.LoopStopped):
        asyncio.run(
            lp.run_opcua(
                url,
                lambda: sk.compensator("kalman"),
                sk.T_TARGET,
                latencies=[],
                make_guard=lambda: ps.Interlocks(sk.T_TARGET, sk.A_G, max_faults=4),
                info=info,
            )
        )
    th.join(20)
    assert not errors and status.get("fault") is True
    assert info["rejected"] == 4 and info["pockets"] == 2  # the pocket count read from the controller


def test_connect_retries_until_the_server_is_up():
    """`skin loop --connect-timeout`: a server that starts 1.5 s after the client is reached."""
    pytest.importorskip("asyncua")
    import time

    ms = sk.machines(seed=3)
    url = "opc.tcp://127.0.0.1:48416/ncadapt/"

    def server():
        time.sleep(1.5)
        asyncio.run(lp.serve_machine(ms, sk.A_G, endpoint=url))

    th = threading.Thread(target=server, daemon=True)
    th.start()
    t0 = time.monotonic()
    steps = asyncio.run(
        lp.run_opcua(
            url,
            lambda: sk.compensator("kalman"),
            sk.T_TARGET,
            connect_timeout=20,
            make_guard=lambda: ps.Interlocks(sk.T_TARGET, sk.A_G),
        )
    )
    th.join(20)
    assert time.monotonic() - t0 > 1.5
    assert steps == sk.run("kalman", seed=3).steps


def test_unreachable_controller_after_the_connect_timeout():
    import time

    url = "opc.tcp://127.0.0.1:48417/ncadapt/"  # nothing listens here
    t0 = time.monotonic()
    r = _cli("skin", "loop", "--opcua", url, "--target", 1.5, "--depth", A_G, "--connect-timeout", 1, "--insecure")
    assert r.exit_code == 2 and r.output.startswith(f"{url}: error: cannot reach the controller")
    assert 0.5 < time.monotonic() - t0 < 10


# ------------------------------------------------------------------------------ item 4
def test_fallbacks_are_counted_once_per_step():
    """A secant step whose slope is rejected *and* whose step is bounded is one fallback (it was
    counted twice: 3 steps, 4 fallbacks)."""
    c = ps.SecantCompensator(A_G, noise=0.001, max_step=0.05)
    c.step(0.2)  # the mirror step, bounded to 0.05: a fallback
    c.step(0.2)  # dδ = 0 ≤ 3σ: the slope is rejected, and the mirror step is bounded again
    c.step(0.2)
    assert c.steps == 3 and c.fallbacks == 3
    k = ps.KalmanCompensator(A_G, max_step=0.01)
    for _ in range(5):
        k.step(0.45)  # κ = 0.9 + … clamped, and the step bounded
    assert k.fallbacks <= k.steps == 5


# ------------------------------------------------------------------------------ fuzz findings
@pytest.mark.parametrize(
    "args",
    [
        ("loop", "--target", 1.5, "--depth", "1e-245", "--replay", "G", "-o", "O"),
        ("loop", "--target", "1e308", "--depth", 0.5, "--replay", "G", "-o", "O"),
        ("loop", "--target", 1.5, "--depth", 0.5, "--noise", "1e-300", "--replay", "G", "-o", "O"),
        ("simulate", "--latency-ms", "1.8e308"),
        ("simulate", "--noise", "1e300"),
        ("correct", "P", "--thickness", "M", "--target", "1e308", "--allowance", "1e308", "-o", "O"),
    ],
)
def test_physical_bounds_of_the_options(tmp_path, args):
    g = _gauge(tmp_path / "g.csv", [1.5, 1.51])
    (tmp_path / "p.ngc").write_text(sk.finishing_program(0, 0.5))
    (tmp_path / "m.csv").write_text("x,y,thickness\n300,500,1.7\n600,500,1.7\n300,700,1.7\n")
    sub = {"G": g, "O": tmp_path / "o.csv", "P": tmp_path / "p.ngc", "M": tmp_path / "m.csv"}
    r = _cli("skin", *[sub.get(a, a) for a in args])
    assert r.exit_code == 2, r.output
    assert "Invalid value for '--" in r.output and "Traceback" not in r.output
    assert not (tmp_path / "o.csv").exists()


def test_a_thickness_map_with_a_negative_thickness_is_located(tmp_path):
    (tmp_path / "p.ngc").write_text(sk.finishing_program(0, 0.5))
    (tmp_path / "m.csv").write_text("x,y,thickness\n300,500,1.7\n600,500,-1.7\n300,700,1.7\n")
    r = _cli(
        "skin",
        "correct",
        tmp_path / "p.ngc",
        "--thickness",
        tmp_path / "m.csv",
        "--target",
        1.5,
        "-o",
        tmp_path / "o.ngc",
    )
    assert r.exit_code == 2 and f"{tmp_path / 'm.csv'}:3:" in r.output and "> 0" in r.output


# ------------------------------------------------------------------------------ item 6
def test_offline_second_round_on_the_testbed(tmp_path):
    """Round 1 (map after a 0.3 mm semi-finishing pass, allowance 0.2) brings the pocket inside the
    ±0.1 mm tolerance on the testbed with constant-force supports (0.011 mm at the centre, 0.028 mm
    at most); a second round (measure, correct the corrected program with --allowance 0) re-cuts
    a few µm with almost no cutting force while the supports still push 75 N: the wall is pushed
    onto the cutter and over-cut (−0.147 mm at the centre). Thicknesses come from the testbed's cut
    (`recut`), not from the corrector."""
    seed = 1
    m1 = sk.thickness_map(0.3, seed=seed)
    x, y = m1[:, 0], m1[:, 1]
    cx, cy = sk.POCKETS[0]
    lx, ly = x - cx, y - cy
    t_s = sk.T_INITIAL + sk.thickness_variation(seed)(x, y)
    t_semi = sk.recut(lx, ly, t_s, 0.3, t_s)
    pts = np.column_stack([x, y, np.zeros_like(x)])

    def dz(rows, allowance):
        path = tmp_path / "map.csv"
        np.savetxt(path, rows, delimiter=",", header="x,y,thickness", comments="", fmt="%.6f")
        field, _ = ps.thickness_field(path, T_G, allowance=allowance)
        return field(pts)[:, 2]

    z1 = A_G - dz(m1, 0.2)  # the tool goes deeper by the excess (dz < 0 along −Z)
    t1 = sk.recut(lx, ly, t_semi, z1, t_s)
    centre = (lx == 0) & (ly == 0)
    assert (t1 - T_G)[centre][0] == pytest.approx(0.011, abs=0.002)
    assert np.abs(t1 - T_G).max() < 0.03  # inside the tolerance after one round
    rng = np.random.default_rng(11)
    m2 = np.column_stack([x, y, t1 + rng.normal(0, 0.005, x.shape)])
    z2 = z1 - dz(m2, 0.0)
    t2 = sk.recut(lx, ly, t1, z2, t_s)
    assert (t2 - T_G)[centre][0] == pytest.approx(-0.147, abs=0.005)  # over-cut: do not offer a 2nd round blindly


def test_recut_is_the_testbeds_cut_law():
    """recut from the roughed floor equals the uncompensated error law, and a pass that does not
    reach the floor removes nothing."""
    a = np.array([0.2, 0.5])
    np.testing.assert_allclose(sk.recut(0.0, 0.0, sk.T_INITIAL, a), sk.error(0.0, 0.0, a) + sk.T_TARGET, atol=1e-15)
    assert sk.recut(10.0, 5.0, 1.6, 0.0) == pytest.approx(1.6)  # the floor is at 0.4 mm: no contact
    # 0.1 mm short of a 1.6 mm floor, the supports (constant forces) push it onto the cutter anyway
    assert sk.recut(10.0, 5.0, 1.6, 0.3) < 1.6


def test_skin_correct_says_what_remains(tmp_path):
    (tmp_path / "p.ngc").write_text(sk.finishing_program(0, 0.5))
    m = sk.thickness_map(0.3, seed=1)
    np.savetxt(tmp_path / "m.csv", m, delimiter=",", header="x,y,thickness", comments="", fmt="%.6f")
    r = _cli(
        "skin",
        "correct",
        tmp_path / "p.ngc",
        "--thickness",
        tmp_path / "m.csv",
        "--target",
        1.5,
        "--allowance",
        0.2,
        "-o",
        tmp_path / "o.ngc",
    )
    assert r.exit_code == 0, r.output
    assert "not corrected: the finishing pass's own deflection" in r.output and "--allowance 0" in r.output


# ------------------------------------------------------------------------------ item 3: variants
def test_spiral_path_geometry():
    """The spiral out: inside the pocket's cutting area, 12.5 mm between rings, through the
    centre and the checkpoints (±75, ±50) exactly, (±100, 0) on the ring of half-size 100."""
    p = sk.spiral_path()
    assert np.abs(p[:, 0]).max() <= 140 and np.abs(p[:, 1]).max() <= 87.5
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    np.testing.assert_allclose(steps, sk.STEP, atol=1e-9)
    for x, y in ((0, 0), (75, 50), (-75, 50), (75, -50), (-75, -50), (100, 0), (-100, 0)):
        assert np.hypot(p[:, 0] - x, p[:, 1] - y).min() < 1e-9
    r = sk.readable(p)
    assert not r[0] and not r[-1] and r.mean() > 0.85


def test_fixed_rate_gauge_and_servo_closed_forms():
    """A fixed-rate gauge reads every round(v/(f·step)) samples; a first-order W1 servo reaches
    1 − e^(−t/τ) of a command's step after t."""
    m = sk.machines(seed=1, variant="fixed-rate")[0]
    m.advance()
    i0 = m.i
    m.advance()
    assert m.i - i0 == m.period and m.period in (4, 5)  # 25 mm/s at 20–25 Hz, 0.25 mm samples
    m = sk.machines(seed=1, variant="servo")[0]
    m.advance()
    m.command(sk.A_G + 0.1)
    start = m.i + m.lag
    while m.i < start + 3:
        m.advance()
    n = m.i - start
    dt = sk.STEP / sk.FEED
    expected = sk.A_G + 0.1 * (1 - np.exp(-n * dt / 0.030))
    assert m.a_eff == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("variant", ["spiral", "fast", "servo"])
def test_the_default_beats_the_mirror_on_the_fresh_gauge_variants(variant):
    """On 3 seeds here (20 in `make bench`): the default compensator with a fresh gauge (ours) has a
    smaller maximum error than the mirror on every variant, on the mean over the seeds. Not on
    every seed any more since the supports are constant forces: spiral seed 3, 23.4 vs 22.2 µm
    (docs/skin.md)."""
    assert ps.default_method("fresh") == "kalman"
    k = [sk.run("kalman", seed=seed, variant=variant).as_dict()["max_abs_error"] for seed in (1, 2, 3)]
    m = [sk.run("mirror", seed=seed, variant=variant).as_dict()["max_abs_error"] for seed in (1, 2, 3)]
    assert np.mean(k) < np.mean(m), (variant, k, m)


def test_a_fixed_rate_gauge_gets_the_mirror():
    """On a fixed-rate gauge the Kalman filter identifies κ from readings cut at older depths and
    runs away (the interlocks stop it); the default there is the mirror, which holds."""
    assert ps.default_method("fixed-rate") == "mirror"
    k = sk.run("kalman", seed=1, variant="fixed-rate").as_dict()
    m = sk.run("mirror", seed=1, variant="fixed-rate").as_dict()
    assert m["max_abs_error"] < 0.02 < k["max_abs_error"]
    r = _cli("skin", "simulate", "--variant", "fixed-rate", "--seed", 1)
    assert r.exit_code == 0 and r.output.startswith("mirror (fixed-rate):")


# ------------------------------------------------------------------------------ item 2: watchdogs
def test_a_killed_client_leaves_the_server_holding_w1(tmp_path):
    """`skin serve` with a client that reads one reading and dies: after --ack-timeout the
    controller holds W1, stops and exits 1 (it hung forever)."""
    import time

    pytest.importorskip("asyncua")
    url = "opc.tcp://127.0.0.1:48418/ncadapt/"
    srv = skin_server("--endpoint", url, "--ack-timeout", "1", "--insecure", "--json", tmp_path / "s.json")
    try:
        assert srv.stderr.readline().startswith("serving")

        async def die_after_one():
            client = await lp.connect(url, 10)
            idx = await client.get_namespace_index(lp.NAMESPACE)
            obj = await client.nodes.objects.get_child(f"{idx}:Controller")
            seq = await obj.get_child(f"{idx}:Sequence")
            while await seq.read_value() == 0:
                await asyncio.sleep(0.01)
            await client.disconnect()  # and never acknowledges

        t0 = time.monotonic()
        asyncio.run(die_after_one())
        out, err = srv.communicate(timeout=30)
    finally:
        srv.kill()
        srv.communicate()
    assert srv.returncode == 1, err
    assert "stopped acknowledging" in err and time.monotonic() - t0 < 20
    assert not (tmp_path / "s.json").exists()


def test_a_killed_server_stops_the_client():
    """`skin loop --opcua` against a server killed mid-run: exit 1 within the stale timeout and
    the request timeout, saying the loop stopped."""
    import time

    pytest.importorskip("asyncua")
    url = "opc.tcp://127.0.0.1:48419/ncadapt/"
    srv = skin_server("--endpoint", url, "--insecure")
    try:
        assert srv.stderr.readline().startswith("serving")
        threading.Timer(1.0, srv.kill).start()
        t0 = time.monotonic()
        r = _cli(
            "skin",
            "loop",
            "--opcua",
            url,
            "--target",
            sk.T_TARGET,
            "--depth",
            sk.A_G,
            "--stale-timeout",
            1,
            "--insecure",
        )
    finally:
        srv.kill()
        srv.communicate()
    assert r.exit_code == 1, r.output
    assert "the loop stopped" in r.output and time.monotonic() - t0 < 20


def test_secured_exchange_equals_the_in_process_run(tmp_path, monkeypatch):
    """Basic256Sha256 SignAndEncrypt with certificates (`skin certs`) and a user and password: the
    run equals the in-process one; a wrong password, a client without security and a command
    without either --insecure or the credentials are refused (exit 2)."""

    pytest.importorskip("asyncua")
    r = _cli("skin", "certs", tmp_path)
    assert r.exit_code == 0, r.output
    assert (tmp_path / "client.pem").stat().st_mode & 0o077 == 0  # a private key: its owner's only
    url = "opc.tcp://127.0.0.1:48420/ncadapt/"
    env = dict(__import__("os").environ, NCADAPT_OPCUA_PASSWORD="s3cret")
    srv = skin_server(
        "--endpoint",
        url,
        "--seed",
        "4",
        "--cert",
        tmp_path / "controller.der",
        "--key",
        tmp_path / "controller.pem",
        "--user",
        "op",
        "--json",
        tmp_path / "srv.json",
        env=env,
    )
    client = (
        "--cert",
        tmp_path / "client.der",
        "--key",
        tmp_path / "client.pem",
        "--server-cert",
        tmp_path / "controller.der",
        "--user",
        "op",
    )
    common = ("skin", "loop", "--opcua", url, "--target", sk.T_TARGET, "--depth", sk.A_G)
    try:
        assert "Basic256Sha256 SignAndEncrypt" in srv.stderr.readline()
        monkeypatch.setenv("NCADAPT_OPCUA_PASSWORD", "wrong")
        r = _cli(*common, *client)
        assert r.exit_code == 2 and "refused the session" in r.output and "BadUserAccessDenied" in r.output
        r = _cli(*common, "--insecure")
        assert r.exit_code == 2 and "refused the session" in r.output
        r = _cli(*common)
        assert r.exit_code == 2 and "--insecure" in r.output
        monkeypatch.setenv("NCADAPT_OPCUA_PASSWORD", "s3cret")
        r = _cli(*common, *client, "--json", tmp_path / "cl.json")
        assert r.exit_code == 0, r.output
        out, err = srv.communicate(timeout=60)
    finally:
        srv.kill()
        srv.communicate()
    assert srv.returncode == 0, err
    ref = sk.run("kalman", seed=4).as_dict()
    assert json.loads((tmp_path / "srv.json").read_text())["checkpoints"] == ref["checkpoints"]
    assert json.loads((tmp_path / "cl.json").read_text())["steps"] == ref["compensator_steps"]


def test_trust_lists_on_both_sides(tmp_path, monkeypatch):
    """`skin serve --trust DIR` accepts only the client certificates in DIR, and `skin loop`
    refuses a controller presenting another certificate than --server-cert. Two pairs from
    `skin certs` differ only in their keys (same names and URIs): a client with the other pair's
    certificate is refused, and both sides say so; the trusted one runs the pockets."""
    pytest.importorskip("asyncua")
    for name in ("a", "b", "trust"):
        (tmp_path / name).mkdir()
    for name in ("a", "b"):
        assert _cli("skin", "certs", tmp_path / name).exit_code == 0
    (tmp_path / "trust" / "client.der").write_bytes((tmp_path / "a" / "client.der").read_bytes())
    monkeypatch.setenv("NCADAPT_OPCUA_PASSWORD", "s3cret")
    a, b = tmp_path / "a", tmp_path / "b"
    serve = ("--cert", a / "controller.der", "--key", a / "controller.pem", "--user", "op")
    r = _cli("skin", "serve", *serve, "--trust", a)  # a private key in the trust folder
    assert r.exit_code == 2 and "not a certificate" in r.output and "client.pem" in r.output
    r = _cli("skin", "serve", "--insecure", "--trust", tmp_path / "trust")
    assert r.exit_code == 2 and "--trust" in r.output
    url = "opc.tcp://127.0.0.1:48421/ncadapt/"
    env = dict(__import__("os").environ, NCADAPT_OPCUA_PASSWORD="s3cret")
    srv = skin_server("--endpoint", url, *serve, "--trust", tmp_path / "trust", "--ack-timeout", 120, env=env)
    common = ("skin", "loop", "--opcua", url, "--target", sk.T_TARGET, "--depth", sk.A_G, "--user", "op")

    def client(pair, server_pair):
        return (
            "--cert",
            pair / "client.der",
            "--key",
            pair / "client.pem",
            "--server-cert",
            server_pair / "controller.der",
        )

    try:
        assert "client certificates trusted from" in srv.stderr.readline()
        r = _cli(*common, *client(b, a))
        assert r.exit_code == 2, r.output
        assert url in r.output and "does not trust this client's certificate" in r.output
        line = srv.stderr.readline()
        assert "refused a client certificate" in line and "BadCertificateUntrusted" in line
        r = _cli(*common, *client(a, b))
        assert r.exit_code == 2, r.output
        assert url in r.output and "not the one given" in r.output and "--server-cert" in r.output
        r = _cli(*common, *client(a, a))
        assert r.exit_code == 0, r.output
        out, err = srv.communicate(timeout=60)
    finally:
        srv.kill()
        srv.communicate()
    assert srv.returncode == 0, err
