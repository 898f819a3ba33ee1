"""``ncadapt correct``: apply a correction field to an NC program."""

from __future__ import annotations

from pathlib import Path

import click

from .. import constants, dialects
from ._common import (
    FiniteRange,
    check_outputs,
    comma_floats,
    dialect_option,
    echo_err,
    expand_read,
    handle_errors,
    machine_option,
    progress,
    resolve_dialect,
    sinumerik_only,
    start_motion_option,
    subprograms_option,
    summary,
    write_json,
)


def _shift(ctx, param, value):
    return None if value is None else comma_floats(value, 3, "DX,DY,DZ (three numbers in mm)")


@click.command()
@click.argument("program", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--field",
    "field_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Correction field: grid CSV (x,y,dz), scattered CSV (x,y,z,dx,dy,dz), bCNC .probe, LinuxCNC "
    "probe log, grbl [PRB:] log, OpenCNCPilot .hmap, Candle .map or a Fanuc DPRNT log.",
)
@click.option("--shift", callback=_shift, metavar="DX,DY,DZ", help="A constant displacement in mm instead of a field.")
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True, help="Corrected program to write."
)
@click.option(
    "--max-segment",
    type=FiniteRange(*constants.MAX_SEGMENT_RANGE),
    default=constants.MAX_SEGMENT,
    show_default=True,
    help="Longest corrected piece, mm.",
)
@click.option(
    "--chord-tol",
    type=FiniteRange(*constants.CHORD_TOL_RANGE),
    default=constants.CHORD_TOL,
    show_default=True,
    help="Arc chord tolerance, mm: the largest distance between an arc and its chords, and between an arc "
    "kept an arc and the displaced arc.",
)
@click.option(
    "--limit",
    type=FiniteRange(min=0, min_open=True),
    default=constants.LIMIT,
    show_default=True,
    help="Refuse if any displacement exceeds this, mm.",
)
@click.option(
    "--outside",
    type=click.Choice(constants.OUTSIDE),
    default="error",
    show_default=True,
    help="Points outside the field's domain.",
)
@click.option(
    "--interp",
    "method",
    type=click.Choice(["linear", "cubic"]),
    default="linear",
    show_default=True,
    help="Grid interpolation.",
)
@click.option("--rapids", is_flag=True, help="Correct rapid (G0) moves too.")
@click.option(
    "--keep-unsupported", is_flag=True, help="Copy blocks with unsupported constructs unchanged instead of refusing."
)
@click.option(
    "--clearance",
    type=FiniteRange(-constants.COORD_MAX, constants.COORD_MAX),
    default=None,
    metavar="Z",
    help="Report uncorrected rapids ending below this Z inside the field, mm (inch programs too: their Z is "
    "compared in mm).",
)
@dialect_option
@machine_option
@click.option(
    "--expand-cycles",
    is_flag=True,
    help="Write canned cycles (G73, G81-G83, G85, G89) as the G0/G1 moves LinuxCNC makes of them. "
    "Without it a cycle stays a cycle block, each hole moved by the field at its bottom: X and Y by "
    "its x and y, Z and R by its z (written on the holes whose values change). Cycles in G18/G19, "
    "G87, G88 and G76, and cycles from an unknown position, are refused.",
)
@click.option(
    "--expand",
    is_flag=True,
    help="Flatten the program's parameters, expressions and O-word flow (LinuxCNC's: o-word subroutines, "
    "if/while/repeat), its M98/M99 subprograms (LinuxCNC's and Fanuc's) and Fanuc Custom Macro B (variables, G65, "
    "IF/GOTO, WHILE/DO) into straight G-code as the control "
    "runs them, and correct and write that. Without it such programs are refused. A Sinumerik program is always "
    "run (its R parameters, variables, IF/WHILE/FOR and GOTO) and its corrected lines rewritten in place; a line "
    "corrected differently on each pass of a loop needs --expand, which then writes the program straight.",
)
@click.option(
    "--tool-table",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="LinuxCNC tool table (T<n> … D<diameter>) for cutter radius compensation: G41/G42 take tool D's "
    "radius (or the loaded tool's), and the field is evaluated where the tool centre is. Needs --tool-units.",
)
@click.option(
    "--tool-units",
    type=click.Choice(["mm", "inch"]),
    help="Units of the tool table's numbers (the machine's; the table does not say).",
)
@subprograms_option
@start_motion_option
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the figures as JSON.")
@handle_errors
def correct(
    program,
    field_path,
    shift,
    output,
    max_segment,
    chord_tol,
    limit,
    outside,
    method,
    rapids,
    keep_unsupported,
    clearance,
    dialect,
    machine,
    expand_cycles,
    expand,
    tool_table,
    tool_units,
    subprograms,
    start_motion,
    json_path,
):
    """Apply a measured correction to PROGRAM and write the corrected program to OUTPUT.

    Unchanged blocks are copied byte for byte; nothing is written when a safety check refuses
    (exit code 1).
    """
    if (field_path is None) == (shift is None):
        raise click.UsageError("give exactly one of --field FILE or --shift DX,DY,DZ")
    check_outputs({"input program": program, "field file": field_path}, {"-o": output, "--json": json_path})
    if (tool_table is None) != (tool_units is None):
        raise click.UsageError("--tool-table and --tool-units go together: the table's numbers have no units")
    d = resolve_dialect(program, dialect, machine)
    sinumerik_only(d, subprograms, start_motion)
    expand_read(expand, d)
    tools = None
    if tool_table is not None:
        from .. import tooltable

        tools = tooltable.read(tool_table, tool_units)
    # the engine starts reading the program while numpy is imported and the field read, on the
    # core that would wait (without a tool table: the read-ahead reads without one)
    from .._nc import read_ahead

    ahead = (
        None
        if tools or expand or d.name in ("sinumerik", "marlin")
        else read_ahead(str(program), constants.PIECE_BYTES, d.engine)
    )
    from .. import fields as _fields
    from .. import nc

    with progress() as say:
        if field_path is not None:
            say(f"reading {field_path}")
            field = _fields.read(field_path, method=method, outside=outside)
        else:
            field = _fields.Shift(shift)
        c = nc.correct_file(
            program,
            output,
            field,
            chord_tol=chord_tol,
            max_segment=max_segment,
            limit=limit,
            rapids=rapids,
            keep_unsupported=keep_unsupported,
            clearance=clearance,
            progress=say,
            expand_cycles=expand_cycles,
            dialect=d.engine,
            read_ahead=ahead,
            tools=tools,
            expand=expand,
            subprograms=subprograms,
            start_motion=start_motion,
        )
    summary(f"{program} -> {output}")
    summary(f"  dialect: {d.describe()}")
    if d.name in dialects.LATHE_DIALECTS:
        summary(f"  machine: {d.describe_machine()}")
    summary(f"  field: {field.describe()}")
    if c.expanded is not None:
        e = c.expanded
        how = {
            "as it is": "no block changed: the program is written as it is",
            "in place": f"{e['lines_rewritten']:,} line(s) rewritten in place, every other line as written",
            "straight": f"the corrected program is written straight, {e['lines_rewritten']:,} lines",
        }[e["written"]]
        ran = {"sinumerik": "run as straight G-code", "marlin": "E carried through the correction"}.get(
            d.name, "flattened (--expand)"
        )
        summary(f"  {ran}: {e['lines_in']:,} lines ran {e['blocks_run']:,} blocks; {how}")
        for name, path in e.get("subprograms", {}).items():
            summary(f"  subprogram {name}: {path}")
    summary(
        f"  lines read {c.lines_in:,}, written {c.lines_out:,}; blocks changed {c.blocks_changed:,}, "
        f"lines added {c.lines_added:,}, arcs linearised {c.arcs_linearised:,}"
        + (f", splines linearised {c.splines_linearised:,}" if c.splines_linearised else "")
    )
    summary(
        f"  displacement max {c.max_displacement:.4f} mm, mean {c.mean_displacement:.4f} mm over {c.n_points:,} points"
    )
    if c.unsupported_kept:
        summary(f"  unsupported constructs kept unchanged ({len(c.unsupported_kept)}), their blocks not corrected:")
        for u in c.unsupported_kept[:20]:
            summary(f"    line {u.line}:{u.col}: {u.construct}")
        if len(c.unsupported_kept) > 20:
            summary(f"    ... and {len(c.unsupported_kept) - 20} more (see --json)")
    else:
        summary("  unsupported constructs: none")
    for n_line, msg in c.notes[:20]:
        summary(f"  note: line {n_line}: {msg}")
    for w in c.warnings:
        echo_err(f"  warning: {w}")
    if json_path is not None:
        payload = {
            "input": str(program),
            "output": str(output),
            "field": str(field_path) if field_path else {"shift": shift},
        }
        payload.update(c.as_dict())
        payload["dialect"] = d.as_dict()
        payload["field_interpolation"] = field.describe()
        payload["options"] = {
            "max_segment": max_segment,
            "chord_tol": chord_tol,
            "limit": limit,
            "outside": outside,
            "interp": method,
            "rapids": rapids,
            "keep_unsupported": keep_unsupported,
            "clearance": clearance,
            "dialect": dialect,
            "machine": machine,
            "expand_cycles": expand_cycles,
            "expand": expand,
            "tool_table": None if tool_table is None else str(tool_table),
            "tool_units": tool_units,
            "subprograms": [str(f) for f in subprograms],
            "start_motion": start_motion,
        }
        write_json(json_path, payload)
