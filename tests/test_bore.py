"""Precision bores: circle fits, the plan's formulas on hand-computed cases, the pass-by-pass
rules, the offset blocks, the virtual testbed's targets and the CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

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
    a1 = 0.030 * (0.025 + 0.060) / 0.5  # 5.1 µm
    a2 = a1 * (0.025 + 2 * a1) / (0.025 + 0.060)  # the recurrence, not the paper's t0 closed form
    a3 = a2 * (0.025 + 2 * a2) / (0.025 + 2 * a1)
    assert p.predicted[:3] == pytest.approx([a1, a2, a3], rel=1e-12)
    assert p.predicted[0] == pytest.approx(0.0051, rel=1e-12)
    b1 = 0.020 * (0.025 + 0.030 + 0.020) / 0.5
    assert p.predicted_b[0] == pytest.approx(b1, rel=1e-12)
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
        rows += [f"{label},{centre[0] + d / 2 * math.cos(f):.7f},{centre[1] + d / 2 * math.sin(f):.7f},{z}" for f in phi]
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
    """Pre-finished soft (k_c 2000), finished hardened (k_c 3200): compliance ratio 2000/3200."""
    r = sb.simulate(200, seed=2, material="hardened")
    assert r["stiffness_ratio_mean"] == pytest.approx(2000 / 3200, rel=0.05)
    assert r["within_tolerance"] >= 0.95


def test_cli_plan_next_simulate(tmp_path):
    run = CliRunner().invoke
    res = run(main, ["bore", "plan", "--diameter", "40", "--final", "H6", "--prefinish", "H9", "--t0", "0.5",
                     "--allowance", "0.1", "--delta-a", "0.03", "--delta-b", "0.02", "--json", str(tmp_path / "plan.json")])
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "plan.json").read_text())
    assert d["it_final"] == 0.016 and d["it_prefinish"] == 0.062 and d["passes"] == 4 and d["applicable"] is True
    assert d["depth_per_pass"] == pytest.approx(0.025) and d["predicted"][0] == pytest.approx(0.0051)
    assert d["t_max"] == pytest.approx(0.5 * 0.25 * 0.016 / 0.062)
    aim0 = 40.008 - 0.2
    probe = _probe_csv(tmp_path, (aim0 - 0.060, aim0 - 0.050, aim0 - 0.040))
    res = run(main, ["bore", "plan", "--diameter", "40", "--t0", "0.5", "--allowance", "0.1", "--measured", str(probe),
                     "--json", str(tmp_path / "plan2.json")])
    assert res.exit_code == 0, res.output
    d2 = json.loads((tmp_path / "plan2.json").read_text())
    assert d2["delta_a"] == pytest.approx(0.030, abs=1e-6) and d2["delta_b"] == pytest.approx(0.020, abs=1e-6)
    res = run(main, ["bore", "next", "--plan", str(tmp_path / "plan.json"), "--measured", str(probe), "--pass", "0",
                     "--controller", "linuxcnc", "--tool-radius", "6", "--json", str(tmp_path / "next.json")])
    assert res.exit_code == 0, res.output
    n = json.loads((tmp_path / "next.json").read_text())
    assert n["correction"] == pytest.approx(0.030, abs=1e-6) and n["block"] == "G10 L1 P1 R5.9700"
    # the plan saved by an editor that writes a byte-order mark reads the same; a broken one is located
    bom = tmp_path / "plan_bom.json"
    bom.write_bytes(b"\xef\xbb\xbf" + (tmp_path / "plan.json").read_bytes())
    res = run(main, ["bore", "next", "--plan", str(bom), "--measured", str(probe), "--pass", "0",
                     "--controller", "linuxcnc", "--tool-radius", "6"])
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
