"""On-machine probing: the programs (checked by LinuxCNC's rs274 and by grammars), the readers of
sender height maps, the plan that pairs a log with its nominal points, and the virtual probe."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import fields, measure, probing
from ncadapt.cli import main
from ncadapt.errors import InputError

RS274 = shutil.which("rs274")
needs_rs274 = pytest.mark.skipif(RS274 is None, reason="rs274 (linuxcnc-uspace) is not installed")


def run(args, cwd=None):
    r = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return r


def rs274(path: Path) -> list[tuple[str, tuple[float, ...]]]:
    """The canonical calls of a program as LinuxCNC's interpreter reads it; fails on its errors."""
    out = path.with_suffix(".canon")
    r = subprocess.run(
        [RS274, "-g", str(path), str(out)], stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60
    )
    text = out.read_text()
    assert r.returncode == 0 and "error" not in (r.stdout + r.stderr).lower(), r.stdout + r.stderr
    calls = []
    for line in text.splitlines():
        m = re.search(r"(STRAIGHT_PROBE|STRAIGHT_TRAVERSE|STRAIGHT_FEED)\(([^)]*)\)", line)
        if m:
            calls.append((m.group(1), tuple(float(v) for v in m.group(2).split(",")[:3])))
    return calls


# ------------------------------------------------------------------------------------ grammars
# grbl 1.1's G-code (gcode.c, gc_execute_line): the words it knows, the G and M codes it accepts.
GRBL_G = {
    "0",
    "1",
    "2",
    "3",
    "4",
    "10",
    "17",
    "18",
    "19",
    "20",
    "21",
    "28",
    "28.1",
    "30",
    "30.1",
    "38.2",
    "38.3",
    "38.4",
    "38.5",
    "40",
    "43.1",
    "49",
    "53",
    "54",
    "55",
    "56",
    "57",
    "58",
    "59",
    "61",
    "80",
    "90",
    "91",
    "91.1",
    "92",
    "92.1",
    "93",
    "94",
}
GRBL_M = {"0", "1", "2", "30", "3", "4", "5", "7", "8", "9", "56"}
GRBL_MOTION = {"0", "1", "2", "3", "38.2", "38.3", "38.4", "38.5", "80"}


def grbl_errors(text: str) -> list[str]:
    """Lines outside grbl's grammar: a word is a letter of grbl's set and a plain decimal number;
    no O-words, parameters (#), expressions ([ ]), more than one motion or distance mode per
    block; at most 80 characters of a line reach grbl's line buffer."""
    errs = []
    for n, raw in enumerate(text.splitlines(), 1):
        line = re.sub(r"\([^()]*\)", "", raw)
        line = line.split(";", 1)[0].replace(" ", "").upper()
        if len(line) > 79:
            errs.append(f"{n}: longer than grbl's line buffer")
        if not line:
            continue
        if not re.fullmatch(r"(?:[FGIJKLMNPRSTXYZ][-+]?(?:\d+\.?\d*|\.\d+))+", line):
            errs.append(f"{n}: not grbl words: {raw!r}")
            continue
        words = re.findall(r"([A-Z])([-+]?[\d.]+)", line)
        gs = [str(float(v)).rstrip("0").rstrip(".") for a, v in words if a == "G"]
        ms = [str(int(float(v))) for a, v in words if a == "M"]
        if any(g not in GRBL_G for g in gs) or any(m not in GRBL_M for m in ms):
            errs.append(f"{n}: a G or M code grbl does not know: {raw!r}")
        if sum(g in GRBL_MOTION for g in gs) > 1 or sum(g in ("90", "91") for g in gs) > 1:
            errs.append(f"{n}: two codes of one modal group: {raw!r}")
        letters = [a for a, _ in words if a not in "GM"]
        if len(letters) != len(set(letters)):
            errs.append(f"{n}: a word repeated: {raw!r}")
    return errs


def test_grbl_grammar_catches_what_grbl_refuses():
    assert grbl_errors("G0 X1 Y2\nG38.2 Z-1 F100 (probe)\nG91 G0 Z1\nG90\nM2\n") == []
    for bad in ("O100", "#1=2", "G1 X[1+2]", "G38.2 Z#5063", "G0 G1 X1", "G65 P1", "IF[#1 GT 0] GOTO 9"):
        assert grbl_errors(bad + "\n"), bad


def fanuc_errors(text: str) -> list[str]:
    """Fanuc custom macro B as the programs use it: %, O, N, comments, words, IF[...]GOTOn,
    #3000=n(...), POPEN/DPRNT[...]/PCLOS; every GOTO's target present."""
    errs, targets, gotos = [], set(), []
    for n, raw in enumerate(text.splitlines(), 1):
        s = raw.strip()
        m = re.match(r"N(\d+)\s*", s)
        if m:
            targets.add(int(m.group(1)))
            s = s[m.end() :]
        if s in ("%", "POPEN", "PCLOS") or re.fullmatch(r"O\d{1,4}", s) or re.fullmatch(r"\([^()a-z]*\)", s):
            continue
        if re.fullmatch(r"#3000=\d+\([A-Z0-9 ]*\)", s) or re.fullmatch(r"DPRNT\[[A-Z#0-9\[\]*]*\]", s):
            continue
        m = re.fullmatch(r"IF\[(.*)\]GOTO(\d+)", s)
        if m:
            gotos.append(int(m.group(2)))
            continue
        if not re.fullmatch(r"(?:[GXYZFM]-?\d+(?:\.\d+)?\s*)+", s):
            errs.append(f"{n}: {raw!r}")
    errs += [f"GOTO{g}: no N{g}" for g in gotos if g not in targets]
    return errs


def sinumerik_errors(text: str) -> list[str]:
    errs, labels, jumps = [], set(), []
    for n, raw in enumerate(text.splitlines(), 1):
        s = raw.strip()
        if (
            not s
            or s.startswith(";")
            or s in ("DEF INT _ERR", "STOPRE", "M0", "M30")
            or re.fullmatch(r"SETAL\(\d+\)", s)
        ):
            continue
        m = re.fullmatch(r"([A-Z_][A-Z0-9_]*):", s)
        if m:
            labels.add(m.group(1))
            continue
        m = re.fullmatch(r"IF \$AC_MEA\[1\]==0 GOTOF ([A-Z_]+)", s)
        if m:
            jumps.append(m.group(1))
            continue
        if re.fullmatch(r'WRITE\(_ERR,"[\w.-]+",\$AA_MW\[X\]<<" "<<\$AA_MW\[Y\]<<" "<<\$AA_MW\[Z\]\)', s):
            continue
        if not re.fullmatch(r"(?:MEAS=1 )?(?:[GXYZF]-?\d+(?:\.\d+)?\s*)+", s):
            errs.append(f"{n}: {raw!r}")
    errs += [f"GOTOF {j}: no label" for j in jumps if j not in labels]
    return errs


# ------------------------------------------------------------------------------------ grid
def test_grid_is_serpentine_with_the_spacing_asked():
    g = probing.grid_points((0, 40, 0, 30), step=12)  # ceil(40/12) + 1 = 5 along x, ceil(30/12) + 1 = 4 along y
    assert (g.nx, g.ny) == (5, 4)
    np.testing.assert_allclose(g.points[:5], [[0, 0], [10, 0], [20, 0], [30, 0], [40, 0]])
    np.testing.assert_allclose(g.points[5:10], [[40, 10], [30, 10], [20, 10], [10, 10], [0, 10]])
    g = probing.grid_points((-5, 5, 2, 3), nx=3, ny=2)
    np.testing.assert_allclose(g.points, [[-5, 2], [0, 2], [5, 2], [5, 3], [0, 3], [-5, 3]])


@needs_rs274
def test_linuxcnc_grid_runs_in_rs274_as_planned(tmp_path):
    out = tmp_path / "grid.ngc"
    r = run(
        [
            "probe",
            "grid",
            "--extent",
            "0,40,0,30",
            "--step",
            "10",
            "--safe-z",
            "5",
            "--depth",
            "-2",
            "--feed",
            "100",
            "-o",
            out,
        ]
    )
    assert r.exit_code == 0, r.output
    text = out.read_text()
    assert "(PROBEOPEN probe-log.txt)" in text and "(PROBECLOSE)" in text
    calls = rs274(out)
    probes = [c for k, c in calls if k == "STRAIGHT_PROBE"]
    expected = probing.grid_points((0, 40, 0, 30), step=10).points
    np.testing.assert_allclose([p[:2] for p in probes], expected)
    assert all(p[2] == -2 for p in probes)
    # between two probes the probe goes back up to the safe height, and moves only there
    k = [i for i, (kind, _) in enumerate(calls) if kind == "STRAIGHT_PROBE"]
    for a, b in zip(k, k[1:]):
        between = calls[a + 1 : b]
        assert between[0] == ("STRAIGHT_TRAVERSE", (*probes[k.index(a)][:2], 5.0))
        assert all(c[2] == 5.0 for _, c in between)


@needs_rs274
def test_linuxcnc_second_touch_logs_the_slow_touch_only(tmp_path):
    out = tmp_path / "grid2.ngc"
    r = run(
        [
            "probe",
            "grid",
            "--extent",
            "0,10,0,10",
            "--nx",
            "2",
            "--ny",
            "2",
            "--safe-z",
            "5",
            "--depth",
            "-2",
            "--feed",
            "20",
            "--fast-feed",
            "200",
            "-o",
            out,
        ]
    )
    assert r.exit_code == 0, r.output
    text = out.read_text()
    assert text.count("(LOG,#5061 #5062 #5063)") == 4 and "(LOGOPEN,probe-log.txt)" in text
    assert text.count("F200.0") == 4 and text.count("F20.0") == 4
    calls = rs274(out)
    assert sum(k == "STRAIGHT_PROBE" for k, _ in calls) == 8


@needs_rs274
def test_grid_from_a_program_takes_its_feed_area(tmp_path):
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nG0 X-50 Y-50 Z5\nG1 X10 Y5 Z-1 F100\nG1 X30 Y25\nM2\n")
    out = tmp_path / "g.ngc"
    r = run(
        [
            "probe",
            "grid",
            "--program",
            prog,
            "--margin",
            "2",
            "--nx",
            "2",
            "--ny",
            "2",
            "--safe-z",
            "5",
            "--depth",
            "-2",
            "--feed",
            "100",
            "--json",
            tmp_path / "g.json",
            "-o",
            out,
        ]
    )
    assert r.exit_code == 0, r.output
    import json

    # the feed moves run from the rapid's end (-50, -50) through (10, 5) to (30, 25): 2 mm wider
    assert json.loads((tmp_path / "g.json").read_text())["extent"] == [-52, 32, -52, 27]


@pytest.mark.parametrize("dialect", probing.DIALECTS)
@pytest.mark.parametrize("fast", [None, 300.0])
def test_every_dialect_stops_without_contact_and_keeps_its_grammar(dialect, fast):
    g = probing.grid_points((0, 20, 0, 10), nx=3, ny=2)
    text = probing.grid_program(g, safe_z=5, depth=-1.5, feed=50, fast_feed=fast, dialect=dialect)
    touches = 6 * (2 if fast else 1)
    if dialect in ("linuxcnc", "grbl"):
        # G38.2: the controller's error (LinuxCNC) or alarm (grbl) when the move ends without contact
        assert text.count("G38.2 Z-1.5000") == touches and "G38.3" not in text
    if dialect == "grbl":
        assert grbl_errors(text) == []
    if dialect == "fanuc":
        assert fanuc_errors(text) == []
        lines = text.splitlines()
        for i, ln in enumerate(lines):
            if ln.startswith("G31"):
                assert lines[i + 1] == "IF[[ABS[#5063-[-1.5000]]LT0.0001]]GOTO9000"
        assert "N9000 #3000=1(PROBE NO CONTACT)" in lines
        assert text.count("DPRNT") == 6
    if dialect == "sinumerik":
        assert sinumerik_errors(text) == []
        lines = text.splitlines()
        for i, ln in enumerate(lines):
            if ln.startswith("MEAS=1"):
                assert lines[i + 1 : i + 3] == ["STOPRE", "IF $AC_MEA[1]==0 GOTOF NOCONTACT"]
        assert text.count("WRITE(") == 6 and "SETAL(65000)" in text


def test_grid_refusals():
    r = run(
        [
            "probe",
            "grid",
            "--extent",
            "0,10,0,10",
            "--step",
            "1",
            "--safe-z",
            "-3",
            "--depth",
            "-2",
            "--feed",
            "1",
            "-o",
            "x.ngc",
        ]
    )
    assert r.exit_code == 2 and "error: --depth: -2 must be below --safe-z -3" in r.output
    r = run(
        [
            "probe",
            "grid",
            "--extent",
            "0,10,0,10",
            "--step",
            "0.001",
            "--safe-z",
            "3",
            "--depth",
            "-2",
            "--feed",
            "1",
            "-o",
            "x.ngc",
        ]
    )
    assert r.exit_code == 2 and "error: --step: a spacing of 0.001 mm over 10 x 10 mm needs 10001 x 10001" in r.output
    r = run(["probe", "grid", "--extent", "0,10,0,10", "--safe-z", "3", "--depth", "-2", "--feed", "1", "-o", "x.ngc"])
    assert r.exit_code == 2 and "--step MM, or --nx N and --ny N" in r.output
    r = run(
        [
            "probe",
            "grid",
            "--extent",
            "0,10,0,10",
            "--step",
            "1",
            "--safe-z",
            "3",
            "--depth",
            "-2",
            "--feed",
            "nan",
            "-o",
            "x.ngc",
        ]
    )
    assert r.exit_code == 2


# ------------------------------------------------------------------------------------ readers
def plane(x, y):
    return 0.1 + 0.01 * x - 0.02 * y


def test_grbl_console_log_in_work_coordinates(tmp_path):
    """UGS-style console: status reports carry WCO; the PRB reports are machine positions."""
    wco = (-100.0, -50.0, -20.0)
    rows = [
        "[MSG:'$H'|'$X' to unlock]",
        "ok",
        "<Idle|MPos:-100.000,-50.000,-15.000|FS:0,0|WCO:-100.000,-50.000,-20.000>",
    ]
    for y in (0.0, 10.0):
        for x in (0.0, 10.0, 20.0) if y == 0 else (20.0, 10.0, 0.0):
            z = plane(x, y)
            rows.append(">>> G38.2 Z-2 F100")
            rows.append(f"[PRB:{x + wco[0]:.3f},{y + wco[1]:.3f},{z + wco[2]:.3f}:1]")
            rows.append("ok")
    log = tmp_path / "console.log"
    log.write_text("\n".join(rows) + "\n")
    f = fields.read(log)
    assert isinstance(f, fields.GridField)
    np.testing.assert_allclose(f.xs, [0, 10, 20]) and np.testing.assert_allclose(f.ys, [0, 10])
    q = np.array([[5.0, 5.0, 0.0], [17.0, 2.0, 0.0]])
    np.testing.assert_allclose(f(q)[:, 2], plane(q[:, 0], q[:, 1]), atol=5e-4)  # a plane: bilinear is exact


def test_grbl_plain_capture_with_the_offsets_report_and_two_touches(tmp_path):
    g54, g92, tlo = (-10.0, -20.0, -30.0), (1.0, 2.0, 3.0), 0.5
    rows = [
        f"[G54:{g54[0]:.3f},{g54[1]:.3f},{g54[2]:.3f}]",
        "[G55:0.000,0.000,0.000]",
        f"[G92:{g92[0]:.3f},{g92[1]:.3f},{g92[2]:.3f}]",
        f"[TLO:{tlo:.3f}]",
        "[PRB:0.000,0.000,0.000:0]",
        "ok",
    ]  # the `$#` report's last line: no probe since power-up
    off = np.add(g54, g92) + [0, 0, tlo]
    for x, y in ((0, 0), (10, 0), (10, 10), (0, 10)):
        z = plane(x, y)
        rows.append(f"[PRB:{x + off[0]:.3f},{y + off[1]:.3f},{z + off[2] - 0.3:.3f}:1]")  # the fast touch
        rows.append(f"[PRB:{x + off[0]:.3f},{y + off[1]:.3f},{z + off[2]:.3f}:1]")  # the slow one counts
    rows += rows[:4] + [rows[-1], "ok"]  # `$#` again at the end: its PRB repeats the last probe
    log = tmp_path / "capture.txt"
    log.write_text("\n".join(rows) + "\n")
    f = fields.read(log)
    assert isinstance(f, fields.GridField) and f.dz.shape == (2, 2)
    q = np.array([[4.0, 7.0, 0.0]])
    assert f(q)[0, 2] == pytest.approx(plane(4.0, 7.0), abs=5e-4)


@pytest.mark.parametrize(
    "text, line, col, msg",
    [
        ("[PRB:1.000,2.000,3.000:1]\n", 1, 1, "holds no work offset"),
        ("WCO:0,0,0\n[PRB:1.000,2.000,3.000:0]\n", 2, 1, "success flag 0"),
        ("WCO:0,0,0\n[PRB:1.000,x,3.000:1]\n", 2, 12, "probe position: expected a number, found 'x'"),
        ("$13=1\nWCO:0,0,0\n[PRB:1,2,3:1]\n", 1, 1, "inches"),
        ("WCO:0,0,0\n[PRB:1,2:1]\n", 2, 6, "needs x,y,z"),
    ],
)
def test_grbl_log_errors_are_located(tmp_path, text, line, col, msg):
    p = tmp_path / "g.log"
    p.write_text(text)
    with pytest.raises(InputError, match=re.escape(msg)) as e:
        fields.read(p)
    assert (e.value.line, e.value.col) == (line, col)


def hmap_text(nodes, size=(3, 2), lo=(0.0, 0.0), hi=(20.0, 10.0)):
    pts = "".join(f'  <point X="{i}" Y="{j}">{v}</point>\n' for (i, j), v in nodes.items())
    return (
        f'<?xml version="1.0" encoding="utf-8"?>\n<heightmap MinX="{lo[0]}" MinY="{lo[1]}" MaxX="{hi[0]}" '
        f'MaxY="{hi[1]}" SizeX="{size[0]}" SizeY="{size[1]}">\n{pts}</heightmap>\n'
    )


def test_opencncpilot_hmap(tmp_path):
    nodes = {(i, j): f"{plane(10.0 * i, 10.0 * j):.4f}" for i in range(3) for j in range(2)}
    p = tmp_path / "m.hmap"
    p.write_text(hmap_text(nodes))
    f = fields.read(p)
    np.testing.assert_allclose(f.xs, [0, 10, 20])
    assert f(np.array([[13.0, 4.0, 0.0]]))[0, 2] == pytest.approx(plane(13.0, 4.0), abs=1e-4)
    del nodes[(2, 1)]
    p.write_text(hmap_text(nodes))
    with pytest.raises(InputError, match="1 of 6 nodes not probed, e.g. X=2 Y=1") as e:
        fields.read(p)
    assert e.value.line == 2
    nodes[(3, 1)] = "0.1"
    p.write_text(hmap_text(nodes))
    with pytest.raises(InputError, match="X=3 is beyond the map's SizeX=3") as e:
        fields.read(p)
    assert e.value.line == 8
    p.write_text("<heightmap MinX='0'")
    with pytest.raises(InputError, match="not well-formed XML") as e:
        fields.read(p)
    assert e.value.line == 1


def candle_text(rows, head=("0;0;20;10", "3;2;-1;1", "0;10;10")):
    return "\r\n".join([*head, *(";".join(r) for r in rows)]) + "\r\n"


def test_candle_map(tmp_path):
    rows = [[f"{plane(10.0 * j, 10.0 * i):.4f}" for j in range(3)] for i in range(2)]
    p = tmp_path / "m.map"
    p.write_text(candle_text(rows))
    f = fields.read(p)
    np.testing.assert_allclose(f.ys, [0, 10])
    assert f(np.array([[3.0, 9.0, 0.0]]))[0, 2] == pytest.approx(plane(3.0, 9.0), abs=1e-4)
    rows[1][1] = "abc"
    p.write_text(candle_text(rows))
    with pytest.raises(InputError, match="height: expected a number, found 'abc'") as e:
        fields.read(p)
    assert (e.value.line, e.value.col) == (5, len(rows[1][0]) + 2)
    rows[1] = rows[1][:2]
    p.write_text(candle_text(rows))
    with pytest.raises(InputError, match="expected 3 values") as e:
        fields.read(p)
    assert e.value.line == 5


def test_height_maps_correct_a_program_through_the_cli(tmp_path):
    rows = [[f"{plane(10.0 * j, 10.0 * i):.4f}" for j in range(3)] for i in range(2)]
    (tmp_path / "m.map").write_text(candle_text(rows))
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90\nG0 X0 Y0 Z1\nG1 X20 Y10 Z0 F100\nM2\n")
    out = tmp_path / "o.ngc"
    r = run(["correct", prog, "--field", tmp_path / "m.map", "-o", out])
    assert r.exit_code == 0, r.output
    for line in out.read_text().splitlines():
        m = re.match(r"G1 X([-\d.]+) Y([-\d.]+) Z([-\d.]+)", line) or re.match(
            r"X([-\d.]+) Y([-\d.]+) Z([-\d.]+)", line
        )
        if m:
            x, y, z = map(float, m.groups())
            # Z of the line from (0, 0, 1) to (20, 10, 0) plus the plane
            assert z == pytest.approx(1 - x / 20 + plane(x, y), abs=2e-4)
    r = run(["correct", prog, "--field", tmp_path / "nothing.hmap", "-o", out])
    assert r.exit_code == 2


# ------------------------------------------------------------------------------------ CAD faces
def plane_step(path: Path, z=5.0, size=(50.0, 30.0)) -> Path:
    """A STEP file of one planar face, z = ``z`` over [0, w] x [0, h], built with OpenCASCADE."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    face = BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0, 0, z), gp_Dir(0, 0, 1)), 0.0, size[0], 0.0, size[1]).Face()
    w = STEPControl_Writer()
    w.Transfer(face, STEPControl_AsIs)
    w.Write(str(path))
    return path


@needs_rs274
def test_points_on_a_plane_face_probed_along_the_normal(tmp_path):
    step = plane_step(tmp_path / "plate.step")
    out, plan = tmp_path / "insp.ngc", tmp_path / "plan.csv"
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
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
            out,
            "--plan",
            plan,
        ]
    )
    assert r.exit_code == 0, r.output
    p = probing.read_plan(plan)
    assert len(p.nominal) == 12 and p.stylus_radius == 1.5
    np.testing.assert_allclose(p.nominal[:, 2], 5.0, atol=1e-9)
    np.testing.assert_allclose(p.normal, np.tile([0, 0, 1.0], (12, 1)), atol=1e-12)
    x, y = p.nominal[:, 0], p.nominal[:, 1]
    assert np.minimum.reduce([x, 50 - x, y, 30 - y]).min() >= 1.5 - 1e-6  # the stylus stays off the edges
    calls = rs274(out)
    probes = [c for k, c in calls if k == "STRAIGHT_PROBE"]
    np.testing.assert_allclose(probes, p.nominal - 1.0 * p.normal, atol=1e-4)
    starts = [calls[i - 1][1] for i, (k, _) in enumerate(calls) if k == "STRAIGHT_PROBE"]
    np.testing.assert_allclose(starts, p.nominal + 3.0 * p.normal, atol=1e-4)


def test_adaptive_points_gather_where_the_face_bends(tmp_path):
    from ncadapt import cad
    from ncadapt.sim import freeform as ff

    part = ff.demo_part()
    step = cad.write(part, tmp_path / "part.step")
    face = cad.faces(cad.read_shape(step))[0]
    uni = probing.face_points(face, 150, margin=2.0)
    ada = probing.face_points(face, 150, margin=2.0, adaptive=True)
    assert len(ada.points) == 150 and ada.edge_distance.min() >= 2.0
    # the curvature by ncadapt's own surface (not OpenCASCADE): larger on average at the adaptive points
    k = lambda q: np.abs(part.mean_curvature(q[:, 0], q[:, 1])).mean()  # noqa: E731
    assert k(ada.points) > 1.2 * k(uni.points)  # measured: 1.24
    # and the points lie on the part
    np.testing.assert_allclose(ada.points[:, 2], part.point(ada.points[:, 0], ada.points[:, 1])[..., 2], atol=1e-6)


def test_points_from_a_file_must_lie_on_the_face(tmp_path):
    step = plane_step(tmp_path / "plate.step")
    pts = tmp_path / "pts.csv"
    pts.write_text("x,y,z\n10,10,5\n20,10,5.5\n")
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--points",
            pts,
            "--stylus-radius",
            "1",
            "--approach",
            "2",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "-o",
            tmp_path / "o.ngc",
        ]
    )
    assert r.exit_code == 2
    assert f"{pts}:3:1: error: point 20 10 5.5 is 0.5000 mm from face 1" in r.output
    assert not (tmp_path / "o.ngc").exists()
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--n",
            "4",
            "--stylus-radius",
            "2",
            "--approach",
            "2",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "-o",
            tmp_path / "o.ngc",
        ]
    )
    assert r.exit_code == 2 and "error: --approach: 2 mm must exceed --stylus-radius 2 mm" in r.output
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--face",
            "2",
            "--n",
            "4",
            "--stylus-radius",
            "1",
            "--approach",
            "2",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "-o",
            tmp_path / "o.ngc",
        ]
    )
    assert r.exit_code == 2 and "the CAD file has faces 1 to 1" in r.output
    bad = tmp_path / "bad.step"
    bad.write_text("ISO-10303-21;\nnonsense\n")
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            bad,
            "--n",
            "4",
            "--stylus-radius",
            "1",
            "--approach",
            "2",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "-o",
            tmp_path / "o.ngc",
        ]
    )
    assert r.exit_code == 2 and str(bad) in r.output


def test_points_grbl_program_keeps_grbl_grammar(tmp_path):
    step = plane_step(tmp_path / "plate.step")
    out = tmp_path / "g.nc"
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--n",
            "6",
            "--stylus-radius",
            "1",
            "--approach",
            "2",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "--fast-feed",
            "400",
            "--dialect",
            "grbl",
            "-o",
            out,
        ]
    )
    assert r.exit_code == 0, r.output
    assert grbl_errors(out.read_text()) == []


# ------------------------------------------------------------------------------------ plan + log
def test_plan_pairs_with_the_log(tmp_path):
    """Logged ball centres at p + (r + e) n give the deviations e back, through `analyze PLAN`."""
    step = plane_step(tmp_path / "plate.step")
    plan = tmp_path / "plan.csv"
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--n",
            "20",
            "--stylus-radius",
            "1.5",
            "--approach",
            "3",
            "--overtravel",
            "1",
            "--feed",
            "100",
            "-o",
            tmp_path / "o.ngc",
            "--plan",
            plan,
        ]
    )
    assert r.exit_code == 0, r.output
    p = probing.read_plan(plan)
    e = 0.01 * np.sin(np.arange(20))
    c = p.nominal + (1.5 + e)[:, None] * p.normal
    (tmp_path / "probe-log.txt").write_text(
        "".join(" ".join(f"{v:f}" for v in (*q, 0, 0, 0, 0, 0, 0)) + "\n" for q in c)
    )
    m = measure.read(plan)
    np.testing.assert_allclose(m.deviation, e, atol=2e-6)
    assert m.ids[0] == "P1"
    r = run(["analyze", plan, "--json", tmp_path / "a.json"])
    assert r.exit_code == 0, r.output
    # the log is an input of analyze and compensate: no output may replace it
    log = (tmp_path / "probe-log.txt").read_bytes()
    for args in (
        ["analyze", plan, "--json", tmp_path / "probe-log.txt"],
        ["compensate", plan, "--points-out", tmp_path / "probe-log.txt"],
    ):
        r = run(args)
        assert r.exit_code == 2 and "probe log" in r.output, r.output
        assert (tmp_path / "probe-log.txt").read_bytes() == log
    # a log that stopped early (a probe did not touch) is refused, naming the point
    (tmp_path / "probe-log.txt").write_text("".join(" ".join(f"{v:f}" for v in q) + "\n" for q in c[:7]))
    with pytest.raises(
        InputError,
        match=r"the log has 7 probed point\(s\), the plan 20: the probing stopped before "
        r"point P8 \(plan line 12\)",
    ):
        measure.read(plan)
    (tmp_path / "probe-log.txt").unlink()
    r = run(["analyze", plan])
    assert r.exit_code == 2 and "probe-log.txt' is not beside the plan" in r.output


# ------------------------------------------------------------------------------------ virtual probe
def flat_zmap(h=2.0):
    from ncadapt.sim.freeform import ZMap

    return ZMap(0.0, 0.0, 0.25, np.full((161, 121), h))


def test_virtual_probe_trips_where_the_ball_touches(tmp_path):
    from ncadapt.sim import probing as sp

    g = probing.grid_points((10, 30, 10, 20), nx=3, ny=2)
    text = probing.grid_program(g, safe_z=10, depth=0, feed=120, dialect="linuxcnc")
    # a ball of 1.5 mm on a floor at 2: its centre stops at 3.5 (closed form); 2 ms at 120 mm/min
    # runs on 4 µm
    res = sp.run(text, flat_zmap(), stylus_radius=1.5, trigger_delay=0.002)
    np.testing.assert_allclose(res.trips[:, 2], 3.5 - 0.004, atol=2e-6)
    log = res.log.splitlines()
    assert len(log) == 6 and len(log[0].split()) == 9
    (tmp_path / "probe-log.txt").write_text(res.log)  # read back as LinuxCNC's log: a 3 x 2 grid
    f = fields.read(tmp_path / "probe-log.txt")
    assert isinstance(f, fields.GridField) and f.dz.shape == (2, 3)
    np.testing.assert_allclose(f.dz, 3.5 - 0.004, atol=2e-6)


def test_virtual_probe_stops_the_program_without_contact(tmp_path):
    from ncadapt.sim import probing as sp

    g = probing.grid_points((10, 30, 10, 20), nx=3, ny=2)
    text = probing.grid_program(g, safe_z=10, depth=3, feed=120)  # the floor at 2 is never reached by z = 3 - 0
    with pytest.raises(sp.ProbeFailure, match="without tripping") as e:
        sp.run(text, flat_zmap(), stylus_radius=0.5)
    assert e.value.log == ""
    lines = text.splitlines()
    assert lines[e.value.line - 1].startswith("G38.2")


def test_plan_with_grbl_two_touches_takes_the_slow_one(tmp_path):
    step = plane_step(tmp_path / "plate.step")
    plan = tmp_path / "plan.csv"
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--n",
            "4",
            "--stylus-radius",
            "1",
            "--approach",
            "2",
            "--overtravel",
            "1",
            "--feed",
            "50",
            "--fast-feed",
            "500",
            "--dialect",
            "grbl",
            "-o",
            tmp_path / "o.nc",
            "--plan",
            plan,
            "--log",
            "grbl.log",
        ]
    )
    assert r.exit_code == 0, r.output
    p = probing.read_plan(plan)
    assert p.touches == 2
    e = np.array([0.01, -0.02, 0.005, 0.0])
    rows = ["[G54:-100.000,-50.000,-20.000]"]
    for q, d in zip(p.nominal, e):
        for over in (0.004, 0.0):  # the fast touch runs on further
            c = q + (1 + d - over) * p.normal[0] + [-100, -50, -20]
            rows.append(f"[PRB:{c[0]:.3f},{c[1]:.3f},{c[2]:.3f}:1]")
    (tmp_path / "grbl.log").write_text("\n".join(rows) + "\n")
    np.testing.assert_allclose(measure.read(plan).deviation, e, atol=6e-4)  # grbl prints 3 decimals


def test_safe_plane_clears_the_whole_face(tmp_path):
    """The default safe plane is above the face's highest point (the demo dome's 9.895 mm, found
    on a fine grid of ncadapt's own surface) plus the approach, however few points are probed."""
    import json

    from ncadapt import cad
    from ncadapt.sim import freeform as ff

    part = ff.demo_part()
    step = cad.write(part, tmp_path / "part.step")
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--n",
            "3",
            "--stylus-radius",
            "1",
            "--approach",
            "3",
            "--overtravel",
            "1",
            "--feed",
            "50",
            "-o",
            tmp_path / "o.ngc",
            "--json",
            tmp_path / "o.json",
        ]
    )
    assert r.exit_code == 0, r.output
    x, y = np.meshgrid(np.linspace(0, 80, 401), np.linspace(0, 60, 301))
    assert json.loads((tmp_path / "o.json").read_text())["safe_z"] >= part.point(x, y)[..., 2].max() + 3
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--n",
            "3",
            "--stylus-radius",
            "1",
            "--approach",
            "3",
            "--overtravel",
            "1",
            "--feed",
            "50",
            "--safe-z",
            "9",
            "-o",
            tmp_path / "o.ngc",
        ]
    )
    assert r.exit_code == 2 and "error: --safe-z: 9 is below" in r.output


@needs_rs274
def test_points_with_two_touches_run_in_rs274(tmp_path):
    step = plane_step(tmp_path / "plate.step")
    out = tmp_path / "p2.ngc"
    r = run(
        [
            "probe",
            "points",
            "--nominal",
            step,
            "--n",
            "5",
            "--stylus-radius",
            "1",
            "--approach",
            "3",
            "--overtravel",
            "1",
            "--feed",
            "20",
            "--fast-feed",
            "200",
            "-o",
            out,
        ]
    )
    assert r.exit_code == 0, r.output
    probes = [c for k, c in rs274(out) if k == "STRAIGHT_PROBE"]
    assert len(probes) == 10
    np.testing.assert_allclose([c[2] for c in probes], 4.0, atol=1e-4)  # z = 5 − overtravel 1, both touches
    assert out.read_text().count("(LOG,#5061 #5062 #5063)") == 5


def test_companion_inputs_name_the_plans_log(tmp_path):
    plan = tmp_path / "plan.csv"
    plan.write_text(probing.plan_text([[0, 0, 0]], [[0, 0, 1]], stylus_radius=1, log="run1.txt"))
    assert probing.companion_inputs(plan) == {"probe log": tmp_path / "run1.txt"}
    other = tmp_path / "m.csv"
    other.write_text("x,y,z,i,j,k,dev\n")
    assert probing.companion_inputs(other) == {}


def test_fanuc_dprnt_logs(tmp_path):
    """DPRNT[X#5061[54]*Y#5062[54]*Z#5063[54]] prints X, the value, a space, …: as a field and
    paired with a plan."""
    rows = [f"X{x:10.4f} Y{y:10.4f} Z{plane(x, y):10.4f}" for y in (0.0, 10.0) for x in (0.0, 10.0, 20.0)]
    log = tmp_path / "fanuc.txt"
    log.write_text("\n".join(rows) + "\n")
    f = fields.read(log)
    assert isinstance(f, fields.GridField)
    assert f(np.array([[15.0, 5.0, 0.0]]))[0, 2] == pytest.approx(plane(15.0, 5.0), abs=1e-4)
    log.write_text("\n".join(rows[:2] + ["X1.0 Y2.0"] + rows[3:]) + "\n")
    with pytest.raises(InputError, match="expected a line 'X<x> Y<y> Z<z>'") as e:
        fields.read(log)
    assert e.value.line == 3
    plan = tmp_path / "plan.csv"
    nominal = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 1.0, 2.0]])
    plan.write_text(probing.plan_text(nominal, np.tile([0, 0, 1.0], (3, 1)), stylus_radius=0.5, log="fanuc.txt"))
    e_known = np.array([0.01, -0.02, 0.003])
    log.write_text("".join(f"X{q[0]:10.4f} Y{q[1]:10.4f} Z{q[2] + 0.5 + d:10.4f}\n" for q, d in zip(nominal, e_known)))
    np.testing.assert_allclose(measure.read(plan).deviation, e_known, atol=1e-9)
