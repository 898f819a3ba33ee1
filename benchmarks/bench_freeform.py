"""Benchmark: Moran's I and the bilateral filter on 1,000,000 points, Moran's I beside PySAL
esda on the same 20,000-point inverse-distance case, and the decision's error rates — how often
it calls pure noise "systematic" (nominal: alpha = 5 %) over 200 seeds, esda's rate on the same
data beside ours, and how often it finds the testbed's systematic error — in one run.

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
    commands()
    gate()
    border()
    return 0


def commands(n_side: int = 1000) -> None:
    """`ncadapt analyze` and `ncadapt compensate` on a 1000 x 1000 grid of measured points (0.1 mm
    apart, deviations along +z: a smooth pattern and 2 µm noise), whole processes as a user runs them."""
    import subprocess
    from pathlib import Path

    out = Path(__file__).resolve().parent / "out"
    out.mkdir(exist_ok=True)
    f = out / f"grid_{n_side}x{n_side}.csv"
    if not f.exists():
        rng = np.random.default_rng(3)
        x, y = np.meshgrid(np.arange(n_side) * 0.1, np.arange(n_side) * 0.1, indexing="ij")
        dev = 0.01 * np.sin(x / 9) * np.cos(y / 7) + rng.normal(0, 0.002, x.shape)
        rows = np.column_stack(
            [x.ravel(), y.ravel(), np.zeros(x.size), np.zeros(x.size), np.zeros(x.size), np.ones(x.size), dev.ravel()]
        )
        np.savetxt(
            f,
            rows,
            fmt=["%.1f", "%.1f", "%g", "%g", "%g", "%g", "%.6f"],
            delimiter=",",
            header="x,y,z,i,j,k,dev",
            comments="",
        )
    exe = str(Path(sys.executable).with_name("ncadapt"))
    print(f"\n{n_side * n_side:,} measured points (a grid 0.1 mm apart), whole commands")
    total = 0.0
    for cmd in (["analyze", str(f)], ["compensate", str(f)]):
        t, _ = timed(lambda cmd=cmd: subprocess.run([exe, *cmd], check=True, stdout=subprocess.DEVNULL))
        total += t
        print(f"   ncadapt {cmd[0]:10s} {t:6.2f} s")
    print(f"   together           {total:6.2f} s  (target < 30 s)")
    try:
        import esda
        import libpysal

        m = 100_000
        xy = np.column_stack([(np.arange(m) // 100) * 0.1, (np.arange(m) % 100) * 0.1])
        v = np.random.default_rng(3).normal(size=m)

        def peer():
            w = libpysal.weights.KNN(xy, k=8)
            w.transform = "r"
            return esda.Moran(v, w, permutations=0)

        t_esda, _ = timed(peer)
        t_ours, _ = timed(lambda: stats.moran(xy, v, weights="knn", neighbors=8))
        print(
            f"   Moran's I alone on {m:,} points, 8 nearest: esda {t_esda:.2f} s, ncadapt {t_ours:.2f} s "
            f"(ratio {t_esda / t_ours:.1f} x)"
        )
    except ImportError:
        print("   esda not installed (make test installs it)")


def gate(seeds: int = 200, alpha: float = 0.05) -> None:
    """The gate's rates at the demo's probe points (95 % Wilson intervals): pure noise called
    systematic (nominal alpha), Moran's I alone at alpha / 2 beside esda's normal approximation on
    the same values and weights, and how often a uniform offset of 3 sigma and the demo's error
    are found."""
    from ncadapt import demo, measure, nc
    from ncadapt.processes import freeform as pf
    from ncadapt.sim import freeform as ff

    part = ff.demo_part()
    p, n = ff.probe_points(part, demo.PROBE_BORDER, demo.PROBE_SPACING)
    print(
        f"\nthe gate on the demo's {len(p)} probe points, alpha = {alpha:g} (Moran's I and the offset test "
        f"each at {alpha / 2:g})"
    )
    try:
        import esda
        import libpysal
    except ImportError:
        esda = None

    def rate(k):
        lo, hi = wilson(k, seeds)
        return f"{k:3d}/{seeds} = {k / seeds:5.1%} (95 % CI {lo:.1%}-{hi:.1%})"

    for kind, opts in (
        ("1/d, all pairs", {}),
        ("1/d within 6 mm", {"threshold": 6.0}),
        ("8 nearest", {"weights": "knn", "neighbors": 8}),
    ):
        w = None
        if esda is not None:
            if opts:
                wm = stats.weights_matrix(
                    p[:, :2],
                    stats.Weights(
                        opts.get("weights", "idw"),
                        1.0 if "neighbors" not in opts else None,
                        opts.get("threshold"),
                        opts.get("neighbors"),
                    ),
                )
            else:  # all pairs, 1/d
                from scipy import sparse
                from scipy.spatial.distance import cdist

                d = cdist(p[:, :2], p[:, :2])
                np.fill_diagonal(d, np.inf)
                wm = sparse.csr_matrix(1.0 / d)
            w = libpysal.weights.WSP(wm).to_W(silence_warnings=True)
            w.transform = "r"
        gate_hits = moran_hits = peer = 0
        for seed in range(seeds):
            e = np.random.default_rng(seed).normal(0, 0.005, len(p))
            a = pf.analyze(measure.from_arrays(p, n, deviation=e), alpha=alpha, **opts)
            gate_hits += a.systematic
            moran_hits += "moran" in a.verdict.by
            if w is not None:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    ref = esda.Moran(e, w, permutations=0, two_tailed=False)
                peer += ref.z_rand > 0 and ref.p_rand < alpha / 2
        peer_txt = f"; esda's normal approximation {peer / seeds:5.1%}" if w is not None else ""
        print(
            f"   noise only, {kind:16s} gate {rate(gate_hits)}; Moran alone (permutation) "
            f"{moran_hits / seeds:5.1%}{peer_txt}"
        )
    offset = sum(
        pf.analyze(
            measure.from_arrays(p, n, deviation=0.015 + np.random.default_rng(s).normal(0, 0.005, len(p)))
        ).systematic
        for s in range(seeds)
    )
    print(f"   a uniform offset of 15 um (3 sigma) + 5 um noise: found in {rate(offset)}")
    prog = nc.parse(demo.program_text())
    err = ff.ErrorModel(part, (("curvature", demo.CURVATURE_AMPLITUDE), ("polynomial", demo.POLYNOMIAL)))
    first = ff.machine(prog, part, err, demo.TOOL_RADIUS)
    found = sum(
        pf.analyze(measure.from_arrays(p, n, measured=ff.measure(first, p, n, noise=demo.NOISE, seed=s))).systematic
        for s in range(seeds)
    )
    print(f"   the demo's systematic error + 5 um noise: found in {rate(found)}")


def border(seeds=(1, 2, 3)) -> None:
    """The systematic error left in the unmeasured border strip after one compensation, with the
    border held at the nearest measured value and with the paper's cubic extrapolation."""
    from ncadapt import demo, measure, nc
    from ncadapt.processes import freeform as pf
    from ncadapt.sim import freeform as ff

    part = ff.demo_part()
    prog = nc.parse(demo.program_text())
    p, n = ff.probe_points(part, demo.PROBE_BORDER, demo.PROBE_SPACING)
    allp, alln = ff.probe_points(part, 0.5, 1.0)
    b = demo.PROBE_BORDER
    inner = (allp[:, 0] >= b) & (allp[:, 0] <= 80 - b) & (allp[:, 1] >= b) & (allp[:, 1] <= 60 - b)
    print(f"\nthe unmeasured {b:g} mm border after one compensation (RMS at 1 mm spacing, seeds {list(seeds)})")
    rms = lambda v: float(np.sqrt(np.mean(v * v)))  # noqa: E731
    for name, model in (
        ("demo error", (("curvature", demo.CURVATURE_AMPLITUDE), ("polynomial", demo.POLYNOMIAL))),
        ("bench error", (("curvature", 0.10), ("polynomial", {(1, 0): 0.02, (0, 2): -0.015}))),
    ):
        err = ff.ErrorModel(part, model)
        first = ff.machine(prog, part, err, demo.TOOL_RADIUS)
        before = np.einsum("ij,ij->i", ff.measure(first, allp, alln) - allp, alln)
        left = {m: [] for m in pf.BORDERS}
        for seed in seeds:
            m = measure.from_arrays(p, n, measured=ff.measure(first, p, n, noise=demo.NOISE, seed=seed))
            d = pf.decompose(m)
            for mode in pf.BORDERS:
                c = pf.compensate(part, m, d.systematic, border=mode)
                second = ff.machine(prog.correct(c.field(demo.TOOL_RADIUS, "clamp")), part, err, demo.TOOL_RADIUS)
                after = np.einsum("ij,ij->i", ff.measure(second, allp, alln) - allp, alln)
                left[mode].append((rms(after[inner]), rms(after[~inner])))
        print(
            f"   {name}: before {rms(before[inner]) * 1e3:.1f} um inside, {rms(before[~inner]) * 1e3:.1f} um in the border"
        )
        for mode, v in left.items():
            a = np.array(v) * 1e3
            print(
                f"     --border {mode:5s} inside {a[:, 0].mean():.2f} um, border {a[:, 1].mean():.2f} um "
                f"({a[:, 1].min():.2f}-{a[:, 1].max():.2f})"
            )


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion k/n."""
    ph = k / n
    c = (ph + z * z / (2 * n)) / (1 + z * z / n)
    h = z * np.sqrt(ph * (1 - ph) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return c - h, c + h


if __name__ == "__main__":
    sys.exit(main())
