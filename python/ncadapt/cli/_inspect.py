"""``ncadapt inspect``: what a program contains and what the engine can do with it."""

from __future__ import annotations

from pathlib import Path

import click

from .. import dialects, nc
from ._common import (
    check_outputs,
    dialect_option,
    expand_read,
    handle_errors,
    machine_option,
    resolve_dialect,
    sinumerik_only,
    start_motion_option,
    subprograms_option,
    summary,
    write_json,
)


@click.command()
@click.argument("program", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@dialect_option
@machine_option
@click.option(
    "--expand",
    is_flag=True,
    help="Flatten the program's parameters, O-word flow, M98 subprograms and Fanuc Macro B first, as "
    "`correct --expand` does, and report what the flattened program contains (lines named are the program's).",
)
@subprograms_option
@start_motion_option
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the report as JSON.")
@handle_errors
def inspect(program, dialect, machine, expand, subprograms, start_motion, json_path):
    """Report units, planes, motion counts, extents and unsupported constructs of PROGRAM."""
    check_outputs({"program": program}, {"--json": json_path})
    d = resolve_dialect(program, dialect, machine)
    sinumerik_only(d, subprograms, start_motion)
    expand_read(expand, d)
    info = nc.inspect_file(program, d.engine, subprograms, expand, start_motion)
    info["dialect"] = d.as_dict()
    m = info["motions"]
    summary(f"{program}: {info['lines']:,} lines, units {info['units']}")
    summary(f"  dialect: {d.describe()}")
    if d.name in dialects.LATHE_DIALECTS:
        summary(f"  machine: {d.describe_machine()}")
    if expand and d.name != "sinumerik":
        summary(f"  flattened (--expand): {info['lines']:,} lines ran {info['blocks_run']:,} blocks")
    splines = m["spline"] + m["spline_quadratic"]
    summary(
        f"  motions: {m['rapid']:,} rapid, {m['feed']:,} feed, {m['arc_cw']:,} G2, {m['arc_ccw']:,} G3"
        + (f", {m['spline']:,} G5, {m['spline_quadratic']:,} G5.1" if splines else "")
    )
    p = info["planes"]
    summary(f"  arc planes: G17 {p['G17']:,}, G18 {p['G18']:,}, G19 {p['G19']:,}")
    e = info["extents"]["all"]
    if e:
        radius = ", X a radius" if d.lathe else ""
        summary(f"  extents (mm{radius}): " + ", ".join(f"{a.upper()} {lo:.4f}..{hi:.4f}" for a, (lo, hi) in e.items()))
    if info["work_offsets"]:
        summary("  work offsets: " + " ".join(info["work_offsets"]))
    if info["tools"]:
        summary("  tools: " + " ".join(f"T{t}" for t in info["tools"]))
    if info["block_delete_lines"]:
        summary(f"  block-delete lines: {info['block_delete_lines']:,} (interpreted as executed)")
    if info["unsupported"]:
        summary(f"  unsupported constructs ({len(info['unsupported'])}):")
        for u in info["unsupported"]:
            extra = f" ({u['blocks']} motion block(s))" if u["blocks"] else ""
            summary(f"    line {u['line']}:{u['col']}: {u['construct']}{extra}")
    else:
        summary("  unsupported constructs: none")
    for name, path in info.get("subprograms", {}).items():
        summary(f"  subprogram {name}: {path}")
    for n in info["notes"]:
        summary(f"  note: line {n['line']}: {n['message']}")
    if json_path is not None:
        write_json(json_path, info)
