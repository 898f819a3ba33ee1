"""The main job on shipped data: a freeform part as a CAD model, its ball-end finishing program,
simulated measurements of actual points → projection onto the CAD faces → analysis → decomposition
→ the compensated part (STEP) and the corrected program → re-machining.

The part (:func:`ncadapt.sim.freeform.demo_part`) ships as a STEP solid (``data/demo_part.step``,
made by :func:`nominal_shape`: the part's B-spline surface on top of a block down to z = 0) and its
program (``data/freeform_finish.ngc``, made by :func:`ncadapt.sim.freeform.finishing_program` with
the constants below). The machine's systematic error is a curvature term (A_m = 0.10 mm) plus a
second-degree polynomial in the normalised (u, v) (the freeform paper's models (4) and (7)); the
measurement adds 5 µm normal noise along the normal. Seeded: the same seed gives the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

TOOL_RADIUS = 4.0  # mm, ball end
STEPOVER = 0.25  # mm
STEP = 0.5  # mm along a raster line
NOISE = 0.005  # mm, measurement noise std
CURVATURE_AMPLITUDE = 0.10  # mm, A_m
POLYNOMIAL = {(1, 0): 0.02, (0, 2): -0.015, (1, 1): 0.01}  # mm, coefficients of u_n^i v_n^j
PROBE_BORDER = 5.0  # mm of unmeasured border strip
PROBE_SPACING = 2.5  # mm
# the report's profile tolerance (±20 µm: a fine-milled freeform surface) and its sections
TOLERANCE = 0.02  # mm
SECTIONS = (("x", 40.0), ("y", 30.0))  # the part's middle lines, through its bump


BOTTOM = 0.0  # mm, the z of the block's flat bottom under the part's surface


@dataclass
class DemoResult:
    """What :func:`run` made: ``summary`` (the figures of ``summary.json``) and ``files`` {what: file
    name in the output folder}."""

    summary: dict
    files: dict


def program_text() -> str:
    """The shipped finishing program (G-code text)."""
    return (resources.files("ncadapt") / "data" / "freeform_finish.ngc").read_text()


def nominal_path() -> Path:
    """The shipped CAD model of the demo part (STEP), made by :func:`nominal_shape`."""
    return Path(str(resources.files("ncadapt") / "data" / "demo_part.step"))


def nominal_shape():
    """The demo part as an OpenCASCADE solid: :func:`ncadapt.sim.freeform.demo_part`'s surface on a
    block down to z = :data:`BOTTOM` (:func:`ncadapt.cad.block`); its top face's (u, v) are (x, y)."""
    from . import cad
    from .sim import freeform as ff

    return cad.block(ff.demo_part(), BOTTOM)


def _plane_view(face, meas):
    """The compensated top face as a :class:`~ncadapt.processes.freeform.Compensation` over (x, y)
    for the report's correction map and sections: the face's (u, v) must be its points' (x, y)."""
    from .processes import freeform as pf
    from .surfaces import Frame, Surface

    U, V = np.meshgrid(face.u, face.v, indexing="ij")
    p = np.asarray(face.compensated.grid) + face.df_grid[..., None] * face.normal
    if not np.allclose(p[..., 0], U, atol=1e-6) or not np.allclose(p[..., 1], V, atol=1e-6):
        raise ValueError("the demo part's top face is not parametrised by (x, y)")
    nominal = Surface(face.u, face.v, p)
    pc = meas.nominal - face.decomposition.systematic[:, None] * meas.normal
    return pf.Compensation(
        nominal, face.df_grid, face.measured_region, face.compensated, pc, Frame(np.eye(3)), face.gain
    )


def run(out: Path, seed: int = 1, method: str = "bilateral", say=lambda msg: None) -> DemoResult:
    """Run the demo into the folder ``out`` (created): machine, measure, compensate against the CAD
    model, correct the program, machine again; write the files of :attr:`DemoResult.files`."""
    import json

    from . import freeform, nc
    from ._io import atomic_write
    from .report import freeform as rep
    from .report import write as write_report
    from .sim import freeform as ff

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    part = ff.demo_part()
    error = ff.ErrorModel(part, (("curvature", CURVATURE_AMPLITUDE), ("polynomial", POLYNOMIAL)))
    prog_path = out / "part.ngc"
    atomic_write(prog_path, program_text().encode())
    step_path = out / "part.step"
    atomic_write(step_path, nominal_path().read_bytes())
    prog = nc.read(prog_path)
    say("machining the first part (virtual)")
    first = ff.machine(prog, part, error, TOOL_RADIUS)
    nominal, normal = ff.probe_points(part, PROBE_BORDER, PROBE_SPACING)
    measured = ff.measure(first, nominal, normal, noise=NOISE, seed=seed)
    rows = ["id,x,y,z,i,j,k,mx,my,mz"] + [
        f"P{k + 1}," + ",".join(f"{v:.6f}" for v in (*p, *n, *m))
        for k, (p, n, m) in enumerate(zip(nominal, normal, measured))
    ]
    atomic_write(out / "measurements.csv", ("\n".join(rows) + "\n").encode())
    # what a CMM reports against a CAD model: the actual points only
    rows = ["id,x,y,z"] + [f"P{k + 1}," + ",".join(f"{v:.6f}" for v in m) for k, m in enumerate(measured)]
    actual_path = out / "actual.csv"
    atomic_write(actual_path, ("\n".join(rows) + "\n").encode())
    say(f"projecting the actual points onto {step_path.name}, compensating its top face, correcting the program")
    corrected_path = out / "corrected.ngc"
    # the program runs along the part's edge: tool centres up to a tool radius beyond the face's
    # tips take the edge value
    res = freeform.run(
        actual_path,
        nominal=step_path,
        program=prog_path,
        output=corrected_path,
        tool_radius=TOOL_RADIUS,
        outside="clamp",
        method=method,
        part=out / "compensated.step",
    )
    meas, analysis, decomposition, pc = res.measurements, res.analysis, res.decomposition, res.compensation
    (face,) = pc.faces
    comp = _plane_view(face, meas)
    say("machining the second part with the corrected program (virtual)")
    second = ff.machine(nc.read(corrected_path), part, error, TOOL_RADIUS)
    # the systematic error itself: the same points measured without noise
    before = np.einsum("ij,ij->i", ff.measure(first, nominal, normal) - nominal, normal)
    after = np.einsum("ij,ij->i", ff.measure(second, nominal, normal) - nominal, normal)
    after_measured = np.einsum(
        "ij,ij->i", ff.measure(second, nominal, normal, noise=NOISE, seed=seed + 1) - nominal, normal
    )
    rms = lambda v: float(np.sqrt(np.mean(v * v)))  # noqa: E731
    summary = {
        "seed": seed,
        "n_points": len(meas),
        "systematic_rms_before": rms(before),
        "systematic_rms_after": rms(after),
        "ratio": rms(after) / rms(before),
        "systematic_max_abs_before": float(np.abs(before).max()),
        "systematic_max_abs_after": float(np.abs(after).max()),
        "measured_rms_before": rms(meas.deviation),
        "measured_rms_after": rms(after_measured),
        "moran": analysis.moran.as_dict(),
        "offset": analysis.offset.as_dict(),
        "verdict": analysis.verdict.as_dict(),
        "filter": decomposition.as_dict(),
        "faces": pc.ids,
        "part": pc.as_dict(),
        "program": res.program.as_dict(),
        "model": {
            "tool_radius": TOOL_RADIUS,
            "stepover": STEPOVER,
            "noise": NOISE,
            "curvature_amplitude": CURVATURE_AMPLITUDE,
            "polynomial": {f"u^{i} v^{j}": c for (i, j), c in POLYNOMIAL.items()},
        },
    }
    files = {
        "program": "part.ngc",
        "nominal part": "part.step",
        "measurements": "measurements.csv",
        "actual points": "actual.csv",
        "corrected program": "corrected.ngc",
        "compensated part": "compensated.step",
        "report": "report.html",
        "summary": "summary.json",
    }
    cards = {
        "systematic RMS before": f"{summary['systematic_rms_before'] * 1000:.1f} µm",
        "after one compensation": f"{summary['systematic_rms_after'] * 1000:.1f} µm",
        "remaining": f"{100 * summary['ratio']:.0f} %",
    }
    write_report(
        out / "report.html",
        rep.render(
            title="Freeform compensation: demo part",
            analysis=analysis,
            decomposition=decomposition,
            xy=meas.nominal[:, :2],
            deviation=meas.deviation,
            after=after_measured,
            summary=cards,
            files=files,
            compensation=comp,
            points=meas.nominal,
            tolerance=TOLERANCE,
            sections=[rep.section(comp, meas.nominal[:, :2], a, at) for a, at in SECTIONS],
        ),
    )
    atomic_write(out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode())
    return DemoResult(summary, files)
