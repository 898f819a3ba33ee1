"""``ncadapt skin simulate``: mirror milling of thin skins on the virtual testbed
(see :mod:`ncadapt.processes.skin` and :mod:`ncadapt.sim.skin`)."""

from __future__ import annotations

from pathlib import Path

import click

from ._common import handle_errors, write_json


@click.group()
def skin() -> None:
    """Mirror milling of thin skins: real-time wall-thickness compensation."""


@skin.command("simulate")
@click.option("--method", type=click.Choice(["none", "mirror", "secant", "kalman"]), default="kalman",
              show_default=True, help="Compensator (kalman: ours).")
@click.option("--noise", type=click.FloatRange(min=0), default=0.005, show_default=True, help="Gauge noise σ, mm.")
@click.option("--latency-ms", type=click.FloatRange(min=0), default=45.0, show_default=True,
              help="Dead time from reading to axis motion, ms.")
@click.option("--seed", type=int, default=1, show_default=True)
@click.option("--protocol", is_flag=True, help="The paper's noise-free protocol at the checkpoints instead.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--report", "report_path", type=click.Path(dir_okay=False, path_type=Path),
              help="HTML report with the error along the toolpath.")
@handle_errors
def simulate(method, noise, latency_ms, seed, protocol, json_path, report_path):
    """Finish the testbed's two pockets with a compensator; errors at the 13 checkpoints."""
    from ..sim import skin as sk

    if protocol:
        if method in ("none",):
            raise click.UsageError("the protocol compares compensators; choose one")
        r = sk.protocol(method)
        click.echo(f"{method}: max |error| after {r['compensations']} compensations {r['max_abs_error'] * 1000:.4g} µm")
        if json_path:
            write_json(json_path, r)
        return
    run = sk.run(method, noise=noise, latency_ms=latency_ms, seed=seed)
    d = run.as_dict()
    click.echo(f"{method}: |error| at 13 checkpoints max {d['max_abs_error'] * 1000:.1f} µm, "
               f"min {d['min_abs_error'] * 1000:.1f} µm, mean {d['mean_abs_error'] * 1000:.1f} µm; "
               f"{d['compensator_steps']} steps, {d['fallbacks']} fallbacks, {d['rejected_readings']} readings rejected")
    if json_path:
        write_json(json_path, d)
    if report_path:
        _report(report_path, run)


def _report(path, run) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from ..report import figure_png, page, table, write
    from ..sim import skin as sk

    fig, axes = plt.subplots(1, len(run.path_errors), figsize=(11, 3.8), squeeze=False)
    for k, (ax, err) in enumerate(zip(axes[0], run.path_errors)):
        p = sk.toolpath(k)
        sc = ax.scatter(p[:, 0], p[:, 1], c=np.asarray(err) * 1000, s=1, cmap="RdBu_r", vmin=-50, vmax=50)
        cps = [c for c in run.checkpoints if c["pocket"] == k + 1]
        ax.plot([c["x"] - sk.POCKETS[k][0] for c in cps], [c["y"] - sk.POCKETS[k][1] for c in cps], "k+", ms=10)
        ax.set_title(f"pocket {k + 1}", fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlabel("x, mm")
    fig.colorbar(sc, ax=axes[0].tolist(), label="thickness error, µm")
    d = run.as_dict()
    rows = [(c["pocket"], f"{c['x']:.0f}", f"{c['y']:.0f}", f"{c['error'] * 1000:+.1f}") for c in run.checkpoints]
    sections = [("Result", table([("method", run.method), ("gauge noise σ, mm", run.noise), ("dead time, ms", run.latency_ms),
                                   ("max |error|, µm", d["max_abs_error"] * 1000), ("mean |error|, µm", d["mean_abs_error"] * 1000),
                                   ("fallbacks", d["fallbacks"])], ["", "value"])),
                ("Error along the toolpath", figure_png(fig)),
                ("Checkpoints", table(rows, ["pocket", "x, mm", "y, mm", "error, µm"]))]
    write(path, page(f"Skin mirror milling: {run.method}", "ncadapt skin testbed", sections))
