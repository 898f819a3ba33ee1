"""Property-based fuzzing of the ``ncadapt`` command's contract (hypothesis, in process).

Every command that reads a file is run on byte-mutated versions of its example inputs (bytes
flipped, inserted or deleted; numbers replaced by NaN, inf, 1e308, huge integers, ...; CR-only
line ends; long tokens; truncation; duplicated, deleted or swapped lines), and every numeric
option is given extreme values (nan, ±inf, 0, −1, 1e-300, 1e300, ...). Whatever the input, the
command must keep its contract:

- the exit code is 0, 1 (refused by a safety check) or 2 (bad input or usage) — 3 is an internal
  error, a bug — and no exception escapes the command;
- no Python traceback is printed;
- the input files are left byte for byte as they were, and no temporary file (``.ncadapt-tmp-*``)
  is left in the folder;
- when the exit code is not 0, no output was created, changed or removed (outputs are sometimes
  made to exist beforehand, to see that a failure leaves them as they were).

Budget: ``NCADAPT_CLI_FUZZ_EXAMPLES`` examples per target (default 100, about 3,500 cases in
``make test``; ``make fuzz`` runs 300, about 10,500; a few slow targets get a fixed share of it,
see ``scale``). The runs are derandomized, so the default run is reproducible.
``NCADAPT_CLI_FUZZ_TIMEOUT`` (seconds, default 30) fails a single call that hangs (a third of it,
once a target has hung, so that shrinking a hang does not take many times that long).
``NCADAPT_CLI_FUZZ_COLLECT=FILE`` is a tool for triage: failures are appended to FILE as JSON
lines instead of failing the test, so that one run lists every distinct failure.

Left out: ``demo`` and ``waffle simulate`` (about a second a call or more and no input file; their
only numeric option is --seed, an IntRange), ``skin serve`` and ``skin loop --opcua`` (network),
and option values that make a legitimate run arbitrarily long (``bore simulate --parts 1e9``).
"""

from __future__ import annotations

import base64
import contextlib
import functools
import json
import math
import os
import re
import shutil
import signal
import stat
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, Phase, given, note, settings
from hypothesis import strategies as st

from ncadapt.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
BUDGET = int(os.environ.get("NCADAPT_CLI_FUZZ_EXAMPLES", "100"))
TIMEOUT = float(os.environ.get("NCADAPT_CLI_FUZZ_TIMEOUT", "30"))
COLLECT = os.environ.get("NCADAPT_CLI_FUZZ_COLLECT")
TMP_PREFIX = ".ncadapt-tmp-"
TRACEBACK = "Traceback (most recent call last)"
PREVIOUS = b"previous contents of an output\n"


# ------------------------------------------------------------------------------------ seeds
def _example(sub: str, name: str, head: int | None = None) -> bytes:
    data = (EXAMPLES / sub / name).read_bytes()
    if head is not None:  # a shorter copy of a long input keeps each call fast
        data = b"".join(data.splitlines(keepends=True)[:head])
    return data


def _measurements() -> dict[str, bytes]:
    """Measured points on a 9 x 5 grid of a plane z = 0 (normal +z) with a smooth deviation, in
    the four formats `analyze` reads."""
    pts = []
    for y in range(0, 41, 10):
        for x in range(-10, 71, 10):
            k = len(pts) + 1
            pts.append((k, x, y, 0.01 + 0.0004 * x - 0.0003 * y + 0.002 * math.sin(1.7 * k)))
    csv = "id,x,y,z,i,j,k,dev\n" + "".join(f"P{k},{x},{y},0,0,0,1,{d:.5f}\n" for k, x, y, d in pts)
    csv_m = "x,y,z,i,j,k,mx,my,mz\n" + "".join(f"{x},{y},0,0,0,1,{x},{y},{d:.5f}\n" for k, x, y, d in pts[:20])
    xyz = "PC-DMIS XYZIJK export\n" + "".join(f"{x} {y} 0 0 0 1 {d:.5f}\n" for k, x, y, d in pts[:20])
    dmis = (
        "DMISMN/'report',05.0\n"
        + "".join(
            f"F(PT{k})=FEAT/POINT,CART,$\n  {x},{y},0,0,0,1\nFA(PT{k})=FEAT/POINT,CART,{x},{y},{d:.5f},0,0,1\n"
            for k, x, y, d in pts[:12]
        )
        + "ENDFIL\n"
    )
    nominals = "".join(
        f'<PointFeatureNominal id="{100 + k}"><Location>{x} {y} 0</Location>'
        f"<Normal>0 0 1</Normal></PointFeatureNominal>\n"
        for k, x, y, d in pts[:12]
    )
    items = "".join(
        f'<PointFeatureItem id="{200 + k}"><FeatureNominalId>{100 + k}</FeatureNominalId></PointFeatureItem>\n'
        for k, x, y, d in pts[:12]
    )
    meas = "".join(
        f'<PointFeatureMeasurement id="{300 + k}"><FeatureItemId>{200 + k}</FeatureItemId>'
        f"<Location>{x} {y} {d:.5f}</Location></PointFeatureMeasurement>\n"
        for k, x, y, d in pts[:12]
    )
    qif = (
        '<?xml version="1.0"?>\n<QIFDocument xmlns="http://qifstandards.org/xsd/qif3">\n'
        f"<Features><FeatureNominals>\n{nominals}</FeatureNominals><FeatureItems>\n{items}</FeatureItems>\n"
        f"</Features><MeasurementsResults><FeatureMeasurements>\n{meas}</FeatureMeasurements>"
        "</MeasurementsResults></QIFDocument>\n"
    )
    return {
        "meas.csv": csv.encode(),
        "meas_m.csv": csv_m.encode(),
        "meas.txt": xyz.encode(),
        "meas.dmo": dmis.encode(),
        "meas.qif": qif.encode(),
    }


def _probe() -> bytes:
    """A pre-finished Ø40 bore probed in three planes (8 points each), as `bore` reads it."""
    rows = ["plane,x,y,z"]
    for label, d, z in zip("AMB", (39.748, 39.758, 39.768), (55, 30, 5)):
        rows += [
            f"{label},{d / 2 * math.cos(f):.7f},{d / 2 * math.sin(f):.7f},{z}"
            for f in (2 * math.pi * i / 8 for i in range(8))
        ]
    return ("\n".join(rows) + "\n").encode()


def _height_maps() -> dict[str, bytes]:
    """The plate's probe map (examples/nc/plate_probe.csv) as an OpenCNCPilot .hmap, a Candle .map,
    a grbl console log (status reports with WCO, a fast and a slow touch per point) and a Fanuc
    DPRNT log."""
    rows = [r.split(",") for r in _example("nc", "plate_probe.csv").decode().split()[1:]]
    pts = {(float(x), float(y)): float(dz) for x, y, dz in rows}
    xs, ys = sorted({x for x, _ in pts}), sorted({y for _, y in pts})
    hmap = (
        f'<?xml version="1.0" encoding="utf-8"?>\n<heightmap MinX="{xs[0]}" MinY="{ys[0]}" MaxX="{xs[-1]}" '
        f'MaxY="{ys[-1]}" SizeX="{len(xs)}" SizeY="{len(ys)}">\n'
    )
    uniform = np.allclose(np.diff(xs), xs[1] - xs[0]) and np.allclose(np.diff(ys), ys[1] - ys[0])
    gx = np.linspace(xs[0], xs[-1], len(xs)) if not uniform else xs
    gy = np.linspace(ys[0], ys[-1], len(ys)) if not uniform else ys
    from ncadapt import fields as _f

    field = _f.read(EXAMPLES / "nc" / "plate_probe.csv")
    z = lambda x, y: float(field(np.array([[x, y, 0.0]]))[0, 2])  # noqa: E731
    hmap += "".join(
        f'  <point X="{i}" Y="{j}">{z(x, y):.4f}</point>\n' for i, x in enumerate(gx) for j, y in enumerate(gy)
    )
    hmap += "</heightmap>\n"
    candle = [f"{gx[0]};{gy[0]};{gx[-1] - gx[0]};{gy[-1] - gy[0]}", f"{len(gx)};{len(gy)};-1;1", "0;10;10"]
    candle += [";".join(f"{z(x, y):.4f}" for x in gx) for y in gy]
    log = ["<Idle|MPos:-100.000,-50.000,-15.000|FS:0,0|WCO:-100.000,-50.000,-20.000>"]
    for j, y in enumerate(gy):
        for x in gx if j % 2 == 0 else gx[::-1]:
            for dz in (-0.05, 0.0):
                log += [">>> G38.2 Z-2 F100", f"[PRB:{x - 100:.3f},{y - 50:.3f},{z(x, y) - 20 + dz:.3f}:1]", "ok"]
    fanuc = [f"X{x:10.4f} Y{y:10.4f} Z{z(x, y):10.4f}" for y in gy for x in gx]
    return {
        "plate.hmap": hmap.encode(),
        "plate.map": ("\r\n".join(candle) + "\r\n").encode(),
        "plate_grbl.log": ("\n".join(log) + "\n").encode(),
        "plate_fanuc.txt": ("\n".join(fanuc) + "\n").encode(),
    }


def _plate_step() -> bytes:
    """A STEP file of one planar face, z = 5 over [0, 50] x [0, 30], written by OpenCASCADE."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    face = BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0, 0, 5), gp_Dir(0, 0, 1)), 0.0, 50.0, 0.0, 30.0).Face()
    with tempfile.TemporaryDirectory() as d:
        w = STEPControl_Writer()
        w.Transfer(face, STEPControl_AsIs)
        w.Write(str(Path(d) / "f.step"))
        return (Path(d) / "f.step").read_bytes()


def _probe_log() -> bytes:
    """LinuxCNC's log of the plan's points: ball centres 1.5 mm above, with a smooth deviation."""
    from ncadapt import probing

    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "plan.csv").write_bytes(seed("plan.csv"))
        plan = probing.read_plan(Path(d) / "plan.csv")
    c = plan.nominal + (1.5 + 0.01 * np.sin(plan.nominal[:, 0] / 7))[:, None] * plan.normal
    return "".join(" ".join(f"{v:f}" for v in (*q, 0, 0, 0, 0, 0, 0)) + "\n" for q in c).encode()


def _shaft_coarse() -> bytes:
    """The shaft example planned every 5 mm instead of 1 (a fifth of the stations: faster)."""
    text = _example("turning", "shaft_d20_l430.toml")
    out = re.sub(rb"(?m)^step = 1\.0 ", b"step = 5.0 ", text)
    assert out != text
    return out


def _cli_output(args: list[str], name: str, inputs: dict[str, bytes]) -> bytes:
    """A file written by a valid ncadapt run (a bore plan, a lathe program), as a seed."""
    with tempfile.TemporaryDirectory() as d, contextlib.chdir(d):
        for n, data in inputs.items():
            Path(n).write_bytes(data)
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 0, r.output
        return Path(name).read_bytes()


SEEDS: dict[str, bytes] = {
    "plate.ngc": _example("nc", "plate.ngc"),
    "plate_probe.csv": _example("nc", "plate_probe.csv"),
    "pocket1_finish.ngc": _example("skin", "pocket1_finish.ngc"),
    "pocket1_thickness.csv": _example("skin", "pocket1_thickness.csv"),
    "cell_r1c1.ngc": _example("waffle", "cell_r1c1.ngc"),
    "tracking.csv": _example("waffle", "tracking.csv"),
    "thickness_r1c1.csv": _example("waffle", "thickness_r1c1.csv"),
    # the fit's cost grows with the signal: its first 150 samples
    "backlash_signals.csv": _example("waffle", "backlash_signals.csv", head=152),
    "shaft_d20_l430.toml": _example("turning", "shaft_d20_l430.toml"),
    "shaft.toml": _shaft_coarse(),
    "probe.csv": _probe(),
    # the same bore as a DMIS report of circle actuals (plane A first), one continued with $
    "probe.dmo": b"DMISMN/'bore',05.0\nF(CA)=FEAT/CIRCLE,INNER,CART,0,0,55,0,0,1,40.0\n"
    b"FA(CA)=FEAT/CIRCLE,INNER,CART,0,0.002,55,0,0,1,39.748\n"
    b"FA(CM)=FEAT/CIRCLE,INNER,CART,0,0,30,0,0,1,$\n39.758\n"
    b"FA(CB)=FEAT/CIRCLE,INNER,CART,0.01,0,5,0,0,1,39.768\nENDFIL\n",
    "gauge.csv": b't,thickness,note\n0.00,1.52,"a, b"\n0.05,,\n0.10,1.51,\n0.15,nan,\n0.20,1.495,x\n'
    b"0.25,1.503,\n0.30,1.498,\n0.35,1.501,\n",
    **_measurements(),
    **_height_maps(),
    "points.csv": b"x,y,z\n10,10,5\n20,10,5\n30,20,5\n",
}

# seeds written by the command itself, made on first use
_LAZY = {
    "plan.json": lambda: _cli_output(
        [
            "bore",
            "plan",
            "--diameter",
            "40",
            "--t0",
            "0.5",
            "--allowance",
            "0.1",
            "--delta-a",
            "0.03",
            "--delta-b",
            "0.02",
            "--json",
            "plan.json",
        ],
        "plan.json",
        {},
    ),
    "plate.step": _plate_step,
    "plan.csv": lambda: _cli_output(
        [
            "probe",
            "points",
            "--nominal",
            "plate.step",
            "--n",
            "12",
            "--stylus-radius",
            "1.5",
            "--approach",
            "3",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "-o",
            "i.ngc",
            "--plan",
            "plan.csv",
        ],
        "plan.csv",
        {"plate.step": seed("plate.step")},
    ),
    "probe-log.txt": _probe_log,
    "lathe.ngc": lambda: _cli_output(
        ["turning", "plan", "shaft.toml", "--mode", "path", "-o", "lathe.ngc"],
        "lathe.ngc",
        {"shaft.toml": SEEDS["shaft.toml"]},
    ),
}


@functools.cache
def seed(name: str) -> bytes:
    return SEEDS[name] if name in SEEDS else _LAZY[name]()


# ------------------------------------------------------------------------------------ targets
@dataclass(frozen=True)
class Target:
    """A command line (file names relative to a fresh folder holding ``inputs``) and its outputs.

    ``victim``: the input that is mutated (its content drawn from ``seeds``, by default its own
    seed); ``options``: the options given extreme values, ``(option, kind)``; ``extras``:
    alternative additional arguments, one drawn per example; ``scale``: share of the budget;
    ``updates``: inputs that a successful run may replace (a failed one leaves them as they were)."""

    id: str
    args: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...] = ()
    victim: str | None = None
    seeds: tuple[str, ...] = ()
    options: tuple[tuple[str, str], ...] = ()
    extras: tuple[tuple[str, ...], ...] = ((),)
    scale: float = 1.0
    updates: tuple[str, ...] = ()  # inputs a successful run replaces (the bore plan `bore next` appends to)

    @property
    def budget(self) -> int:
        return max(1, round(BUDGET * self.scale))


_CORRECT_EXTRAS = (
    (),
    ("--outside", "clamp"),
    ("--outside", "extrapolate"),
    ("--interp", "cubic"),
    ("--rapids",),
    ("--keep-unsupported",),
    ("--clearance", "1"),
    ("--max-segment", "0.5", "--chord-tol", "0.01"),
)
_BORE_PLAN = ("bore", "plan", "--diameter", "40", "--t0", "0.5", "--allowance", "0.1")
_SKIN_CORRECT = (
    "skin",
    "correct",
    "pocket1_finish.ngc",
    "--thickness",
    "pocket1_thickness.csv",
    "--target",
    "1.5",
    "--allowance",
    "0.2",
    "-o",
    "o.ngc",
    "--json",
    "o.json",
)
_SKIN_IN = ("pocket1_finish.ngc", "pocket1_thickness.csv")
_WAFFLE_CORRECT = (
    "waffle",
    "correct",
    "cell_r1c1.ngc",
    "--tracking",
    "tracking.csv",
    "--tool-radius",
    "5",
    "--diameter",
    "2000",
    "--thickness",
    "thickness_r1c1.csv",
    "--target",
    "2",
    "--allowance",
    "0.3",
    "-o",
    "o.ngc",
    "--json",
    "o.json",
)
_WAFFLE_IN = ("cell_r1c1.ngc", "tracking.csv", "thickness_r1c1.csv")
_WAFFLE_EXTRAS = ((), ("--outside", "clamp"), ("--into", "-y"), ("--limit", "5"), ("--segment", "4"))
_PROGRAMS = ("plate.ngc", "pocket1_finish.ngc", "cell_r1c1.ngc", "lathe.ngc")
_MEASUREMENTS = ("meas.csv", "meas_m.csv", "meas.txt", "meas.dmo", "meas.qif")

MUTATION_TARGETS = [
    Target(
        "correct-program",
        ("correct", "@", "--shift", "0,0,0.01", "-o", "o.ngc", "--json", "o.json"),
        ("@",),
        ("o.ngc", "o.json"),
        "@",
        seeds=_PROGRAMS,
        extras=_CORRECT_EXTRAS,
    ),
    Target(
        "correct-program-field",
        ("correct", "plate.ngc", "--field", "plate_probe.csv", "-o", "o.ngc", "--json", "o.json"),
        ("plate.ngc", "plate_probe.csv"),
        ("o.ngc", "o.json"),
        "plate.ngc",
        extras=_CORRECT_EXTRAS,
    ),
    Target(
        "correct-field",
        ("correct", "plate.ngc", "--field", "plate_probe.csv", "-o", "o.ngc", "--json", "o.json"),
        ("plate.ngc", "plate_probe.csv"),
        ("o.ngc", "o.json"),
        "plate_probe.csv",
        extras=_CORRECT_EXTRAS,
    ),
    Target(
        "correct-height-map",
        ("correct", "plate.ngc", "--field", "@", "-o", "o.ngc", "--json", "o.json"),
        ("plate.ngc", "@"),
        ("o.ngc", "o.json"),
        "@",
        seeds=("plate.hmap", "plate.map", "plate_grbl.log", "plate_fanuc.txt"),
        extras=_CORRECT_EXTRAS,
    ),
    Target(
        "probe-grid-program",
        (
            "probe",
            "grid",
            "--program",
            "@",
            "--margin",
            "1",
            "--step",
            "5",
            "--safe-z",
            "5",
            "--depth",
            "-2",
            "--feed",
            "100",
            "-o",
            "g.ngc",
            "--json",
            "g.json",
        ),
        ("@",),
        ("g.ngc", "g.json"),
        "@",
        seeds=("plate.ngc", "pocket1_finish.ngc"),
        extras=((), ("--dialect", "grbl"), ("--dialect", "fanuc", "--fast-feed", "300"), ("--dialect", "sinumerik")),
    ),
    Target(
        "probe-points-step",
        (
            "probe",
            "points",
            "--nominal",
            "plate.step",
            "--n",
            "9",
            "--stylus-radius",
            "1",
            "--approach",
            "2",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "-o",
            "p.ngc",
            "--plan",
            "p.csv",
            "--json",
            "p.json",
        ),
        ("plate.step",),
        ("p.ngc", "p.csv", "p.json"),
        "plate.step",
        extras=((), ("--adaptive",), ("--dialect", "grbl")),
        scale=0.2,
    ),
    Target(
        "probe-points-file",
        (
            "probe",
            "points",
            "--nominal",
            "plate.step",
            "--points",
            "points.csv",
            "--stylus-radius",
            "1",
            "--approach",
            "2",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "-o",
            "p.ngc",
            "--plan",
            "p.csv",
        ),
        ("plate.step", "points.csv"),
        ("p.ngc", "p.csv"),
        "points.csv",
        extras=((), ("--dialect", "fanuc")),
    ),
    Target(
        "analyze-plan",
        ("analyze", "plan.csv", "--json", "a.json"),
        ("plan.csv", "probe-log.txt"),
        ("a.json",),
        "plan.csv",
    ),
    Target(
        "analyze-plan-log",
        ("analyze", "plan.csv", "--json", "a.json"),
        ("plan.csv", "probe-log.txt"),
        ("a.json",),
        "probe-log.txt",
    ),
    Target("inspect", ("inspect", "@", "--json", "i.json"), ("@",), ("i.json",), "@", seeds=_PROGRAMS),
    Target(
        "analyze",
        ("analyze", "@", "--json", "a.json"),
        ("@",),
        ("a.json",),
        "@",
        seeds=_MEASUREMENTS,
        extras=((), ("--weights", "knn"), ("--threshold", "15"), ("--probe-radius", "0.5")),
    ),
    Target(
        "compensate-measurements",
        (
            "compensate",
            "meas.csv",
            "--program",
            "plate.ngc",
            "--tool-radius",
            "1",
            "--outside",
            "clamp",
            "-o",
            "o.ngc",
            "--json",
            "o.json",
        ),
        ("meas.csv", "plate.ngc"),
        ("o.ngc", "o.json"),
        "meas.csv",
        extras=((), ("--filter", "spline"), ("--tool-radius", "3"), ("--extent", "-10,70,0,40")),
        scale=0.5,
    ),
    Target(
        "compensate-program",
        (
            "compensate",
            "meas.csv",
            "--program",
            "plate.ngc",
            "--tool-radius",
            "1",
            "--outside",
            "clamp",
            "-o",
            "o.ngc",
            "--json",
            "o.json",
        ),
        ("meas.csv", "plate.ngc"),
        ("o.ngc", "o.json"),
        "plate.ngc",
        extras=((), ("--tool-radius", "3")),
        scale=0.5,
    ),
    Target(
        "bore-plan-measured",
        _BORE_PLAN + ("--measured", "probe.csv", "--json", "p.json"),
        ("probe.csv",),
        ("p.json",),
        "probe.csv",
        extras=((), ("--entry", "bottom")),
    ),
    Target(
        "bore-next-plan",
        ("bore", "next", "--plan", "plan.json", "--measured", "probe.csv", "--json", "n.json"),
        ("plan.json", "probe.csv"),
        ("n.json",),
        "plan.json",
        extras=((), ("--pass", "1", "--applied", "0.03"), ("--controller", "fanuc"), ("--hardened",)),
        updates=("plan.json",),
    ),
    Target(
        "bore-next-measured",
        ("bore", "next", "--plan", "plan.json", "--measured", "probe.csv", "--json", "n.json"),
        ("plan.json", "probe.csv"),
        ("n.json",),
        "probe.csv",
        updates=("plan.json",),
        extras=(
            (),
            ("--pass", "1", "--applied", "0.03"),
            ("--controller", "linuxcnc", "--tool-radius", "6"),
            ("--hardened",),
        ),
    ),
    Target(
        "skin-correct-program",
        _SKIN_CORRECT,
        _SKIN_IN,
        ("o.ngc", "o.json"),
        "pocket1_finish.ngc",
        extras=((), ("--outside", "clamp"), ("--into", "+z")),
    ),
    Target(
        "skin-correct-map",
        _SKIN_CORRECT,
        _SKIN_IN,
        ("o.ngc", "o.json"),
        "pocket1_thickness.csv",
        extras=((), ("--outside", "clamp"), ("--outside", "extrapolate")),
    ),
    Target(
        "skin-loop-replay",
        (
            "skin",
            "loop",
            "--target",
            "1.5",
            "--depth",
            "0.2",
            "--replay",
            "gauge.csv",
            "-o",
            "w1.csv",
            "--json",
            "w1.json",
        ),
        ("gauge.csv",),
        ("w1.csv", "w1.json"),
        "gauge.csv",
        extras=((), ("--method", "mirror"), ("--method", "secant")),
    ),
    Target(
        "waffle-backlash",
        ("waffle", "backlash", "--signals", "backlash_signals.csv", "--json", "b.json"),
        ("backlash_signals.csv",),
        ("b.json",),
        "backlash_signals.csv",
        scale=0.3,
    ),
    Target(
        "waffle-tilt",
        (
            "waffle",
            "tilt",
            "--tracking",
            "tracking.csv",
            "--tool-radius",
            "5",
            "--diameter",
            "2000",
            "--json",
            "t.json",
        ),
        ("tracking.csv",),
        ("t.json",),
        "tracking.csv",
        extras=((), ("--segment", "4"), ("--segment", "1000")),
    ),
    Target(
        "waffle-correct-program",
        _WAFFLE_CORRECT,
        _WAFFLE_IN,
        ("o.ngc", "o.json"),
        "cell_r1c1.ngc",
        extras=_WAFFLE_EXTRAS,
    ),
    Target(
        "waffle-correct-tracking",
        _WAFFLE_CORRECT,
        _WAFFLE_IN,
        ("o.ngc", "o.json"),
        "tracking.csv",
        extras=_WAFFLE_EXTRAS,
    ),
    Target(
        "waffle-correct-thickness",
        _WAFFLE_CORRECT,
        _WAFFLE_IN,
        ("o.ngc", "o.json"),
        "thickness_r1c1.csv",
        extras=_WAFFLE_EXTRAS,
    ),
    # path mode (milliseconds); the feed mode solves an optimisation per station: a smaller share
    Target(
        "turning-plan-path",
        ("turning", "plan", "@", "--mode", "path", "-o", "t.ngc", "--json", "t.json"),
        ("@",),
        ("t.ngc", "t.json"),
        "@",
        seeds=("shaft.toml", "shaft_d20_l430.toml"),
        extras=((), ("--radius-mode",), ("--css",)),
    ),
    Target(
        "turning-plan-feed",
        ("turning", "plan", "shaft.toml", "--mode", "feed", "-o", "t.ngc", "--json", "t.json"),
        ("shaft.toml",),
        ("t.ngc", "t.json"),
        "shaft.toml",
        scale=0.1,
    ),
    Target(
        "turning-simulate-config",
        ("turning", "simulate", "shaft.toml", "lathe.ngc", "--json", "s.json"),
        ("shaft.toml", "lathe.ngc"),
        ("s.json",),
        "shaft.toml",
        scale=0.5,
    ),
    Target(
        "turning-simulate-program",
        ("turning", "simulate", "shaft.toml", "lathe.ngc", "--json", "s.json"),
        ("shaft.toml", "lathe.ngc"),
        ("s.json",),
        "lathe.ngc",
        scale=0.5,
    ),
    # the finished map of cell 1 read from the folder itself
    Target(
        "waffle-cells",
        (
            "waffle",
            "cells",
            "--thickness-dir",
            ".",
            "--cells",
            "1x2",
            "--target",
            "2",
            "--band",
            "1.9,2.1",
            "--json",
            "c.json",
        ),
        ("thickness_r1c1.csv",),
        ("c.json",),
        "thickness_r1c1.csv",
    ),
    Target(
        "bore-next-dmis",
        ("bore", "next", "--plan", "plan.json", "--measured", "probe.dmo", "--json", "n.json"),
        ("plan.json", "probe.dmo"),
        ("n.json",),
        "probe.dmo",
        updates=("plan.json",),
    ),
]

_F, _I = "float", "int"
_MORAN = (("--power", _F), ("--threshold", _F), ("--neighbors", "int_small"), ("--alpha", _F), ("--probe-radius", _F))
OPTION_TARGETS = [
    Target(
        "correct",
        ("correct", "plate.ngc", "--field", "plate_probe.csv", "-o", "o.ngc", "--json", "o.json"),
        ("plate.ngc", "plate_probe.csv"),
        ("o.ngc", "o.json"),
        options=(("--max-segment", _F), ("--chord-tol", _F), ("--limit", _F), ("--clearance", _F)),
        extras=_CORRECT_EXTRAS,
    ),
    Target(
        "probe-grid",
        ("probe", "grid", "--extent", "0,40,0,30", "-o", "g.ngc", "--json", "g.json"),
        (),
        ("g.ngc", "g.json"),
        options=(
            ("--step", _F),
            ("--safe-z", _F),
            ("--depth", _F),
            ("--feed", _F),
            ("--fast-feed", _F),
            ("--extent", "extent"),
        ),
        extras=((), ("--dialect", "grbl"), ("--dialect", "fanuc"), ("--dialect", "sinumerik")),
    ),
    Target(
        "probe-grid-n",
        ("probe", "grid", "--program", "plate.ngc", "-o", "g.ngc"),
        ("plate.ngc",),
        ("g.ngc",),
        options=(("--nx", "int_small"), ("--ny", "int_small"), ("--margin", _F)),
    ),
    Target(
        "probe-points",
        ("probe", "points", "--nominal", "plate.step", "-o", "p.ngc", "--plan", "p.csv"),
        ("plate.step",),
        ("p.ngc", "p.csv"),
        options=(
            ("--n", "int_small"),
            ("--stylus-radius", _F),
            ("--approach", _F),
            ("--overtravel", _F),
            ("--feed", _F),
            ("--safe-z", _F),
            ("--edge-margin", _F),
            ("--face", "int_small"),
        ),
        extras=((), ("--adaptive",)),
        scale=0.3,
    ),
    Target(
        "correct-shift",
        ("correct", "plate.ngc", "-o", "o.ngc", "--json", "o.json"),
        ("plate.ngc",),
        ("o.ngc", "o.json"),
        options=(("--shift", "shift"), ("--limit", _F), ("--max-segment", _F)),
        extras=((), ("--rapids",)),
    ),
    Target(
        "analyze",
        ("analyze", "meas.csv", "--json", "a.json"),
        ("meas.csv",),
        ("a.json",),
        options=_MORAN,
        extras=((), ("--weights", "knn")),
    ),
    Target(
        "compensate",
        (
            "compensate",
            "meas.csv",
            "--program",
            "plate.ngc",
            "--tool-radius",
            "1",
            "--outside",
            "clamp",
            "-o",
            "o.ngc",
            "--json",
            "o.json",
        ),
        ("meas.csv", "plate.ngc"),
        ("o.ngc", "o.json"),
        options=(
            ("--sigma-c", _F),
            ("--sigma-s", _F),
            ("--p", _F),
            ("--tool-radius", _F),
            ("--extent", "extent"),
            ("--limit", _F),
        )
        + _MORAN,
        extras=((), ("--filter", "spline"), ("--weights", "knn")),
        scale=0.5,
    ),
    Target(
        "bore-plan",
        ("bore", "plan", "--json", "p.json"),
        (),
        ("p.json",),
        options=(
            ("--diameter", _F),
            ("--t0", _F),
            ("--allowance", _F),
            ("--delta-a", _F),
            ("--delta-b", _F),
            ("--k", _F),
            ("--target", _F),
            ("--final", "class"),
            ("--prefinish", "class"),
        ),
    ),
    Target(
        "bore-next",
        ("bore", "next", "--plan", "plan.json", "--measured", "probe.csv", "--json", "n.json"),
        ("plan.json", "probe.csv"),
        ("n.json",),
        updates=("plan.json",),
        options=(("--pass", _I), ("--applied", _F), ("--tool", _I), ("--tool-radius", _F)),
        extras=((), ("--controller", "linuxcnc", "--tool-radius", "6"), ("--controller", "fanuc"), ("--hardened",)),
    ),
    # --parts only small: a legitimate request for 1e9 parts runs for as long as it takes
    Target(
        "bore-simulate",
        ("bore", "simulate", "--json", "s.json"),
        (),
        ("s.json",),
        options=(
            ("--parts", "parts"),
            ("--seed", _I),
            ("--diameter", _F),
            ("--t0", _F),
            ("--allowance", _F),
            ("--k", _F),
        ),
        extras=((), ("--material", "titanium"), ("--material", "hardened")),
    ),
    Target(
        "skin-correct",
        _SKIN_CORRECT,
        _SKIN_IN,
        ("o.ngc", "o.json"),
        options=(("--target", _F), ("--allowance", _F), ("--limit", _F)),
        extras=((), ("--outside", "clamp"), ("--into", "+z")),
    ),
    Target(
        "skin-loop",
        ("skin", "loop", "--replay", "gauge.csv", "-o", "w1.csv", "--json", "w1.json"),
        ("gauge.csv",),
        ("w1.csv", "w1.json"),
        options=(("--target", _F), ("--depth", _F), ("--noise", _F)),
        extras=(("--method", "mirror"), ("--method", "secant"), ("--method", "kalman")),
    ),
    # the noise-free protocol takes milliseconds
    Target(
        "skin-simulate-protocol",
        ("skin", "simulate", "--protocol", "--json", "s.json"),
        (),
        ("s.json",),
        options=(("--noise", _F), ("--latency-ms", _F), ("--seed", _I)),
        extras=(("--method", "mirror"), ("--method", "secant"), ("--method", "kalman")),
    ),
    # a full run takes about 0.2 to 1.5 s: a small share of the budget
    Target(
        "skin-simulate",
        ("skin", "simulate", "--method", "mirror", "--json", "s.json"),
        (),
        ("s.json",),
        options=(("--noise", _F), ("--latency-ms", _F), ("--seed", _I)),
        scale=0.05,
    ),
    Target(
        "waffle-backlash",
        ("waffle", "backlash", "--signals", "backlash_signals.csv", "--json", "b.json"),
        ("backlash_signals.csv",),
        ("b.json",),
        options=(("--dt", _F),),
        scale=0.3,
    ),
    Target(
        "waffle-tilt",
        ("waffle", "tilt", "--tracking", "tracking.csv", "--json", "t.json"),
        ("tracking.csv",),
        ("t.json",),
        options=(("--tool-radius", _F), ("--diameter", _F), ("--segment", _I)),
    ),
    Target(
        "waffle-correct",
        (
            "waffle",
            "correct",
            "cell_r1c1.ngc",
            "--tracking",
            "tracking.csv",
            "--thickness",
            "thickness_r1c1.csv",
            "-o",
            "o.ngc",
            "--json",
            "o.json",
        ),
        _WAFFLE_IN,
        ("o.ngc", "o.json"),
        options=(
            ("--tool-radius", _F),
            ("--diameter", _F),
            ("--segment", _I),
            ("--target", _F),
            ("--allowance", _F),
            ("--limit", _F),
        ),
        extras=((), ("--outside", "clamp")),
    ),
    Target(
        "turning-plan-path",
        ("turning", "plan", "shaft.toml", "--mode", "path", "-o", "t.ngc", "--json", "t.json"),
        ("shaft.toml",),
        ("t.ngc", "t.json"),
        options=(("--wear-weight", _F),),
        scale=0.2,
    ),
    Target(
        "turning-plan-feed",
        ("turning", "plan", "shaft.toml", "--mode", "feed", "-o", "t.ngc", "--json", "t.json"),
        ("shaft.toml",),
        ("t.ngc", "t.json"),
        options=(("--wear-weight", _F),),
        scale=0.1,
    ),
    Target(
        "turning-simulate",
        ("turning", "simulate", "shaft.toml", "lathe.ngc", "--json", "s.json"),
        ("shaft.toml", "lathe.ngc"),
        ("s.json",),
        options=(("--rho-sigma", _F), ("--stiffness-sigma", _F), ("--seed", _I)),
        scale=0.5,
    ),
    Target(
        "waffle-cells",
        ("waffle", "cells", "--thickness-dir", ".", "--cells", "1x2", "--json", "c.json"),
        ("thickness_r1c1.csv",),
        ("c.json",),
        options=(("--target", _F), ("--band", "pair")),
    ),
    Target(
        "bore-probe-program",
        ("bore", "probe-program", "--planes", "55,30,5", "-o", "p.ngc"),
        (),
        ("p.ngc",),
        options=(("--diameter", _F), ("--points", _I), ("--feed", _F), ("--safe-z", _F)),
        extras=((), ("--dialect", "fanuc")),
    ),
]

# options a target needs whatever else is drawn: a value from the extremes, or this valid one
_REQUIRED = {
    "bore-plan": {"--diameter": "40", "--t0": "0.5", "--allowance": "0.1", "--delta-a": "0.03", "--delta-b": "0.02"},
    "waffle-tilt": {"--tool-radius": "5", "--diameter": "2000"},
    "waffle-correct": {"--tool-radius": "5", "--diameter": "2000", "--target": "2"},
    "skin-loop": {"--target": "1.5", "--depth": "0.2"},
    "correct-shift": {"--shift": "0,0,0.01"},
    "probe-grid": {"--step": "10", "--safe-z": "5", "--depth": "-2", "--feed": "100"},
    "probe-grid-n": {"--nx": "3", "--ny": "3", "--safe-z": "5", "--depth": "-2", "--feed": "100"},
    "probe-points": {"--n": "9", "--stylus-radius": "1", "--approach": "2", "--overtravel": "1", "--feed": "100"},
    "bore-simulate": {"--parts": "5"},
    "waffle-cells": {"--target": "2", "--band": "1.9,2.1"},
    "bore-probe-program": {"--diameter": "40"},
}  # the default 1000 parts take seconds


# ------------------------------------------------------------------------------------ strategies
NASTY_NUMBERS = [
    b"nan",
    b"NaN",
    b"-nan",
    b"inf",
    b"-inf",
    b"+inf",
    b"Infinity",
    b"1e308",
    b"-1e308",
    b"1e309",
    b"-1e309",
    b"1.7976931348623157e308",
    b"1e300",
    b"-1e300",
    b"1e-300",
    b"1e-320",
    b"5e-324",
    b"0",
    b"-0",
    b"0.0",
    b"-1",
    b"1",
    b"2",
    b"99999999999999999999999999999999999999",
    b"-9223372036854775809",
    b"18446744073709551616",
    b"1" + b"0" * 400,
    b"0." + b"0" * 400 + b"1",
    b"1e99999",
    b"1e",
    b"1e+",
    b".",
    b"-",
    b"+",
    b"1.2.3",
    b"0x10",
    b"1_0",
    b"",
    b" ",
]
NASTY_TOKENS = [
    b"\r",
    b"\r\n",
    b"\n",
    b"\n\n",
    b";",
    b",",
    b",,",
    b"(",
    b")",
    b"[",
    b"]",
    b"=",
    b'"',
    b"'",
    b"#",
    b"%",
    b"\x00",
    b"\t",
    b" ",
    b"\xff",
    b"\xe9",
    b"\xef\xbb\xbf",
    b"\xc2\xa0",
    b"E",
    b"e",
    b"$",
    b"G2 ",
    b"G3 ",
    b"R0 ",
    b"I0 J0 ",
    b"G20 ",
    b"G91 ",
    b"G18 ",
    b"M30\n",
    b"#1=2 ",
    b"[1/0]",
    b"X",
    b"N1 ",
    b"/",
    b"[",
    b"]",
    b"=",
    b"\\",
    b"<",
    b">",
    b"&",
    b"]]>",
    b"<!--",
    b"<x>",
    b"\xd8\x00",
]
LONG_TOKENS = [b"9" * 5000, b"A" * 20000, b"(" + b"x" * 5000 + b")", b"1" * 400 + b".5", b"," * 3000, b"X1 " * 3000]

number = st.one_of(
    st.sampled_from(NASTY_NUMBERS),
    st.floats().map(lambda f: repr(f).encode()),
    st.integers(-(10**40), 10**40).map(lambda i: str(i).encode()),
)
token = st.one_of(
    st.sampled_from(NASTY_TOKENS), number, st.sampled_from(LONG_TOKENS), st.binary(min_size=1, max_size=6)
)
position = st.integers(0, 1 << 20)

mutation = st.one_of(
    st.tuples(st.just("number"), position, number),  # the k-th number replaced
    st.tuples(st.just("number"), position, number),  # (drawn twice as often: the numbers carry the meaning)
    st.tuples(st.just("flip"), position, st.integers(1, 255)),
    st.tuples(st.just("insert"), position, token),
    st.tuples(st.just("delete"), position, st.integers(1, 64)),
    st.tuples(st.just("truncate"), position),
    st.tuples(st.just("dup_line"), position, st.sampled_from([1, 2, 10, 300])),
    st.tuples(st.just("del_line"), position),
    st.tuples(st.just("swap_lines"), position, position),
    st.tuples(st.just("line"), position, token),  # a whole line replaced
    st.tuples(st.just("eol"), st.sampled_from([b"\r", b"\r\n", b"\n\n", b"\n\r", b" "])),
    st.tuples(st.just("empty")),
)

_NUMBER_RE = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def mutate(data: bytes, ops) -> bytes:
    for op in ops:
        kind, n = op[0], len(data)
        lines = data.splitlines(keepends=True)
        if kind == "number":
            found = list(_NUMBER_RE.finditer(data))
            if found:
                m = found[op[1] % len(found)]
                data = data[: m.start()] + op[2] + data[m.end() :]
        elif kind == "flip" and n:
            p = op[1] % n
            data = data[:p] + bytes([data[p] ^ op[2]]) + data[p + 1 :]
        elif kind == "insert":
            p = op[1] % (n + 1)
            data = data[:p] + op[2] + data[p:]
        elif kind == "delete":
            p = op[1] % (n + 1)
            data = data[:p] + data[p + op[2] :]
        elif kind == "truncate":
            data = data[: op[1] % (n + 1)]
        elif kind == "dup_line" and lines:
            k = op[1] % len(lines)
            line = lines[k] if lines[k].endswith((b"\n", b"\r")) else lines[k] + b"\n"
            data = b"".join(lines[:k] + [line] * (op[2] + 1) + lines[k + 1 :])
        elif kind == "del_line" and lines:
            k = op[1] % len(lines)
            data = b"".join(lines[:k] + lines[k + 1 :])
        elif kind == "swap_lines" and lines:
            a, b = op[1] % len(lines), op[2] % len(lines)
            lines[a], lines[b] = lines[b], lines[a]
            data = b"".join(lines)
        elif kind == "line" and lines:
            k = op[1] % len(lines)
            lines[k] = op[2] + b"\n"
            data = b"".join(lines)
        elif kind == "eol":
            data = data.replace(b"\r\n", b"\n").replace(b"\n", op[1])
        elif kind == "empty":
            data = b""
    return data


EXTREME_FLOATS = [
    "nan",
    "NaN",
    "inf",
    "-inf",
    "0",
    "-0",
    "-1",
    "1e-300",
    "1e300",
    "-1e300",
    "1e308",
    "1e309",
    "-1e309",
    "5e-324",
    "1",
    "0.5",
    "1e-9",
    "2",
    "1000",
    "1e20",
    "-0.5",
    "+1",
    "1e",
    "",
    " 1",
    "0x10",
]
EXTREME_INTS = [
    "0",
    "-1",
    "1",
    "2",
    "3",
    "1000",
    "2147483648",
    "9223372036854775807",
    "9223372036854775808",
    "-9223372036854775809",
    "99999999999999999999999",
    "1e3",
    "1.5",
    "nan",
    "inf",
    "",
]
# N nearest neighbours: up to far more than the points (45), but not arrays of 2**63 entries
SMALL_INTS = ["0", "-1", "1", "2", "3", "44", "45", "46", "1000", "100000", "1e3", "1.5", "nan", ""]
PARTS = ["0", "-1", "1", "2", "5", "1.5", "nan", "inf", "1e3", ""]
CLASSES = [
    "H6",
    "H7",
    "H9",
    "h6",
    "g6",
    "H01",
    "H0",
    "H1",
    "H18",
    "H19",
    "H20",
    "A1",
    "ZC11",
    "js6",
    "JS6",
    "K6",
    "N6",
    "H",
    "6",
    "",
    " ",
    "H6H6",
    "H-1",
    "H99999999999999999999",
    "Hnan",
    "40H6",
    "\u0397\u0036",
]

# values most options accept (x > 0), from the smallest to the largest double
POSITIVE_FLOATS = [
    "5e-324",
    "1e-300",
    "1e-12",
    "1e-6",
    "0.001",
    "0.1",
    "1",
    "3",
    "10",
    "1000",
    "1e6",
    "1e12",
    "1e20",
    "1e300",
    "1.7976931348623157e308",
]

float_value = st.one_of(
    st.sampled_from(EXTREME_FLOATS),
    st.sampled_from(POSITIVE_FLOATS),
    st.floats().map(repr),
    st.floats(-100, 100).map(lambda f: f"{f:.4g}"),
)
OPTION_VALUES = {
    "float": float_value,
    "int": st.one_of(
        st.sampled_from(EXTREME_INTS), st.integers(0, 10**6).map(str), st.integers(-(10**20), 10**20).map(str)
    ),
    "int_small": st.sampled_from(SMALL_INTS),
    "parts": st.sampled_from(PARTS),
    "class": st.sampled_from(CLASSES),
    "pair": st.lists(float_value, min_size=2, max_size=2).map(",".join) | st.sampled_from(["2", "2,1", ",", ""]),
    "shift": st.lists(float_value, min_size=3, max_size=3).map(",".join)
    | st.sampled_from(["0,0", "0,0,0,0", ",,", ""]),
    "extent": st.lists(float_value, min_size=4, max_size=4).map(",".join) | st.sampled_from(["0,0,0,0", "70,-10,40,0"]),
}


# ------------------------------------------------------------------------------------ the contract
class CallTimeout(BaseException):
    """A call ran past NCADAPT_CLI_FUZZ_TIMEOUT (a BaseException: nothing in the command catches it)."""


@contextlib.contextmanager
def time_limit(seconds: float):
    def expire(signum, frame):  # noqa: ARG001
        raise CallTimeout(f"no answer after {seconds:g} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


#: Targets that have hung in this run: their later calls (shrinking) get a third of the time.
_HUNG: set = set()


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


def _tail(text: str, n: int = 4) -> str:
    return "\n".join(text.strip().splitlines()[-n:])


def run_case(target: Target, args: list[str], files: dict[str, bytes], preexisting: bool, case: str) -> None:
    """Run ``ncadapt ARGS`` in a fresh folder holding ``files`` (the inputs) and check the contract."""
    folder = Path(tempfile.mkdtemp(prefix="ncadapt-fuzz-"))
    try:
        for name, data in files.items():
            (folder / name).write_bytes(data)
        if preexisting:
            for name in target.outputs:
                (folder / name).write_bytes(PREVIOUS)
        before = snapshot(folder)
        problems = []
        t0 = time.monotonic()
        # warnings stay warnings, as for the installed command (pytest's configuration makes them
        # errors, which the command would report as internal errors); recorded for triage
        with contextlib.chdir(folder), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            try:
                with time_limit(TIMEOUT / 3 if target in _HUNG else TIMEOUT):
                    r = CliRunner().invoke(main, args)
            except CallTimeout as e:
                _HUNG.add(target)
                problems.append(f"hang: {e}")
                r = None
        elapsed = time.monotonic() - t0
        if r is not None:
            out = r.stdout + r.stderr
            after = snapshot(folder)
            if r.exit_code not in (0, 1, 2):
                problems.append(f"exit code {r.exit_code}")
            if r.exception is not None and not isinstance(r.exception, SystemExit):
                problems.append(f"exception escaped the command: {r.exception!r}")
            if TRACEBACK in out:
                problems.append("a traceback was printed")
            changed_inputs = sorted(
                n
                for n in files
                if after.get(n) != files[n] and not (r.exit_code == 0 and n in target.updates and n in after)
            )
            if changed_inputs:
                problems.append(f"inputs changed: {changed_inputs}")
            temporaries = sorted(n for n in after if n.startswith(TMP_PREFIX))
            if temporaries:
                problems.append(f"temporary files left: {temporaries}")
            if r.exit_code != 0:
                touched = sorted(
                    n
                    for n in set(before) | set(after)
                    if n not in files and not n.startswith(TMP_PREFIX) and before.get(n) != after.get(n)
                )
                if touched:
                    problems.append(f"exit {r.exit_code} but outputs created or changed: {touched}")
        if COLLECT and r is not None and not problems:  # for triage: what the contract does not cover
            notes = [f"slow: {elapsed:.1f} s"] if elapsed > 1.0 else []
            notes += sorted(
                {f"{w.category.__name__}: {w.message} ({Path(w.filename).name}:{w.lineno})" for w in caught}
            )
            if r.exit_code == 0 and re.search(r"\bnan\b|\binf\b", r.stdout):
                notes.append("nan or inf in the summary")
            if notes:
                _collect(target, args, files, preexisting, case, ["note: " + n for n in notes], r)
        if problems:
            report = f"[{target.id}] ncadapt {' '.join(args)}\n  {case}\n  problems: {'; '.join(problems)}\n" + (
                f"  exit {r.exit_code}; output:\n{_tail(out)}" if r is not None else ""
            )
            if COLLECT:
                _collect(target, args, files, preexisting, case, problems, r)
            else:
                raise AssertionError(report)
    finally:
        for p in folder.iterdir():  # a test may leave a file read-only
            with contextlib.suppress(OSError):
                p.chmod(p.stat().st_mode | stat.S_IWUSR)
        shutil.rmtree(folder, ignore_errors=True)


def _collect(target, args, files, preexisting, case, problems, r) -> None:
    record = {
        "target": target.id,
        "args": args,
        "case": case,
        "preexisting": preexisting,
        "problems": problems,
        "exit_code": None if r is None else r.exit_code,
        "exception": None if r is None or r.exception is None else repr(r.exception),
        "stderr": "" if r is None else _tail(r.stderr, 3),
        "stdout": "" if r is None else _tail(r.stdout, 2),
        "files": {n: base64.b64encode(d).decode() for n, d in files.items()},
    }
    with open(COLLECT, "a", encoding="utf-8") as f:
        f.write(json.dumps(record) + "\n")


def _settings(target: Target):
    # no explain phase: its tracing makes the report of a failure many times slower
    return settings(
        max_examples=target.budget,
        deadline=None,
        derandomize=True,
        database=None,
        phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.target, Phase.shrink],
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )


def _resolve(target: Target, victim_name: str) -> tuple[list[str], dict[str, bytes]]:
    """The inputs' contents and the argument list with ``@`` naming the victim's file."""
    files = {}
    for name in target.inputs:
        real = victim_name if name == "@" else name
        files[real] = seed(real)
    return [victim_name if a == "@" else a for a in target.args], files


# ------------------------------------------------------------------------------------ the tests
@pytest.mark.parametrize("target", MUTATION_TARGETS, ids=[t.id for t in MUTATION_TARGETS])
def test_mutated_inputs_keep_the_contract(target: Target):
    victims = target.seeds or (target.victim,)

    @_settings(target)
    @given(
        victim=st.sampled_from(victims),
        ops=st.lists(mutation, min_size=1, max_size=4),
        extra=st.sampled_from(target.extras),
        preexisting=st.booleans(),
    )
    def check(victim, ops, extra, preexisting):
        args, files = _resolve(target, victim)
        name = victim if target.victim == "@" else target.victim
        files[name] = data = mutate(files[name], ops)
        note(f"{name} after the mutations ({len(data)} bytes): {data[:2000]!r}")
        run_case(target, args + list(extra), files, preexisting, f"{name} mutated by {ops!r}")

    check()


@pytest.mark.parametrize("target", OPTION_TARGETS, ids=[t.id for t in OPTION_TARGETS])
def test_extreme_option_values_keep_the_contract(target: Target):
    names = [o for o, _ in target.options]
    kinds = dict(target.options)
    required = _REQUIRED.get(target.id, {})

    @_settings(target)
    @given(
        chosen=st.lists(st.sampled_from(names), min_size=1, max_size=2, unique=True),
        data=st.data(),
        extra=st.sampled_from(target.extras),
        preexisting=st.booleans(),
    )
    def check(chosen, data, extra, preexisting):
        args, files = _resolve(target, "")
        opts = []
        for o in chosen:
            opts.append(f"{o}={data.draw(OPTION_VALUES[kinds[o]], label=o)}")
        opts += [f"{o}={v}" for o, v in required.items() if o not in chosen]
        run_case(target, args + list(extra) + opts, files, preexisting, f"options {opts!r}")

    check()


# seeds a safety check refuses as they are (a lathe program in diameter mode is not corrected)
_REFUSED_SEEDS = {("correct-program", "lathe.ngc")}


def test_the_seeds_are_valid_inputs():
    """The harness's own check: every target exits 0 on its unmutated inputs with each of its
    extra arguments (1 for the seeds in _REFUSED_SEEDS), so a failure above is the mutation's or
    the option value's, not the harness's."""
    for t in MUTATION_TARGETS + OPTION_TARGETS:
        for victim in (t.seeds or (t.victim,)) if t.victim == "@" else ("",):
            for extra in t.extras:
                args, files = _resolve(t, victim)
                args += list(extra) + [f"{o}={v}" for o, v in _REQUIRED.get(t.id, {}).items()]
                with tempfile.TemporaryDirectory() as d, contextlib.chdir(d):
                    for name, data in files.items():
                        Path(name).write_bytes(data)
                    r = CliRunner().invoke(main, args)
                assert r.exit_code == 0 or (t.id, victim) in _REFUSED_SEEDS and r.exit_code == 1, (
                    f"{t.id} {victim}: {args}\n{r.output}"
                )
