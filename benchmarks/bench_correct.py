"""Benchmark: `ncadapt correct` beside LinuxCNC's rs274 and bCNC's autolevel, in one run.

1. Throughput: a generated 1,000,000-line program (short G1 moves in X, Y, Z and every tenth line
   a full circle of radius 0.25 mm) corrected with a 101 x 101 grid field and --max-segment 5:
   wall time, input lines per second and peak memory of the whole `ncadapt correct` command
   (read + correct + write), `rs274 -g` reading the same file in the same run, and their ratio.
2. A generated 200,000-line program with a 21 x 21 probe map: ncadapt beside bCNC's autolevel
   (its `CNC.py` GCode/Probe classes, without the GUI: load, autolevel, write).
3. A 50,000,000-line program (the first one's body fifty times, 1.4 GB) corrected with a shift:
   the peak resident memory of the whole command (`/usr/bin/time`), which the engine bounds by
   reading, correcting and writing the program piece by piece.

Run with `make bench`. Programs are generated with a fixed seed into benchmarks/out/.
`python benchmarks/bench_correct.py --parts 1` runs the first part alone (a few seconds).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "out"
HERE = Path(__file__).resolve().parent


def machine() -> str:
    cpu = platform.processor() or ""
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return f"{cpu}, {os.cpu_count()} cores, {mem:.0f} GiB, Python {platform.python_version()}, {platform.system()}"


def generate(path: Path, n_lines: int, seed: int, size: float = 100.0) -> None:
    """A milling-like program: short G1 moves, ~10 % G2/G3 arcs, a comment every ~10 lines."""
    rng = np.random.default_rng(seed)
    lines = [
        "%",
        "(generated benchmark program)",
        "G21 G90 G17 G94",
        "G0 X50.0000 Y50.0000 Z5.0000",
        "G1 Z-0.5000 F800",
    ]
    x, y, z = 50.0, 50.0, -0.5
    kinds = rng.random(n_lines)
    steps = rng.uniform(-2.5, 2.5, size=(n_lines, 2))
    dzs = rng.uniform(-0.05, 0.05, n_lines)
    radii = rng.uniform(1.0, 4.0, n_lines)
    angles = rng.uniform(0.3, 2.5, n_lines)
    lo, hi = 5.0, size - 5.0
    k = 0
    while len(lines) < n_lines - 2:
        if kinds[k] < 0.1:
            # arc: centre to the left of the current point, sweep a random angle
            r, a = radii[k], angles[k]
            cx, cy = x - r, y
            ccw = kinds[k] < 0.05
            th = a if ccw else -a
            nx, ny = cx + r * np.cos(th), cy + r * np.sin(th)
            if lo < nx < hi and lo < ny < hi and lo < cx - r and cx + r < hi:
                lines.append(f"{'G3' if ccw else 'G2'} X{nx:.4f} Y{ny:.4f} I{-r:.4f} J0.0000")
                x, y = float(f"{nx:.4f}"), float(f"{ny:.4f}")
            else:
                lines.append(f"G1 X{x:.4f} Y{y:.4f}")
        elif kinds[k] < 0.2:
            lines.append(f"(pass {k})")
        else:
            nx = min(max(x + steps[k, 0], lo), hi)
            ny = min(max(y + steps[k, 1], lo), hi)
            nz = min(max(z + dzs[k], -1.0), 0.0)
            lines.append(f"G1 X{nx:.4f} Y{ny:.4f} Z{nz:.4f}")
            x, y, z = float(f"{nx:.4f}"), float(f"{ny:.4f}"), float(f"{nz:.4f}")
        k += 1
        if k == n_lines:
            k = 0
    lines += ["G0 Z5.0000", "M30", "%"]
    path.write_text("\n".join(lines[: n_lines - 1] + lines[-1:]) + "\n")


def generate_circles(path: Path, n_lines: int, seed: int, size: float = 100.0) -> None:
    """The throughput program: short G1 moves in X, Y and Z, and every tenth line a full circle of
    radius 0.25 mm (``G2 X.. Y.. I-0.25 J0``, ending where it starts)."""
    rng = np.random.default_rng(seed)
    head = [
        "%",
        "(generated throughput program)",
        "G21 G90 G17 G94",
        "G0 X50.0000 Y50.0000 Z5.0000",
        "G1 Z-0.5000 F800",
    ]
    tail = ["G0 Z5.0000", "M30", "%"]
    n = n_lines - len(head) - len(tail)
    steps = rng.uniform(-2.5, 2.5, size=(n, 2))
    dzs = rng.uniform(-0.05, 0.05, n)
    lines = list(head)
    x, y, z = 50.0, 50.0, -0.5
    lo, hi = 5.0, size - 5.0
    for k in range(n):
        if k % 10 == 9:
            lines.append(f"G2 X{x:.4f} Y{y:.4f} I-0.2500 J0.0000")
        else:
            x = round(min(max(x + steps[k, 0], lo), hi), 4)
            y = round(min(max(y + steps[k, 1], lo), hi), 4)
            z = round(min(max(z + dzs[k], -1.0), 0.0), 4)
            lines.append(f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f}")
    path.write_text("\n".join(lines + tail) + "\n")


def grid_csv(path: Path, n: int, size: float = 100.0) -> None:
    xs = np.linspace(0, size, n)
    X, Y = np.meshgrid(xs, xs)
    dz = 0.02 * np.sin(X / 17) * np.cos(Y / 23) + 0.0002 * X
    rows = ["x,y,dz"] + [f"{a:.4f},{b:.4f},{c:.6f}" for a, b, c in zip(X.ravel(), Y.ravel(), dz.ravel())]
    path.write_text("\n".join(rows) + "\n")


def probe_file(path: Path, n: int, size: float = 100.0) -> None:
    """The same map as a bCNC .probe file."""
    xs = np.linspace(0, size, n)
    rows = [f"0 {size:g} {n}", f"0 {size:g} {n}", "-1 1 100", "", ""]
    for y in xs:
        for x in xs:
            rows.append(f"{x:g} {y:g} {0.02 * np.sin(x / 17) * np.cos(y / 23) + 0.0002 * x:g}")
        rows.append("")
    path.write_text("\n".join(rows) + "\n")


def timed(cmd: list[str]) -> tuple[float, float]:
    """Wall time (s) and peak resident memory (MiB) of a child command."""
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)  # this child's own resource use
    dt = time.perf_counter() - t
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise subprocess.CalledProcessError(proc.returncode, cmd)
    return dt, usage.ru_maxrss / 1024


def best_of(n, cmd):
    runs = [timed(cmd) for _ in range(n)]
    return min(r[0] for r in runs), max(r[1] for r in runs)


BCNC_SCRIPT = r"""
import os, sys, time
import bCNC
d = os.path.dirname(bCNC.__file__)
sys.path[:0] = [d, os.path.join(d, "lib")]
import CNC
prog, probe, out = sys.argv[1:4]
t = time.perf_counter()
g = CNC.GCode()
g.load(prog)
g.probe.load(probe)
g.autolevel(range(len(g.blocks)))
with open(out, "w") as f:
    for line in g.lines():
        f.write(line + "\n")
print(time.perf_counter() - t)
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="1,2,3", help="which parts to run, e.g. 1 or 1,3 (default: all)")
    parts = {int(p) for p in ap.parse_args().parts.split(",")}
    OUT.mkdir(exist_ok=True)
    print(f"machine: {machine()}")

    if 1 in parts:
        part1()
    if 3 in parts:
        part3()
    if 2 in parts:
        part2()
    return 0


def part1() -> None:
    ncadapt = str(Path(sys.executable).with_name("ncadapt"))
    grid = OUT / "grid_101.csv"
    grid_csv(grid, 101)
    circles = OUT / "bench_1m_circles.ngc"
    if not circles.exists():
        print("generating 1,000,000-line throughput program ...", flush=True)
        generate_circles(circles, 1_000_000, seed=1)
    n_c = sum(1 for _ in open(circles, "rb"))
    cmd = [
        ncadapt,
        "correct",
        str(circles),
        "--field",
        str(grid),
        "--max-segment",
        "5",
        "-o",
        str(OUT / "bench_1m_circles_c.ngc"),
    ]
    rs = shutil.which("rs274")
    rs_cmd = [rs, "-g", str(circles), str(OUT / "bench_1m_circles.canon")] if rs else None
    # the two commands take turns, so a change in the machine's load falls on both
    runs, rs_runs = [], []
    for _ in range(3):
        runs.append(timed(cmd))
        if rs_cmd:
            rs_runs.append(timed(rs_cmd))
    t_nc, mem_nc = min(r[0] for r in runs), max(r[1] for r in runs)
    print(f"\n1. {n_c:,} lines (10 % full circles r 0.25 mm), 101x101 grid field, --max-segment 5")
    print(
        f"   ncadapt correct (read+correct+write): {t_nc:7.2f} s  {n_c / t_nc:>12,.0f} lines/s  peak {mem_nc:,.0f} MiB"
    )
    if rs:
        t_rs = min(r[0] for r in rs_runs)
        print(f"   rs274 -g (read only):                 {t_rs:7.2f} s  {n_c / t_rs:>12,.0f} lines/s")
        print(f"   ratio ncadapt / rs274 (lines/s):      {t_rs / t_nc:7.1f} x  (target 8 x)")
    else:
        print("   rs274 not installed (make test installs linuxcnc-uspace)")
    (OUT / "bench_1m_circles_c.ngc").unlink(missing_ok=True)


def part3() -> None:
    ncadapt = str(Path(sys.executable).with_name("ncadapt"))
    # the program of part 3: milling-like moves and arcs of radius 1-4 mm, with comments
    big = OUT / "bench_1m.ngc"
    if not big.exists():
        print("generating 1,000,000-line program ...", flush=True)
        generate(big, 1_000_000, seed=1)

    # 3. memory: a 50,000,000-line program (the 1,000,000-line body fifty times) corrected with a
    # shift; the peak resident memory of the command, from /usr/bin/time, is bounded by the piece
    # size, not by the program
    huge = OUT / "bench_50m.ngc"
    if not huge.exists():
        print("\ngenerating 50,000,000-line program ...", flush=True)
        body = [ln for ln in big.read_bytes().splitlines(keepends=True)[1:-1] if ln not in (b"M30\n", b"G0 Z5.0000\n")]
        with open(huge, "wb") as f:
            f.write(b"%\n")
            for _ in range(50):
                f.writelines(body)
            f.write(b"G0 Z5.0000\nM30\n%\n")
    n_huge = sum(1 for _ in open(huge, "rb"))
    out_huge = OUT / "bench_50m_c.ngc"
    t = time.perf_counter()
    proc = subprocess.run(
        [
            "/usr/bin/time",
            "-f",
            "%M",
            ncadapt,
            "correct",
            str(huge),
            "--shift",
            "0,0,0.01",
            "--max-segment",
            "5",
            "-o",
            str(out_huge),
        ],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        stdin=subprocess.DEVNULL,
    )
    t_huge = time.perf_counter() - t
    peak = int(proc.stderr.strip().splitlines()[-1]) / 1024
    print(f"\n3. {n_huge:,} lines, --shift 0,0,0.01 --max-segment 5")
    print(
        f"   ncadapt correct: {t_huge:7.1f} s  {n_huge / t_huge:>12,.0f} lines/s  peak {peak:,.0f} MiB (target < 500 MiB)"
    )
    out_huge.unlink()


def part2() -> None:
    ncadapt = str(Path(sys.executable).with_name("ncadapt"))
    big = OUT / "bench_1m.ngc"
    if not big.exists():
        generate(big, 1_000_000, seed=1)
    mid = OUT / "bench_200k.ngc"
    probe = OUT / "map_21.probe"
    if not mid.exists():
        generate(mid, 200_000, seed=2)
    probe_file(probe, 21)
    n_mid = sum(1 for _ in open(mid, "rb"))
    t_nc2, _ = best_of(3, [ncadapt, "correct", str(mid), "--field", str(probe), "-o", str(OUT / "bench_200k_c.ngc")])
    print(f"\n2. {n_mid:,} lines, 21x21 probe map (bCNC .probe)")
    print(f"   ncadapt correct:                      {t_nc2:7.2f} s  {n_mid / t_nc2:>12,.0f} lines/s")
    try:
        import bCNC  # noqa: F401

        script = OUT / "bcnc_autolevel.py"
        script.write_text(BCNC_SCRIPT)
        t = time.perf_counter()
        subprocess.run(
            [sys.executable, str(script), str(mid), str(probe), str(OUT / "bench_200k_bcnc.ngc")],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        t_bc = time.perf_counter() - t
        print(f"   bCNC autolevel (load+level+write):    {t_bc:7.2f} s  {n_mid / t_bc:>12,.0f} lines/s")
        print(f"   ratio ncadapt / bCNC (lines/s):       {t_bc / t_nc2:7.1f} x")
    except ImportError:
        print("   bCNC not installed (make bench installs it)")


if __name__ == "__main__":
    sys.exit(main())
