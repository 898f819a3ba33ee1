"""Regenerate the waffle examples from the testbed (seed 1), running the documented commands.

    python examples/waffle/make_examples.py [FOLDER]

The workflow of Pas & Serkov's section 4 on row 1 of the virtual shell (`ncadapt.sim.waffle`):

1. tracking pre-measurement of row 1, cells 1 and 2 (`tracking.csv`: B 0–30°, every 5 mm of Z),
   and the pair of signals for the backlash (`backlash_signals.csv`, with its time column t);
2. the semi-finishing program of cell 1 (`cell_r1c1_semi.ngc`, the finishing program 0.3 mm
   shallower) corrected by the disturbance corrector K_dist:
   `ncadapt waffle correct cell_r1c1_semi.ngc --tracking tracking.csv --tool-radius 10 --diameter 1500 -o …`;
3. the testbed cuts it and gauges the web: `thickness_r1c1.csv` (K_fb's source — it carries
   K_dist, so the tilt is not corrected twice);
4. the finishing program of cell 1 corrected by K_dist + K_fb (`--thickness thickness_r1c1.csv
   --target 2.0 --allowance 0.3`); the testbed cuts it: `finished/thickness_r1c1.csv`;
5. `ncadapt waffle cells --thickness-dir finished --cells 4x24 --target 2.0 --band 1.97,2.03` decides
   whether cell 2 needs a semi-finishing pass; if not, cell 2's program is corrected with cell 1's
   K_fb moved by the cell pitch (`--map-origin 7.5,-180 --cell-origin 22.5,-180`).

`tests/test_waffle_workflow.py` runs the same commands and checks the finished webs.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from ncadapt.sim import waffle as sw

SEED = 1
HERE = Path(__file__).resolve().parent


def ncadapt(*args, cwd) -> str:
    r = subprocess.run(
        [sys.executable, "-c", "from ncadapt.cli import main; main()", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
    )
    if r.returncode != 0:
        raise SystemExit(f"ncadapt {' '.join(map(str, args))}: exit {r.returncode}\n{r.stdout}{r.stderr}")
    return r.stdout


def write_map(path: Path, rows, title: str) -> None:
    with open(path, "w") as f:
        f.write(f"# {title}\nB,Z,thickness\n")
        for b, z, t in rows:
            f.write(f"{b:.2f},{z:.1f},{t:.4f}\n")


def tracking(folder: Path) -> None:
    shell = sw.Shell.make(SEED)
    rng = np.random.default_rng([SEED, 3])
    b = np.arange(0.0, 30.0 + 1e-9, 0.25)
    zs = np.arange(-230.0, -130.0 + 1e-9, 5.0)
    with open(folder / "tracking.csv", "w") as f:
        f.write(
            f"# ncadapt waffle testbed (seed {SEED}): tracking pre-measurement of row 1, cells 1-2, one-way along B\n"
            "B,Z,V\n"
        )
        for z in zs:
            v = shell.v(b, np.full_like(b, z)) + rng.normal(0, sw.NOISE_TRACK, b.shape)
            for bi, vi in zip(b, v):
                f.write(f"{bi:.2f},{z:.1f},{vi:.4f}\n")


def backlash(folder: Path) -> None:
    """The pair of signals of section 3 (`sim.waffle.backlash_pair`) with their time column."""
    vi, vm, dt = sw.backlash_pair(SEED)
    with open(folder / "backlash_signals.csv", "w") as f:
        f.write(
            f"# ncadapt waffle testbed (seed {SEED}): row 1 cell 1 zig-zag, dt = {dt:.5f} s\nt,V_ideal,V_measured\n"
        )
        for i, (a, b) in enumerate(zip(vi, vm)):
            f.write(f"{i * dt:.5f},{a:.5f},{b:.5f}\n")


def main(folder: Path = HERE) -> None:
    folder.mkdir(exist_ok=True)
    (folder / "finished").mkdir(exist_ok=True)
    tracking(folder)
    backlash(folder)
    for cell in (0, 1):
        (folder / f"cell_r1c{cell + 1}.ngc").write_text(sw.cell_program(0, cell))
    (folder / "cell_r1c1_semi.ngc").write_text(sw.cell_program(0, 0, depth=8.0 - sw.ALLOWANCE))
    common = ("--tracking", "tracking.csv", "--tool-radius", sw.R_TOOL, "--diameter", sw.D)
    ncadapt("waffle", "correct", "cell_r1c1_semi.ngc", *common, "-o", "cell_r1c1_semi_corrected.ngc", cwd=folder)
    semi = sw.machine_program(folder / "cell_r1c1_semi_corrected.ngc", SEED, 0, 0)
    write_map(
        folder / "thickness_r1c1.csv",
        sw.gauge_map(semi, SEED, 0, 0),
        f"ncadapt waffle testbed (seed {SEED}): web thickness after semi-finishing row 1 cell 1 with K_dist "
        f"(allowance {sw.ALLOWANCE} mm)",
    )
    fb = ("--thickness", "thickness_r1c1.csv", "--target", sw.T_REF, "--allowance", sw.ALLOWANCE)
    ncadapt("waffle", "correct", "cell_r1c1.ngc", *common, *fb, "-o", "cell_r1c1_corrected.ngc", cwd=folder)
    fin = sw.machine_program(folder / "cell_r1c1_corrected.ngc", SEED, 0, 0)
    write_map(
        folder / "finished" / "thickness_r1c1.csv",
        sw.gauge_map(fin, SEED, 0, 0),
        f"ncadapt waffle testbed (seed {SEED}): web thickness after finishing row 1 cell 1",
    )
    for f in ("cell_r1c1_semi_corrected.ngc", "cell_r1c1_corrected.ngc"):
        (folder / f).unlink()
    print(
        ncadapt(
            "waffle",
            "cells",
            "--thickness-dir",
            "finished",
            "--cells",
            f"{sw.ROWS}x{sw.CELLS}",
            "--target",
            sw.T_REF,
            "--band",
            f"{sw.T_REF - sw.BAND:g},{sw.T_REF + sw.BAND:g}",
            cwd=folder,
        ),
        end="",
    )


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE)
