"""``ncadapt waffle``: waffle-grid shells on tracking machines (see :mod:`ncadapt.processes.waffle`
and :mod:`ncadapt.sim.waffle`)."""

from __future__ import annotations

from pathlib import Path

import click

from .. import constants
from ._common import (
    FiniteRange,
    about,
    check_outputs,
    comma_floats,
    echo_err,
    handle_errors,
    json_option,
    progress,
    progress_bar,
    seed_option,
    summary,
    write_json,
)

#: physical bounds of the options: a cutter's radius up to 1 m, a shell's diameter 1 mm to 100 m
_RADIUS = dict(type=FiniteRange(min=0.01, max=1000), required=True, help="Cutter radius R, mm (0.01 to 1000).")
_DIAMETER = dict(type=FiniteRange(min=1, max=1e5), required=True, help="Shell diameter D, mm (1 to 100,000).")
_Z_TOL = dict(
    type=FiniteRange(min=0, max=1000),
    default=0.01,
    show_default=True,
    help="Rows whose Z differs from the previous row's by at most this are one pass (encoder jitter), mm.",
)


def _tracking_options(f):
    """The tracking log and the geometry the tilt is identified with (tilt and correct)."""
    for o in reversed(
        [
            click.option(
                "--tracking",
                "log",
                type=click.Path(exists=True, dir_okay=False, path_type=Path),
                required=True,
                help="Tracking pre-measurement: CSV with columns B (deg), Z (mm), V (mm).",
            ),
            click.option("--tool-radius", **_RADIUS),
            click.option("--diameter", **_DIAMETER),
            click.option(
                "--segment",
                type=click.IntRange(min=2, max=10**6),
                default=10,
                show_default=True,
                help="Points per least-squares segment of the tracking log (restarting where Z changes).",
            ),
            click.option("--z-tol", **_Z_TOL),
        ]
    ):
        f = o(f)
    return f


def _pair(value, what, option):
    """Two comma-separated finite numbers of ``option`` (None when not given)."""
    if value is None:
        return None
    try:
        return comma_floats(value, 2, what)
    except click.BadParameter as e:
        e.param_hint = f"'{option}'"
        raise


@click.group()
def waffle() -> None:
    """Waffle-grid shells: spindle-tilt and copying-system corrections, cell-to-cell self-tuning."""


@waffle.command("tilt")
@_tracking_options
@json_option
@handle_errors
def tilt(log, tool_radius, diameter, segment, z_tol, json_path):
    """The web-thickness error from the spindle's tilt to the back wall: E = R·(360/(πD))·k per
    segment, signed (the web is left thinner by |E|)."""
    from ..processes import waffle as pw

    check_outputs({"tracking log": log}, {"--json": json_path})
    b, z, v = pw.read_tracking(log)
    with about(log):
        t = pw.tilt(b, z, v, tool_radius=tool_radius, diameter=diameter, segment=segment, z_tol=z_tol)
    d = t.as_dict()
    summary(
        f"{log}: {len(b)} rows, {d['segments']} segments of {segment}; |E| max {d['max_abs_error'] * 1000:.2f} µm, "
        f"RMS {d['rms_error'] * 1000:.2f} µm"
    )
    if json_path:
        write_json(
            json_path,
            {
                "tracking": str(log),
                "tool_radius": tool_radius,
                "diameter": diameter,
                "segment": segment,
                "z_tol": z_tol,
                **d,
            },
        )


@waffle.command("correct")
@click.argument("program", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@_tracking_options
@click.option(
    "--thickness",
    "map_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Thickness map of a semi-finished cell: CSV with columns B, Z, thickness (self-tuning K_fb).",
)
@click.option(
    "--target",
    type=FiniteRange(min=0, min_open=True, max=1000),
    help="Target web thickness T_ref, mm (with --thickness; > 0, at most 1000).",
)
@click.option(
    "--allowance",
    type=FiniteRange(min=0, max=1000),
    default=0.0,
    show_default=True,
    help="Semi-finishing allowance b, mm (with --thickness; 0 to 1000).",
)
@click.option(
    "--map-origin",
    metavar="B,Z",
    help="Cell reuse (the paper's eq. 9): the origin (centre) of the cell the --thickness map was "
    "measured on, deg,mm; with --cell-origin.",
)
@click.option(
    "--cell-origin",
    metavar="B,Z",
    help="The origin of the cell PROGRAM cuts, deg,mm: the map is moved by --cell-origin − --map-origin, "
    "so K_fb of one cell applies to the next.",
)
@click.option(
    "--depth-axis",
    type=click.Choice(["X", "Y", "Z", "U", "V", "W"], case_sensitive=False),
    default="Y",
    show_default=True,
    help="The axis along the spindle (U, V or W: a parallel axis such as a quill, which the program "
    "must set before its first move).",
)
@click.option(
    "--axial-axis",
    type=click.Choice(["X", "Y", "Z", "U", "V", "W"], case_sensitive=False),
    default="Z",
    show_default=True,
    help="The axis along the shell.",
)
@click.option(
    "--rotary-axis",
    type=click.Choice(["A", "B", "C"], case_sensitive=False),
    default="B",
    show_default=True,
    help="The rotary axis turning the shell (degrees).",
)
@click.option(
    "--into",
    type=click.Choice([s + a for a in "xyzuvw" for s in "+-"], case_sensitive=False),
    default=None,
    help="Direction of the depth axis in which the tool cuts deeper (thinner web), e.g. +y; "
    "default + along --depth-axis.",
)
@click.option(
    "--outside",
    type=click.Choice(["error", "clamp", "extrapolate"]),
    default="error",
    show_default=True,
    help="Program points outside the measured B × Z area.",
)
@click.option(
    "--limit",
    type=FiniteRange(min=0, min_open=True),
    default=constants.LIMIT,
    show_default=True,
    help="Refuse if any correction exceeds this, mm.",
)
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True, help="Corrected program to write."
)
@json_option
@handle_errors
def correct(
    program,
    log,
    tool_radius,
    diameter,
    segment,
    z_tol,
    map_path,
    target,
    allowance,
    map_origin,
    cell_origin,
    depth_axis,
    axial_axis,
    rotary_axis,
    into,
    outside,
    limit,
    output,
    json_path,
):
    """Rewrite PROGRAM with Y_c = Y_p + K_dist (+ K_fb): the tilt corrector from the tracking
    pre-measurement, and with --thickness the self-tuning corrector K_fb = T_pf − T_ref − b,
    interpolated at every point of the program by (B, Z); rotary words are kept exact."""
    import numpy as np

    from .. import nc
    from ..processes import waffle as pw

    if map_path is not None and target is None:
        raise click.UsageError("--thickness needs --target")
    if map_path is None and (target is not None or allowance or map_origin or cell_origin):
        raise click.UsageError("--target, --allowance, --map-origin and --cell-origin go with --thickness")
    if (map_origin is None) != (cell_origin is None):
        raise click.UsageError("--map-origin and --cell-origin go together")
    map_origin = _pair(map_origin, "B,Z (deg,mm)", "--map-origin")
    cell_origin = _pair(cell_origin, "B,Z (deg,mm)", "--cell-origin")
    shift = (0.0, 0.0) if map_origin is None else (cell_origin[0] - map_origin[0], cell_origin[1] - map_origin[1])
    check_outputs(
        {"input program": program, "tracking log": log, "thickness map": map_path}, {"-o": output, "--json": json_path}
    )
    axes = dict(
        diameter=diameter, depth_axis=depth_axis, axial_axis=axial_axis, rotary_axis=rotary_axis, outside=outside
    )
    into = (into or "+" + depth_axis).lower()
    if into[1] != depth_axis.lower():
        raise click.BadParameter(
            f"{into} is not along the depth axis {depth_axis.upper()}; give "
            f"+{depth_axis.lower()} or -{depth_axis.lower()}",
            param_hint="'--into'",
        )
    sign = 1.0 if into[0] == "+" else -1.0
    with progress() as say:
        say(f"reading {log}")
        b, z, v = pw.read_tracking(log)
        with about(log):
            t = pw.tilt(b, z, v, tool_radius=tool_radius, diameter=diameter, segment=segment, z_tol=z_tol)
            parts = [pw.DepthField(b, z, sign * t.correction, **axes)]
        k_fb = None
        if map_path is not None:
            say(f"reading {map_path}")
            bt, zt, th, _ = pw.read_thickness(map_path)
            k_fb = pw.feedback_correction(th, target, allowance)
            with about(map_path):
                parts.append(pw.DepthField(bt + shift[0], zt + shift[1], sign * k_fb, **axes))
        field = pw.Sum(parts)
        say(f"reading {program}")
        prog = nc.read(program)
        c = prog.correct_to(output, field, limit=limit, progress=say)
    summary(f"{program} -> {output}")
    summary(f"  K_dist (tilt): |E| max {np.abs(t.error).max():.4f} mm over {len(b)} tracking rows")
    if k_fb is not None:
        summary(
            f"  K_fb (self-tuning): min {k_fb.min():+.4f} max {k_fb.max():+.4f} mm over {len(k_fb)} map points"
            + (f", moved by B {shift[0]:+g} deg, Z {shift[1]:+g} mm to this cell" if any(shift) else "")
        )
    summary(
        f"  blocks changed {c.blocks_changed:,}, lines added {c.lines_added:,}; correction max "
        f"{c.max_displacement:.4f} mm, mean {c.mean_displacement:.4f} mm"
    )
    for w in c.warnings:
        echo_err(f"  warning: {w}")
    if c.n_points == 0:
        echo_err(
            "  warning: no point of the program was corrected — does it set every linear axis (X, Y, Z) "
            "before cutting, and cut with G1/G2/G3?"
        )
    if json_path:
        d = {
            "input": str(program),
            "output": str(output),
            "tracking": str(log),
            "thickness": str(map_path) if map_path else None,
            "tool_radius": tool_radius,
            "diameter": diameter,
            "segment": segment,
            "target": target,
            "allowance": allowance,
            "depth_axis": depth_axis.upper(),
            "into": into,
            "tilt_max_abs_error": float(np.abs(t.error).max()),
            "k_fb_min": None if k_fb is None else float(k_fb.min()),
            "k_fb_max": None if k_fb is None else float(k_fb.max()),
            "map_shift": list(shift),
            "z_tol": z_tol,
        }
        d.update(c.as_dict())
        write_json(json_path, d)


@waffle.command("backlash")
@click.option(
    "--signals",
    "path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    required=True,
    help="CSV with columns V_ideal (one-way pre-measurement) and V_measured (while machining), mm; "
    "optionally t, s (the sampling period is then read from it).",
)
@click.option(
    "--dt",
    type=FiniteRange(min=1e-6, max=3600),
    default=None,
    help="Sampling period, s (1e-6 to 3600); required unless the signals have a column t.",
)
@json_option
@handle_errors
def backlash(path, dt, json_path):
    """Estimate the copying system's gap g (and drive τ) by least squares from a pair of signals.
    Refused when the signals cannot identify g: a constant or one-way V_ideal, or reversals
    shorter than the gap."""
    import numpy as np

    from .. import fields
    from ..errors import InputError
    from ..processes import waffle as pw

    check_outputs({"signals": path}, {"--json": json_path})
    c, lines = fields.read_columns(path, ("v_ideal", "v_measured"))
    pw._check_ranges(
        path,
        c,
        lines,
        {"v_ideal": (pw.V_RANGE, "mm (the sensor's travel)"), "v_measured": (pw.V_RANGE, "mm (the sensor's travel)")},
    )
    try:
        tc, _ = fields.read_columns(path, ("t",))
    except InputError as e:
        if not e.message.startswith("missing column"):
            raise
        tc = None
    if tc is not None:
        steps = np.diff(tc["t"])
        if not len(steps) or not np.all(steps > 0):
            raise InputError("column t: the times must increase from row to row", str(path))
        period = float(np.median(steps))
        if not np.allclose(steps, period, rtol=0.01, atol=0):
            raise InputError(
                f"column t: the samples are not evenly spaced (steps from {steps.min():g} to {steps.max():g} s)",
                str(path),
            )
        if dt is not None and not abs(dt - period) <= 0.01 * period:
            raise click.BadParameter(
                f"{dt:g} s disagrees with the column t of {path} ({period:g} s)", param_hint="'--dt'"
            )
        dt = period
    elif dt is None:
        raise click.UsageError(
            "give --dt (the sampling period, s) or a column t in the signals: without it τ would be in samples"
        )
    with about(path):
        r = pw.estimate_backlash(c["v_ideal"], c["v_measured"], dt)
    summary(
        f"gap g = {r.gap * 1000:.2f} µm, τ = {r.tau:.4g} s, offset {r.offset * 1000:+.2f} µm; "
        f"residual RMS {r.residual_rms * 1000:.2f} µm; web error at reversals up to "
        f"{np.abs(r.web_error).max() * 1000:.1f} µm"
    )
    if json_path:
        write_json(json_path, {"signals": str(path), "dt": dt, **r.as_dict()})


class _Withdraw:
    """A constant displacement along the depth axis (the semi-finishing allowance); `axis` is its
    index in XYZABCUVW."""

    uses_axes = True

    def __init__(self, axis: int, value: float):
        self.axis, self.value = axis, value

    def __call__(self, points, axes=None):
        import numpy as np

        d = np.zeros((len(points), 3 if self.axis < 3 else 9))
        d[:, self.axis] = self.value
        return d


def _cells_shape(value: str) -> tuple[int, int]:
    import re

    m = re.fullmatch(r"\s*(\d{1,4})\s*[xX×]\s*(\d{1,4})\s*", value or "")
    if not m or not (1 <= int(m[1]) <= 1000 and 1 <= int(m[2]) <= 1000):
        raise click.BadParameter(
            f"expected ROWSxCOLS (1 to 1000 each), e.g. 4x24, got {value!r}"[:120], param_hint="'--cells'"
        )
    return int(m[1]), int(m[2])


@waffle.command("cells")
@click.option(
    "--thickness-dir",
    "folder",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    required=True,
    help="Folder of finished thickness maps thickness_r<ROW>c<CELL>.csv (columns B, Z, thickness; "
    "1-based row and cell, machined row by row).",
)
@click.option("--cells", "shape", required=True, metavar="ROWSxCOLS", help="The shell's cells, e.g. 4x24.")
@click.option(
    "--target", type=FiniteRange(min=0, min_open=True, max=1000), required=True, help="Target web thickness T_ref, mm."
)
@click.option(
    "--band",
    required=True,
    metavar="TMIN,TMAX",
    help="The signal band T_th,min,T_th,max, mm: a finished cell with max ≥ TMAX or min ≤ TMIN makes "
    "the next cell semi-finished.",
)
@click.option(
    "--programs",
    "prog_dir",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="Folder of the cells' finishing programs cell_r<ROW>c<CELL>.ngc: the next cell's "
    "semi-finishing program is written to -o when it needs one.",
)
@click.option(
    "--allowance",
    type=FiniteRange(min=0, min_open=True, max=1000),
    default=None,
    help="Semi-finishing allowance b, mm (with --programs): the depth axis is withdrawn by b.",
)
@click.option(
    "--depth-axis",
    type=click.Choice(["X", "Y", "Z", "U", "V", "W"], case_sensitive=False),
    default="Y",
    show_default=True,
    help="The axis along the spindle (U, V or W: a parallel axis such as a quill, which the program "
    "must set before its first move).",
)
@click.option(
    "--into",
    type=click.Choice([s + a for a in "xyzuvw" for s in "+-"], case_sensitive=False),
    default=None,
    help="Direction of the depth axis that cuts deeper; default + along --depth-axis.",
)
@click.option(
    "-o",
    "--output-dir",
    "out_dir",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="Folder for the semi-finishing program semi_r<ROW>c<CELL>.ngc (with --programs).",
)
@click.option(
    "--limit",
    type=FiniteRange(min=0, min_open=True),
    default=constants.LIMIT,
    show_default=True,
    help="Refuse if any correction exceeds this, mm (raise it for an allowance above it).",
)
@json_option
@handle_errors
def cells(folder, shape, target, band, prog_dir, allowance, depth_axis, into, out_dir, limit, json_path):
    """The self-tuning decision of the paper's section 4 from the finished thickness maps there
    are: which cells were in the band, and whether the next cell needs a semi-finishing pass
    (retune when a finished cell has max ≥ TMAX or min ≤ TMIN); with --programs, its program."""
    import re

    from .. import nc
    from ..errors import InputError
    from ..processes import waffle as pw

    rows, cols = _cells_shape(shape)
    t_lo, t_hi = _pair(band, "TMIN,TMAX in mm", "--band")
    if not t_lo < target < t_hi:
        raise click.BadParameter(
            f"the band {t_lo:g}..{t_hi:g} mm must contain --target {target:g} mm", param_hint="'--band'"
        )
    if (prog_dir is None) != (out_dir is None) or (prog_dir is None) != (allowance is None):
        raise click.UsageError("--programs, --allowance and -o go together")
    check_outputs({}, {"--json": json_path})
    finished = {}
    for f in sorted(folder.iterdir()):
        m = re.fullmatch(r"thickness_r(\d+)c(\d+)\.csv", f.name, flags=re.IGNORECASE)
        if not m or not f.is_file():
            continue
        key = (int(m[1]), int(m[2]))
        if not (1 <= key[0] <= rows and 1 <= key[1] <= cols):
            raise InputError(f"row {key[0]} cell {key[1]} is outside the {rows} x {cols} shell of --cells", str(f))
        _, _, t, _ = pw.read_thickness(f)
        if not len(t):
            raise InputError("no thickness rows", str(f))
        finished[key] = (t, str(f))
    if not finished:
        summary(f"{folder}: no finished thickness map (thickness_r<ROW>c<CELL>.csv) yet")
    try:
        states = pw.plan_cells(finished, rows, cols, t_lo, t_hi)
    except ValueError as e:
        raise InputError(str(e), str(folder)) from None
    nxt = next((st for st in states if st.status == "next"), None)
    written = None
    if nxt is not None and prog_dir is not None and nxt.semi_finish:
        src = prog_dir / f"cell_r{nxt.row}c{nxt.cell}.ngc"
        if not src.is_file():
            raise InputError(f"no finishing program for row {nxt.row} cell {nxt.cell}", str(src))
        written = out_dir / f"semi_r{nxt.row}c{nxt.cell}.ngc"
        check_outputs({"finishing program": src}, {"-o": written})
        into_ = (into or "+" + depth_axis).lower()
        if into_[1] != depth_axis.lower():
            raise click.BadParameter(f"{into_} is not along the depth axis {depth_axis.upper()}", param_hint="'--into'")
        sign = 1.0 if into_[0] == "+" else -1.0
        with progress() as say:
            say(f"reading {src}")
            c = nc.read(src).correct_to(
                written, _Withdraw("XYZABCUVW".index(depth_axis.upper()), -sign * allowance), limit=limit, progress=say
            )
    done = [st for st in states if st.status == "finished"]
    out = [st for st in done if not st.in_band]
    summary(
        f"{folder}: {len(done)} of {rows * cols} cells finished, {len(out)} out of the band "
        f"{t_lo:g}..{t_hi:g} mm; {sum(1 for st in done if st.semi_finish)} semi-finished"
    )
    for st in out:
        summary(f"  row {st.row} cell {st.cell}: thickness {st.t_min:.4f} .. {st.t_max:.4f} mm (out of band)")
    if nxt is None:
        summary("  every cell is finished")
    else:
        how = (
            "semi-finish it first (retune K_fb from its semi-finished map)"
            if nxt.semi_finish
            else "finish it with the K_fb of the last semi-finished cell (waffle correct --thickness … "
            "--map-origin B,Z --cell-origin B,Z)"
        )
        summary(f"  next: row {nxt.row} cell {nxt.cell}: {how}")
        if written is not None:
            summary(
                f"  {written}: the finishing program withdrawn by {allowance:g} mm "
                f"({c.blocks_changed:,} blocks changed)"
            )
    if json_path:
        write_json(
            json_path,
            {
                "folder": str(folder),
                "rows": rows,
                "cells_per_row": cols,
                "target": target,
                "band": [t_lo, t_hi],
                "finished": len(done),
                "out_of_band": len(out),
                "next": nxt.as_dict() if nxt else None,
                "semi_program": str(written) if written else None,
                "cells": [st.as_dict() for st in states],
            },
        )


@waffle.command("simulate")
@click.option(
    "--strategy",
    type=click.Choice(["none", "disturbance", "self-tuning", "combined"]),
    default="combined",
    show_default=True,
    help="Correction: none, the tilt disturbance K_dist, self-tuning K_fb cell to cell, or both.",
)
@seed_option
@click.option(
    "--tolerance",
    type=FiniteRange(min=0, min_open=True, max=1),
    default=0.03,
    show_default=True,
    help="Web-thickness tolerance ±, mm (0 to 1): cells with points outside it are listed.",
)
@json_option
@click.option(
    "--report",
    "report_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="HTML report: thickness maps of the shell before and after, every strategy compared.",
)
@handle_errors
def simulate(strategy, seed, tolerance, json_path, report_path):
    """Mill the virtual shell's waffle grid with a correction strategy; report the RMS error and
    the cells with points out of --tolerance."""
    from ..sim import waffle as sw

    check_outputs({}, {"--json": json_path, "--report": report_path})
    total = sw.ROWS * sw.CELLS * (1 + (len(sw.STRATEGIES) - 1 if report_path else 0))
    with progress_bar(f"waffle {strategy}", total) as advance:
        r = sw.simulate(strategy, seed, on_cell=lambda k, n: advance(k))
        if report_path:
            base = sw.ROWS * sw.CELLS
            _report(report_path, r, tolerance, on_cell=lambda k, n: advance(base + k))
    d = r.as_dict(tolerance)
    summary(
        f"{strategy}: web thickness error RMS {d['rms_error'] * 1000:.1f} µm (uncorrected "
        f"{d['rms_error_uncorrected'] * 1000:.1f}), max {d['max_abs_error'] * 1000:.1f} µm; "
        f"{d['retunes']} of {d['cells_total']} cells semi-finished"
    )
    bad = [c for c in d["cells"] if c["points_out_of_tolerance"]]
    summary(
        f"  out of tolerance ±{tolerance * 1000:g} µm: {len(bad)} of {d['cells_total']} cells, "
        f"{d['points_out_of_tolerance']:,} of {d['points_total']:,} points"
    )
    for c in bad:
        summary(
            f"    row {c['row']} cell {c['cell']} (B {c['B']:g} deg, Z {c['Z']:g} mm): "
            f"{c['points_out_of_tolerance']} points, max |error| {c['max_abs_error'] * 1000:.1f} µm"
        )
    if json_path:
        write_json(json_path, d)


def _report(path, r, tolerance: float = 0.03, on_cell=None) -> None:
    import numpy as np

    from ..processes import waffle as pw
    from ..report import figure_png, page, pyplot, table, write
    from ..sim import waffle as sw

    plt = pyplot()

    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
    lim = 1000 * float(np.nanmax(np.abs(r.before)))
    for ax, m, title in ((axes[0], r.before, "uncorrected"), (axes[1], r.maps, f"{r.strategy}")):
        img, ext = sw.shell_map(m)
        im = ax.imshow(
            img * 1000,
            extent=ext,
            origin="lower",
            aspect="auto",
            cmap="RdBu_r",
            vmin=-lim,
            vmax=lim,
            interpolation="nearest",
        )
        ax.set_title(f"web thickness error, {title}", fontsize=10)
        ax.set_ylabel("Z, mm")
    axes[1].set_xlabel("B, deg")
    fig.colorbar(im, ax=axes.tolist(), label="µm")
    rows = []
    done = 0
    for st in sw.STRATEGIES:
        if st == r.strategy:
            d = r.as_dict(tolerance)
        else:
            d = sw.simulate(
                st, r.seed, on_cell=(lambda k, n, _d=done: on_cell(_d + k, n)) if on_cell else None
            ).as_dict(tolerance)
            done += sw.ROWS * sw.CELLS
        rows.append(
            (
                st,
                f"{d['rms_error'] * 1000:.1f}",
                f"{d['max_abs_error'] * 1000:.1f}",
                d["retunes"],
                d["cells_out_of_tolerance"],
            )
        )
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
    sections = [
        (
            f"Strategies on this shell (seed {r.seed})",
            table(
                rows,
                [
                    "strategy",
                    "RMS error, µm",
                    "max |error|, µm",
                    "semi-finished cells",
                    f"cells out of ±{tolerance * 1000:g} µm",
                ],
            ),
        ),
        ("Thickness maps over B × Z", figure_png(fig)),
        (
            "The copying system's backlash",
            table(
                [
                    ("gap g, µm (true 30)", est.gap * 1000),
                    ("τ, s (true 0.05)", est.tau),
                    ("fit residual RMS, µm", est.residual_rms * 1000),
                    ("predicted web error at reversals, max, µm", float(np.abs(est.web_error).max()) * 1000),
                ],
                ["", "value"],
            )
            + figure_png(fig2),
        ),
    ]
    write(path, page(f"Waffle shell: {r.strategy}", "ncadapt waffle testbed", sections))
