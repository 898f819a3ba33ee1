"""``ncadapt bore plan|next|simulate``: precision bores by corrective finishing passes
(see :mod:`ncadapt.processes.bore`)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .._io import read_text
from ..errors import InputError
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

_CLASS = {"type": str, "show_default": True}
#: ISO 286 tabulates sizes up to 3150 mm.
_DIAMETER = FiniteRange(0, 3150, min_open=True)


@click.group()
def bore() -> None:
    """Precision bores: H9 → H6 by corrective finishing passes with on-machine probing."""


def _um(v: float) -> str:
    return f"{v * 1000:+.1f} µm"


@bore.command("plan")
@click.option("--diameter", type=_DIAMETER, required=True, help="Nominal diameter, mm (ISO 286: up to 3150).")
@click.option("--final", default="H6", help="Final hole class (upper case: a bore).", **_CLASS)
@click.option("--prefinish", default="H9", help="Class reached by pre-finishing (upper case).", **_CLASS)
@click.option(
    "--t0",
    type=FiniteRange(0.001, 10),
    required=True,
    help="Radial depth of the last pre-finish pass, mm (0.001 … 10).",
)
@click.option(
    "--allowance",
    type=FiniteRange(0, 10, min_open=True),
    required=True,
    help="Radial stock z left for the corrective passes, mm (at most 10).",
)
@click.option(
    "--delta-a",
    type=FiniteRange(-1, 1),
    help="Radial deviation near face A (tool entry) after pre-finishing, mm, material left > 0 (within ±1).",
)
@click.option(
    "--delta-b",
    type=FiniteRange(-1, 1),
    help="Radial deviation near face B after pre-finishing, mm, material left > 0 (within ±1).",
)
@click.option(
    "--measured",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="The pre-finished bore measured (instead of --delta-a/--delta-b): probe points (CSV plane,x,y,z or "
    "x,y,z; a LinuxCNC/Fanuc probe log), a CSV plane,z,diameter table, DMIS FEAT/CIRCLE actuals or a "
    "PC-DMIS report.",
)
@click.option(
    "--entry",
    type=click.Choice(["top", "bottom"]),
    default="top",
    show_default=True,
    help="Where the tool enters (face A) in the probe file's z.",
)
@click.option(
    "--k",
    type=FiniteRange(0.01, 1),
    default=0.25,
    show_default=True,
    help="Share of the final tolerance allowed for form error (0.01 … 1; the paper: 0.2 … 0.25 for H6).",
)
@click.option("--target", type=_DIAMETER, help="Target diameter, mm, inside the final class (default: its middle).")
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the plan as JSON (- for standard output); `bore next` reads it and records each pass in it.",
)
@handle_errors
def plan_cmd(diameter, final, prefinish, t0, allowance, delta_a, delta_b, measured, entry, k, target, json_path):
    """The number and depth of corrective passes and the predicted deviations."""
    from ..processes import bore as pb

    if measured is not None and (delta_a is not None or delta_b is not None):
        raise click.UsageError("give either --measured or --delta-a/--delta-b, not both")
    if measured is None and (delta_a is None or delta_b is None):
        raise click.UsageError("give --delta-a and --delta-b, or --measured PROBE.csv")
    check_outputs({"probe file": measured}, {"--json": json_path})
    if measured is not None:
        meas = pb.read_measurement(measured, entry)
        p = pb.plan_from_measurement(
            diameter, meas, final=final, prefinish=prefinish, t0=t0, allowance=allowance, k=k, target_diameter=target
        )
    else:
        p = pb.plan(diameter, final, prefinish, t0, allowance, delta_a, delta_b, k=k, target_diameter=target)
    summary(
        f"Ø{diameter:g} {prefinish} → {final}: IT {p.it_prefinish * 1000:g} → {p.it_final * 1000:g} µm, "
        f"target Ø{p.target_diameter:.4f}"
    )
    summary(
        f"condition (3): |δA − δB| = {p.form_before * 1000:.1f} µm ≤ {p.applicability_limit * 1000:.1f} µm: "
        f"{'yes' if p.applicable else 'NO'}"
    )
    summary(f"t_max {p.t_max:.4f} mm → {p.passes} passes of {p.depth_per_pass:.4f} mm")
    for i, (a, b) in enumerate(zip(p.predicted, p.predicted_b), start=1):
        summary(f"  pass {i}: predicted δA {_um(a)}, δB {_um(b)}")
    da, db = p.predicted_diameters
    summary(
        f"predicted: condition (4) form δA − δB {p.predicted_form * 1000:.2f} µm (limit (k/2)·IT "
        f"{p.form_limit * 1000:.2f}), Ø near A {da:.4f}, near B {db:.4f}: "
        f"{'inside' if p.predicted_ok else 'OUTSIDE'} {final}"
    )
    for w in p.warnings:
        echo_err(f"warning: {w}")
    if json_path:
        write_json(json_path, p.as_dict())


def _read_plan(plan_path):
    from ..processes import bore as pb

    try:
        data = json.loads(read_text(plan_path))  # with or without a byte-order mark
    except json.JSONDecodeError as err:
        raise InputError(f"not a plan (JSON): {err.msg}", str(plan_path), err.lineno, err.colno) from None
    except (ValueError, RecursionError) as err:  # an integer of thousands of digits; nesting too deep
        raise InputError(f"not a plan (JSON): {str(err)[:100]}", str(plan_path)) from None
    return data, pb.Plan.from_dict(data, str(plan_path))


@bore.command("next")
@click.option(
    "--plan",
    "plan_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    required=True,
    help="The plan written by `ncadapt bore plan --json`; each pass measured is recorded in it.",
)
@click.option(
    "--measured",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    required=True,
    help="The bore after the pass, in any form --measured of `bore plan` takes (one plane near A is enough "
    "from pass 1 on).",
)
@click.option(
    "--pass",
    "pass_done",
    type=click.IntRange(0, 100),
    help="The pass just measured (0: after pre-finishing) [default: the next the plan records].",
)
@click.option(
    "--applied",
    type=FiniteRange(-1, 1),
    help="The correction δ_K the measured pass was made with, mm [default: the plan's record].",
)
@click.option("--hardened", is_flag=True, help="Hardened material: three planes every time, first pass uncorrected.")
@click.option(
    "--entry",
    type=click.Choice(["top", "bottom"]),
    default="top",
    show_default=True,
    help="Where the tool enters (face A) in the probe file's z.",
)
@click.option(
    "--controller",
    type=click.Choice(["linuxcnc", "fanuc", "fanuc-geometry", "fanuc-lathe", "sinumerik", "plain"]),
    default="plain",
    show_default=True,
    help="Form of the offset block (docs/bore.md: which offset each one sets).",
)
@click.option("--tool", type=click.IntRange(1, 99999), default=1, show_default=True, help="Tool / offset number.")
@click.option(
    "--tool-radius",
    type=FiniteRange(0, 1000, min_open=True),
    help="The tool's nominal radius, mm (as preset, without any correction): the LinuxCNC and Fanuc "
    "geometry blocks set nominal − δ_K, so corrections never add up.",
)
@click.option(
    "--report",
    "report_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="HTML report of the passes so far: diameters per plane per pass with the tolerance band, form "
    "error, the plan's prediction beside the measurement.",
)
@json_option
@handle_errors(staged=True)
def next_cmd(
    plan_path, measured, pass_done, applied, hardened, entry, controller, tool, tool_radius, report_path, json_path
):
    """The correction for the next pass and its tool-offset block (after the last pass: the finished
    bore judged); the pass is recorded in the plan file."""
    from dataclasses import replace

    from .._io import atomic_write
    from ..processes import bore as pb

    check_outputs({"plan": plan_path, "probe file": measured}, {"--json": json_path, "--report": report_path})
    import os

    folder = plan_path.resolve().parent
    if not (os.access(plan_path, os.W_OK) and os.access(folder, os.W_OK)):
        raise InputError("cannot record the pass in the plan: the file or its folder is not writable", str(plan_path))
    data, p = _read_plan(plan_path)
    hist = list(p.history)
    if hist and hist[-1].get("pass") == p.passes:
        raise InputError(
            f"the plan records the finished bore (pass {p.passes}); start a new plan for the next bore", str(plan_path)
        )
    if pass_done is None:
        pass_done = len(hist)
    if pass_done > p.passes:
        raise click.BadParameter(
            f"the plan has {p.passes} corrective passes; the finished bore is pass {p.passes}, got {pass_done}",
            param_hint="'--pass'",
        )
    record = pass_done == len(hist)
    if pass_done < len(hist):
        raise click.BadParameter(
            f"the plan records passes 0 … {len(hist) - 1} already; the next to measure is {len(hist)}",
            param_hint="'--pass'",
        )
    recorded_applied = (
        0.0 if pass_done == 0 else (hist[pass_done - 1]["correction"] if pass_done <= len(hist) else None)
    )
    if applied is None:
        if recorded_applied is None:
            raise click.BadParameter(
                f"the plan records no correction for pass {pass_done} (it records passes 0 … "
                f"{len(hist) - 1}); give the δ_K pass {pass_done} was made with",
                param_hint="'--applied'",
            )
        applied = recorded_applied
    elif recorded_applied is not None and abs(applied - recorded_applied) > 1e-9:
        raise click.BadParameter(
            f"{applied:g} mm, but the plan records pass {pass_done} made with δ_K = {recorded_applied:g} mm",
            param_hint="'--applied'",
        )
    meas = pb.read_measurement(measured, entry)
    for circ in meas.circles:
        rd = f", roundness {circ.roundness * 1000:.1f} µm" if circ.n else ""
        summary(f"  plane {circ.plane:>8s}: Ø{circ.diameter:.4f}{rd}")
    if len(meas.circles) >= 2:
        summary(f"taper {meas.taper * 1000:+.1f} µm, barrel {meas.barrel * 1000:+.1f} µm")
    entry_rec = {
        "pass": pass_done,
        "probe": str(measured),
        "planes": [c.as_dict() for c in meas.circles],
        "applied": applied,
        "predicted": (p.delta_a if pass_done == 0 else p.predicted[pass_done - 1]),
    }
    if pass_done == p.passes:
        fin = pb.judge(p, meas)
        lo, hi = fin.limits
        summary(
            f"finished bore (after pass {p.passes}): Ø "
            + ", ".join(f"{d:.4f}" for d in fin.diameters)
            + f" against {p.final} {lo:.4f} … {hi:.4f}: {'inside' if fin.inside else 'OUTSIDE'}"
        )
        summary(
            f"condition (4): form δA − δB {fin.form * 1000:+.2f} µm, limit ±{fin.form_limit * 1000:.2f} µm: "
            f"{'yes' if fin.form_ok else 'NO'} (predicted {p.predicted_form * 1000:+.2f} µm)"
        )
        summary(f"the bore is {'GOOD' if fin.ok else 'NOT GOOD'}")
        entry_rec.update({"correction": None, "finished": fin.as_dict()})
        out = {**fin.as_dict(), "measurement": meas.as_dict()}
    else:
        c = pb.next_correction(p, meas, pass_done, applied=applied, hardened=hardened)
        block = pb.offset_block(c.correction, controller=controller, tool=tool, radius=tool_radius, previous=applied)
        for circ, e in zip(meas.circles, c.errors):
            summary(f"  plane {circ.plane:>8s}: error against the aim {_um(e)}")
        summary(
            f"pass {c.next_pass} of {p.passes}: correction δK {_um(c.correction)} ({c.rule}); "
            f"cutting edge at R {c.radial_position:.4f}"
        )
        if pass_done >= 1:
            summary(
                f"measured δA {_um(c.deviations[0])} after pass {pass_done}, the plan predicted "
                f"{_um(p.predicted[pass_done - 1])}"
            )
        if c.stiffness_ratio is not None:
            summary(f"stiffness ratio (pre-finish / now) {c.stiffness_ratio:.3f}")
        summary(block)
        entry_rec.update(
            {
                "errors": c.errors,
                "deviations": c.deviations,
                "correction": c.correction,
                "rule": c.rule,
                "block": block,
                "controller": controller,
            }
        )
        out = {**c.as_dict(), "measurement": meas.as_dict(), "block": block, "controller": controller}
    if record:
        hist.append(entry_rec)
        data = {**p.as_dict(), "history": hist}
        atomic_write(plan_path, (json.dumps(data, indent=2, allow_nan=False) + "\n").encode())
        summary(f"recorded pass {pass_done} in {plan_path}")
    else:
        echo_err(f"warning: pass {pass_done} is not recorded: {plan_path} records passes 0 … {len(hist) - 1}")
    if report_path:
        _report(report_path, replace(p, history=tuple(hist)), str(plan_path))
    if json_path:
        write_json(json_path, out)


def _report(path, p, source) -> None:
    """Diameters per plane per pass with the tolerance band, the form error, the prediction."""
    from ..report import figure_png, page, pyplot, table, write

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 4))
    lo, hi = p.final_limits
    ax.axhspan(p.diameter + lo, p.diameter + hi, color="tab:green", alpha=0.15, label=f"{p.final}")
    rows = []
    for h in p.history:
        n = h["pass"]
        aim = p.nominal_diameter_after(n)
        ds = [pl["diameter"] for pl in h["planes"]]
        ax.plot([n] * len(ds), ds, "o", color="tab:blue", ms=4)
        form = (ds[-1] - ds[0]) / 2 if len(ds) >= 2 else None
        meas_a = h.get("deviations", [None])[0] if h.get("deviations") else None
        rows.append(
            (
                str(n),
                f"{aim:.4f}",
                ", ".join(f"{pl['plane']}: {pl['diameter']:.4f}" for pl in h["planes"]),
                "" if form is None else f"{form * 1000:+.2f}",
                f"{h['predicted'] * 1000:+.2f}" if h.get("predicted") is not None else "",
                "" if meas_a is None else f"{meas_a * 1000:+.2f}",
                "" if h.get("correction") is None else f"{h['correction'] * 1000:+.2f}",
            )
        )
    ax.plot(
        range(p.passes + 1),
        [p.nominal_diameter_after(i) for i in range(p.passes + 1)],
        "k--",
        lw=1,
        label="aimed (uncorrected) diameter",
    )
    ax.set_xlabel("pass (0: pre-finish)")
    ax.set_ylabel("diameter, mm")
    ax.legend(fontsize=8)
    figures = [
        ("diameter, class", f"Ø{p.diameter:g} {p.final}: {p.diameter + lo:.4f} … {p.diameter + hi:.4f} mm"),
        ("passes planned", f"{p.passes} of {p.depth_per_pass * 1000:.1f} µm"),
        ("condition (4) limit (k/2)·IT, µm", f"{p.form_limit * 1000:.2f}"),
        ("predicted final form δA − δB, µm", f"{p.predicted_form * 1000:+.2f}"),
    ]
    write(
        path,
        page(
            "Bore: corrective passes",
            source,
            [
                ("Plan", table(figures, ["", "value"])),
                (
                    "Diameters per plane per pass",
                    figure_png(fig)
                    + table(
                        rows,
                        [
                            "pass",
                            "aimed Ø, mm",
                            "measured Ø per plane, mm",
                            "form δA − δB, µm",
                            "predicted δA, µm",
                            "measured δA, µm",
                            "correction δK next, µm",
                        ],
                    ),
                ),
            ],
        ),
    )


@bore.command("probe-program")
@click.option("--diameter", type=_DIAMETER, required=True, help="Nominal bore diameter, mm.")
@click.option(
    "--planes", required=True, help="z of the probing planes, mm, face A first, comma-separated (e.g. 55,30,5)."
)
@click.option(
    "--dialect",
    type=click.Choice(["linuxcnc", "fanuc"]),
    default="linuxcnc",
    show_default=True,
    help="LinuxCNC G38.2 with a PROBEOPEN log, or Fanuc G31 skip with DPRNT.",
)
@click.option("--points", type=click.IntRange(3, 360), default=8, show_default=True, help="Touches per plane.")
@click.option("--feed", type=FiniteRange(1, 5000), default=100.0, show_default=True, help="Probing feed, mm/min.")
@click.option(
    "--safe-z",
    type=FiniteRange(-1e4, 1e4),
    help="Clearance height above the bore, mm [default: 5 mm above the highest plane].",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="The probing program to write.",
)
@handle_errors
def probe_program_cmd(diameter, planes, dialect, points, feed, safe_z, output):
    """A program probing the bore in three planes from its centre (X0 Y0 on the bore's axis)."""
    import math

    from .._io import atomic_write
    from ..processes import bore as pb

    try:
        zs = [float(v) for v in planes.split(",")]
    except ValueError:
        raise click.BadParameter(
            f"expected z values separated by commas, got {planes[:80]!r}", param_hint="'--planes'"
        ) from None
    if not zs or len(zs) > 20 or not all(math.isfinite(z) and abs(z) <= 1e4 for z in zs):
        raise click.BadParameter("1 … 20 finite z values within ±10000 mm", param_hint="'--planes'")
    check_outputs({}, {"-o": output})
    if safe_z is None:
        safe_z = max(zs) + 5.0
    elif safe_z <= max(zs):
        raise click.BadParameter(
            f"{safe_z:g} mm is not above the highest plane {max(zs):g} mm", param_hint="'--safe-z'"
        )
    atomic_write(
        output, pb.probing_program(diameter, zs, dialect=dialect, points=points, feed=feed, safe_z=safe_z).encode()
    )
    summary(f"wrote {output}: {len(zs)} plane(s) × {points} touches ({dialect})")


@bore.command("simulate")
@click.option(
    "--parts",
    type=click.IntRange(1, 1_000_000),
    default=1000,
    show_default=True,
    help="Number of simulated parts (at most 1,000,000).",
)
@seed_option
@click.option(
    "--material",
    type=click.Choice(["steel", "titanium", "aluminium", "hardened"]),
    default="steel",
    show_default=True,
    help="Material of the simulated parts (sets the cutting behaviour of the model).",
)
@click.option(
    "--model",
    type=click.Choice(["beam", "linear"]),
    default="beam",
    show_default=True,
    help="The machine: a cantilever bar cut by a Kienzle force on the nose radius (its own physics), "
    "or deflection proportional to depth (the paper's assumption, the planner's model).",
)
@click.option("--diameter", type=_DIAMETER, default=40.0, show_default=True, help="Nominal diameter, mm.")
@click.option(
    "--t0",
    type=FiniteRange(0.001, 10),
    default=0.5,
    show_default=True,
    help="Radial depth of the last pre-finish pass, mm (0.001 … 10).",
)
@click.option(
    "--allowance",
    type=FiniteRange(0, 10, min_open=True),
    default=0.1,
    show_default=True,
    help="Radial stock z left for the corrective passes, mm (at most 10).",
)
@click.option(
    "--k",
    type=FiniteRange(0.01, 1),
    default=0.25,
    show_default=True,
    help="Share of the final tolerance allowed for form error (0.01 … 1).",
)
@json_option
@handle_errors
def simulate_cmd(parts, seed, material, model, diameter, t0, allowance, k, json_path):
    """Run the plan and the pass-by-pass loop on seeded virtual parts, against one uncorrected pass."""
    from ..sim import bore as sb

    check_outputs({}, {"--json": json_path})
    with progress() as say:
        r = sb.simulate(
            parts,
            seed,
            material=material,
            model=model,
            diameter=diameter,
            t0=t0,
            allowance=allowance,
            k=k,
            progress=say,
        )
    w = r["without_correction"]
    summary(
        f"{parts} {material} parts, {model} model (applicability held for {r['applicable_share']:.1%} of those drawn)"
    )
    summary(
        f"corrective passes: {r['within_tolerance']:.1%} inside H6 with form ≤ k·IT6, {r['mean_passes']:.2f} "
        f"passes, form error {r['form_error_mean'] * 1000:.2f} µm, diameter {_um(r['diameter_error_mean'])}"
    )
    summary(
        f"one uncorrected pass: {w['within_tolerance']:.1%} inside, form error {w['form_error_mean'] * 1000:.2f} µm, "
        f"diameter {_um(w['diameter_error_mean'])}"
    )
    if json_path:
        write_json(json_path, r)
