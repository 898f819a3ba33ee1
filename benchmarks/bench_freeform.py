"""Benchmark: Moran's I and the bilateral filter on 1,000,000 points, and Moran's I beside PySAL
esda on the same 20,000-point inverse-distance case, in one run.

Points are uniform in a 1000 × 1000 mm square (seeded), values a smooth pattern plus noise.
Run with `make bench`.
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

from bench_correct import machine
from ncadapt import filters, stats


def data(n: int, seed: int = 7):
    rng = np.random.default_rng(seed)
    side = 1000.0 * np.sqrt(n / 1e6)  # one point per mm² whatever n
    p = rng.uniform(0, side, (n, 2))
    v = 0.02 * np.sin(p[:, 0] / 40) * np.cos(p[:, 1] / 55) + rng.normal(0, 0.005, n)
    return p, v


def timed(f):
    t = time.perf_counter()
    r = f()
    return time.perf_counter() - t, r


def main() -> int:
    print(f"machine: {machine()}")
    p, v = data(1_000_000)
    print("\n1,000,000 points (one per mm²)")
    t, m = timed(lambda: stats.moran(p, v, weights="knn", neighbors=8))
    print(f"   Moran's I, 8 nearest neighbours:       {t:6.2f} s   I = {m.I:.4f}, z = {m.z_randomization:.1f}")
    t, m = timed(lambda: stats.moran(p, v, weights="idw", threshold=3.0))
    print(f"   Moran's I, 1/d within 3 mm (~27 nb.):  {t:6.2f} s   I = {m.I:.4f}, z = {m.z_randomization:.1f}")
    t, _ = timed(lambda: filters.bilateral(p, v, sigma_c=1.5, sigma_s=0.015))
    print(f"   bilateral, sigma_c 1.5 mm (r 3 mm):    {t:6.2f} s")

    p, v = data(20_000, seed=8)
    thr = float(np.sqrt(100 / np.pi))  # ~100 neighbours at one point per mm²
    print(f"\n20,000 points, 1/d weights within {thr:.2f} mm (~100 neighbours), row-standardised")
    t_ours, m = timed(lambda: stats.moran(p, v, weights="idw", threshold=thr))
    print(f"   ncadapt:                               {t_ours:6.2f} s   I = {m.I:.6f}")
    try:
        import esda
        import libpysal

        def peer():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                w = libpysal.weights.DistanceBand(p, threshold=thr, binary=False, alpha=-1.0, silence_warnings=True)
                w.transform = "r"
                return esda.Moran(v, w, permutations=0)

        t_esda, ref = timed(peer)
        print(f"   esda (DistanceBand + Moran):           {t_esda:6.2f} s   I = {ref.I:.6f}")
        print(f"   ratio esda / ncadapt:                  {t_esda / t_ours:6.1f} x")
    except ImportError:
        print("   esda not installed (make test installs it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
