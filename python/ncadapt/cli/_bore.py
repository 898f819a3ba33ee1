"""``ncadapt bore plan|next|simulate``: precision bores by corrective finishing passes
(see :mod:`ncadapt.processes.bore`)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from ..errors import InputError
from .._io import read_text
from ._common import FiniteRange, check_outputs, handle_errors, json_option, progress, seed_option, summary, write_json

_CLASS = {"type": str, "show_default": True}


@click.group()
def bore() -> None:
    """Precision bores: H9 → H6 by corrective finishing passes with on-machine probing."""


def _um(v: float) -> str:
    return f"{v * 1000:+.1f} µm"


@bore.command("plan")
@click.option("--diameter", type=FiniteRange(min=0, min_open=True), required=True, help="Nominal diameter, mm.")
@click.option("--final", default="H6", help="Final hole class.", **_CLASS)
@click.option("--prefinish", default="H9", help="Class reached by pre-finishing.", **_CLASS)
@click.option("--t0", type=FiniteRange(min=0, min_open=True), required=True,
              help="Radial depth of the last pre-finish pass, mm.")
@click.option("--allowance", type=FiniteRange(min=0, min_open=True), required=True,
              help="Radial stock z left for the corrective passes, mm.")
@click.option("--delta-a", type=FiniteRange(), help="Radial deviation near face A (tool entry) after pre-finishing, mm.")
@click.option("--delta-b", type=FiniteRange(), help="Radial deviation near face B after pre-finishing, mm.")
@click.option("--measured", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Probe points of the pre-finished bore, CSV plane,x,y,z (instead of --delta-a/--delta-b).")
@click.option("--entry", type=click.Choice(["top", "bottom"]), default="top", show_default=True,
              help="Where the tool enters (face A) in the probe file's z.")
@click.option("--k", type=FiniteRange(0, 1, min_open=True), default=0.25, show_default=True,
              help="Share of the final tolerance allowed for form error.")
@click.option("--target", type=FiniteRange(), help="Target diameter, mm (default: the middle of the final class).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the plan as JSON.")
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
        meas = pb.read_probe(measured, entry)
        p = pb.plan_from_measurement(diameter, meas, final=final, prefinish=prefinish, t0=t0, allowance=allowance,
                                     k=k, target_diameter=target)
    else:
        p = pb.plan(diameter, final, prefinish, t0, allowance, delta_a, delta_b, k=k, target_diameter=target)
    summary(f"Ø{diameter:g} {prefinish} → {final}: IT {p.it_prefinish * 1000:g} → {p.it_final * 1000:g} µm, "
               f"target Ø{p.target_diameter:.4f}")
    summary(f"applicability: δA − δB = {(p.delta_a - p.delta_b) * 1000:.1f} µm ≤ "
               f"{pb.APPLICABILITY_SHARE * p.it_prefinish * 1000:.1f} µm: {'yes' if p.applicable else 'NO'}")
    summary(f"t_max {p.t_max:.4f} mm → {p.passes} passes of {p.depth_per_pass:.4f} mm")
    for i, (a, b) in enumerate(zip(p.predicted, p.predicted_b), start=1):
        summary(f"  pass {i}: predicted δA {_um(a)}, δB {_um(b)}")
    da, db = p.predicted_diameters
    summary(f"predicted: form δA − δB {p.predicted_form * 1000:.2f} µm (limit "
               f"{pb.FINAL_FORM_SHARE * p.it_final * 1000:.2f}), Ø near A {da:.4f}, near B {db:.4f}: "
               f"{'inside' if p.predicted_ok else 'OUTSIDE'} {final}")
    if not p.applicable:
        click.echo("warning: the applicability condition does not hold; the plan's predictions are not reliable", err=True)
    if json_path:
        write_json(json_path, p.as_dict())


@bore.command("next")
@click.option("--plan", "plan_path", type=click.Path(exists=True, dir_okay=False, path_type=Path), required=True,
              help="The plan written by `ncadapt bore plan --json`.")
@click.option("--measured", type=click.Path(exists=True, dir_okay=False, path_type=Path), required=True,
              help="Probe points after the pass, CSV plane,x,y,z.")
@click.option("--pass", "pass_done", type=click.IntRange(min=0), default=0, show_default=True,
              help="The pass just measured (0: after pre-finishing).")
@click.option("--applied", type=FiniteRange(), default=0.0, show_default=True,
              help="The correction δ_K the measured pass was made with, mm.")
@click.option("--hardened", is_flag=True, help="Hardened material: three planes every time, first pass uncorrected.")
@click.option("--entry", type=click.Choice(["top", "bottom"]), default="top", show_default=True,
              help="Where the tool enters (face A) in the probe file's z.")
@click.option("--controller", type=click.Choice(["linuxcnc", "fanuc", "plain"]), default="plain", show_default=True,
              help="Form of the offset block.")
@click.option("--tool", type=click.IntRange(min=1), default=1, show_default=True, help="Tool / offset number.")
@click.option("--tool-radius", type=FiniteRange(min=0, min_open=True),
              help="The tool's current radius in the LinuxCNC tool table, mm.")
@json_option
@handle_errors
def next_cmd(plan_path, measured, pass_done, applied, hardened, entry, controller, tool, tool_radius, json_path):
    """The correction for the next pass and its tool-offset block."""
    from ..processes import bore as pb

    check_outputs({"plan": plan_path, "probe file": measured}, {"--json": json_path})
    try:
        data = json.loads(read_text(plan_path))  # with or without a byte-order mark
    except json.JSONDecodeError as err:
        raise InputError(f"not a plan (JSON): {err.msg}", str(plan_path), err.lineno, err.colno) from None
    p = pb.Plan.from_dict(data, str(plan_path))
    meas = pb.read_probe(measured, entry)
    c = pb.next_correction(p, meas, pass_done, applied=applied, hardened=hardened)
    block = pb.offset_block(c.correction, controller=controller, tool=tool, radius=tool_radius)
    for circ, e in zip(meas.circles, c.errors):
        summary(f"  plane {circ.plane:>8s}: Ø{circ.diameter:.4f}, roundness {circ.roundness * 1000:.1f} µm, "
                   f"error {_um(e)}")
    summary(f"taper {meas.taper * 1000:+.1f} µm, barrel {meas.barrel * 1000:+.1f} µm")
    summary(f"pass {c.next_pass} of {p.passes}: correction δK {_um(c.correction)} ({c.rule}); "
               f"cutting edge at R {c.radial_position:.4f}")
    if c.stiffness_ratio is not None:
        summary(f"stiffness ratio (pre-finish / now) {c.stiffness_ratio:.3f}")
    summary(block)
    if json_path:
        write_json(json_path, {**c.as_dict(), "measurement": meas.as_dict(), "block": block, "controller": controller})


@bore.command("simulate")
@click.option("--parts", type=click.IntRange(1, 1_000_000), default=1000, show_default=True,
              help="Number of simulated parts (at most 1,000,000).")
@seed_option
@click.option("--material", type=click.Choice(["steel", "titanium", "aluminium", "hardened"]), default="steel",
              show_default=True, help="Material of the simulated parts (sets the cutting behaviour of the model).")
@click.option("--diameter", type=FiniteRange(min=0, min_open=True), default=40.0, show_default=True,
              help="Nominal diameter, mm.")
@click.option("--t0", type=FiniteRange(min=0, min_open=True), default=0.5, show_default=True,
              help="Radial depth of the last pre-finish pass, mm.")
@click.option("--allowance", type=FiniteRange(min=0, min_open=True), default=0.1, show_default=True,
              help="Radial stock z left for the corrective passes, mm.")
@click.option("--k", type=FiniteRange(0, 1, min_open=True), default=0.25, show_default=True,
              help="Share of the final tolerance allowed for form error.")
@json_option
@handle_errors
def simulate_cmd(parts, seed, material, diameter, t0, allowance, k, json_path):
    """Run the plan and the pass-by-pass loop on seeded virtual parts, against one uncorrected pass."""
    from ..sim import bore as sb

    with progress() as say:
        r = sb.simulate(parts, seed, material=material, diameter=diameter, t0=t0, allowance=allowance, k=k, progress=say)
    w = r["without_correction"]
    summary(f"{parts} {material} parts (applicability held for {r['applicable_share']:.1%} of those drawn)")
    summary(f"corrective passes: {r['within_tolerance']:.1%} inside H6 with form ≤ k·IT6, {r['mean_passes']:.2f} "
               f"passes, form error {r['form_error_mean'] * 1000:.2f} µm, diameter {_um(r['diameter_error_mean'])}")
    summary(f"one uncorrected pass: {w['within_tolerance']:.1%} inside, form error {w['form_error_mean'] * 1000:.2f} µm, "
               f"diameter {_um(w['diameter_error_mean'])}")
    if json_path:
        write_json(json_path, r)
