"""``ncadapt skin simulate``: mirror milling of thin skins on the virtual testbed
(see :mod:`ncadapt.processes.skin` and :mod:`ncadapt.sim.skin`)."""

from __future__ import annotations

from pathlib import Path

import click

from ._common import check_outputs, handle_errors, write_json


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

    check_outputs({}, {"--json": json_path, "--report": report_path})
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
    import numpy as np

    from ..report import figure_png, page, pyplot, table, write
    from ..sim import skin as sk

    plt = pyplot()

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
    # every method on the same seed, noise and dead time, and the paper's noise-free protocol
    methods = ("none", "mirror", "secant", "kalman")
    runs = {m: (run if m == run.method else sk.run(m, noise=run.noise, latency_ms=run.latency_ms, seed=run.seed)).as_dict()
            for m in methods}
    rows = [(c["pocket"], f"{c['x']:.0f}", f"{c['y']:.0f}", *(f"{runs[m]['checkpoints'][i]['error'] * 1000:+.1f}" for m in methods))
            for i, c in enumerate(run.checkpoints)]
    for key in ("max_abs_error", "min_abs_error", "mean_abs_error"):
        rows.append((key.split("_")[0] + " |error|", "", "", *(f"{runs[m][key] * 1000:.1f}" for m in methods)))
    rows.append(("fallbacks", "", "", *(str(runs[m]["fallbacks"]) for m in methods)))
    proto = [(m, f"{sk.protocol(m)['max_abs_error'] * 1000:.4g}") for m in ("mirror", "secant", "kalman")]
    sections = [("Result", table([("method", run.method), ("gauge noise σ, mm", run.noise), ("dead time, ms", run.latency_ms),
                                   ("max |error|, µm", f"{d['max_abs_error'] * 1000:.1f}"),
                                   ("mean |error|, µm", f"{d['mean_abs_error'] * 1000:.1f}"),
                                   ("fallbacks", d["fallbacks"])], ["", "value"])),
                ("Error along the toolpath", figure_png(fig)),
                ("Checkpoints: every method on the same seed (error, µm)",
                 table(rows, ["pocket", "x, mm", "y, mm", *methods])),
                ("The paper's noise-free protocol: max |error| after the second compensation, µm",
                 table(proto, ["method", "max |error|, µm"]))]
    write(path, page(f"Skin mirror milling: {run.method}", "ncadapt skin testbed", sections))


@skin.command("correct")
@click.argument("program", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--thickness", "map_path", type=click.Path(exists=True, dir_okay=False, path_type=Path), required=True,
              help="Thickness map: CSV with columns x,y,thickness (mm), on a grid or scattered.")
@click.option("--target", type=float, required=True, help="Target wall thickness T, mm.")
@click.option("--allowance", type=click.FloatRange(min=0), default=0.0, show_default=True,
              help="Material the finishing pass was planned to remove (0: the map is after finishing), mm.")
@click.option("--into", type=click.Choice(["-z", "+z"]), default="-z", show_default=True,
              help="Direction in which the tool cuts deeper.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True)
@click.option("--limit", type=click.FloatRange(min=0, min_open=True), default=0.5, show_default=True,
              help="Refuse if any correction exceeds this, mm.")
@click.option("--outside", type=click.Choice(["error", "clamp", "extrapolate"]), default="error", show_default=True,
              help="Program points outside the map.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
@handle_errors
def correct(program, map_path, target, allowance, into, output, limit, outside, json_path):
    """Correct a finishing PROGRAM from a thickness MAP measured after the previous pass: the
    tool goes deeper by the excess thickness − target − allowance (offline mode)."""
    import numpy as np

    from .. import nc
    from ..processes import skin as ps
    from ._common import echo_err, progress

    check_outputs({"input program": program, "thickness map": map_path}, {"-o": output, "--json": json_path})
    with progress() as say:
        say(f"reading {map_path}")
        field, excess = ps.thickness_field(map_path, target, allowance=allowance, into=into, outside=outside)
        say(f"reading {program}")
        prog = nc.read(program)
        c = prog.correct_to(output, field, limit=limit, progress=say)
    echo_err(f"{program} -> {output}")
    echo_err(f"  map: {len(excess)} points, excess thickness min {excess.min():+.4f} max {excess.max():+.4f} "
             f"mean {excess.mean():+.4f} mm")
    echo_err(f"  blocks changed {c.blocks_changed:,}, lines added {c.lines_added:,}; displacement max "
             f"{c.max_displacement:.4f} mm, mean {c.mean_displacement:.4f} mm")
    for w in c.warnings:
        echo_err(f"  warning: {w}")
    if json_path:
        d = {"input": str(program), "output": str(output), "thickness": str(map_path), "target": target,
             "allowance": allowance, "into": into, "map_points": int(len(excess)),
             "excess_min": float(np.min(excess)), "excess_max": float(np.max(excess)),
             "excess_mean": float(np.mean(excess))}
        d.update(c.as_dict())
        write_json(json_path, d)
