"""Precision bores: circle fits, the plan's formulas on hand-computed cases, the pass-by-pass
rules, the offset blocks, the virtual testbed's targets and the CLI."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import needs_rs274
from ncadapt import InputError
from ncadapt.cli import main
from ncadapt.processes import bore as pb
from ncadapt.sim import bore as sb


def test_circle_fit_closed_forms():
    phi = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    c = pb.fit_circle(3 + 20 * np.cos(phi), -2 + 20 * np.sin(phi))
    assert c.centre == pytest.approx((3, -2), abs=1e-12) and c.diameter == pytest.approx(40, abs=1e-12)
    assert c.roundness == pytest.approx(0, abs=1e-12)
    # three lobes of amplitude e: the least-squares circle has the mean radius, roundness 2e
    r = 20 + 0.004 * np.cos(3 * phi)
    c = pb.fit_circle(r * np.cos(phi), r * np.sin(phi))
    assert c.diameter == pytest.approx(40, abs=1e-9) and c.roundness == pytest.approx(0.008, abs=1e-9)
    with pytest.raises(InputError, match="at least 3"):
        pb.fit_circle([0, 1], [0, 1])
    with pytest.raises(InputError, match="collinear"):
        pb.fit_circle([0, 1, 2], [0, 1, 2])


def test_plan_by_hand():
    """Ø40 H9 → H6 (IT6 16 µm, IT9 62 µm), t0 0.5, z 0.1, δA 30 µm, δB 20 µm, k 0.25."""
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.030, 0.020, k=0.25)
    assert (p.it_final, p.it_prefinish) == (0.016, 0.062)
    assert p.applicable  # 10 µm ≤ 0.25 · 62 = 15.5 µm
    assert p.t_max == pytest.approx(0.5 * 0.25 * 0.016 / 0.062)  # 0.03226
    assert p.passes == 4 and p.depth_per_pass == pytest.approx(0.025)  # ⌈0.1 / 0.03226⌉ = ⌈3.1⌉
    c = 0.030 / 0.5  # compliance near A: the pre-finish deviation over its depth
    a1 = c * (0.025 + 0.030 + 0.030)  # the paper's (6): real depth t + δA (left) + δK1 = 5.1 µm
    a2 = c * (0.025 + (a1 - 0.030) + a1)  # real depth: t + what pass 1 left against its aim + δK2
    a3 = c * (0.025 + (a2 - a1) + a2)
    assert p.predicted[:3] == pytest.approx([a1, a2, a3], rel=1e-12)
    assert p.predicted[0] == pytest.approx(0.0051, rel=1e-12)
    b1 = 0.020 * (0.025 + 0.020 + 0.030) / 0.5  # near B: the same shift δK1 = δA
    assert p.predicted_b[0] == pytest.approx(b1, rel=1e-12)
    # the paper's (6)-(8), kept for reference; its closed form (9) is (7) with (6) substituted
    pa = p.predicted_paper
    assert pa[0] == pytest.approx(a1, rel=1e-12)
    assert pa[1] == pytest.approx(a1 * (0.025 + 2 * a1) / (0.025 + 0.060), rel=1e-12)  # (7)
    assert pa[1] == pytest.approx(0.030 * (0.025 + 2 * 0.030 * (0.025 + 0.060) / 0.5) / 0.5, rel=1e-12)  # (9)
    assert pa[1] * 1000 == pytest.approx(2.112, abs=5e-4)  # the 2.112 µm, both ways
    assert p.target_diameter == pytest.approx(40.008)
    assert not pb.plan(40, "H6", "H9", 0.5, 0.1, 0.030, 0.010).applicable  # 20 µm > 15.5 µm
    with pytest.raises(InputError, match="finer"):
        pb.plan(40, "H9", "H6", 0.5, 0.1, 0.03, 0.02)
    with pytest.raises(InputError, match="unknown fundamental deviation"):
        pb.plan(40, "X6", "H9", 0.5, 0.1, 0.03, 0.02)


def _probe_csv(tmp_path, diameters, zs=(55, 30, 5), name="probe.csv", centre=(0.0, 0.0)):
    phi = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    rows = ["plane,x,y,z"]
    for label, d, z in zip("AMB", diameters, zs):
        rows += [
            f"{label},{centre[0] + d / 2 * math.cos(f):.7f},{centre[1] + d / 2 * math.sin(f):.7f},{z}" for f in phi
        ]
    p = tmp_path / name
    p.write_text("\n".join(rows) + "\n")
    return p


def test_read_probe_orders_planes_and_names_lines(tmp_path):
    p = _probe_csv(tmp_path, (39.9, 39.95, 39.92), zs=(5, 30, 55))
    m = pb.read_probe(p)  # tool enters at the top: face A is the highest z
    assert [c.plane for c in m.circles] == ["B", "M", "A"]
    assert m.taper == pytest.approx(39.92 - 39.9, abs=1e-6) and m.barrel == pytest.approx(39.95 - 39.91, abs=1e-6)
    assert [c.plane for c in pb.read_probe(p, "bottom").circles] == ["A", "M", "B"]
    bad = tmp_path / "bad.csv"
    bad.write_text("plane,x,y,z\nA,1,0,0\nA,0,1,0\nA,-1,zero,0\n")
    with pytest.raises(InputError) as e:
        pb.read_probe(bad)
    assert e.value.line == 4
    bad.write_text("plane,x,y,z\nA,1,0,0\nA,0,1,0\nA,-1,0,0\nB,1,0,5\nB,0,1,5\n")
    with pytest.raises(InputError, match="'B' has 2 points") as e:
        pb.read_probe(bad)
    assert e.value.line == 5


def test_next_correction_rules(tmp_path):
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.030, 0.020)
    aim0 = p.nominal_diameter_after(0)  # 40.008 − 0.2
    m0 = pb.read_probe(_probe_csv(tmp_path, (aim0 - 0.060, aim0 - 0.050, aim0 - 0.070)))
    c = pb.next_correction(p, m0, 0)
    assert c.correction == pytest.approx(0.035)  # the largest of the three planes (B here)
    assert c.radial_position == pytest.approx(p.nominal_diameter_after(1) / 2 + 0.035)
    aim1 = p.nominal_diameter_after(1)
    m1 = pb.read_probe(_probe_csv(tmp_path, (aim1 - 0.002, aim1 + 0.004, aim1 + 0.006), name="p1.csv"))
    c = pb.next_correction(p, m1, 1, applied=0.035)
    assert c.correction == pytest.approx(0.001 + 0.035)  # near A: error + the shift it was made with
    assert c.rule == "deviation near face A"
    h = pb.next_correction(p, m0, 0, hardened=True)
    assert h.correction == 0.0
    with pytest.raises(InputError, match="pass must be"):
        pb.next_correction(p, m1, 4)


def test_offset_blocks():
    assert pb.offset_block(0.0031, controller="linuxcnc", tool=3, radius=6.0) == "G10 L1 P3 R5.9969"
    assert pb.offset_block(0.0031, controller="fanuc", tool=3) == "G10 L13 P3 R-0.0031"
    assert "+0.0062 mm on diameter" in pb.offset_block(0.0031, controller="plain")
    with pytest.raises(InputError, match="radius"):
        pb.offset_block(0.001, controller="linuxcnc")


def test_testbed_targets():
    """1000 applicable steel parts: ≥ 95 % inside H6 with form ≤ k·IT6 in the planned passes, and
    far fewer when the allowance is taken in one uncorrected pass."""
    r = sb.simulate(1000, seed=1)
    assert r["parts"] == 1000 and r["within_tolerance"] >= 0.95
    assert r["without_correction"]["within_tolerance"] <= 0.5 * r["within_tolerance"]
    assert r["mean_passes"] == 4  # ⌈0.1 / 0.0323⌉


def test_hardened_identifies_the_stiffness_ratio():
    """Pre-finished soft (k_c 2000), finished hardened (k_c 3200): compliance ratio 2000/3200 on the
    linear testbed, where the compliance is a ratio of k_c (on the beam testbed the identified ratio
    also carries the force law's non-linearity: see test_beam_testbed_reaches_h6)."""
    r = sb.simulate(200, seed=2, material="hardened", model="linear")
    assert r["stiffness_ratio_mean"] == pytest.approx(2000 / 3200, rel=0.05)
    assert r["within_tolerance"] >= 0.95


def test_cli_plan_next_simulate(tmp_path):
    run = CliRunner().invoke
    res = run(
        main,
        [
            "bore",
            "plan",
            "--diameter",
            "40",
            "--final",
            "H6",
            "--prefinish",
            "H9",
            "--t0",
            "0.5",
            "--allowance",
            "0.1",
            "--delta-a",
            "0.03",
            "--delta-b",
            "0.02",
            "--json",
            str(tmp_path / "plan.json"),
        ],
    )
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "plan.json").read_text())
    assert d["it_final"] == 0.016 and d["it_prefinish"] == 0.062 and d["passes"] == 4 and d["applicable"] is True
    assert d["depth_per_pass"] == pytest.approx(0.025) and d["predicted"][0] == pytest.approx(0.0051)
    assert d["t_max"] == pytest.approx(0.5 * 0.25 * 0.016 / 0.062)
    aim0 = 40.008 - 0.2
    probe = _probe_csv(tmp_path, (aim0 - 0.060, aim0 - 0.050, aim0 - 0.040))
    res = run(
        main,
        [
            "bore",
            "plan",
            "--diameter",
            "40",
            "--t0",
            "0.5",
            "--allowance",
            "0.1",
            "--measured",
            str(probe),
            "--json",
            str(tmp_path / "plan2.json"),
        ],
    )
    assert res.exit_code == 0, res.output
    d2 = json.loads((tmp_path / "plan2.json").read_text())
    assert d2["delta_a"] == pytest.approx(0.030, abs=1e-6) and d2["delta_b"] == pytest.approx(0.020, abs=1e-6)
    res = run(
        main,
        [
            "bore",
            "next",
            "--plan",
            str(tmp_path / "plan.json"),
            "--measured",
            str(probe),
            "--pass",
            "0",
            "--controller",
            "linuxcnc",
            "--tool-radius",
            "6",
            "--json",
            str(tmp_path / "next.json"),
        ],
    )
    assert res.exit_code == 0, res.output
    n = json.loads((tmp_path / "next.json").read_text())
    assert n["correction"] == pytest.approx(0.030, abs=1e-6) and n["block"] == "G10 L1 P1 R5.9700"
    # the plan saved by an editor that writes a byte-order mark reads the same; a broken one is located
    bom = tmp_path / "plan_bom.json"
    bom.write_bytes(b"\xef\xbb\xbf" + (tmp_path / "plan2.json").read_bytes())
    res = run(
        main,
        [
            "bore",
            "next",
            "--plan",
            str(bom),
            "--measured",
            str(probe),
            "--pass",
            "0",
            "--controller",
            "linuxcnc",
            "--tool-radius",
            "6",
        ],
    )
    assert res.exit_code == 0 and "G10 L1 P1 R5.9700" in res.output, res.output
    bom.write_text('{\n  "diameter": 40,\n  oops\n}\n')
    res = run(main, ["bore", "next", "--plan", str(bom), "--measured", str(probe), "--pass", "0"])
    assert res.exit_code == 2 and f"{bom}:3:3: error: not a plan (JSON)" in res.output, res.output
    res = run(main, ["bore", "simulate", "--parts", "50", "--seed", "3", "--json", str(tmp_path / "sim.json")])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "sim.json").read_text())
    assert s["parts"] == 50 and 0 <= s["within_tolerance"] <= 1 and s["mean_passes"] == 4
    res = run(main, ["bore", "plan", "--diameter", "40", "--t0", "0.5", "--allowance", "0.1"])
    assert res.exit_code == 2 and "--delta-a" in res.output


# ------------------------------------------------------------------ issue 20: bores
def test_condition_3_is_two_sided():
    """(3) bounds the taper either way: δA 0, δB 50 µm is |−50| > 0.25·62 = 15.5 µm."""
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.0, 0.05)
    assert p.form_before == pytest.approx(0.05) and not p.applicable
    assert any("condition (3) does not hold" in w for w in p.warnings)
    r = CliRunner().invoke(
        main,
        [
            "bore",
            "plan",
            "--diameter",
            "40",
            "--t0",
            "0.5",
            "--allowance",
            "0.1",
            "--delta-a",
            "0",
            "--delta-b",
            "0.05",
        ],
    )
    assert r.exit_code == 0 and "|δA − δB| = 50.0 µm ≤ 15.5 µm: NO" in r.stdout, r.output


@pytest.mark.parametrize("k,limit_um", [(0.25, 2.0), (0.2, 1.6), (0.5, 4.0)])
def test_condition_4_follows_k(k, limit_um):
    """(4) is the paper's (2) on the radius: (k/2)·IT6 — 0.125·16 = 2.0 µm, 0.1·16 = 1.6 µm."""
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.03, 0.02, k=k)
    assert p.form_limit * 1000 == pytest.approx(limit_um, rel=1e-12)


def _spy_corrections(monkeypatch) -> list:
    """A noise-free testbed whose every corrective step is recorded: (plan, pass done, deviation
    at face A the plan predicts)."""
    _noise_free(monkeypatch)
    seen = []
    real = pb.next_correction

    def spy(p, meas, pass_done, **kw):
        c = real(p, meas, pass_done, **kw)
        seen.append((p, pass_done, c.deviations[0]))
        return c

    monkeypatch.setattr(pb, "next_correction", spy)
    return seen


def _noise_free(monkeypatch):
    for name in ("SETTING_SIGMA", "PASS_SIGMA", "PROBE_SIGMA", "STIFFNESS_SIGMA"):
        monkeypatch.setattr(sb, name, 0.0)


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_plan_agrees_with_the_noise_free_testbed(monkeypatch, seed):
    """The linear testbed (the paper's assumption, kept for this) cuts with its own model (compliance × real depth at every point of the bore,
    the tool set δK into the body on the aim); its deflection measured near A after each pass is
    the plan's prediction to 0.1 µm (the paper's (8) is not, from pass 2 on)."""
    seen = _spy_corrections(monkeypatch)
    res = sb.run_part(np.random.default_rng(seed), model="linear")
    assert res.applicable and res.passes == 4
    p = seen[0][0]
    measured = [d for _, n, d in seen if n >= 1]
    assert len(measured) == 3
    np.testing.assert_allclose(measured, p.predicted[:3], atol=1e-4)
    assert max(abs(np.array(measured) - p.predicted_paper[:3])) > 1e-4  # the paper's (8) drifts off
    assert res.ok


def test_finished_bore_is_judged(tmp_path):
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.03, 0.02)
    good = pb.read_probe(_probe_csv(tmp_path, (40.008, 40.0085, 40.0088)))
    f = pb.judge(p, good)
    assert f.inside and f.form == pytest.approx(0.0004, abs=1e-6) and f.form_ok and f.ok
    bad = pb.read_probe(_probe_csv(tmp_path, (40.004, 40.008, 40.0125), name="bad.csv"))
    f = pb.judge(p, bad)
    assert f.inside and not f.form_ok  # 4.25 µm > 2.0 µm
    out = pb.read_probe(_probe_csv(tmp_path, (40.017, 40.017, 40.017), name="out.csv"))
    assert not pb.judge(p, out).inside  # H6 on Ø40: 40.000 … 40.016


def test_plan_validation():
    with pytest.raises(InputError, match="shaft class"):
        pb.plan(40, "h6", "H9", 0.5, 0.1, 0.03, 0.02)
    with pytest.raises(InputError, match="outside Ø40 H6"):
        pb.plan(40, "H6", "H9", 0.5, 0.1, 0.03, 0.02, target_diameter=50)
    with pytest.raises(InputError, match="does not converge"):  # the δA 0.3 mm, z 0.1 mm
        pb.plan(40, "H6", "H9", 0.5, 0.1, 0.3, 0.28)
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, -0.005, -0.01)
    assert any("negative" in w for w in p.warnings)
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.09, 0.08)
    assert any("larger than IT(H9)" in w for w in p.warnings)


def _cli(*args):
    return CliRunner().invoke(main, list(args))


def test_pass_state_is_recorded_in_the_plan(tmp_path):
    """`bore next` reads the correction each pass was made with from the plan and records the new
    pass: forgetting --applied no longer turns the correction around; a wrong one is refused."""
    plan = tmp_path / "plan.json"
    r = _cli(
        "bore",
        "plan",
        "--diameter",
        "40",
        "--t0",
        "0.5",
        "--allowance",
        "0.1",
        "--delta-a",
        "0.03",
        "--delta-b",
        "0.02",
        "--json",
        str(plan),
    )
    assert r.exit_code == 0, r.output
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.03, 0.02)
    aim0 = p.nominal_diameter_after(0)
    m0 = _probe_csv(tmp_path, (aim0 - 0.060, aim0 - 0.050, aim0 - 0.040), name="m0.csv")
    r = _cli(
        "bore", "next", "--plan", str(plan), "--measured", str(m0), "--controller", "linuxcnc", "--tool-radius", "6"
    )
    assert r.exit_code == 0 and "G10 L1 P1 R5.9700" in r.stdout, r.output
    d = json.loads(plan.read_text())
    assert [h["pass"] for h in d["history"]] == [0] and d["history"][0]["correction"] == pytest.approx(0.030, abs=1e-6)
    # after pass 1 (made 30 µm into the body) the bore near A is 1 µm under its aim: deflection 31 µm
    aim1 = p.nominal_diameter_after(1)
    m1 = _probe_csv(tmp_path, (aim1 - 0.002,), zs=(55,), name="m1.csv")  # plane A only
    r = _cli("bore", "next", "--plan", str(plan), "--measured", str(m1), "--applied", "0.01")
    assert r.exit_code == 2 and "--applied" in r.output and "0.03" in r.output, r.output
    r = _cli(
        "bore", "next", "--plan", str(plan), "--measured", str(m1), "--controller", "linuxcnc", "--tool-radius", "6"
    )
    assert r.exit_code == 0, r.output
    # the block sets nominal − δK2 = 6 − 0.031, not (6 − 0.030) − 0.031
    assert "G10 L1 P1 R5.9690" in r.stdout and "+31.0 µm" in r.stdout, r.output
    d = json.loads(plan.read_text())
    assert d["history"][1]["applied"] == pytest.approx(0.030, abs=1e-6)
    assert d["history"][1]["correction"] == pytest.approx(0.031, abs=1e-6)
    r = _cli("bore", "next", "--plan", str(plan), "--measured", str(m1), "--pass", "1")
    assert r.exit_code == 2 and "records passes 0 … 1 already" in r.output


def test_finished_bore_from_the_cli_with_a_report(tmp_path):
    plan = tmp_path / "plan.json"
    assert (
        _cli(
            "bore",
            "plan",
            "--diameter",
            "40",
            "--t0",
            "0.5",
            "--allowance",
            "0.1",
            "--delta-a",
            "0.03",
            "--delta-b",
            "0.02",
            "--json",
            str(plan),
        ).exit_code
        == 0
    )
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.03, 0.02)
    for n in range(p.passes):
        aim = p.nominal_diameter_after(n)
        f = _probe_csv(tmp_path, (aim - 0.004, aim - 0.003, aim - 0.002), name=f"m{n}.csv")
        r = _cli("bore", "next", "--plan", str(plan), "--measured", str(f))
        assert r.exit_code == 0, r.output
    fin = _probe_csv(tmp_path, (40.008, 40.0085, 40.0088), name="fin.csv")
    r = _cli(
        "bore",
        "next",
        "--plan",
        str(plan),
        "--measured",
        str(fin),
        "--report",
        str(tmp_path / "r.html"),
        "--json",
        str(tmp_path / "f.json"),
    )
    assert r.exit_code == 0 and "the bore is GOOD" in r.stdout, r.output
    f = json.loads((tmp_path / "f.json").read_text())
    assert f["inside"] and f["form_ok"] and f["form"] == pytest.approx(0.0004, abs=1e-6)
    html = (tmp_path / "r.html").read_text()
    assert "Diameters per plane per pass" in html and "40.0088" in html
    r = _cli("bore", "next", "--plan", str(plan), "--measured", str(fin))
    assert r.exit_code == 2 and "finished bore" in r.output


def test_probe_files_as_measured(tmp_path):
    """x,y,z with ±0.01 mm z scatter: three planes, not one-point planes; a semicolon CSV; one plane."""
    rng = np.random.default_rng(1)
    phi = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    rows = ["x,y,z"]
    for d, z in ((39.9, 55), (39.95, 30), (39.92, 5)):
        rows += [f"{d / 2 * math.cos(f):.6f},{d / 2 * math.sin(f):.6f},{z + rng.uniform(-0.01, 0.01):.4f}" for f in phi]
    f = tmp_path / "xyz.csv"
    f.write_text("\n".join(rows) + "\n")
    m = pb.read_probe(f)
    assert len(m.circles) == 3 and m.diameters == pytest.approx([39.9, 39.95, 39.92], abs=1e-6)
    g = tmp_path / "semi.csv"
    g.write_text(f.read_text().replace(",", ";"))
    assert pb.read_probe(g).diameters == pytest.approx(m.diameters, abs=1e-12)
    one = _probe_csv(tmp_path, (39.9,), zs=(55,), name="one.csv")
    assert len(pb.read_probe(one).circles) == 1
    p = pb.plan(40, "H6", "H9", 0.5, 0.1, 0.03, 0.02)
    with pytest.raises(InputError, match="three planes"):
        pb.next_correction(p, pb.read_probe(one), 0)
    with pytest.raises(InputError, match="near faces A and B"):
        pb.plan_from_measurement(40, pb.read_probe(one), t0=0.5, allowance=0.1)


def test_offset_blocks_for_real_controllers():
    assert pb.offset_block(0.0031, controller="fanuc-geometry", tool=3, radius=6.0) == "G10 L12 P3 R5.9969"
    assert pb.offset_block(0.0031, controller="sinumerik", tool=3) == "$TC_DP15[3,1]=-0.0031"
    # a lathe's X wear on the diameter, incremented by the change since the last correction
    assert pb.offset_block(0.0031, controller="fanuc-lathe", tool=3, previous=0.0021) == "G10 P3 U0.0020"
    with pytest.raises(InputError, match="nominal radius"):
        pb.offset_block(0.001, controller="fanuc-geometry")


@pytest.mark.parametrize(
    "args,says",
    [
        (("--delta-a", "-1e300", "--delta-b", "0.02"), "--delta-a"),
        (("--delta-a", "0.03", "--delta-b", "0.02", "--k", "5e-324"), "--k"),
        (("--delta-a", "0.03", "--delta-b", "0.02", "--t0", "5e-324"), "--t0"),
    ],
)
def test_fuzz_findings_plan_options(args, says):
    base = ["bore", "plan", "--diameter", "40", "--allowance", "0.1"]
    if "--t0" not in args:
        base += ["--t0", "0.5"]
    r = CliRunner().invoke(main, base + list(args))
    assert r.exit_code == 2 and says in r.output and "Traceback" not in r.output, r.output


@pytest.mark.parametrize(
    "text,says",
    [
        ("0", "expected a JSON object, got int"),
        ("[]", "expected a JSON object, got list"),
        (
            '{"diameter": NaN, "final": "H6", "prefinish": "H9", "t0": 0.5, "allowance": 0.1, "delta_a": 0.03, '
            '"delta_b": 0.02, "k": 0.25}',
            "'diameter' must be a finite number",
        ),
        ('{"diameter": ' + "1" * 5000 + "}", "not a plan (JSON)"),
        (
            '{"diameter": 40, "final": 6, "prefinish": "H9", "t0": 0.5, "allowance": 0.1, "delta_a": 0.03, '
            '"delta_b": 0.02, "k": 0.25}',
            "'final' must be a class",
        ),
    ],
)
def test_fuzz_findings_plan_file(tmp_path, text, says):
    plan = tmp_path / "plan.json"
    plan.write_text(text)
    probe = _probe_csv(tmp_path, (39.75, 39.76, 39.77))
    r = CliRunner().invoke(main, ["bore", "next", "--plan", str(plan), "--measured", str(probe)])
    assert r.exit_code == 2 and f"{plan}" in r.output and says in r.output, r.output


def test_fuzz_finding_simulate_t0():
    """Settings for which condition (3) almost never holds end with the reason instead of drawing
    forever. On the linear testbed the pre-finish deflection grows with t₀ and --t0 3 is refused; on
    the beam testbed (the CLI's) a 3 mm pre-finish chip flows along the feed, the radial force
    stays moderate and the run finishes."""
    with pytest.raises(InputError, match="smaller --t0"):
        sb.simulate(5, seed=1, t0=3, model="linear")
    r = CliRunner().invoke(main, ["bore", "simulate", "--parts", "5", "--t0", "3"])
    assert r.exit_code in (0, 2) and "Traceback" not in r.output, r.output
    r = CliRunner().invoke(main, ["bore", "simulate", "--parts", "5", "--t0", "3", "--model", "linear"])
    assert r.exit_code == 2 and "smaller --t0" in r.output, r.output


# ------------------------------------------------------------------ real probe results (issue 20, bores 11)
def _expect_planes(m, diameters, centres=None):
    assert m.diameters == pytest.approx(list(diameters), abs=1e-9)
    if centres:
        assert [c.centre for c in m.circles] == [pytest.approx(c, abs=1e-9) for c in centres]


def test_measurement_formats(tmp_path):
    """The same bore — Ø39.80 near A (z 55), 39.81 mid, 39.82 near B — as a circle table, DMIS
    FEAT/CIRCLE actuals, a PC-DMIS report and a LinuxCNC probe log: the same planes, A first."""
    t = tmp_path / "table.csv"
    t.write_text("plane;z;diameter;x;y\nB;5;39.82;0.01;0\nM;30;39.81;0;0\nA;55;39.80;0;0.002\n")
    _expect_planes(pb.read_measurement(t), (39.80, 39.81, 39.82), [(0, 0.002), (0, 0), (0.01, 0)])
    d = tmp_path / "bore.dms"
    d.write_text(
        "DMISMN/'bore',05.0\nF(CA)=FEAT/CIRCLE,INNER,CART,0,0,55,0,0,1,40.0\n"
        "FA(CA)=FEAT/CIRCLE,INNER,CART,0,0.002,55,0,0,1,39.80\n"
        "FA(CM)=FEAT/CIRCLE,INNER,CART,0,0,30,0,0,1,$\n39.81\n"
        "FA(CB)=FEAT/CIRCLE,INNER,CART,0.01,0,5,0,0,-1,39.82\nENDFIL\n"
    )
    _expect_planes(pb.read_measurement(d), (39.80, 39.81, 39.82), [(0, 0.002), (0, 0), (0.01, 0)])
    r = tmp_path / "report.txt"
    blocks = []
    for name, z, dia in (("CIR_A", 55, 39.80), ("CIR_M", 30, 39.81), ("CIR_B", 5, 39.82)):
        blocks.append(
            f"DIM LOC{name[-1]}= LOCATION OF CIRCLE {name}  UNITS=MM ,$\n"
            "AX    NOMINAL       +TOL       -TOL       MEAS        DEV     OUTTOL\n"
            f"X       0.0000     0.0100     0.0100     0.0000     0.0000     0.0000 ----#----\n"
            f"Y       0.0000     0.0100     0.0100     0.0000     0.0000     0.0000 ----#----\n"
            f"Z      {z:.4f}     0.0100     0.0100    {z:.4f}     0.0000     0.0000 ----#----\n"
            f"D      40.0000     0.0160     0.0000    {dia:.4f}    -0.1900     0.1900 #--------\n"
        )
    r.write_text("PART NAME  : bore\n" + "\n".join(blocks))
    _expect_planes(pb.read_measurement(r), (39.80, 39.81, 39.82))
    phi = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    lines = [
        f"{d / 2 * math.cos(f):.6f} {d / 2 * math.sin(f):.6f} {z + 0.003 * math.sin(3 * f):.6f} 0 0 0 0 0 0"
        for d, z in ((39.80, 55), (39.81, 30), (39.82, 5))
        for f in phi
    ]
    log = tmp_path / "bore_probe.txt"
    log.write_text("\n".join(lines) + "\n")
    m = pb.read_measurement(log)
    assert m.diameters == pytest.approx([39.80, 39.81, 39.82], abs=2e-6)
    bad = tmp_path / "bad.dms"
    bad.write_text("FA(C1)=FEAT/CIRCLE,OUTER,CART,0,0,55,0,0,1,39.80\n")
    with pytest.raises(InputError, match="OUTER") as e:
        pb.read_measurement(bad)
    assert e.value.line == 1
    bad.write_text(r.read_text().replace("39.8000", "nan"))
    with pytest.raises(InputError, match="MEAS must be a finite number"):
        pb.read_measurement(bad)


def test_a_plan_from_a_dmis_report_through_the_cli(tmp_path):
    d = tmp_path / "bore.dms"
    aim0 = 40.008 - 0.2
    d.write_text(
        "".join(
            f"FA(C{z})=FEAT/CIRCLE,INNER,CART,0,0,{z},0,0,1,{aim0 - 2 * dev:.4f}\n"
            for z, dev in ((55, 0.03), (30, 0.025), (5, 0.02))
        )
    )
    r = CliRunner().invoke(
        main,
        ["bore", "plan", "--diameter", "40", "--t0", "0.5", "--allowance", "0.1", "--measured", str(d), "--json", "-"],
    )
    assert r.exit_code == 0, r.output
    p = json.loads(r.stdout)
    assert p["delta_a"] == pytest.approx(0.03, abs=1e-9) and p["delta_b"] == pytest.approx(0.02, abs=1e-9)


@pytest.mark.parametrize("dialect", ["linuxcnc", "fanuc"])
def test_probing_program(tmp_path, dialect):
    out = tmp_path / "probe.ngc"
    r = CliRunner().invoke(
        main, ["bore", "probe-program", "--diameter", "40", "--planes", "55,30,5", "--dialect", dialect, "-o", str(out)]
    )
    assert r.exit_code == 0, r.output
    text = out.read_text()
    touch = "G38.2" if dialect == "linuxcnc" else "G31"
    moves = re.findall(touch + r" X(-?[\d.]+) Y(-?[\d.]+)", text)
    assert len(moves) == 24
    radii = [math.hypot(float(x), float(y)) for x, y in moves]
    assert radii == pytest.approx([21.0] * 24, abs=2e-3)  # 1 mm past the nominal wall
    assert text.index("Z60.000") < text.index("Z55.000")  # the safe height above the highest plane
    if dialect == "fanuc":
        assert text.count("DPRNT[*#5061[44]*#5062[44]*#5063[44]]") == 24 and "POPEN" in text and "PCLOS" in text


@needs_rs274
def test_probing_program_runs_in_rs274(tmp_path):
    from rs274 import canonical

    out = tmp_path / "probe.ngc"
    out.write_text(pb.probing_program(40, [55, 30, 5]))
    assert canonical(out).error is None


# ------------------------------------------------------------------ the testbed's own physics (issue 20, Tests)
# Values below are computed here from the force law and the beam, not read from the testbed.
R_EPS, FEED, KAPPA = 0.4, 0.05, math.radians(95.0)  # CCMT-style insert, boring bar κr 95°, f 0.05 mm/rev


def _profile_x(y):
    """The insert's edge at height y above the tip: trailing side (arc), leading side (arc up to
    r(1 − cos κ), then the straight edge at κ)."""
    y = np.asarray(y, dtype=float)
    yk = R_EPS * (1 - math.cos(KAPPA))
    arc = np.sqrt(np.clip(R_EPS**2 - (R_EPS - np.minimum(y, yk)) ** 2, 0, None))
    right = np.where(y <= yk, arc, R_EPS * math.sin(KAPPA) + (y - yk) / math.tan(KAPPA))
    return -np.sqrt(np.clip(R_EPS**2 - (R_EPS - np.minimum(y, R_EPS)) ** 2, 0, None)), right


def _chip_numerically(ap, n=400_001):
    """The chip between the tool and its position one revolution earlier (shifted by f), by
    integrating its width over the height and measuring the engaged edge as a polyline."""
    y = np.linspace(0, ap, n)
    left, right = _profile_x(y)
    width = right - np.maximum(left, right - FEED)
    area = float(np.sum((width[1:] + width[:-1]) / 2 * np.diff(y)))
    # the engaged edge: the trailing side below the feed mark (where left > right − f), all the leading side
    trailing = left > right - FEED
    xs = np.concatenate([left[trailing][::-1], right])
    ys = np.concatenate([y[trailing][::-1], y])
    length = float(np.sum(np.hypot(np.diff(xs), np.diff(ys))))
    lead = math.atan2(ys[-1] - ys[0], xs[-1] - xs[0])  # Colwell's chord, end to end
    return length, area, lead


@pytest.mark.parametrize("ap", [0.0004, 0.005, 0.025, 0.1, 0.3, 0.5])
def test_chip_geometry_against_the_drawn_profile(ap):
    c = sb.chip(ap)
    length, area, lead = _chip_numerically(ap)
    assert float(c.length) == pytest.approx(length, rel=2e-4)
    assert float(c.area) == pytest.approx(area, rel=2e-4)
    assert float(c.lead_angle) == pytest.approx(lead, abs=2e-4)


def test_cutting_force_by_hand():
    """Steel (Sandvik P: k_c1 2000 N/mm², m_c 0.25), r_ε 0.4, f 0.05, a_p 25 µm, by hand:
    α_s = asin(0.05/0.8) = 0.062541, y_s = 0.4(1 − cos α_s) = 0.782 µm, θ = acos(1 − 0.025/0.4)
    = 0.355421; b = 0.4(θ + α_s) = 0.167185 mm; A = 0.05(0.025 − y_s) + 0.4²(α_s − sin α_s cos α_s)
    = 1.23697e-3 mm²; h = A/b = 7.3988 µm; F_c = 2000·b·h^0.75 = 8.4353 N; Colwell's chord from
    (−0.025, y_s) to (0.4 sin θ, 0.025): κ_e = 8.3904°; F_p = 0.5 F_c cos κ_e = 4.1725 N."""
    fc, fp = sb.forces(0.025, 2000.0, 0.25)
    assert float(fc) == pytest.approx(8.4353, rel=1e-4) and float(fp) == pytest.approx(4.1725, rel=1e-4)
    c = sb.chip(0.025)
    assert float(c.thickness) * 1000 == pytest.approx(7.3988, rel=1e-4)
    assert math.degrees(float(c.lead_angle)) == pytest.approx(8.3904, abs=1e-3)
    # the radial force is not proportional to depth: per mm of depth 208 N at 5 µm, 133 N at 0.1 mm,
    # 75 N at the 0.5 mm pre-finish (past the nose arc the chip turns to flow along the feed)
    per_mm = sb.forces(np.array([0.005, 0.1, 0.5]), 2000.0, 0.25)[1] / np.array([0.005, 0.1, 0.5])
    assert per_mm == pytest.approx([208.0, 132.9, 75.2], rel=2e-3)
    assert float(sb.forces(0.0, 2000.0, 0.25)[1]) == 0.0 and float(sb.forces(-0.01, 2000.0, 0.25)[1]) == 0.0


def test_single_pass_deflection_by_hand():
    """Ø16 steel bar, 100 mm overhang: c = L³/(3EI) = 10⁶ / (3 · 210000 · π·16⁴/64) = 4.9341e-4 mm/N.
    A pass set 0.5 mm deep on a straight bore cuts 0.5 − d with d = c F_p(0.5 − d); with the chuck
    (20 N/µm at face A, x² from the jaws) the wall adds 5e-5 (x/80)² mm/N."""
    c_bar = 100**3 / (3 * 210_000 * math.pi * 16**4 / 64)
    assert sb.bar_compliance() == pytest.approx(4.9341e-4, rel=1e-4)
    part = sb.BeamPart(c_bar, 1 / 20_000, 2000.0, 2000.0, 0.25)
    r_prev = np.full_like(sb.ZETA, 19.5)
    r = part.cut(20.0, r_prev, 1.0)
    d = 20.0 - r
    c = c_bar + (1 / 20_000) * ((80 - 60 * sb.ZETA) / 80) ** 2  # face A at 80 mm from the jaws, B at 20 mm
    fp = np.array([float(sb.forces(0.5 - di, 2000.0, 0.25)[1]) for di in d])
    np.testing.assert_allclose(d, c * fp, rtol=1e-9)  # the static equilibrium
    # by hand at face B (c = 4.9341e-4 + 5e-5/16 = 4.9654e-4 mm/N), iterating d = c F_p(0.5 − d):
    # F_p(0.5) = 37.580 N → 18.660 µm; F_p(0.48134) = 37.186 N → 18.464 µm; → 18.466 µm
    assert d[-1] * 1000 == pytest.approx(18.466, abs=0.001)
    assert d[0] > d[-1]  # more compliant at the entry: the paper's taper, smaller diameter at A
    # the planner's assumption would scale d with depth; the testbed's deflection at 25 µm nominal
    # depth (by hand as above: 1.934 µm at face B) is 2.09 × what 25/500 of the pre-finish's gives
    r25 = part.cut(20.0, np.full_like(sb.ZETA, 19.975), 1.0)
    assert (20.0 - r25[-1]) * 1000 == pytest.approx(1.934, abs=0.001)
    assert (20.0 - r25[-1]) / (d[-1] * 0.025 / 0.5) == pytest.approx(2.09, abs=0.01)


def _h6_limits_40():
    """ISO 286-1 from its formula, not its table: Ø40 is in 30–50 mm, D = √(30·50), i = 0.45 ∛D +
    0.001 D µm, IT6 = 10 i rounded = 16 µm; H: lower deviation 0."""
    dm = math.sqrt(30 * 50)
    it6 = round(10 * (0.45 * dm ** (1 / 3) + 0.001 * dm))
    assert it6 == 16
    return 40.0, 40.0 + it6 / 1000, it6 / 1000


@pytest.mark.parametrize("material", ["steel", "hardened"])
def test_beam_testbed_reaches_h6(material):
    """The plan and the measured loop on the beam testbed: the finished bores, judged here against
    H6 and k·IT6 on the form, over 150 parts; one uncorrected pass does far worse."""
    lo, hi, it6 = _h6_limits_40()
    rng = np.random.default_rng(11)
    ok = one = n = 0
    while n < 150:
        res = sb.run_part(rng, material=material)
        if not res.applicable:
            continue
        n += 1
        assert res.passes == 4
        d, d1 = res.diameters, res.one_pass
        ok += bool(d.min() >= lo and d.max() <= hi and d.max() - d.min() <= 0.25 * it6)
        one += bool(d1.min() >= lo and d1.max() <= hi and d1.max() - d1.min() <= 0.25 * it6)
    assert ok / n >= 0.95 and one / n <= 0.1


def test_beam_testbed_is_not_the_planners_model(monkeypatch):
    """Noise-free, the plan's prediction after pass 1 (δ_A/t₀ × real depth) falls short of the
    beam testbed's deflection: finishing chips are thin and the chip flows across the feed, so the
    radial force per µm of depth is about twice the pre-finish's. The loop corrects by what it
    measures and still finishes inside H6."""
    seen = _spy_corrections(monkeypatch)
    res = sb.run_part(np.random.default_rng(1))
    p = seen[0][0]
    measured = [d for _, n, d in seen if n >= 1]
    assert measured[0] / p.predicted[0] > 1.5
    lo, hi, it6 = _h6_limits_40()
    assert res.diameters.min() >= lo and res.diameters.max() <= hi and res.ok
