"""``ncadapt turning``: feed and path trajectories for slender shafts (see
:mod:`ncadapt.processes.turning` and :mod:`ncadapt.sim.turning`)."""

from __future__ import annotations

from pathlib import Path

import click

from ._common import (
    FiniteRange,
    check_outputs,
    echo_err,
    handle_errors,
    json_option,
    progress,
    seed_option,
    summary,
    write_json,
)


@click.group()
def turning() -> None:
    """Turning slender shafts: trajectories that keep the diameter constant."""


@turning.command("plan")
@click.argument("config", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--mode",
    type=click.Choice(["feed", "path"]),
    default="feed",
    show_default=True,
    help="feed: a feed (and speed) schedule; path: the X path pre-distorted at constant feed.",
)
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), help="Lathe program to write.")
@click.option("--radius-mode", is_flag=True, help="X words as radii (G8) instead of diameters (G7).")
@click.option(
    "--css",
    is_flag=True,
    help="Constant surface speed: G96 with a D rpm limit and the surface speed (m/min) per block at the "
    "tool's diameter, so the spindle turns at the planned rpm (default: G97 with S rpm per block).",
)
@click.option(
    "--tool",
    type=click.IntRange(1, 99),
    default=1,
    show_default=True,
    help="Tool number of the program's tool call (LinuxCNC T<n> M6 G43, Fanuc T<nn><nn>, Sinumerik T<n> D1).",
)
@click.option(
    "--dialect",
    type=click.Choice(["linuxcnc", "fanuc", "sinumerik"]),
    default="linuxcnc",
    show_default=True,
    help="Controller of the program: LinuxCNC (G7/G8, G95, G96 D), Fanuc lathe (G-code system A: G99, "
    "G50 S limit, diameter programming), Sinumerik (DIAMON, G95, LIMS=).",
)
@click.option(
    "--wear-weight",
    type=FiniteRange(min=0),
    default=0.0,
    show_default=True,
    help="Weight of tool wear (Taylor's law) in the cost, s per tool life.",
)
@json_option
@click.option(
    "--report",
    "report_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="HTML report: the feed/speed/position family and the diameter profiles.",
)
@handle_errors
def plan(config, mode, output, radius_mode, css, tool, dialect, wear_weight, json_path, report_path):
    """Plan the trajectory for the shaft in CONFIG (TOML, the paper's units)."""
    from .._io import atomic_write
    from ..processes import turning as tu

    check_outputs({"configuration": config}, {"-o": output, "--json": json_path, "--report": report_path})
    if dialect == "fanuc" and radius_mode:
        raise click.BadParameter(
            "a Fanuc lathe programs X as a diameter (radius programming is a machine parameter); drop --radius-mode",
            param_hint="'--dialect'",
        )
    cfg = tu.load(config)
    with progress() as say:  # a bar with percentage and time left on a terminal, quiet otherwise
        p = tu.plan(cfg, mode, wear_weight=wear_weight, progress=lambda f: say("planning", f, 1.0))
    d = p.as_dict()
    summary(
        f"{mode}: diameter variation (max D − min D) on the model {d['diameter_variation'] * 1000:.1f} µm "
        f"(constant feed {d['constant_feed']:.3f} mm/rev at {d['constant_rpm']:.0f} rpm with the best X offset: "
        f"{d['diameter_variation_constant_feed'] * 1000:.1f} µm, ratio {d['diameter_variation_ratio']:.3f}); "
        f"machining time {d['machining_time_s']:.1f} s"
        + (
            f", a constant feed with the same variation {d['constant_feed_same_error']:.4f} mm/rev takes "
            f"{d['machining_time_same_error_s']:.1f} s"
            if d["machining_time_same_error_s"] is not None
            else ""
        )
    )
    if d["entry"]:
        step = 2 * (d["entry"][0]["x1_offset"] - d["profile"][0]["x1_offset"]) * 1000
        summary(
            f"  entry: the first {len(d['entry'])} revolutions with their own X (the entry transient: "
            f"{step:+.2f} µm on the diameter over the stations' X at the first)"
        )
    for b in d["baselines"]:
        summary(
            f"  baseline {b['name']}: feed {b['feed']:.3f}"
            + (
                f" then {b['finish_feed']:.3f} mm/rev over the last {b['finish_depth']:.2f} mm"
                if "finish_feed" in b
                else " mm/rev"
            )
            + f", diameter variation {b['diameter_variation'] * 1000:.1f} µm, "
            f"{b['machining_time_s']:.1f} s"
        )
    if output:
        atomic_write(
            output, tu.program(p, cfg, diameter_mode=not radius_mode, css=css, tool=tool, dialect=dialect).encode()
        )
        summary(f"wrote {output}")
    if json_path:
        write_json(json_path, {"config": str(config), **d})
    if report_path:
        _report(report_path, cfg, p, css)


@turning.command("simulate")
@click.argument("config", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("program", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--rho-sigma",
    type=FiniteRange(0, 0.5),
    default=0.0,
    show_default=True,
    help="Relative scatter σ of the cutting pressure ρ (a log-normal factor exp(σN) per run and a drift "
    "of ±σ/2 along the cut), 0 … 0.5.",
)
@click.option(
    "--stiffness-sigma",
    type=FiniteRange(0, 0.5),
    default=0.0,
    show_default=True,
    help="Relative scatter σ of the stiffness (a log-normal factor exp(σN) per run), 0 … 0.5.",
)
@click.option(
    "--dialect",
    type=click.Choice(["linuxcnc", "fanuc", "sinumerik"]),
    default="linuxcnc",
    show_default=True,
    help="How PROGRAM is read: LinuxCNC, Fanuc lathe (G-code system A) or Sinumerik.",
)
@seed_option
@json_option
@handle_errors
def simulate(config, program, rho_sigma, stiffness_sigma, dialect, seed, json_path):
    """Turn the shaft of CONFIG with PROGRAM on the virtual lathe: the diameter along the shaft."""
    from ..processes import turning as tu
    from ..sim import turning as st

    check_outputs({"configuration": config, "program": program}, {"--json": json_path})
    cfg = tu.load(config)
    with progress() as say:
        prof = st.simulate(
            cfg,
            program,
            rho_sigma=rho_sigma,
            stiffness_sigma=stiffness_sigma,
            seed=seed,
            progress=lambda f: say("turning", f, 1.0),
            dialect=dialect,
        )
    d = prof.as_dict()
    summary(
        f"{program}: diameter {d['diameter_min']:.4f} .. {d['diameter_max']:.4f} mm (target "
        f"{d['diameter_target']:.3f}; max |D − target| {d['diameter_error_max'] * 1000:.1f} µm, variation "
        f"max D − min D {d['diameter_variation'] * 1000:.1f} µm), {d['machining_time_s']:.1f} s, "
        f"{d['revolutions']:,} revolutions"
    )
    for a, b, n in prof.no_contact:
        echo_err(
            f"warning: {program}: no contact from x3 = {a:.2f} to {b:.2f} mm ({n} revolutions): the tool "
            "passes outside the stock there; the surface is left as it was"
        )
    if json_path:
        write_json(json_path, {"config": str(config), "program": str(program), **d})


#: the report's names of the plan's JSON keys, with their units
_LABELS = {
    "mode": "mode",
    "measure": "measure",
    "diameter_error_max": "max |D − D_target| on the model, mm",
    "diameter_variation": "diameter variation max D − min D on the model, mm",
    "diameter_error_constant_feed": "max |D − D_target| at the constant feed (best X offset), mm",
    "diameter_variation_constant_feed": "diameter variation at the constant feed, mm",
    "diameter_variation_ratio": "ratio of the two variations",
    "constant_offset": "the constant feed's best X offset (radius), mm",
    "machining_time_s": "machining time, s",
    "machining_time_constant_feed_s": "machining time at the constant feed, s",
    "constant_feed": "the constant feed, mm/rev",
    "constant_rpm": "its spindle speed, rpm",
    "constant_feed_same_error": "a constant feed with the same diameter variation, mm/rev",
    "machining_time_same_error_s": "its machining time, s",
    "deflection_target": "deflection kept, mm",
}


def _report(path, cfg, p, css) -> None:
    import tempfile
    from pathlib import Path

    import numpy as np

    from ..processes import turning as tu
    from ..report import figure_png, page, pyplot, table, write
    from ..sim import turning as st

    plt = pyplot()

    fam = p.family_feed * 1e3
    fig = plt.figure(figsize=(10, 5.5))
    ax = fig.add_subplot(projection="3d")
    X, N = np.meshgrid(p.x3 * 1e3, p.family_rpm)
    ax.plot_surface(X, N, np.where(np.isfinite(fam), fam, np.nan), cmap="viridis", alpha=0.8)
    ax.plot(p.x3 * 1e3, p.rpm, p.feed * 1e3, "r-", lw=2, label="chosen (dynamic programming)")
    ax.set_xlabel("x3 from the tailstock, mm")
    ax.set_ylabel("spindle, rpm")
    ax.set_zlabel("feed, mm/rev")
    ax.legend()
    # diameter profiles on the virtual lathe: constant feed, X pre-distortion, feed schedule
    fig2, ax2 = plt.subplots(figsize=(10, 3.8))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        plans = {
            "constant feed": None,
            "X pre-distortion": p if p.mode == "path" else tu.plan(cfg, "path"),
            "feed schedule": p if p.mode == "feed" else tu.plan(cfg, "feed"),
        }
        for name, q in plans.items():
            if q is None:
                q = plans["feed schedule"].constant_feed_plan()  # with its best constant X offset
            f = f"{tmp}/p.ngc"
            Path(f).write_text(tu.program(q, cfg, css=False))
            prof = st.simulate(cfg, f)
            ax2.plot(prof.x3, (prof.diameter - prof.target) * 1000, label=name)
            rows.append((name, f"{prof.error_max * 1000:.1f}", f"{prof.variation * 1000:.1f}", f"{prof.time_s:.1f}"))
    ax2.set_xlabel("x3 from the tailstock, mm")
    ax2.set_ylabel("diameter − target, µm")
    ax2.legend(fontsize=8)
    d = p.as_dict()
    figures = [(_LABELS.get(k, k), v) for k, v in d.items() if k != "profile" and v is not None]
    write(
        path,
        page(
            f"Turning plan: {p.mode} mode",
            cfg.source,
            [
                ("Summary", table(figures, ["", "value"])),
                ("Feed / spindle speed / position: the family keeping the deflection constant", figure_png(fig)),
                (
                    "Diameter along the shaft on the virtual lathe",
                    figure_png(fig2)
                    + table(
                        rows, ["program", "max |D − D_target|, µm", "diameter variation max D − min D, µm", "time, s"]
                    ),
                ),
            ],
        ),
    )
