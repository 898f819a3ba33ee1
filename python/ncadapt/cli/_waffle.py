"""``ncadapt waffle``: waffle-grid shells on tracking machines (see :mod:`ncadapt.processes.waffle`
and :mod:`ncadapt.sim.waffle`)."""

from __future__ import annotations

from pathlib import Path

import click

from .. import constants
from ._common import FiniteRange, about, check_outputs, echo_err, handle_errors, json_option, progress, seed_option, summary, write_json

_POS = dict(type=FiniteRange(min=0, min_open=True), required=True)


@click.group()
def waffle() -> None:
    """Waffle-grid shells: spindle-tilt and copying-system corrections, cell-to-cell self-tuning."""


@waffle.command("tilt")
@click.option("--tracking", "log", type=click.Path(exists=True, dir_okay=False, path_type=Path), required=True,
              help="Tracking pre-measurement: CSV with columns B (deg), Z (mm), V (mm).")
@click.option("--tool-radius", help="Cutter radius R, mm.", **_POS)
@click.option("--diameter", help="Shell diameter D, mm.", **_POS)
@click.option("--segment", type=click.IntRange(min=2), default=10, show_default=True,
              help="Points per least-squares segment (restarting where Z changes).")
@json_option
@handle_errors
def tilt(log, tool_radius, diameter, segment, json_path):
    """The web-thickness error from the spindle's tilt to the back wall: E = R·(360/(πD))·k per
    segment, signed (the web is left thinner by |E|)."""
    from ..processes import waffle as pw

    check_outputs({"tracking log": log}, {"--json": json_path})
    b, z, v = pw.read_tracking(log)
    with about(log):
        t = pw.tilt(b, z, v, tool_radius=tool_radius, diameter=diameter, segment=segment)
    d = t.as_dict()
    summary(f"{log}: {len(b)} rows, {d['segments']} segments of {segment}; |E| max {d['max_abs_error'] * 1000:.2f} µm, "
               f"RMS {d['rms_error'] * 1000:.2f} µm")
    if json_path:
        write_json(json_path, {"tracking": str(log), "tool_radius": tool_radius, "diameter": diameter,
                               "segment": segment, **d})


@waffle.command("correct")
@click.argument("program", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--tracking", "log", type=click.Path(exists=True, dir_okay=False, path_type=Path), required=True,
              help="Tracking pre-measurement: CSV with columns B, Z, V.")
@click.option("--tool-radius", help="Cutter radius R, mm.", **_POS)
@click.option("--diameter", help="Shell diameter D, mm.", **_POS)
@click.option("--segment", type=click.IntRange(min=2), default=10, show_default=True,
              help="Points per least-squares segment of the tracking log (restarting where Z changes).")
@click.option("--thickness", "map_path", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Thickness map of a semi-finished cell: CSV with columns B, Z, thickness (self-tuning K_fb).")
@click.option("--target", type=FiniteRange(), help="Target web thickness T_ref, mm (with --thickness).")
@click.option("--allowance", type=FiniteRange(min=0), default=0.0, show_default=True,
              help="Semi-finishing allowance b, mm (with --thickness).")
@click.option("--depth-axis", type=click.Choice(["X", "Y", "Z"], case_sensitive=False), default="Y", show_default=True,
              help="The axis along the spindle.")
@click.option("--axial-axis", type=click.Choice(["X", "Y", "Z", "U", "V", "W"], case_sensitive=False), default="Z",
              show_default=True, help="The axis along the shell.")
@click.option("--rotary-axis", type=click.Choice(["A", "B", "C"], case_sensitive=False), default="B", show_default=True,
              help="The rotary axis turning the shell (degrees).")
@click.option("--into", type=click.Choice(["+x", "-x", "+y", "-y", "+z", "-z"], case_sensitive=False), default=None,
              help="Direction of the depth axis in which the tool cuts deeper (thinner web), e.g. +y; "
                   "default + along --depth-axis.")
@click.option("--outside", type=click.Choice(["error", "clamp", "extrapolate"]), default="error", show_default=True,
              help="Program points outside the measured B × Z area.")
@click.option("--limit", type=FiniteRange(min=0, min_open=True), default=constants.LIMIT, show_default=True,
              help="Refuse if any correction exceeds this, mm.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="Corrected program to write.")
@json_option
@handle_errors
def correct(program, log, tool_radius, diameter, segment, map_path, target, allowance, depth_axis, axial_axis,
            rotary_axis, into, outside, limit, output, json_path):
    """Rewrite PROGRAM with Y_c = Y_p + K_dist (+ K_fb): the tilt corrector from the tracking
    pre-measurement, and with --thickness the self-tuning corrector K_fb = T_pf − T_ref − b,
    interpolated at every point of the program by (B, Z); rotary words are kept exact."""
    import numpy as np

    from .. import nc
    from ..processes import waffle as pw

    if map_path is not None and target is None:
        raise click.UsageError("--thickness needs --target")
    if map_path is None and (target is not None or allowance):
        raise click.UsageError("--target and --allowance go with --thickness")
    check_outputs({"input program": program, "tracking log": log, "thickness map": map_path},
                  {"-o": output, "--json": json_path})
    axes = dict(diameter=diameter, depth_axis=depth_axis, axial_axis=axial_axis, rotary_axis=rotary_axis, outside=outside)
    into = (into or "+" + depth_axis).lower()
    if into[1] != depth_axis.lower():
        raise click.BadParameter(f"{into} is not along the depth axis {depth_axis.upper()}; give "
                                 f"+{depth_axis.lower()} or -{depth_axis.lower()}", param_hint="'--into'")
    sign = 1.0 if into[0] == "+" else -1.0
    with progress() as say:
        say(f"reading {log}")
        b, z, v = pw.read_tracking(log)
        with about(log):
            t = pw.tilt(b, z, v, tool_radius=tool_radius, diameter=diameter, segment=segment)
            parts = [pw.DepthField(b, z, sign * t.correction, **axes)]
        k_fb = None
        if map_path is not None:
            say(f"reading {map_path}")
            bt, zt, th, _ = pw.read_thickness(map_path)
            k_fb = pw.feedback_correction(th, target, allowance)
            with about(map_path):
                parts.append(pw.DepthField(bt, zt, sign * k_fb, **axes))
        field = pw.Sum(parts)
        say(f"reading {program}")
        prog = nc.read(program)
        c = prog.correct_to(output, field, limit=limit, progress=say)
    summary(f"{program} -> {output}")
    summary(f"  K_dist (tilt): |E| max {np.abs(t.error).max():.4f} mm over {len(b)} tracking rows")
    if k_fb is not None:
        summary(f"  K_fb (self-tuning): min {k_fb.min():+.4f} max {k_fb.max():+.4f} mm over {len(k_fb)} map points")
    summary(f"  blocks changed {c.blocks_changed:,}, lines added {c.lines_added:,}; correction max "
             f"{c.max_displacement:.4f} mm, mean {c.mean_displacement:.4f} mm")
    for w in c.warnings:
        echo_err(f"  warning: {w}")
    if c.n_points == 0:
        echo_err("  warning: no point of the program was corrected — does it set every linear axis (X, Y, Z) "
                 "before cutting, and cut with G1/G2/G3?")
    if json_path:
        d = {"input": str(program), "output": str(output), "tracking": str(log), "thickness": str(map_path) if map_path else None,
             "tool_radius": tool_radius, "diameter": diameter, "segment": segment, "target": target, "allowance": allowance,
             "depth_axis": depth_axis.upper(), "into": into, "tilt_max_abs_error": float(np.abs(t.error).max()),
             "k_fb_min": None if k_fb is None else float(k_fb.min()), "k_fb_max": None if k_fb is None else float(k_fb.max())}
        d.update(c.as_dict())
        write_json(json_path, d)


@waffle.command("backlash")
@click.option("--signals", "path", type=click.Path(exists=True, dir_okay=False, path_type=Path), required=True,
              help="CSV with columns V_ideal (one-way pre-measurement) and V_measured (while machining), mm.")
@click.option("--dt", type=FiniteRange(min=0, min_open=True), default=1.0, show_default=True,
              help="Sampling period, s (τ comes out in the same unit).")
@json_option
@handle_errors
def backlash(path, dt, json_path):
    """Estimate the copying system's gap g (and drive τ) by least squares from a pair of signals."""
    from .. import fields
    from ..processes import waffle as pw

    check_outputs({"signals": path}, {"--json": json_path})
    c, _ = fields.read_columns(path, ("v_ideal", "v_measured"))
    with about(path):
        r = pw.estimate_backlash(c["v_ideal"], c["v_measured"], dt)
    summary(f"gap g = {r.gap * 1000:.2f} µm, τ = {r.tau:.4g} s, offset {r.offset * 1000:+.2f} µm; "
               f"residual RMS {r.residual_rms * 1000:.2f} µm; web error at reversals up to {r.web_error.__abs__().max() * 1000:.1f} µm")
    if json_path:
        write_json(json_path, {"signals": str(path), "dt": dt, **r.as_dict()})


@waffle.command("simulate")
@click.option("--strategy", type=click.Choice(["none", "disturbance", "self-tuning", "combined"]), default="combined",
              show_default=True, help="Correction: none, the tilt disturbance K_dist, self-tuning K_fb cell to cell, or both.")
@seed_option
@json_option
@click.option("--report", "report_path", type=click.Path(dir_okay=False, path_type=Path),
              help="HTML report: thickness maps of the shell before and after, every strategy compared.")
@handle_errors
def simulate(strategy, seed, json_path, report_path):
    """Mill the virtual shell's waffle grid with a correction strategy."""
    from ..sim import waffle as sw

    check_outputs({}, {"--json": json_path, "--report": report_path})
    r = sw.simulate(strategy, seed)
    d = r.as_dict()
    summary(f"{strategy}: web thickness error RMS {d['rms_error'] * 1000:.1f} µm (uncorrected "
               f"{d['rms_error_uncorrected'] * 1000:.1f}), max {d['max_abs_error'] * 1000:.1f} µm; "
               f"{d['retunes']} of {d['cells_total']} cells semi-finished")
    if json_path:
        write_json(json_path, d)
    if report_path:
        _report(report_path, r)


def _report(path, r) -> None:
    import numpy as np

    from ..processes import waffle as pw
    from ..report import figure_png, page, pyplot, table, write
    from ..sim import waffle as sw

    plt = pyplot()

    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
    lim = 1000 * float(np.nanmax(np.abs(r.before)))
    for ax, m, title in ((axes[0], r.before, "uncorrected"), (axes[1], r.maps, f"{r.strategy}")):
        img, ext = sw.shell_map(m)
        im = ax.imshow(img * 1000, extent=ext, origin="lower", aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim,
                       interpolation="nearest")
        ax.set_title(f"web thickness error, {title}", fontsize=10)
        ax.set_ylabel("Z, mm")
    axes[1].set_xlabel("B, deg")
    fig.colorbar(im, ax=axes.tolist(), label="µm")
    rows = []
    for st in sw.STRATEGIES:
        d = (r if st == r.strategy else sw.simulate(st, r.seed)).as_dict()
        rows.append((st, f"{d['rms_error'] * 1000:.1f}", f"{d['max_abs_error'] * 1000:.1f}", d["retunes"]))
    vi, vm, dt = sw.backlash_pair(r.seed)
    est = pw.estimate_backlash(vi, vm, dt)
    fig2, ax = plt.subplots(figsize=(11, 3.2))
    n = 3 * len(sw.cell_path()[0][0])
    ax.plot(vi[:n] * 1000, "k-", lw=1, label="ideal V (pre-measurement)")
    ax.plot(vm[:n] * 1000, color="0.6", lw=1, label="V while machining the zig-zag")
    ax.plot((vi[:n] - est.web_error[:n]) * 1000, "r--", lw=1, label=f"model, g = {est.gap * 1000:.1f} µm")
    ax.set_xlabel("sample along the cell's first three lines")
    ax.set_ylabel("V, µm")
    ax.legend(fontsize=8)
    sections = [("Strategies on this shell (seed %d)" % r.seed,
                 table(rows, ["strategy", "RMS error, µm", "max |error|, µm", "semi-finished cells"])),
                ("Thickness maps over B × Z", figure_png(fig)),
                ("The copying system's backlash", table([("gap g, µm (true 30)", est.gap * 1000), ("τ, s (true 0.05)", est.tau),
                                                         ("fit residual RMS, µm", est.residual_rms * 1000),
                                                         ("predicted web error at reversals, max, µm",
                                                          float(np.abs(est.web_error).max()) * 1000)], ["", "value"])
                 + figure_png(fig2))]
    write(path, page(f"Waffle shell: {r.strategy}", "ncadapt waffle testbed", sections))
