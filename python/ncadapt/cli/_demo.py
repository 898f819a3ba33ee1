"""``ncadapt demo``: the main job on shipped data (see :mod:`ncadapt.demo`)."""

from __future__ import annotations

from pathlib import Path

import click

from ._common import handle_errors, progress, summary


@click.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("demo-out"),
    show_default=True,
    help="Folder for the demo's inputs and outputs.",
)
@click.option(
    "--seed",
    type=click.IntRange(0, 2**63 - 1),
    default=1,
    show_default=True,
    help="Seed of the simulated measurement noise.",
)
@click.option(
    "--filter",
    "method",
    type=click.Choice(["bilateral", "spline"]),
    default="bilateral",
    show_default=True,
    help="How the systematic error is separated from the noise.",
)
@handle_errors(staged=False)  # it reads back the files it writes
def demo(out_dir, seed, method):
    """Compensate a shipped freeform part from simulated measurements, end to end.

    Machines the part virtually with a systematic machine error, measures actual points on it with
    5 µm noise, projects them onto the part's shipped STEP model (compensate --nominal), tests the
    deviations with Moran's I, separates the systematic part, writes the corrected program, the
    compensated STEP part, an HTML report and summary.json into OUT, re-machines with the corrected
    program and prints the systematic error before and after.
    """
    from .. import demo as run_demo

    with progress() as say:
        r = run_demo.run(out_dir, seed=seed, method=method, say=say)
    s = r.summary
    summary(
        f"systematic error RMS before: {s['systematic_rms_before'] * 1000:.1f} µm "
        f"(max {s['systematic_max_abs_before'] * 1000:.1f} µm)"
    )
    summary(
        f"systematic error RMS after one compensation: {s['systematic_rms_after'] * 1000:.1f} µm "
        f"(max {s['systematic_max_abs_after'] * 1000:.1f} µm), {100 * s['ratio']:.1f} % of before"
    )
    m, v = s["moran"], s["verdict"]
    by = " and ".join("Moran's I" if b == "moran" else "the offset" for b in v["by"])
    summary(
        f"Moran's I {m['I']:.3f}, z {m['z_randomization']:.1f}; mean offset {s['offset']['mean'] * 1000:+.1f} µm, "
        f"t {s['offset']['t']:.1f}: systematic {'yes, by ' + by if v['systematic'] else 'no'}"
    )
    for name, f in r.files.items():
        summary(f"  {name:22s} {out_dir / f}")
