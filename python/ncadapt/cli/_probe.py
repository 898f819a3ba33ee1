"""``ncadapt probe``: write on-machine probing programs (a grid for autoleveling, points on a CAD
face for inspection) and the plan that pairs the machine's log with the nominal points."""

from __future__ import annotations

import re
from pathlib import Path

import click

from ..constants import COORD_MAX
from ._common import FiniteRange, check_outputs, extent_value, handle_errors, json_option, progress, summary, write_json

_LENGTH = FiniteRange(-COORD_MAX, COORD_MAX)
_POSITIVE = FiniteRange(0, COORD_MAX, min_open=True)
#: Feeds from 0.001 mm/min to 100 m/min.
_FEED = FiniteRange(0.001, 100_000.0)


def _dialect(f):
    from ..probing import DIALECTS

    return click.option(
        "--dialect",
        type=click.Choice(DIALECTS),
        default="linuxcnc",
        show_default=True,
        help="Controller the program is written for.",
    )(f)


def _log_name(ctx, param, value):
    if not re.fullmatch(r"[A-Za-z0-9_.][A-Za-z0-9_.-]{0,63}", value):
        raise click.BadParameter(
            f"{value!r}: a file name of letters, digits, '.', '_' and '-' (at most 64 "
            "characters), without folders: it goes into a comment of the program"
        )
    return value


_log_option = click.option(
    "--log",
    "log_name",
    default="probe-log.txt",
    show_default=True,
    callback=_log_name,
    help="Name of the log file the program makes the controller write (LinuxCNC PROBEOPEN/LOGOPEN, Sinumerik WRITE).",
)


def _bad(option: str, message: str):
    from ..errors import InputError

    return InputError(f"{option}: {message}")


@click.group()
def probe() -> None:
    """Write on-machine probing programs: a grid (autoleveling) or points on a CAD face (inspection)."""


@probe.command()
@click.option("--extent", callback=extent_value, metavar="XMIN,XMAX,YMIN,YMAX", help="Area to probe, mm.")
@click.option(
    "--program",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Probe the area of this NC program's feed moves instead of --extent.",
)
@click.option(
    "--margin",
    type=FiniteRange(0, COORD_MAX),
    default=0.0,
    show_default=True,
    help="Widen the program's area by this on every side, mm (with --program).",
)
@click.option("--step", type=FiniteRange(0.001, COORD_MAX), help="Largest spacing of the grid, mm, 0.001 to 1000000.")
@click.option("--nx", type=click.IntRange(2, 100_000), help="Points along X (with --ny).")
@click.option("--ny", type=click.IntRange(2, 100_000), help="Points along Y (with --nx).")
@click.option("--safe-z", type=_LENGTH, required=True, help="Height the probe retracts to between points, mm (work Z).")
@click.option(
    "--depth",
    type=_LENGTH,
    required=True,
    help="Lowest Z a probe move goes to, mm (work Z); not touching by then stops the program.",
)
@click.option(
    "--feed", type=_FEED, required=True, help="Probing feed (the touch that is logged), mm/min, 0.001 to 100000."
)
@click.option(
    "--fast-feed",
    type=_FEED,
    default=None,
    help="Touch first at this feed, back off 1 mm and touch again at --feed, mm/min, 0.001 to 100000.",
)
@_dialect
@_log_option
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True, help="Program to write."
)
@json_option
@handle_errors
def grid(extent, program, margin, step, nx, ny, safe_z, depth, feed, fast_feed, dialect, log_name, output, json_path):
    """A grid probing program for autoleveling: serpentine order, retract to --safe-z between
    points, a probe that does not touch stops the program."""
    from .. import probing

    if (extent is None) == (program is None):
        raise click.UsageError("give exactly one of --extent XMIN,XMAX,YMIN,YMAX or --program PROG.ngc")
    if margin and program is None:
        raise click.UsageError("--margin goes with --program")
    if (step is None) == (nx is None and ny is None) or (step is None and (nx is None or ny is None)):
        raise click.UsageError("give --step MM, or --nx N and --ny N")
    if not depth < safe_z:
        raise _bad("--depth", f"{depth:g} must be below --safe-z {safe_z:g}")
    if fast_feed is not None and not fast_feed > feed:
        raise _bad("--fast-feed", f"{fast_feed:g} must exceed --feed {feed:g} (the second touch is the slow one)")
    check_outputs({"input program": program}, {"-o": output, "--json": json_path})
    with progress() as say:
        if program is not None:
            import numpy as np

            from .. import nc

            say(f"reading {program}")
            tp = nc.read(program).toolpath(rapids=False)
            pts = np.vstack([tp.starts, tp.points])  # feed moves from where they start
            pts = pts[np.isfinite(pts).all(axis=1)]
            if len(pts) == 0:
                raise _bad("--program", f"{program} has no feed moves to take the area from")
            lo, hi = pts[:, :2].min(axis=0) - margin, pts[:, :2].max(axis=0) + margin
            if not (hi[0] > lo[0] and hi[1] > lo[1]):
                raise _bad(
                    "--program", f"the feed moves of {program} span no area in X and Y; give --extent or --margin"
                )
            extent = (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
        try:
            plan = probing.grid_points(extent, step=step, nx=nx, ny=ny)
        except ValueError as e:
            raise _bad("--step" if step is not None else "--nx/--ny", str(e)) from None
        text = probing.grid_program(
            plan, safe_z=safe_z, depth=depth, feed=feed, fast_feed=fast_feed, dialect=dialect, log=log_name
        )
        from .._io import atomic_write

        atomic_write(output, text.encode())
    summary(
        f"{output}: {plan.nx} x {plan.ny} = {len(plan.points):,} points ({dialect}), X {extent[0]:.4f}..{extent[1]:.4f}, "
        f"Y {extent[2]:.4f}..{extent[3]:.4f} mm, spacing {(extent[1] - extent[0]) / (plan.nx - 1):.4f} x "
        f"{(extent[3] - extent[2]) / (plan.ny - 1):.4f} mm"
    )
    if json_path:
        write_json(
            json_path,
            {
                "output": str(output),
                "dialect": dialect,
                "nx": plan.nx,
                "ny": plan.ny,
                "points": len(plan.points),
                "extent": list(extent),
                "safe_z": safe_z,
                "depth": depth,
                "feed": feed,
                "fast_feed": fast_feed,
                "log": log_name,
            },
        )


@probe.command()
@click.option(
    "--nominal",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    required=True,
    help="The part's CAD model, STEP (.step/.stp) or IGES (.igs/.iges).",
)
@click.option(
    "--face",
    "face_id",
    metavar="ID|NAME",
    default="1",
    show_default=True,
    help="Face to probe: its number from 1 in the file's order, or its name in the STEP file.",
)
@click.option("--n", "n", type=click.IntRange(1, 5000), help="Number of points to place on the face, 1 to 5000.")
@click.option("--adaptive", is_flag=True, help="Place the points denser where the face bends more (with --n).")
@click.option(
    "--points",
    "points_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="CSV of points to probe (columns x,y,z, mm), each within 0.01 mm of the face, instead of --n.",
)
@click.option(
    "--stylus-radius", type=FiniteRange(0, 1000), required=True, help="Radius of the stylus ball, mm, 0 to 1000."
)
@click.option(
    "--edge-margin",
    type=FiniteRange(0, COORD_MAX),
    default=None,
    help="Keep the points at least this far from the face's edges, mm [default and least: the stylus radius].",
)
@click.option(
    "--approach",
    type=_POSITIVE,
    required=True,
    help="Start of each probe move: this far from the surface along the normal, mm (more than the stylus radius).",
)
@click.option(
    "--overtravel",
    type=_POSITIVE,
    required=True,
    help="End of each probe move: this far into the surface along the normal, mm; no contact by then stops the program.",
)
@click.option("--feed", type=_FEED, required=True, help="Probing feed, mm/min, 0.001 to 100000.")
@click.option(
    "--fast-feed",
    type=_FEED,
    default=None,
    help="Touch first at this feed, back off 1 mm and touch again at --feed, mm/min, 0.001 to 100000.",
)
@click.option(
    "--safe-z",
    type=_LENGTH,
    default=None,
    help="Retract plane between points, mm [default: the face's top plus --approach].",
)
@_dialect
@_log_option
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True, help="Program to write."
)
@click.option(
    "--plan",
    "plan_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Plan to write (id, nominal x,y,z,i,j,k): `analyze PLAN` and `compensate PLAN` read it with its log.",
)
@json_option
@handle_errors
def points(
    nominal,
    face_id,
    n,
    adaptive,
    points_path,
    stylus_radius,
    edge_margin,
    approach,
    overtravel,
    feed,
    fast_feed,
    safe_z,
    dialect,
    log_name,
    output,
    plan_path,
    json_path,
):
    """An inspection program: points on a face of the CAD model, each probed along its outward
    normal, with a retract to a safe plane between points."""
    import numpy as np

    from .. import cad, probing
    from .._io import atomic_write
    from ..errors import InputError

    if (n is None) == (points_path is None):
        raise click.UsageError("give exactly one of --n N or --points FILE")
    if adaptive and n is None:
        raise click.UsageError("--adaptive goes with --n")
    if not approach > stylus_radius:
        raise _bad(
            "--approach",
            f"{approach:g} mm must exceed --stylus-radius {stylus_radius:g} mm: the ball must start "
            "clear of the surface",
        )
    if fast_feed is not None and not fast_feed > feed:
        raise _bad("--fast-feed", f"{fast_feed:g} must exceed --feed {feed:g} (the second touch is the slow one)")
    if edge_margin is not None and edge_margin < stylus_radius:
        raise _bad("--edge-margin", f"{edge_margin:g} mm is less than --stylus-radius {stylus_radius:g} mm")
    check_outputs(
        {"CAD model": nominal, "points file": points_path}, {"-o": output, "--plan": plan_path, "--json": json_path}
    )
    with progress() as say:
        say(f"reading {nominal}")
        part = cad.read_part(nominal)
        (face_id,) = part.select([face_id])
        face = part.faces[face_id - 1]
        say("placing the points")
        if n is not None:
            try:
                margin = stylus_radius if edge_margin is None else edge_margin
                fp = probing.face_points(face, n, margin=margin, adaptive=adaptive)
            except ValueError as e:
                raise InputError(f"face {face_id}: {e}", str(nominal)) from None
            p, nn, top = fp.points, fp.normals, fp.top
        else:
            from .. import fields

            c, lines = fields.read_columns(points_path, ("x", "y", "z"))
            q = np.column_stack([c["x"], c["y"], c["z"]])
            if not len(q):
                raise InputError("no points", str(points_path))
            p, nn, dist = cad.face_project(face, q)
            far = np.flatnonzero(dist > 0.01)
            if len(far):
                k = int(far[0])
                raise InputError(
                    f"point {q[k, 0]:g} {q[k, 1]:g} {q[k, 2]:g} is {dist[k]:.4f} mm from face {face_id}; "
                    "points must lie on it (within 0.01 mm)",
                    str(points_path),
                    int(lines[k]),
                    1,
                )
            bad = np.flatnonzero(~np.isfinite(nn).all(axis=1))
            if len(bad):
                raise InputError("the face has no normal at this point", str(points_path), int(lines[bad[0]]), 1)
            top = cad.face_top(face)
        steep = np.flatnonzero(nn[:, 2] < np.cos(np.radians(80.0)))
        if len(steep):
            k = int(steep[0])
            raise InputError(
                f"face {face_id}: the normal at {p[k, 0]:.4f} {p[k, 1]:.4f} {p[k, 2]:.4f} is more than 80° "
                "from +Z; the retract to a safe plane above the part is collision-free only for points "
                "seen from above",
                str(nominal),
            )
        start_top = float((p[:, 2] + approach * nn[:, 2]).max())
        if safe_z is None:
            safe_z = max(top, float(p[:, 2].max())) + approach
            safe_z = max(safe_z, start_top)
        elif not safe_z >= max(start_top, top + stylus_radius):
            raise _bad(
                "--safe-z",
                f"{safe_z:g} is below the highest start point ({start_top:.4f}) or the face's top "
                f"plus the stylus radius ({top + stylus_radius:.4f})",
            )
        text = probing.points_program(
            p,
            nn,
            approach=approach,
            overtravel=overtravel,
            feed=feed,
            safe_z=safe_z,
            stylus_radius=stylus_radius,
            dialect=dialect,
            log=log_name,
            fast_feed=fast_feed,
        )
        atomic_write(output, text.encode())
        if plan_path is not None:
            touches = 2 if fast_feed is not None and dialect == "grbl" else 1  # grbl reports both touches
            atomic_write(
                plan_path, probing.plan_text(p, nn, stylus_radius=stylus_radius, log=log_name, touches=touches).encode()
            )
    summary(f"{output}: {len(p):,} points on face {face_id} of {nominal} ({dialect}), safe Z {safe_z:.4f} mm")
    if plan_path is not None:
        summary(
            f"{plan_path}: the plan; after probing, `ncadapt analyze {plan_path}` reads it with {log_name} beside it"
        )
    if json_path:
        write_json(
            json_path,
            {
                "output": str(output),
                "plan": str(plan_path) if plan_path else None,
                "dialect": dialect,
                "face": face_id,
                "points": len(p),
                "adaptive": adaptive,
                "stylus_radius": stylus_radius,
                "approach": approach,
                "overtravel": overtravel,
                "feed": feed,
                "fast_feed": fast_feed,
                "safe_z": safe_z,
                "log": log_name,
            },
        )
