"""The main job on shipped data: a freeform part, its ball-end finishing program, simulated
measurements → analysis → decomposition → compensation → corrected program → re-machining.

The part (:func:`ncadapt.sim.freeform.demo_part`) and its program (``data/freeform_finish.ngc``,
made by :func:`ncadapt.sim.freeform.finishing_program` with the constants below) ship with the
package. The machine's systematic error is a curvature term (A_m = 0.10 mm) plus a second-degree
polynomial in the normalised (u, v) (the freeform paper's models (4) and (7)); the measurement adds
5 µm normal noise along the normal. Seeded: the same seed gives the same numbers.
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


@dataclass
class DemoResult:
    summary: dict
    files: dict


def program_text() -> str:
    return (resources.files("ncadapt") / "data" / "freeform_finish.ngc").read_text()


def run(out: Path, seed: int = 1, method: str = "bilateral", say=lambda msg: None) -> DemoResult:
    from . import cad, measure, nc
    from ._io import atomic_write
    from .processes import freeform as pf
    from .report import freeform as rep
    from .report import write as write_report
    from .sim import freeform as ff

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    part = ff.demo_part()
    error = ff.ErrorModel(part, (("curvature", CURVATURE_AMPLITUDE), ("polynomial", POLYNOMIAL)))
    prog_path = out / "part.ngc"
    atomic_write(prog_path, program_text().encode())
    prog = nc.read(prog_path)
    say("machining the first part (virtual)")
    first = ff.machine(prog, part, error, TOOL_RADIUS)
    nominal, normal = ff.probe_points(part, PROBE_BORDER, PROBE_SPACING)
    measured = ff.measure(first, nominal, normal, noise=NOISE, seed=seed)
    rows = ["id,x,y,z,i,j,k,mx,my,mz"] + [
        f"P{k + 1}," + ",".join(f"{v:.6f}" for v in (*p, *n, *m))
        for k, (p, n, m) in enumerate(zip(nominal, normal, measured))
    ]
    meas_path = out / "measurements.csv"
    atomic_write(meas_path, ("\n".join(rows) + "\n").encode())
    meas = measure.read(meas_path)
    say("analysing")
    analysis = pf.analyze(meas)
    decomposition = pf.decompose(meas, method)
    comp = pf.compensate(part, meas, decomposition.systematic)
    say("correcting the program")
    corrected_path = out / "corrected.ngc"
    # the surface is the whole part: tool centres along its edge, up to a tool radius beyond the
    # tips' hull, take the edge value
    corr = prog.correct_to(corrected_path, comp.field(TOOL_RADIUS, "clamp"), progress=say)
    step_path = out / "compensated.step"
    cad.write(comp.compensated, step_path)
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
        "program": corr.as_dict(),
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
        "measurements": "measurements.csv",
        "corrected program": "corrected.ngc",
        "compensated surface": "compensated.step",
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
            xy=nominal[:, :2],
            deviation=meas.deviation,
            after=after_measured,
            summary=cards,
            files=files,
            compensation=comp,
            points=nominal,
            tolerance=TOLERANCE,
            sections=[rep.section(comp, nominal[:, :2], a, at) for a, at in SECTIONS],
        ),
    )
    import json

    atomic_write(out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode())
    return DemoResult(summary, files)
