"""``ncadapt analyze`` and ``ncadapt compensate``: freeform surfaces from coordinate measurements."""

from __future__ import annotations

from pathlib import Path

import click

from .. import constants
from ..errors import InputError
from ._common import FiniteRange, check_outputs, echo_err, extent_value, handle_errors, progress, summary, write_json


def _moran_options(f):
    opts = [
        click.option(
            "--weights",
            type=click.Choice(["auto", "idw", "knn"]),
            default="auto",
            show_default=True,
            help="Moran's I weights: inverse distance 1/d^K, or the N nearest neighbours; auto: 1/d^K over "
            "all pairs up to 3,000 points (or with --threshold), 8 nearest neighbours above.",
        ),
        click.option("--power", type=FiniteRange(min=1), default=1.0, show_default=True, help="K of idw weights."),
        click.option(
            "--threshold",
            type=FiniteRange(min=0, min_open=True),
            default=None,
            help="Distance band for idw weights, mm (default: all pairs).",
        ),
        click.option("--neighbors", type=click.IntRange(min=1), default=8, show_default=True, help="N of knn weights."),
        click.option(
            "--alpha",
            type=FiniteRange(1e-12, 0.5),
            default=0.05,
            show_default=True,
            help="Significance of the 'systematic' decision, 1e-12 to 0.5 (Moran's I and the offset test each "
            "at alpha/2).",
        ),
        click.option(
            "--probe-radius",
            type=FiniteRange(0, constants.COORD_MAX),
            default=0.0,
            show_default=True,
            help="The measured points are probe-tip centres of this radius, mm.",
        ),
        click.option(
            "--units",
            type=click.Choice(["mm", "inch"]),
            default=None,
            help="Length unit of a measurement file that does not declare one (CSV, XYZIJK; DMIS or QIF "
            "without a units statement) [default: mm]; a file's own must agree.",
        ),
        click.option(
            "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the figures as JSON."
        ),
        click.option(
            "--report", "report_path", type=click.Path(dir_okay=False, path_type=Path), help="Write an HTML report."
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def _section_value(ctx, param, value):  # noqa: ARG001 - a click callback's signature
    """A click callback: ``AXIS=POS`` lines (``x=40``), as (axis name, position mm) pairs."""
    from ._common import comma_floats

    out = []
    for text in value:
        axis, eq, pos = text.partition("=")
        if not eq or not axis.strip():
            raise click.BadParameter(f"expected AXIS=POSITION in mm (x=40), got {text!r}")
        out.append((axis.strip(), comma_floats(pos, 1, "AXIS=POSITION in mm (x=40)")[0]))
    return tuple(out)


def _moran_kw(weights, power, threshold, neighbors, alpha):
    return {"weights": weights, "power": power, "threshold": threshold, "neighbors": neighbors, "alpha": alpha}


def _said(say, what):
    """A ``progress(done, total)`` callback that shows ``what`` with a bar."""
    say(what)
    return lambda done, total: say(what, done, total)


def _print_analysis(a) -> None:
    from ..stats import p_text

    m, d = a.moran, a.deviation
    summary(f"points: {a.n_points:,}; weights: {m.weights.describe()}")
    summary(
        f"deviation (mm): mean {d['mean']:+.4f}, std {d['std']:.4f}, min {d['min']:+.4f}, max {d['max']:+.4f}, rms {d['rms']:.4f}"
    )
    o, v = a.offset, a.verdict
    if m.p_permutation is None:
        p_said = f"p {m.p_said()} (one-sided, normal approximation)"
    else:
        p_said = (
            f"p {m.p_said()} (one-sided, {m.permutations} permutations; normal approximation "
            f"{p_text(m.p_randomization)})"
        )
    summary(
        f"Moran's I {m.I:.4f} (E[I] {m.expected:.4f}), z {m.z_randomization:.2f} (randomisation), "
        f"{m.z_normality:.2f} (normality), {p_said}"
    )
    summary(f"offset: mean {o.mean:+.4f} mm, t {o.t:.2f}, p {p_text(o.p_value)}")
    summary(
        f"systematic at alpha {v.alpha:g} (Moran's I and the offset each at {v.alpha / 2:g}): "
        + (
            f"yes, by {' and '.join('the offset' if b == 'offset' else 'Moran' + chr(39) + 's I' for b in v.by)}"
            if v.systematic
            else "no"
        )
    )


def _align_dof(ctx, param, value):  # noqa: ARG001 - a click callback's signature
    from ..measure import _align

    if value is None:
        return None
    try:
        return _align.parse_dof(value)
    except InputError as e:
        raise click.BadParameter(e.message.removeprefix("--align-dof: ")) from None


def _align_options(f):
    """``--align``, ``--align-dof`` and ``--datums`` (with ``--nominal``); the command passes them to
    :func:`ncadapt.measure.against_cad` and prints the result's ``alignment`` with
    :func:`_print_alignment`."""
    opts = [
        click.option(
            "--align",
            type=click.Choice(["none", "bestfit", "datums"]),
            default="none",
            show_default=True,
            help="With --nominal: move the actual points onto the CAD frame first — none (on-machine probing: the "
            "machine frame is the part's), bestfit (least squares on the distances to the faces) or datums (RPS / "
            "3-2-1 on the datum points and features of --datums).",
        ),
        click.option(
            "--align-dof",
            callback=_align_dof,
            metavar="LIST",
            help="The degrees of freedom --align solves for, among x,y,z,rx,ry,rz (default all six; the others "
            "held at 0).",
        ),
        click.option(
            "--datums",
            type=click.Path(exists=True, dir_okay=False, path_type=Path),
            help="With --align datums: the datum points and features (TOML; docs/freeform.md gives the format).",
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def _cad_options(f):
    """``--nominal``, ``--face`` and ``--max-distance``: a CAD model as the nominal."""
    opts = [
        click.option(
            "--nominal",
            type=click.Path(exists=True, dir_okay=False, path_type=Path),
            help="The CAD model (STEP or IGES) as the nominal: the actual points of MEASUREMENTS (CSV x,y,z; DMIS "
            "FA(label)=FEAT/POINT outputs; QIF 3 PointFeatureActual and MeasuredPointSet) are projected onto the "
            "nearest selected face, the deviation along its outward normal. A file with nominals of its own (CSV "
            "x,y,z,i,j,k with mx,my,mz or dev, XYZIJK, DMIS F/FA pairs, QIF nominal points) gives its actual points "
            "(nominal + dev x normal without them), and its nominals must lie within --max-distance of the faces.",
        ),
        click.option(
            "--face",
            "face_ids",
            metavar="ID|NAME",
            multiple=True,
            help="A face of --nominal: its id (1-based, OpenCASCADE's order) or its name in the STEP file "
            "(ADVANCED_FACE name); repeat for several; default: all.",
        ),
        click.option(
            "--face-set",
            "face_sets",
            metavar="IDS",
            multiple=True,
            callback=_face_set_value,
            help="Faces of --nominal (ids or names, comma-separated) analysed and decomposed together in one (u, v), "
            "that of the plane their normals fit, so the correction is continuous across their common edges "
            "(refused if the set is not a height field over it); repeat for several sets; faces in no set keep "
            "their own (u, v).",
        ),
        click.option(
            "--max-distance",
            type=FiniteRange(0, constants.COORD_MAX, min_open=True),
            default=1.0,
            show_default=True,
            help="With --nominal: refuse points (and a file's own nominal points) farther than this from every "
            "face, mm.",
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def _face_set_value(ctx, param, value):  # noqa: ARG001 - a click callback's signature
    """A click callback: each ``--face-set`` as a list of face ids or names (comma-separated)."""
    out = []
    for text in value:
        ids = [w.strip() for w in text.split(",")]
        if not all(ids):
            raise click.BadParameter(f"expected face ids or names separated by commas (1,2), got {text!r}")
        out.append(ids)
    return tuple(out)


def _face_sets_said(sets, proj) -> None:
    """One summary line per face set."""
    for fs in sets:
        a = fs.analysis
        line = (
            f"face set {', '.join(_face_said(f, proj.name_of(f)).removeprefix('face ') for f in fs.faces)}: {len(fs.points):,} points in "
            f"one (u, v) across w ({', '.join(f'{c:+.3f}' for c in fs.frame.axes[2])}); Moran's I {a.moran.I:.4f}, "
            f"systematic: {'yes' if a.systematic else 'no'}"
        )
        if fs.decomposition is not None:
            sd = fs.decomposition.as_dict()
            line += f"; systematic rms {sd['systematic']['rms']:.4f} mm, random std {sd['random']['std']:.4f} mm"
        summary(line)


def _face_sets_json(sets, proj) -> list[dict]:
    """The ``face_sets`` JSON list: each set's faces, their names, its figures."""
    return [{"faces": list(fs.faces), "names": [proj.name_of(f) for f in fs.faces]} | fs.as_dict() for fs in sets]


def _check_align(nominal, align, align_dof, datums) -> None:
    """Usage errors of the options of :func:`_align_options`."""
    if align != "none" and nominal is None:
        raise click.UsageError("--align needs --nominal")
    if align_dof is not None and align == "none":
        raise click.UsageError("--align-dof needs --align bestfit or datums")
    if (datums is not None) != (align == "datums"):
        raise click.UsageError(
            "--align datums needs --datums FILE.toml" if datums is None else "--datums needs --align datums"
        )


def _print_file_nominals(checked, measurements) -> None:
    """What the measurement file's own nominal points said against the CAD (nothing for a file of
    actual points only)."""
    if checked is None or not checked["points"]:
        return
    how = (
        "the actual points are the file's nominals + deviation x normal; "
        if checked["from_deviation"]
        else "the actual points are used; "
    )
    summary(
        f"{measurements.name} has nominal points of its own: {how}its {checked['points']:,} nominals checked against "
        f"the CAD, the farthest {checked['max_distance']:.4g} mm from the faces (line {checked['line']})"
    )


def _print_alignment(al) -> None:
    """The rigid transform, apart from the form error."""
    if al.mode == "none":
        summary("alignment: none (the measurement's frame is the CAD frame)")
        return
    t, r, st = al.translation, al.rotation, al.std
    what = "points" if al.mode == "bestfit" else "constraints"
    summary(
        f"alignment ({al.mode}, {','.join(al.dof)}; {al.points:,} {what}, "
        f"{al.iterations} iterations): translation (mm) {t[0]:+.5f} {t[1]:+.5f} {t[2]:+.5f}, "
        f"rotation (deg, about fixed X then Y then Z) {r[0]:+.6f} {r[1]:+.6f} {r[2]:+.6f}"
    )
    if al.mode == "bestfit":
        summary(
            f"alignment residual rms {al.rms:.4f} mm; standard uncertainty translation (mm) "
            f"{st[0]:.5f} {st[1]:.5f} {st[2]:.5f}, rotation (deg) {st[3]:.6f} {st[4]:.6f} {st[5]:.6f}"
        )
    elif al.points == len(al.dof):
        summary(f"alignment residual rms {al.rms:.2g} mm (exact: one constraint per degree of freedom)")
    else:
        summary(
            f"alignment residual rms {al.rms:.4f} mm (least squares: {al.points} constraints for {len(al.dof)} "
            f"degrees of freedom); standard uncertainty translation (mm) {st[0]:.5f} {st[1]:.5f} {st[2]:.5f}, "
            f"rotation (deg) {st[3]:.6f} {st[4]:.6f} {st[5]:.6f}"
        )
    for d in al.datums:
        fit = "" if d.feature == "point" else f", {d.points} points, form rms {d.form_rms:.4f} max {d.form_max:.4f} mm"
        size = (
            ""
            if d.radius is None
            else f", radius {d.radius:.4f} mm"
            + ("" if d.radius_nominal is None else f" (nominal {d.radius_nominal:g})")
        )
        summary(f"  datum {d.name} ({d.feature}, {d.constraints}): residual {d.residual:.4f} mm{fit}{size}")


def _tolerance_option(text):
    """``--tolerance T``, mm."""
    return click.option("--tolerance", type=FiniteRange(0, constants.COORD_MAX, min_open=True), help=text)


@click.command()
@click.argument("measurements", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@_cad_options
@_align_options
@_tolerance_option(
    "Profile tolerance ±T, mm: the share of the points inside it and above and below it, in the summary, "
    "the JSON (`tolerance`; with --nominal by face as well) and the report's tolerance-banded maps."
)
@_moran_options
@handle_errors
def analyze(
    measurements,
    nominal,
    face_ids,
    face_sets,
    max_distance,
    align,
    align_dof,
    datums,
    tolerance,
    weights,
    power,
    threshold,
    neighbors,
    alpha,
    probe_radius,
    units,
    json_path,
    report_path,
):
    """Deviations of MEASUREMENTS along the normals and Moran's I: is the error systematic?

    MEASUREMENTS: CSV (x,y,z,i,j,k and mx,my,mz or dev), DMIS, PC-DMIS XYZIJK text or QIF 3; with
    --nominal, actual points (CSV x,y,z, DMIS FA points, QIF measured points and point sets) or any of
    these paired files, whose own nominals are checked against the CAD.
    """
    from .. import measure
    from ..probing import companion_inputs
    from ..processes import freeform as pf

    check_outputs(
        {"measurements": measurements, "nominal": nominal, "datums": datums, **companion_inputs(measurements)},
        {"--json": json_path, "--report": report_path},
    )
    if face_ids and nominal is None:
        raise click.UsageError("--face needs --nominal")
    if face_sets and nominal is None:
        raise click.UsageError("--face-set needs --nominal")
    _check_align(nominal, align, align_dof, datums)
    sets = []
    with progress() as say:
        say(f"reading {measurements}")
        if nominal is not None:
            say(f"projecting onto {nominal}")
            proj = measure.project_on_cad(
                measurements,
                nominal,
                faces=list(face_ids) or None,
                max_distance=max_distance,
                probe_radius=probe_radius,
                units=units,
                align=align,
                align_dof=align_dof,
                datums=datums,
                face_sets=[list(ids) for ids in face_sets] or None,
            )
            meas = proj.measurements
            sets = pf.analyze_face_sets(proj, **_moran_kw(weights, power, threshold, neighbors, alpha))
        else:
            proj = None
            meas = measure.read(measurements, probe_radius=probe_radius, units=units)
        frame = pf.frame_of(meas)
        a = pf.analyze(
            meas,
            frame=frame,
            progress=_said(say, "Moran's I"),
            **_moran_kw(weights, power, threshold, neighbors, alpha),
        )
    if meas.alignment is not None:
        _print_alignment(meas.alignment)
    if proj is not None:
        summary(
            "faces: "
            + "; ".join(f"{_face_said(f['id'], f['name'])} ({f['n_points']:,} points)" for f in proj.faces_used())
        )
        _print_file_nominals(proj.file_nominals, measurements)
    _print_analysis(a)
    faces = proj.faces_used() if proj is not None else None
    if proj is not None:
        _face_sets_said(sets, proj)
        if proj.sets:
            for f in faces or []:
                f["face_set"] = proj.face_set_of(f["id"])
    tol = None
    if tolerance is not None:
        import numpy as np

        from ..report import freeform as rep

        tol = {"value": tolerance, "before": rep.tolerance_shares(meas.deviation, tolerance)}
        for f in faces or []:
            f["tolerance"] = rep.tolerance_shares(meas.deviation[np.asarray(proj.face) == f["id"]], tolerance)
            summary(
                f"{_face_said(f['id'], f['name'])}: tolerance ±{tolerance:g} mm: "
                f"{100 * f['tolerance']['inside']:.1f} % of its points inside"
            )
        b = tol["before"]
        summary(
            f"tolerance ±{tolerance:g} mm: {100 * b['inside']:.1f} % of the points inside, "
            f"{100 * b['above']:.1f} % above, {100 * b['below']:.1f} % below"
        )
    if json_path:
        extra = {"alignment": meas.alignment.as_dict()} if meas.alignment is not None else {}
        if faces is not None:
            extra["faces"] = faces
            extra["face_sets"] = _face_sets_json(sets, proj)
        if proj is not None and proj.file_nominals is not None:
            extra["file_nominals"] = proj.file_nominals
        if tol is not None:
            extra["tolerance"] = tol
        write_json(json_path, {"input": str(measurements), **extra, **a.as_dict()})
    if report_path:
        from ..report import freeform as rep
        from ..report import write

        d = pf.decompose(meas, frame=frame, **_moran_kw(weights, power, threshold, neighbors, alpha))
        write(
            report_path,
            rep.render(
                title=f"Deviation analysis: {measurements.name}",
                analysis=a,
                decomposition=d,
                xy=frame.uv(meas.nominal),
                names=frame.names,
                deviation=meas.deviation,
                points=meas.nominal,
                tolerance=tolerance,
            ),
        )


@click.command()
@click.argument("measurements", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--filter",
    "method",
    type=click.Choice(["bilateral", "spline"]),
    default="bilateral",
    show_default=True,
    help="How the systematic part is separated from noise.",
)
@click.option(
    "--sigma-c", type=FiniteRange(min=0, min_open=True), help="Bilateral spatial sigma, mm (default 1.5 x spacing)."
)
@click.option(
    "--sigma-s", type=FiniteRange(min=0, min_open=True), help="Bilateral range sigma, mm (default 3 x noise)."
)
@click.option("--p", "p", type=FiniteRange(0, 1), help="Smoothing-spline parameter (csaps' p).")
@click.option("--auto", is_flag=True, help="Smoothest filter whose random part has no significant Moran's I.")
@click.option("--program", type=click.Path(exists=True, dir_okay=False, path_type=Path), help="NC program to correct.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), help="Corrected NC program.")
@click.option(
    "--tool-radius",
    type=FiniteRange(0, constants.COORD_MAX),
    default=None,
    help="Ball-end radius of the program's tool, mm (its tip is R below the ball centre); required with "
    "--program (0: the programmed point is the contact point).",
)
@click.option(
    "--extent",
    callback=extent_value,
    metavar="XMIN,XMAX,YMIN,YMAX",
    help="The part's area in (u, v), mm — (x, y) for a part measured from +z; the systematic error is "
    "extrapolated into it (default: the measured area).",
)
@click.option(
    "--border",
    type=click.Choice(["hold", "cubic"]),
    default="hold",
    show_default=True,
    help="The systematic error in the unmeasured border of the surface: the nearest measured value, or "
    "the paper's cubic extrapolation (bounded by the measured range widened by 25 %).",
)
@click.option(
    "--extrapolate-nominal",
    is_flag=True,
    help="Accept a surface reaching beyond the measured points (--extent, or the corners of a scatter): "
    "there the nominal is extrapolated from them, not measured; the JSON and the report say how far.",
)
@click.option(
    "--limit",
    type=FiniteRange(min=0, min_open=True),
    default=constants.LIMIT,
    show_default=True,
    help="Refuse if any program displacement exceeds this, mm.",
)
@click.option(
    "--outside",
    type=click.Choice(["error", "clamp", "extrapolate"]),
    default="error",
    show_default=True,
    help="Program points beyond the compensated surface (the measured area, or --extent): refuse, hold "
    "the nearest edge value, or extrapolate the thin-plate spline.",
)
@click.option(
    "--surface",
    "surface_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Compensated surface, .step/.stp or .igs/.iges.",
)
@click.option(
    "--points-out", type=click.Path(dir_okay=False, path_type=Path), help="CSV of the parts and compensated points."
)
@_cad_options
@click.option(
    "--part",
    "part_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="With --nominal: the whole compensated part, .step/.stp (the compensated faces in place of the nominal "
    "ones; --surface then writes those faces alone).",
)
@_tolerance_option(
    "Profile tolerance ±T, mm: the share of points inside it before and predicted after (measured − "
    "systematic), in the summary, the JSON and the report's tolerance-banded maps (with --nominal: by face "
    "as well)."
)
@click.option(
    "--section",
    "section_lines",
    multiple=True,
    callback=_section_value,
    metavar="AXIS=POS",
    help="A section of the report along the line AXIS = POS mm of the part's plane (x=40, y=30 for a part "
    "measured from +z): nominal, measured, systematic and compensated profiles. With --nominal: the plane "
    "x, y or z = POS of the CAD frame cut through the compensated faces. Repeat for several.",
)
@_align_options
@click.option(
    "--previous",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="A later round: the --json of the round whose corrected program cut the measured part; the new "
    "correction is its correction plus --gain times the systematic error measured now.",
)
@click.option(
    "--gain",
    type=FiniteRange(0, 2, min_open=True, max_open=True),
    default=None,
    help="With --previous: the gain on the new systematic error, damped by the share of it that is not "
    "filtered noise (docs/freeform.md) [default: 1].",
)
@_moran_options
@handle_errors
def compensate(
    measurements,
    method,
    sigma_c,
    sigma_s,
    p,
    auto,
    program,
    output,
    tool_radius,
    extent,
    border,
    extrapolate_nominal,
    limit,
    outside,
    surface_path,
    points_out,
    nominal,
    face_ids,
    face_sets,
    max_distance,
    part_path,
    tolerance,
    section_lines,
    align,
    align_dof,
    datums,
    previous,
    gain,
    weights,
    power,
    threshold,
    neighbors,
    alpha,
    probe_radius,
    units,
    json_path,
    report_path,
):
    """Separate the systematic error of MEASUREMENTS and mirror it: corrected NC program, STEP/IGES
    surface and compensated points; with --nominal, the compensated CAD part."""
    from .. import cad, measure
    from .. import nc as ncmod
    from ..processes import freeform as pf
    from ..report import freeform as rep

    if (program is None) != (output is None):
        raise click.UsageError("--program and -o go together")
    from ..probing import companion_inputs

    check_outputs(
        {
            "measurements": measurements,
            "input program": program,
            "nominal": nominal,
            "datums": datums,
            "--previous": previous,
            **companion_inputs(measurements),
        },
        {
            "-o": output,
            "--surface": surface_path,
            "--part": part_path,
            "--points-out": points_out,
            "--json": json_path,
            "--report": report_path,
        },
    )
    if nominal is None:
        for name, given in (("--face", face_ids), ("--face-set", face_sets), ("--part", part_path)):
            if given:
                raise click.UsageError(f"{name} needs --nominal")
    else:
        for name, given in (("--extent", extent), ("--extrapolate-nominal", extrapolate_nominal)):
            if given:
                raise click.UsageError(
                    f"{name} is for a nominal rebuilt from the measured points; with --nominal the CAD faces "
                    "are compensated over their whole extent"
                )
        if part_path is not None and cad.FORMATS.get(part_path.suffix.lower()) != "step":
            raise click.UsageError(f"--part {part_path}: the part is written as STEP (.step or .stp)")
        for axis, at in section_lines:
            if axis not in ("x", "y", "z"):
                raise click.UsageError(
                    f"--section {axis}={at:g}: with --nominal a section is the plane x=…, y=… or z=… of the CAD "
                    "frame (mm)"
                )
    if section_lines and report_path is None:
        raise click.UsageError("--section draws in the report: give --report")
    _check_align(nominal, align, align_dof, datums)
    if gain is not None and previous is None:
        raise click.UsageError("--gain needs --previous")
    prev = _read_previous(previous)
    if program is not None and tool_radius is None:
        raise click.UsageError(
            "--program needs --tool-radius: the ball-end radius of its tool in mm (0 when the "
            "programmed point is the contact point); the correction is evaluated at the tool's tip"
        )
    kw = _moran_kw(weights, power, threshold, neighbors, alpha)
    if nominal is not None:
        return _compensate_cad(
            measurements,
            nominal,
            list(face_ids) or None,
            [list(ids) for ids in face_sets] or None,
            max_distance,
            dict(method=method, sigma_c=sigma_c, sigma_s=sigma_s, p=p, auto=auto, border=border),
            kw,
            probe_radius=probe_radius,
            units=units,
            align=dict(align=align, align_dof=align_dof, datums=datums),
            rounds=(previous, prev, 1.0 if gain is None else gain),
            program=program,
            output=output,
            tool_radius=tool_radius,
            limit=limit,
            outside=outside,
            surface_path=surface_path,
            part_path=part_path,
            points_out=points_out,
            json_path=json_path,
            report_path=report_path,
            tolerance=tolerance,
            section_lines=section_lines,
        )
    with progress() as say:
        say(f"reading {measurements}")
        meas = measure.read(measurements, probe_radius=probe_radius, units=units)
        frame = pf.frame_of(meas)
        if prev is not None:
            from ..processes import rounds

            rounds.check_frame(prev, frame.axes, str(previous))
        a = pf.analyze(meas, frame=frame, progress=_said(say, "Moran's I"), **kw)
        say("separating systematic and random error")
        d = pf.decompose(meas, method, sigma_c=sigma_c, sigma_s=sigma_s, p=p, auto=auto, frame=frame, **kw)
        surf = pf.fit_height_surface(meas.nominal, extent=extent, frame=frame)
        ext = pf.nominal_extrapolation(surf, meas.nominal, frame)
        if ext.max_distance > 0 and not extrapolate_nominal:
            raise InputError(
                f"the compensated surface would reach {ext.max_distance:.3g} mm beyond the measured points "
                f"({ext.area_fraction:.0%} of its grid, {'the --extent' if extent else 'the corners of the scatter'}): "
                "there its nominal would be extrapolated from them, not measured; give --extrapolate-nominal to "
                "accept that, or an --extent within the measured area",
                str(measurements),
            )
        base, g = None, 1.0
        if prev is not None:
            base = prev.grids[0].at
            g = (1.0 if gain is None else gain) * rounds.damping(
                method, frame.uv(meas.nominal), d.systematic, d.parameters
            )
        c = pf.compensate(surf, meas, d.systematic, frame=frame, border=border, base=base, gain=g)
        secs = [rep.section(c, frame.uv(meas.nominal), a, at, frame.names) for a, at in section_lines]
        corr = None
        if program is not None:
            say(f"correcting {program}")
            corr = ncmod.read(program).correct_to(
                output, c.field(tool_radius or 0.0, outside), limit=limit, progress=say
            )
        if surface_path is not None:
            say(f"writing {surface_path}")
            cad.write(c.compensated, surface_path)
    _print_analysis(a)
    sysd = d.as_dict()
    _print_decomposition(a, d)
    if corr is not None:
        summary(
            f"{program} -> {output}: {corr.blocks_changed:,} blocks changed, {corr.lines_added:,} lines added, "
            f"max displacement {corr.max_displacement:.4f} mm"
        )
    if points_out is not None:
        _write_points(points_out, meas, d, c.points_compensated)
    payload = {"input": str(measurements), **a.as_dict(), **sysd}
    if tolerance is not None:
        payload["tolerance"] = _tolerance_of(meas.deviation, meas.deviation - c.gain * d.systematic, tolerance)
        _tolerance_said(payload["tolerance"], tolerance)
    if ext.max_distance > 0:
        payload["extrapolation"] = ext.as_dict()
        echo_err(
            f"warning: the nominal is extrapolated up to {ext.max_distance:.3g} mm beyond the measured points "
            f"over {ext.area_fraction:.0%} of the surface (--extrapolate-nominal)"
        )
    if corr is not None:
        payload["program"] = {"input": str(program), "output": str(output), **corr.as_dict()}
    payload["correction"] = _correction_of(c, frame, prev, previous)
    if json_path:
        write_json(json_path, payload)
    if report_path:
        from ..report import write

        write(
            report_path,
            rep.render(
                title=f"Freeform compensation: {measurements.name}",
                analysis=a,
                decomposition=d,
                xy=frame.uv(meas.nominal),
                names=frame.names,
                deviation=meas.deviation,
                files={
                    k: str(v) for k, v in (("program", output), ("surface", surface_path), ("points", points_out)) if v
                },
                extrapolation=ext if ext.max_distance > 0 else None,
                compensation=c,
                points=meas.nominal,
                tolerance=tolerance,
                sections=secs,
            ),
        )


def _tolerance_of(before, predicted, tolerance) -> dict:
    """The ``tolerance`` JSON object: the shares of the points inside ±T before and predicted after."""
    from ..report import freeform as rep

    return {
        "value": tolerance,
        "before": rep.tolerance_shares(before, tolerance),
        "predicted": rep.tolerance_shares(predicted, tolerance),
    }


def _tolerance_said(tol, tolerance) -> None:
    summary(
        f"tolerance ±{tolerance:g} mm: {100 * tol['before']['inside']:.1f} % of the points inside before, "
        f"{100 * tol['predicted']['inside']:.1f} % predicted after (measured − systematic)"
    )


def _print_decomposition(a, d) -> None:
    sysd = d.as_dict()
    summary(
        f"systematic part: rms {sysd['systematic']['rms']:.4f} mm, max |.| {sysd['systematic']['max_abs']:.4f} mm "
        f"({d.method}); random part: std {d.noise.std:.4f} mm"
    )
    if not a.systematic:
        echo_err("warning: the deviations are not significantly systematic; compensating them mostly moves noise")
    if d.auto is not None and not d.auto["passed"]:
        setting = d.auto["setting"]
        said = ", ".join(f"{k} {v:g}" for k, v in setting.items()) if isinstance(setting, dict) else "by face"
        summary(
            f"warning: --auto found no {d.method} setting whose random part is free of systematic error; "
            f"the default setting ({said}) is used"
        )
    elif not d.noise.passed:
        summary(
            f"warning: the random part still holds systematic error (Moran z {d.noise.moran_z:.2f}, lag-1 "
            f"r {d.noise.lag1_r:.2f}); smooth less, or try --auto"
        )


def _write_points(path, meas, d, compensated, faces=None) -> None:
    from .._io import atomic_write

    rows = ["x,y,z,deviation,systematic,random,cx,cy,cz" + (",face" if faces is not None else "")]
    for k, (q, e, s, r, cp) in enumerate(zip(meas.nominal, meas.deviation, d.systematic, d.random, compensated)):
        rows.append(",".join(f"{v:.6f}" for v in (*q, e, s, r, *cp)) + (f",{faces[k]}" if faces is not None else ""))
    atomic_write(path, ("\n".join(rows) + "\n").encode())


def _compensate_cad(
    measurements,
    nominal,
    face_ids,
    face_sets,
    max_distance,
    options,
    kw,
    *,
    probe_radius,
    units,
    align,
    rounds,
    program,
    output,
    tool_radius,
    limit,
    outside,
    surface_path,
    part_path,
    points_out,
    json_path,
    report_path,
    tolerance=None,
    section_lines=(),
):
    """``compensate --nominal``: each measured face compensated in its own (u, v), or in its face
    set's, and put in the part."""
    from .. import cad, measure
    from .. import nc as ncmod
    from ..processes import freeform as pf
    from ..report import cad_sections

    with progress() as say:
        say(f"reading {measurements} and projecting onto {nominal}")
        proj = measure.project_on_cad(
            measurements,
            nominal,
            faces=face_ids,
            max_distance=max_distance,
            probe_radius=probe_radius,
            units=units,
            face_sets=face_sets,
            **align,
        )
        meas = proj.measurements
        previous, prev, gain = rounds
        if prev is not None:
            from ..processes import rounds as rmod

            rmod.check_nominal(prev, nominal, {int(f) for f in proj.face}, str(previous))
        a = pf.analyze(meas, coords=meas.nominal, progress=_said(say, "Moran's I"), **kw)
        say("separating systematic and random error on each face, rebuilding the part")
        pc = pf.compensate_cad(
            proj, **options, **kw, previous=None if prev is None else {g.face: g.at for g in prev.grids}, gain=gain
        )
        d = pf.part_decomposition(pc, meas, **kw)
        secs = [cad_sections.cad_section(pc, meas.nominal, axis, at) for axis, at in section_lines]
        corr = None
        if program is not None:
            say(f"correcting {program}")
            corr = ncmod.read(program).correct_to(
                output, pc.field(tool_radius or 0.0, outside), limit=limit, progress=say
            )
        if surface_path is not None:
            say(f"writing {surface_path}")
            cad.write_shape(pc.surfaces(), surface_path)
        if part_path is not None:
            say(f"writing {part_path}")
            # the faces keep the names the STEP file gave them
            cad.write_shape(pc.part, part_path, [(pc.placed[i], proj.name_of(i)) for i in sorted(pc.placed)])
    _print_alignment(meas.alignment)
    _print_file_nominals(proj.file_nominals, measurements)
    _print_analysis(a)
    _print_decomposition(a, d)
    for f in pc.faces:
        fd = f.as_dict()
        summary(
            f"{_face_said(f.face, proj.name_of(f.face))}: {fd['n_points']:,} points, systematic rms {fd['systematic']['rms']:.4f} mm, random std "
            f"{fd['random']['std']:.4f} mm; measured hull {fd['cover']:.0%} of the face, the rest ({_border_said(f)}) "
            f"up to {fd['border']['max_abs_df']:.4f} mm" + ("" if f.face_set is None else " (in its face set's (u, v))")
        )
    _face_sets_said(pc.sets, proj)
    summary(
        f"part: {pc.summary['faces']} faces, {len(pc.faces)} compensated, valid (BRepCheck); the compensated faces lie "
        f"-dF from the nominal within {pc.check_error * 1000:.3f} µm at {pc.check_points} points; widest edge gap "
        f"{pc.max_tolerance:.4f} mm"
    )
    if corr is not None:
        summary(
            f"{program} -> {output}: {corr.blocks_changed:,} blocks changed, {corr.lines_added:,} lines added, "
            f"max displacement {corr.max_displacement:.4f} mm"
        )
    if points_out is not None:
        at = d.systematic.copy()
        if prev is not None:  # the whole correction at the points: previous + gain × systematic
            for f in pc.faces:
                at[f.points] = f.df(proj.uv[f.points, 0], proj.uv[f.points, 1])
        _write_points(points_out, meas, d, meas.nominal - at[:, None] * meas.normal, proj.face)
    payload = {
        "input": str(measurements),
        "nominal": str(nominal),
        "alignment": meas.alignment.as_dict(),
        **a.as_dict(),
        **d.as_dict(),
        # the faces used: their ids, and their names from the STEP file (None where unnamed)
        "faces": list(pc.ids),
        "face_names": [proj.name_of(i) for i in pc.ids],
        "by_face": [
            {"face": f.face, "name": proj.name_of(f.face)} | f.as_dict() | ({"face_set": f.face_set} if pc.sets else {})
            for f in pc.faces
        ],
        "face_sets": _face_sets_json(pc.sets, proj),
        "part": {"output": str(part_path) if part_path else None, **pc.as_dict()},
        "correction": _cad_correction_of(pc, nominal, prev, previous),
    }
    if proj.file_nominals is not None:
        payload["file_nominals"] = proj.file_nominals
    predicted = meas.deviation - pf.part_moved(pc, len(meas))
    if tolerance is not None:
        payload["tolerance"] = _tolerance_of(meas.deviation, predicted, tolerance)
        for f, fd in zip(pc.faces, payload["by_face"]):
            fd["tolerance"] = _tolerance_of(meas.deviation[f.points], predicted[f.points], tolerance)
            summary(
                f"face {f.face}: tolerance ±{tolerance:g} mm: {100 * fd['tolerance']['before']['inside']:.1f} % of its "
                f"points inside before, {100 * fd['tolerance']['predicted']['inside']:.1f} % predicted after"
            )
        _tolerance_said(payload["tolerance"], tolerance)
    if corr is not None:
        payload["program"] = {"input": str(program), "output": str(output), **corr.as_dict()}
    if json_path:
        write_json(json_path, payload)
    if report_path:
        from ..report import cad_maps as rep_cad
        from ..report import freeform as rep
        from ..report import write

        write(
            report_path,
            rep.render(
                title=f"Freeform compensation: {measurements.name} on {nominal.name}",
                analysis=a,
                decomposition=d,
                xy=pf.face_layout(pc, len(meas)),
                names=("u (mm along the face)", "v (mm along the face)"),
                deviation=meas.deviation,
                files={
                    k: str(v)
                    for k, v in (
                        ("program", output),
                        ("surface", surface_path),
                        ("part", part_path),
                        ("points", points_out),
                    )
                    if v
                },
                tolerance=tolerance,
                sections=secs,
                faces=[(f.face, f.points) for f in pc.faces],
                predicted=predicted,
                cad=rep_cad.CadReport(pc, proj.face, proj.uv, meas.nominal, {i: proj.name_of(i) for i in pc.ids}),
            ),
        )


def _read_previous(previous):
    """The correction of ``--previous`` (None without it)."""
    if previous is None:
        return None
    from ..processes import rounds

    return rounds.read(previous)


def _round_said(prev, previous, gains) -> None:
    if prev is None:
        return
    said = ", ".join(f"face {k} {g:.3f}" if k else f"{g:.3f}" for k, g in gains.items())
    summary(
        f"round {prev.round + 1} (--previous {previous}): correction = previous + effective gain × the systematic "
        f"part measured now; effective gain (--gain × damping) {said}"
    )


def _correction_of(c, frame, prev, previous) -> dict:
    """The ``correction`` JSON object of a nominal from the measured points (and the round's line)."""
    from ..processes import rounds

    gains = {0: c.gain}
    _round_said(prev, previous, gains)
    s = c.surface
    r = rounds.Correction(
        "frame",
        (rounds.Grid(s.u, s.v, c.df_grid),),
        1 if prev is None else prev.round + 1,
        frame=frame.axes,
        gains=gains,
    )
    return r.as_dict() | ({"previous": str(previous)} if prev is not None else {})


def _cad_correction_of(pc, nominal, prev, previous) -> dict:
    """The ``correction`` JSON object of a CAD nominal (and the round's line)."""
    from ..processes import rounds

    gains = {f.face: f.gain for f in pc.faces}
    _round_said(prev, previous, gains)
    r = rounds.Correction(
        "faces",
        tuple(rounds.Grid(f.u, f.v, f.df_grid, f.face) for f in pc.faces),
        1 if prev is None else prev.round + 1,
        nominal={"path": str(nominal), "sha256": rounds.file_digest(nominal)},
        gains=gains,
    )
    return r.as_dict() | ({"previous": str(previous)} if prev is not None else {})


def _face_said(face_id: int, name: str | None) -> str:
    """``face 3`` or ``face 3 'top'`` (with the CAD file's name)."""
    return f"face {face_id}" + (f" {name!r}" if name is not None else "")


def _border_said(f) -> str:
    return "dF held at the nearest measured value" if f.border == "hold" else "dF extrapolated by cubics"
