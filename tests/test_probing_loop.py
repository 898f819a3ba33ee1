"""The on-machine loop on the freeform testbed: cut → `probe points` → virtual probing →
`compensate` → cut again."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from ncadapt import cad, demo, nc, probing
from ncadapt.cli import main
from ncadapt.sim import freeform as ff
from ncadapt.sim import probing as sp

NOISE = 0.002  # mm, the probe's repeatability (1σ)
DELAY = 0.001  # s, trigger delay: 1.7 µm of travel at 100 mm/min
FEED = 100.0
RADIUS = 2.0  # mm, nominal stylus ball


def calibrate(radius: float) -> float:
    """The effective stylus radius, as a machinist qualifies it: 20 touches on a flat reference at
    z = 0 at the probing feed; the mean trip height of the ball centre is the radius the probe
    behaves as (the nominal radius less the travel during the trigger delay)."""
    ref = ff.ZMap(0.0, 0.0, 0.25, np.zeros((81, 81)))
    g = probing.grid_points((5, 15, 5, 15), nx=5, ny=4)
    text = probing.grid_program(g, safe_z=10, depth=-1, feed=FEED)
    res = sp.run(text, ref, stylus_radius=radius, noise=NOISE, trigger_delay=DELAY, seed=99)
    return float(res.trips[:, 2].mean())


def test_the_loop_with_on_machine_probing_reaches_the_freeform_target(tmp_path):
    part = ff.demo_part()
    error = ff.ErrorModel(part, (("curvature", demo.CURVATURE_AMPLITUDE), ("polynomial", demo.POLYNOMIAL)))
    program = tmp_path / "part.ngc"
    program.write_text(demo.program_text())
    first = ff.machine(nc.read(program), part, error, demo.TOOL_RADIUS)
    step = cad.write(part, tmp_path / "part.step")

    r_eff = calibrate(RADIUS)
    assert abs(r_eff - (RADIUS - DELAY * FEED / 60)) < 0.0015  # 20 touches: σ/√20 = 0.45 µm
    runner = CliRunner()
    r = runner.invoke(
        main,
        [
            "probe",
            "points",
            "--nominal",
            str(step),
            "--n",
            "609",
            "--stylus-radius",
            f"{r_eff:.6f}",
            "--edge-margin",
            "5",
            "--approach",
            "4",
            "--overtravel",
            "2",
            "--feed",
            str(FEED),
            "-o",
            str(tmp_path / "inspect.ngc"),
            "--plan",
            str(tmp_path / "plan.csv"),
        ],
    )
    assert r.exit_code == 0, r.output
    run = sp.run(
        (tmp_path / "inspect.ngc").read_text(), first, stylus_radius=RADIUS, noise=NOISE, trigger_delay=DELAY, seed=3
    )
    (tmp_path / "probe-log.txt").write_text(run.log)
    r = runner.invoke(
        main,
        [
            "compensate",
            str(tmp_path / "plan.csv"),
            "--program",
            str(program),
            "--tool-radius",
            str(demo.TOOL_RADIUS),
            "--outside",
            "clamp",
            "-o",
            str(tmp_path / "corrected.ngc"),
        ],
    )
    assert r.exit_code == 0, r.output
    second = ff.machine(nc.read(tmp_path / "corrected.ngc"), part, error, demo.TOOL_RADIUS)
    # the systematic error itself, at the demo's probe points, noise-free
    p, n = ff.probe_points(part, demo.PROBE_BORDER, demo.PROBE_SPACING)
    before = np.einsum("ij,ij->i", ff.measure(first, p, n) - p, n)
    after = np.einsum("ij,ij->i", ff.measure(second, p, n) - p, n)
    ratio = np.sqrt((after**2).mean() / (before**2).mean())
    print(
        f"systematic RMS {np.sqrt((before**2).mean()) * 1000:.1f} -> {np.sqrt((after**2).mean()) * 1000:.1f} µm, {ratio:.1%}"
    )
    assert ratio <= 0.10, ratio
