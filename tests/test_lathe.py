"""Lathe programs: no Y (the tool in the plane through the spindle's axis), X a diameter under
LinuxCNC's G7 and always on a Fanuc lathe, whose U and W are increments of X and Z.

rs274 is the oracle: it reads G7 (diameter mode) and prints the radius, so the input's motion,
displaced by an analytic field evaluated at that radius, must be the output's motion as rs274
reads the output (both ways, within the chord tolerance and the printed digits). A Fanuc lathe's
U and W are given to rs274 as ``X[#5420*2+U]`` and ``Z[#5422+W]``: rs274 adds them to the
position it holds itself (``#5420`` is its X, a radius, ``#5422`` its Z).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import needs_rs274
from ncadapt import InputError, RefusedError, dialects, fields, nc
from rs274 import canonical, moves

LINUXCNC = """G21 G18 G7 G90
G0 X30 Z2
G1 Z0 F100
X10
G3 X20 Z-5 I0 K-5
G1 Z-20
G2 X30 Z-25 I5 K0
G91 G1 X4 Z-5
G90 G8 G1 X17 Z-35
G7 G1 X40 Z-36
M2
"""

FANUC = """%
O0100
G18 G21 G99
T0101
G50 S2000
G96 S200 M03
G00 X30. Z2.
G01 Z0. F0.1
X10.
G03 X20. Z-5. R5.
G01 W-15.
G02 U10. W-5. I5. K0.
G01 U4. W-5.
X40. W-1.
G04 X1.5
G28 U0. W0.
M30
%
"""


def _field(p):
    """Radial x and axial z that change fast across the radius: evaluated at the diameter, or
    at another radius, the correction would be off by far more than the tolerance."""
    p = np.asarray(p, dtype=float)
    d = np.zeros((len(p), 3))
    d[:, 0] = 0.01 * np.cos(p[:, 2] / 4) + 0.01 * np.sin(p[:, 0] / 3)
    d[:, 2] = 0.02 * np.sin(p[:, 0] / 2)
    return d


def _for_rs274(text: str) -> str:
    """A Fanuc lathe program as rs274 reads it: G7 first, U and W added to rs274's own position,
    the lines it has no use for (framing, program number, spindle limit, tool, G28) left out."""
    out = ["G7"]
    for line in text.splitlines():
        if line in ("%",) or line.startswith(("O", "G50", "T", "G28")):
            continue
        line = re.sub(r"\bU(-?[\d.]+)", r"X[#5420*2+\1]", line)
        line = re.sub(r"\bW(-?[\d.]+)", r"Z[#5422+\1]", line)
        out.append(line.replace("G04 X", "G04 P"))
    return "\n".join(out) + "\n"


def _path(tmp_path, text, name):
    path = tmp_path / name
    path.write_text(text)
    c = canonical(path)
    assert c.error is None, f"{name}: {c.error}"
    mv = moves(c)[1:]  # (the first move comes from where rs274 starts, the origin)
    assert mv
    return np.concatenate([m.dense(step=0.002, sagitta=1e-7) for m in mv])


def _check_displaced(tmp_path, inp_text, out_text, tol):
    inp = _path(tmp_path, inp_text, "in.ngc")
    out = _path(tmp_path, out_text, "out.ngc")
    assert np.abs(inp[:, 1]).max() == 0 and np.abs(out[:, 1]).max() == 0  # no Y
    want = inp + _field(inp)
    far = max(cKDTree(want).query(out)[0].max(), cKDTree(out).query(want)[0].max())
    assert far <= tol, far
    # (not by chance: the field moves the path by up to 28 µm, evaluated at the diameter by other amounts)
    assert np.abs(_field(inp)).max() > 0.015
    assert np.abs(_field(inp * [2, 1, 1]) - _field(inp)).max() > 10 * tol


@needs_rs274
def test_linuxcnc_lathe_is_corrected_at_the_radius(tmp_path):
    out = nc.parse(LINUXCNC, dialect="linuxcnc-lathe").correct(_field, rapids=True)
    assert out.correction.blocks_changed >= 8
    _check_displaced(tmp_path, LINUXCNC, out.text, 0.0035)


@needs_rs274
def test_fanuc_lathe_is_corrected_with_its_diameters_and_increments(tmp_path):
    out = nc.parse(FANUC, dialect="fanuc-lathe").correct(_field, rapids=True)
    assert out.correction.blocks_changed >= 8
    # written in the program's words: diameters, increments kept increments, the dwell as it was
    assert "G04 X1.5\n" in out.text and "G28 U0. W0.\n" in out.text
    assert re.search(r"^G01 U[-\d.]+ W[-\d.]+$", out.text, re.M)
    _check_displaced(tmp_path, _for_rs274(FANUC), _for_rs274(out.text), 0.0035)


@pytest.mark.parametrize(("text", "dialect"), [(LINUXCNC, "linuxcnc-lathe"), (FANUC, "fanuc-lathe")])
def test_a_zero_field_gives_the_lathe_program_back(text, dialect):
    assert nc.parse(text, dialect=dialect).correct(fields.Shift((0, 0, 0))).text == text


def test_a_shift_moves_a_diameter_by_twice_the_radius():
    # 0.05 mm outwards: every X a diameter 0.1 larger, U and W kept (both ends move alike)
    out = nc.parse(FANUC, dialect="fanuc-lathe").correct(fields.Shift((0.05, 0, 0)), rapids=True)
    assert "X10.1\n" in out.text and "G03 X20.1 Z-5. R5.\n" in out.text
    assert "G02 U10. W-5. I5. K0.\n" in out.text and "X40.1 W-1.\n" in out.text


def test_the_field_s_y_is_not_applied_on_a_lathe(tmp_path):
    prog = nc.parse(FANUC, dialect="fanuc-lathe")
    # within the chord tolerance: left out (the machine has no Y)
    out = prog.correct(fields.Shift((0.05, 0.001, 0)), rapids=True)
    assert "Y" not in out.text
    assert out.text == prog.correct(fields.Shift((0.05, 0, 0)), rapids=True).text
    with pytest.raises(RefusedError, match="a lathe has no Y axis"):
        prog.correct(fields.Shift((0, 0.01, 0)))
    # a field evaluated in Python: refused at the line where it moves Y
    src = tmp_path / "p.nc"
    src.write_text(FANUC)

    def tilted(p):
        d = _field(p)
        d[:, 1] = 0.01
        return d

    with pytest.raises(RefusedError, match=r"line \d+: the field moves Y by 0.0100 mm"):
        nc.correct_file(src, tmp_path / "o.nc", tilted, dialect="fanuc-lathe")
    assert not (tmp_path / "o.nc").exists()


def _unsupported(text, dialect="fanuc-lathe"):
    return [(u.line, u.construct) for u in nc.parse(text, dialect=dialect).unsupported]


def test_what_a_lathe_program_does_that_is_not_followed_is_refused_at_its_line():
    head = "O1\nG18 G21\nG0 X20. Z1.\n"
    # G-code system A's turning cycle, where a block runs it (G90 alone sets it up)
    assert _unsupported(head + "G90 X18. Z-10. F0.2\nX16.\nG0 X30.\nM30\n")[0] == (
        4,
        "turning cycle G90 (a Fanuc lathe's, G-code system A)",
    )
    assert _unsupported(head + "G90 G54\nG01 X18. Z-10. F0.2\nM30\n") == []
    # and after G80 the cycle is still the motion (group 01): its axis words are not a G1 move
    assert _unsupported(head + "G01 X19. F0.2\nG90 X18. Z-10.\nG80\nX16.\nM30\n")[-1] == (
        7,
        "axis words with no motion mode (G80 or none yet)",
    )
    for code, what in [
        ("G71 P10 Q20 U0.2 W0.1 D1. F0.2", "lathe cycle G71"),
        ("G76 X10. Z-5. K1. D.2 F1.", "lathe cycle G76"),
    ]:
        assert _unsupported(head + code + "\nM30\n") == [(4, what)]
    assert "G91 on a Fanuc lathe" in _unsupported(head + "G91\nG1 X1. F0.2\nM30\n")[0][1]
    assert "Y word on a lathe" in _unsupported(head + "G1 Y1. F0.2\nM30\n")[0][1]
    assert "C word on a Fanuc lathe" in _unsupported(head + "G1 X10. C1. F0.2\nM30\n")[0][1]
    with pytest.raises(InputError, match="X and U in one block"):
        _ = nc.parse(head + "G1 X10. U1. F0.2\nM30\n", dialect="fanuc-lathe").blocks
    # LinuxCNC: X before the program says whether it is a diameter (G7) or a radius (G8)
    assert "X before G7 or G8" in _unsupported("G18 G21\nG0 X10 Z1\nG7\nG1 X8\nM2\n", "linuxcnc-lathe")[0][1]
    assert _unsupported("G18 G21 G8\nG0 X10 Z1\nG7\nG1 X8\nM2\n", "linuxcnc-lathe") == []


def test_a_dwell_moves_nothing():
    # Fanuc: G04 X is the dwell's time (seconds), not a move
    text = "O1\nG21 G17\nG0 X0. Y0. Z0.\nG1 X1. F100.\nG04 X1.5\nG04 P500\nM30\n"
    out = nc.parse(text, dialect="fanuc").correct(fields.Shift((0.01, 0, 0)))
    assert "G04 X1.5\n" in out.text and "G1 X1.01 F100.\n" in out.text
    with pytest.raises(InputError, match="axis words in a G04 block"):
        _ = nc.parse("O1\nG0 X0. Y0. Z0.\nG04 X1. Z1.\nM30\n", dialect="fanuc").blocks
    # LinuxCNC wants P (rs274: "Dwell time missing with g4")
    with pytest.raises(InputError, match="dwell time missing with G4"):
        _ = nc.parse("G21\nG0 X0 Y0 Z0\nG4 X1.5\nM2\n").blocks


@pytest.mark.parametrize(
    ("text", "dialect", "line"),
    [
        ("O1\nG18\nT0101\nG0 X10. Z1.\n", "fanuc", 3),
        ("O1\nG97 S500\nG96 S200 M3\n", "fanuc", 3),
        ("O1\n(G96 in a comment)\nG50 S2500\n", "fanuc", 3),
        ("O1\nG0 X10. Z1.\nG71 P10 Q20 U.2 W.1 D1. F.2\n", "fanuc", 3),
        ("G21\nG18 G7\nG0 X10 Z1\n", "linuxcnc", 2),
    ],
)
def test_a_lathe_s_program_is_detected(tmp_path, text, dialect, line):
    p = tmp_path / "p.nc"
    p.write_text(text)
    d = dialects.resolve(p)
    assert (d.name, d.lathe, d.machine_line, d.engine) == (dialect, True, line, f"{dialect}-lathe")
    assert dialects.resolve(p, machine="mill").engine == dialect


@pytest.mark.parametrize(
    "text",
    [
        "O1\nG17 G90\nT1 M6\nG43 H1 Z10.\nG81 X1. Y1. Z-1. R1. F100.\n",  # a mill: T1, a G81
        "O1\nG50\nG51 X0. Y0. P2.\n",  # a Fanuc mill's scaling off and on
        "O1\nG73 X1. Y1. Z-2. R1. Q.5 P100 F50.\n",  # a mill's peck drilling
        "G21\nG70 G71\n",  # (not LinuxCNC's lathe codes)
    ],
)
def test_a_mill_s_program_is_not_a_lathe_s(tmp_path, text):
    p = tmp_path / "p.nc"
    p.write_text(text)
    assert not dialects.resolve(p).lathe


def test_the_corpus_lathe_programs_are_detected():
    folder = Path(__file__).resolve().parents[1] / ".." / "shared" / "corpus" / "nc"
    if not folder.is_dir():
        pytest.skip("the shared corpus is not beside the repository")
    lathes = sorted(p.name for p in folder.iterdir() if p.suffix != ".tsv" and p.name != "README.md" and _lathe(p))
    assert lathes == ["haas__lathe_241006_weld_pin.nc", "linuxcnc__lathe_pawn.ngc"]


def _lathe(p):
    try:
        return dialects.resolve(p).lathe
    except InputError:  # (a dialect the engine does not read)
        return False
