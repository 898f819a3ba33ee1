"""Benchmark: the waffle-shell strategies on the virtual SVO testbed over 20 seeds, the backlash
estimate over those seeds, and the tilt's segment fits against numpy.polyfit on a whole-shell
pre-measurement, in one run.

Run with `make bench`.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from bench_correct import machine
from ncadapt.processes import waffle as pw
from ncadapt.sim import waffle as sw


def main() -> int:
    print(f"machine: {machine()}")
    print(
        f"\n20 seeds, {sw.ROWS} x {sw.CELLS} cells, band ±{sw.BAND * 1000:.0f} µm: web-thickness error (mean over seeds)"
    )
    res = {st: [sw.simulate(st, s).as_dict() for s in range(1, 21)] for st in sw.STRATEGIES}
    none = np.array([r["rms_error"] for r in res["none"]])
    for st, rs in res.items():
        rms = np.array([r["rms_error"] for r in rs])
        rt = np.array([r["retunes"] for r in rs])
        print(
            f"   {st:12s} RMS {rms.mean() * 1000:5.1f} µm  max {np.mean([r['max_abs_error'] for r in rs]) * 1000:6.1f} µm  "
            f"RMS / none {np.mean(rms / none):.2f} (worst seed {np.max(rms / none):.2f})  "
            f"semi-finished cells {rt.mean():4.1f} (max {rt.max()}) of {rs[0]['cells_total']}  "
            f"cells out of ±{sw.BAND * 1000:.0f} µm {np.mean([r['cells_out_of_tolerance'] for r in rs]):4.1f}"
        )
    c = np.array([r["rms_error"] for r in res["combined"]])
    for st in ("disturbance", "self-tuning"):
        o = np.array([r["rms_error"] for r in res[st]])
        print(f"   combined better than {st} on {(c < o).sum()} of 20 seeds")

    print(
        f"\nbacklash from the pair of signals (the testbed's chain: gap {sw.GAP * 1000:.0f} µm, second-order drive "
        f"{sw.DRIVE_HZ:g} Hz, ζ {sw.DRIVE_ZETA:g} — first-order equivalent τ {sw.TAU:.3f} s; 2 µm noise), 20 seeds"
    )
    est = [pw.estimate_backlash(*sw.backlash_pair(s)) for s in range(1, 21)]
    g = np.array([e.gap for e in est]) * 1000
    tau = np.array([e.tau for e in est])
    print(
        f"   g {g.mean():.2f} ± {g.std():.2f} µm, τ {tau.mean():.4f} ± {tau.std():.4f} s, "
        f"residual {np.mean([e.residual_rms for e in est]) * 1000:.2f} µm"
    )

    print("\ntilt of a whole-shell pre-measurement (segments of 10) against numpy.polyfit per segment")
    b, z, v = sw.premeasurement(sw.Shell.make(1), np.random.default_rng(1))
    t0 = time.perf_counter()
    t = pw.tilt(b, z, v, tool_radius=sw.R_TOOL, diameter=sw.D, segment=10)
    ours = time.perf_counter() - t0
    segs = pw.segments(z, 10)
    t0 = time.perf_counter()
    ks = np.array([np.polyfit(b[s:e], v[s:e], 1)[0] for s, e in segs])
    peer = time.perf_counter() - t0
    diff = np.abs(ks[t.segment] * 360 / (np.pi * sw.D) - t.tan_alpha).max()
    print(
        f"   {len(b):,} rows, {len(segs):,} segments: ours {ours:.3f} s, polyfit {peer:.3f} s "
        f"(ratio {peer / ours:.1f} x), largest difference in tan α {diff:.1e}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
