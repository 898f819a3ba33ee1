"""Dialect detection: the controller family a program is written for, and the refusal of those
whose syntax the engine does not read (Sinumerik, Heidenhain), located at the line that shows it."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from corpus import CORPUS, manifest
from ncadapt import InputError, RefusedError, dialects, fields, nc
from ncadapt.cli import main

CASES = [
    # (program, expected dialect, expected evidence line)
    ("BEGIN PGM CIRSTUD  MM\nL Z-10 FMAX\n", "heidenhain", 1),
    ("1 BEGIN PGM 12 MM\n", "heidenhain", 1),
    ("; part\nN10 G0 X=10 Y20\n", "sinumerik", 2),
    ("G90\nX=IC(5)\n", "sinumerik", 2),
    ("DEF REAL R_A\nG0 X0\n", "sinumerik", 1),
    ("G0 X0\nCYCLE81(10, 0, 2, -5)\n", "sinumerik", 2),
    ("G0 X0\nG2 X10 Y0 CR=5\n", "sinumerik", 2),
    ("G0 X0\nTRANS X10\n", "sinumerik", 2),
    (";FLAVOR:Marlin\nG28\n", "marlin", 1),
    ("G21\nM82\nG1 X1 E0.5\n", "marlin", 2),
    ("G21\nG1 X10 Y5 E0.33 F1200\n", "marlin", 2),
    ("$H\nG0 X0\n", "grbl", 1),
    ("G21\n$J=G91 X10 F100\n", "grbl", 2),
    ("%\nO1234\nG0 X0\n%\n", "fanuc", 2),
    ("G0 X0\nM98 P1000 L2\n", "fanuc", 2),
    # LinuxCNC: O-word subroutines, named parameters, comments that look like other syntax
    ("o100 sub\nG0 X0\no100 endsub\no100 call\nM2\n", "linuxcnc", None),
    ("O200 if [#1 GT 0]\nO200 endif\nM2\n", "linuxcnc", None),
    ("#<x> = 5\nG0 X#<x>\nM2\n", "linuxcnc", None),
    ("G0 X0 (X=5 is a comment)\nG70 ; G70=inch on a Siemens control\nM2\n", "linuxcnc", None),
    ("G21 G90\nG1 X10 F100\nM2\n", "linuxcnc", None),
    # LinuxCNC's names are no other dialect's words (ngcgui's #<scale>, a kinematics' x-rot-point)
    ("#<scale> = 1.0\n#<_hal[kins.x-rot-point]> = 2\no<rot> call\nG0 X#<scale>\nM2\n", "linuxcnc", None),
    # plasmac's user M code M190 takes P (Marlin's bed heater M190 takes S); M67/M68 take E
    ("G21\nM190 P1 (material #1)\nM66 P3 L3 Q1\nG1 X10 F100\nM2\n", "linuxcnc", None),
    ("G21\nM68 E0 Q0\nG1 X5 M67 E2 Q25 F100\nM2\n", "linuxcnc", None),
    ("G21\nM190 S60\nG1 X1 F100\n", "marlin", 2),
    # FABtotum's laser programs: a dwell in seconds
    (";laser\nG4 S1\nM728\nG1 X1 F100\n", "marlin", 2),
]


@pytest.mark.parametrize("text, name, line", CASES)
def test_detection(text, name, line):
    d = dialects.detect(text.encode())
    assert (d.name, d.line) == (name, line)
    assert d.detected


def test_sinumerik_file_names_and_a_cut_last_line():
    assert dialects.detect(b"G0 X0\n", "PART.MPF").name == "sinumerik"
    assert dialects.detect(b"G0 X0\n", "sub.spf").name == "sinumerik"
    # the head is cut inside a line: that line is not read (its start could look like anything)
    head = b"(" + b"x" * (dialects.HEAD_BYTES - 9) + b")\nG0 X=5"
    assert len(head) == dialects.HEAD_BYTES
    assert dialects.detect(head).name == "linuxcnc"


def test_unread_dialects_are_refused_at_their_line(tmp_path):
    p = tmp_path / "p.h"
    p.write_text("BEGIN PGM P MM\nL X+10 FMAX\nEND PGM P MM\n")
    with pytest.raises(InputError) as e:
        dialects.resolve(p)
    assert (e.value.line, e.value.col) == (1, 1) and "Heidenhain" in e.value.message
    # a Sinumerik program is read (run into straight G-code); --dialect linuxcnc reads it as RS274NGC
    q = tmp_path / "q.mpf"
    q.write_text("G0 X0 Y0\nG1 X10 F100\nM30\n")
    assert dialects.resolve(q) == dialects.Dialect("sinumerik", True, 1, "the file name q.mpf")
    assert dialects.resolve(q, "linuxcnc") == dialects.Dialect("linuxcnc", False)


def test_cli_reports_the_dialect_and_refuses_with_nothing_written(tmp_path):
    r = CliRunner()
    prog = tmp_path / "p.nc"
    prog.write_text("%\nO1001\nG21 G90 G0 X0 Y0 Z5.\nG1 Z-1. F100\nG1 X10.\nM30\n%\n")
    res = r.invoke(main, ["correct", str(prog), "--shift", "0,0,0.01", "-o", str(tmp_path / "o.nc"), "--json", "-"])
    assert res.exit_code == 0, res.output
    payload = json.loads(res.stdout)
    assert payload["dialect"] == {
        "name": "fanuc",
        "detected": True,
        "line": 2,
        "evidence": "O1001",
        "machine": {"name": "mill", "detected": True, "line": None, "evidence": None},
    }
    assert payload["options"]["dialect"] == "auto"
    assert payload["field_interpolation"] == "a constant shift"
    grid = tmp_path / "g.csv"
    grid.write_text("x,y,dz\n" + "".join(f"{x},{y},0.01\n" for y in (-1, 5, 11) for x in (-1, 11)))
    res = r.invoke(main, ["correct", str(prog), "--field", str(grid), "-o", str(tmp_path / "o2.nc")])
    assert res.exit_code == 0 and "field: grid 2 x 3 (bilinear), outside the grid: error" in res.stdout
    res = r.invoke(main, ["inspect", str(prog), "--dialect", "grbl"])
    assert res.exit_code == 0 and "dialect: grbl (given)" in res.stdout

    hei = tmp_path / "h.h"
    hei.write_text("; part\nBEGIN PGM P MM\nL X+10 FMAX\nEND PGM P MM\n")
    out = tmp_path / "h_out.h"
    res = r.invoke(main, ["correct", str(hei), "--shift", "0,0,0.01", "-o", str(out)])
    assert res.exit_code == 2
    assert f"{hei}:2:1: error: a Heidenhain conversational (Klartext) program (BEGIN PGM P MM)" in res.stderr
    assert not out.exists()
    sie = tmp_path / "s.mpf"
    sie.write_text("; part\nG0 X0 Y0\nG1 X=10 F100\nM30\n")
    res = r.invoke(main, ["correct", str(sie), "--shift", "0,0,0.01", "-o", str(tmp_path / "s_out.mpf")])
    assert res.exit_code == 0 and "dialect: Sinumerik 840D (detected, line 3: G1 X=10 F100)" in res.stdout


@pytest.mark.skipif(not CORPUS.is_dir(), reason="no corpus at ../shared/corpus/nc")
def test_corpus_dialects_are_detected():
    # the manifest's dialect is the corpus' own record of where each program comes from
    expect = {"Heidenhain": "heidenhain", "Sinumerik": "sinumerik", "Fanuc/Haas": "fanuc"}
    seen = {}
    for e in manifest():
        d = dialects.detect(e.path.read_bytes()[: dialects.HEAD_BYTES], e.file)
        if e.dialect in expect:
            assert d.name == expect[e.dialect], e.file
        if e.dialect == "Marlin":
            seen[e.file] = d.name
        if e.dialect.startswith("LinuxCNC") or e.dialect.startswith("FreeCAD"):
            assert d.name == "linuxcnc" or (d.name == "fanuc" and b"M98" in e.path.read_bytes()), e.file
    # every slicer's output is Marlin; a laser program of the same firmware family writes none of its codes
    assert sum(v == "marlin" for v in seen.values()) >= len(seen) - 1


GRBL = "$X\nG21 G90 G0 X0 Y0 Z5\nG1 Z-1 F100\nG1 X10\n$H\nG0 X0 Y0 Z5\nG1 Z-1\n$J=G91 X1 F100\nG1 X3 Y0 Z-1\nM30\n"


def test_grbl_system_commands_are_copied_and_homing_or_jog_forgets_the_position(tmp_path):
    prog = nc.parse(GRBL)
    assert prog.correct(fields.Shift((0, 0, 0))).data == prog.data
    out = prog.correct(fields.Shift((0, 0, 0.01)))
    # the cuts before and after homing are corrected from their known starts (hand-derived: Z -1
    # moves to -0.99; X10 at the corrected depth needs no new Z word); after the jog every axis the
    # block names is known again, so the move is corrected too: it keeps its X3 Y0 and its Z moves
    want = GRBL.replace("G1 Z-1 F100", "G1 Z-0.99 F100").replace("G1 Z-1\n", "G1 Z-0.99\n")
    assert out.text == want.replace("G1 X3 Y0 Z-1", "G1 X3 Y0 Z-0.99")
    notes = [n for n in out.correction.notes if "grbl homing or jog" in n[1]]
    assert [n[0] for n in notes] == [5, 8]


def test_grbl_settings_are_refused_at_their_line():
    prog = nc.parse("$100=250\nG0 X0 Y0 Z0\nG1 X1 F10\n$RST=#\n")
    assert [(u.line, u.col) for u in prog.unsupported] == [(1, 1), (4, 1)]
    assert all("grbl setting" in u.construct for u in prog.unsupported)
    with pytest.raises(RefusedError):
        prog.correct(fields.Shift((0, 0, 0.01)))


# A Fanuc-family control reads a length written without a decimal point in least input increments
# (IS-B: X10 is 0.010 mm, 0.0010 inch) unless parameter 3401#0 (DPI) makes it units: Fanuc's
# "decimal point programming" (addresses X Y Z U V W A B C I J K Q R F; Mitsubishi's Fanuc-style
# M700V manual, 5.3 "Decimal point input", states the same rule and addresses). LinuxCNC reads
# X10 as 10 (rs274 below).
FANUC_DECIMALS = [
    # (program body, refused at (line, col) or None)
    ("G21 G90 G0 X0 Y0 Z5.\nG1 Z-1. F100\nG1 X10 Y0\n", (5, 4)),
    ("G21 G90 G0 X0 Y0 Z5.\nG1 Z-1. F100\nG1 X10. Y0\nG3 X0 Y0 I-5 J0\n", (6, 10)),
    ("G20 G90 G0 X0 Y0 Z5.\nG98 G81 X1. Y1. Z-1. R1 F10\n", (4, 22)),
    # zero is zero either way; F S T M P L N D H are not lengths counted in increments
    ("G21 G90 G0 X0 Y0 Z5.\nN10 G1 Z-1. F100 S1200 M3\nG4 P500\nG1 X10. Y0 Z0\n", None),
]


@pytest.mark.parametrize("body,at", FANUC_DECIMALS)
def test_fanuc_lengths_without_a_decimal_point_are_refused(tmp_path, body, at):
    prog = tmp_path / "p.nc"
    prog.write_text("%\nO1001\n" + body + "M30\n%\n")
    out = tmp_path / "o.nc"
    res = CliRunner().invoke(main, ["correct", str(prog), "--shift", "0,0,0.01", "-o", str(out)])
    if at is None:
        assert res.exit_code == 0, res.output
        return
    assert res.exit_code == 2 and not out.exists(), res.output
    assert f"{prog}:{at[0]}:{at[1]}: error: " in res.stderr and "has no decimal point" in res.stderr, res.stderr
    assert "write the point" in res.stderr
    for given in ("fanuc", "auto"):
        res = CliRunner().invoke(main, ["inspect", str(prog), "--dialect", given])
        assert res.exit_code == 2, res.output
    # the same text as LinuxCNC's RS274NGC is read in units
    res = CliRunner().invoke(main, ["correct", str(prog), "--shift", "0,0,0", "--dialect", "linuxcnc", "-o", str(out)])
    assert res.exit_code == 0 and out.read_bytes() == prog.read_bytes(), res.output
    with pytest.raises(InputError, match="has no decimal point"):
        nc.read(prog, dialect="fanuc")


def test_linuxcnc_reads_a_number_without_a_point_in_units(tmp_path):
    """rs274's own reading: X10 moves to X10 mm."""
    from conftest import needs_rs274  # noqa: F401
    from rs274 import RS274, canonical

    if RS274 is None:
        pytest.skip("LinuxCNC's rs274 is not installed")
    p = tmp_path / "p.ngc"
    p.write_text("G21 G90 G0 X0 Y0 Z5\nG1 X10 F100\nM2\n")
    c = canonical(p)
    assert c.error is None and c.ends[-1, 0] == pytest.approx(10.0)
    assert nc.read(p).blocks.end[-1, 0] == pytest.approx(10.0)


FANUC_G80 = (
    "G21 G90 G17\nG0 X0. Y0. Z10.\nG1 Z5. F100.\nG98 G81 X5. Y5. Z-2. R1. F100.\nX10.\nG80\nX1. Y1.\nG0 Z20.\nM30\n"
)


def test_fanuc_g80_leaves_the_motion_before_the_cycle():
    """On a Fanuc control canned cycles are a modal group of their own (09): G80 cancels them and
    the G0/G1/G2/G3 in force before them moves the next axis words (here G1, a feed), where
    LinuxCNC — one group for both, G80 leaving no motion — refuses the same block as rs274 does."""
    prog = nc.parse(FANUC_G80, dialect="fanuc")
    after = prog.blocks.motion[prog.blocks.line == 7]
    assert list(after) == [nc.MOTIONS.index("feed")]
    with pytest.raises(RefusedError, match="unsupported"):
        nc.parse(FANUC_G80).correct(fields.Shift((0, 0, 0.05)))
    assert any("no motion mode" in u.construct for u in nc.parse(FANUC_G80).unsupported)


def test_fanuc_cycles_expanded_keep_the_program_s_motion_after_g80():
    """Written as moves, a cycle leaves the output in G0; the block after G80 relies on the
    program's G1, so the output writes G1 into it. Kept a cycle block, nothing needs adding."""
    prog = nc.parse(FANUC_G80, dialect="fanuc")
    kept = prog.correct(fields.Shift((0, 0, 0.05))).text.splitlines()
    assert kept[6] == "X1. Y1."
    expanded = prog.correct(fields.Shift((0, 0, 0.05)), expand_cycles=True).text.splitlines()
    assert "G1 X1. Y1." in expanded
    # read back as Fanuc, the output moves as the program does, 0.05 mm higher where it cuts
    back = nc.parse("\n".join(expanded) + "\n", dialect="fanuc")
    assert back.blocks.motion[back.blocks.line == expanded.index("G1 X1. Y1.") + 1][0] == nc.MOTIONS.index("feed")


def test_fanuc_look_ahead_and_smoothing_modes_are_copied():
    """Fanuc's AI contour control (G05.1 Q1/Q0), high-speed mode (G05 P10000/P0) and Haas's
    smoothness control (G187 P E, its E the corner tolerance) change how the control follows the
    programmed path, not the path: copied as written, the moves around them corrected. In
    LinuxCNC's dialect G5/G5.1 are splines, which need axis words (rs274: "All axes missing
    with motion code")."""
    from ncadapt import fields, nc

    src = "O1\nG21 G90 G0 X0. Y0. Z5.\nG05.1 Q1\nG05 P10000\nG187 P1 E0.01\nG1 Z-1. F100.\nX10.\nG187\nG05 P0\nG05.1 Q0\nM30\n"
    prog = nc.parse(src, dialect="fanuc")
    assert not prog.unsupported
    out = prog.correct(fields.Shift((0, 0, 0.1))).text.splitlines()
    assert out[2:5] == ["G05.1 Q1", "G05 P10000", "G187 P1 E0.01"] and out[7:10] == ["G187", "G05 P0", "G05.1 Q0"]
    assert out[5] == "G1 Z-0.9 F100." and out[6] == "X10."
    with pytest.raises(InputError, match="All axes missing") as e:
        nc.parse(src)
    assert e.value.line == 3


def test_fanuc_g10_l20_sets_an_extended_offset_and_l2_p0_the_external_one():
    """On a Fanuc/Haas control G10 L20 P… sets an extended work offset (G54.1 P… / G154 P…), not
    the system in force as LinuxCNC's G10 L20 does: a program in G54 goes on where it was. G10 L2
    P0 sets the external offset, which moves every system (LinuxCNC's P0 is the system in force):
    refused."""
    from ncadapt import fields, nc

    src = "O1\nG21 G90 G54 G0 X0. Y0. Z5.\nG1 Z-1. F100.\nG10 L20 P1 X50. Y50. Z0.\nG1 X10.\nM30\n"
    out = nc.parse(src, dialect="fanuc").correct(fields.Shift((0, 0, 0.1))).text.splitlines()
    assert out[3] == "G10 L20 P1 X50. Y50. Z0." and out[4] == "G1 X10."  # Z-0.9 in force, X as written
    # LinuxCNC's G10 L20 makes the position read X50: the next move is 50 mm off where it was
    lin = nc.parse(src.replace("O1\n", "")).blocks
    assert lin.end[-1][0] != 10.0
    ext = nc.parse(src.replace("L20 P1", "L2 P0"), dialect="fanuc")
    assert [u.construct for u in ext.unsupported] == [
        "external work offset G10 L2 P0 (Fanuc: it moves every work system)"
    ]


def test_fanuc_extended_work_systems():
    """G54.1 P n (Haas G154 P n) is a work system like G54…G59 (Fanuc and Haas manuals): the
    position is unknown after a change, a change after the first move is refused naming both
    systems, and G10 L20 P n on the system in force sets its origin (unknown here)."""
    from ncadapt import fields, nc

    one = "O1\nG21 G90 G54.1 P3 G0 X0. Y0. Z5.\nG1 Z-1. F100.\nX10.\nM30\n"
    prog = nc.parse(one, dialect="fanuc")
    assert not prog.unsupported and prog.inspect()["work_offsets"] == ["G54.1 P3"]
    out = prog.correct(fields.Shift((0, 0, 0.1))).text.splitlines()
    assert out[2] == "G1 Z-0.9 F100."
    two = nc.parse(one.replace("X10.", "G154 P4 X10."), dialect="fanuc")
    assert [u.construct for u in two.unsupported] == [
        "work coordinate system G54.1 P4 after moves in G54.1 P3 (a field is in one system's coordinates)"
    ]
    with pytest.raises(InputError, match="needs P"):
        nc.parse("G54.1 G0 X0.\n", dialect="fanuc")
    reset = nc.parse(one.replace("X10.", "G10 L20 P3 X5.\nG1 X10."), dialect="fanuc")
    c = reset.correct(fields.Shift((0, 0, 0.1)))
    assert c.text.splitlines()[4] == "G1 X10."  # its X in machine terms is not known: left as written
    assert "line 5: the end of X unknown" in c.correction.warnings[0]


@pytest.mark.parametrize(
    ("name", "text", "dialect"),
    [
        ("p.ngc", "G21 G90\nG0 X0 Y0 Z1\nG1 Z0 F100\nX5 Y2\nM2\n", "linuxcnc"),
        ("p.nc", "%\nO1000\nG21 G90 G0 X0. Y0. Z1.\nG1 Z0. F100.\nX5. Y2.\nM30\n%\n", "fanuc"),
        ("p.mpf", "G1 X0 Y0 Z0 F100 ; start\nX5 Y2\nM30\n", "sinumerik"),
        ("p.gcode", ";FLAVOR:Marlin\nG1 X0 Y0 Z0 E0 F100\nG1 X5 Y2 E1\n", "marlin"),
    ],
)
def test_a_byte_order_mark_is_read_as_nothing_and_kept(tmp_path, name, text, dialect):
    """A UTF-8 byte order mark before the first line (an editor's): the program is detected and
    corrected as it is without it, and the output keeps it first (zero field: byte for byte)."""
    bom, plain = tmp_path / name, tmp_path / ("plain" + name)
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode())
    plain.write_text(text)
    assert dialects.resolve(bom).name == dialects.resolve(plain).name == dialect
    field = fields.Shift((0.0, 0.0, 0.05))
    for f in (fields.Shift((0.0, 0.0, 0.0)), field):
        a = nc.correct_file(bom, tmp_path / ("a" + name), f, dialect=dialect)
        b = nc.correct_file(plain, tmp_path / ("b" + name), f, dialect=dialect)
        got, ref = (tmp_path / ("a" + name)).read_bytes(), (tmp_path / ("b" + name)).read_bytes()
        assert got == b"\xef\xbb\xbf" + ref and a.blocks_changed == b.blocks_changed
    assert b.blocks_changed > 0  # the shift did change the program
    r = CliRunner().invoke(main, ["correct", str(bom), "--shift", "0,0,0", "-o", str(tmp_path / ("z" + name))])
    assert r.exit_code == 0 and (tmp_path / ("z" + name)).read_bytes() == bom.read_bytes(), r.output


def test_axis_words_after_g80_name_the_fanuc_dialect():
    """A Fusion 360 Mach3 post moves on after G80 with axis words alone, as a Fanuc-family
    control reads them (its G0 kept across the cycle): RS274NGC has no motion mode there, and the
    refusal says which dialect reads the program so; read as Fanuc it is corrected."""
    from ncadapt import fields, nc

    src = "G21 G90\nG0 X0. Y0. Z10.\nG98 G81 X0. Y0. Z-1. R5. F100.\nG80\nZ5.\nM30\n"
    [u] = nc.parse(src).unsupported
    assert u.line == 5 and "--dialect fanuc" in u.construct
    out = nc.parse(src, dialect="fanuc").correct(fields.Shift((0, 0, 0.05))).text.splitlines()
    assert out[2] == "G98 G81 X0. Y0. Z-0.95 R5.05 F100." and out[4] == "Z5."
