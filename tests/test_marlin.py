"""Marlin programs: the extruder E shared out among the pieces a corrected move is cut into.

The truth is arithmetic on the program's own numbers: under M83 (relative E) a move's pieces feed
exactly its E between them, under M82 (absolute E) its last piece ends at its E, and each piece
feeds in proportion to its length. The E mode follows Marlin's firmware (gcode.h:
``set_relative_mode`` clears every relative bit on G90 and sets them all on G91; M82/M83 set E's
alone). X Y Z motion is checked against rs274 by the corpus test (tests/corpus.py, E removed).
"""

from __future__ import annotations

import re
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from helpers import refused_at
from ncadapt import dialects, fields, nc, rewrite
from ncadapt import marlin as ml
from ncadapt.cli import main
from ncadapt.errors import InputError

CORPUS = Path(__file__).resolve().parents[1].parent / "shared" / "corpus" / "nc"


def bump(p: np.ndarray) -> np.ndarray:
    """A curved field: moves are cut into pieces (mm)."""
    d = np.zeros_like(p)
    d[:, 2] = 0.05 * np.sin(p[:, 0] / 7.0) * np.cos(p[:, 1] / 9.0)
    return d


def pieces(text: str, field=bump, max_segment: float = 1.0):
    """For each line of a Marlin program, the lines the corrected program writes for it."""
    tr = ml.translate(text.encode())
    corrected = nc.parse(tr.data, dialect="marlin").correct(field, max_segment=max_segment).data
    out, _ = ml.assemble(tr, corrected)
    groups = rewrite.groups(corrected, len(tr.straight))[1:]  # after the preamble
    changed = rewrite.changed(groups, tr.straight[1:])
    lines = out.decode().splitlines()
    per, k = [], 0
    for g, ch in zip(groups, changed, strict=True):
        n = len(g) if ch else 1
        per.append(lines[k : k + n])
        k += n
    assert k == len(lines)
    return per


def word(line: str, letter: str) -> Decimal | None:
    m = re.search(rf"{letter}([-+]?[\d.]+)", line.split(";")[0])
    return Decimal(m.group(1)) if m else None


def xyz_ends(lines: list[str], start):
    p, out = list(start), []
    for t in lines:
        for k, a in enumerate("XYZ"):
            v = word(t, a)
            if v is not None:
                p[k] = float(v)
        out.append(tuple(p))
    return np.array(out)


RELATIVE = """G21
G90
M83
G92 E0
G1 X0 Y0 Z0.3 F1200
G1 X40 Y10 E2.51234 ; a long extruding move
G1 X40 Y30 E1.20001
G1 E-0.8 F2400 ; retract
G0 X5 Y5
G1 E0.8
G1 X25 Y25 E1.77777
"""


def test_relative_e_pieces_add_up_to_the_move_and_follow_its_length():
    per = pieces(RELATIVE)
    start = (0.0, 0.0, 0.0)
    for i, src in enumerate(RELATIVE.splitlines()):
        out = per[i]
        ends = xyz_ends(out, start)
        e = word(src, "E")
        if src.startswith("G1 X") and e is not None:
            assert len(out) > 5, out  # cut into pieces
            got = [word(t, "E") or Decimal(0) for t in out]
            assert sum(got) == e  # exactly
            lengths = np.linalg.norm(np.diff(np.vstack([start, ends])[:, :2], axis=0), axis=1)
            share = np.array([float(g) for g in got]) / float(e)
            np.testing.assert_allclose(share, lengths / lengths.sum(), atol=2e-5 / float(e))
        start = tuple(ends[-1])
    assert per[7] == ["G1 E-0.8 F2400 ; retract"]  # a retraction moves nothing the field changes


ABSOLUTE = """G21
G90
M82
G92 E0
G1 X0 Y0 Z0.3 F1200
G1 X40 Y10 E2.51234
G92 E0 ; a new layer restarts E
G1 X40 Y30 E1.2
G1 X0 Y30 E3.7
"""


def test_absolute_e_pieces_end_at_the_move_and_interpolate_along_it():
    per = pieces(ABSOLUTE)
    start, e0 = (0.0, 0.0, 0.0), Decimal(0)
    for i, src in enumerate(ABSOLUTE.splitlines()):
        if src.startswith("G92"):
            e0 = Decimal(0)
        out = per[i]
        ends = xyz_ends(out, start)
        e = word(src, "E")
        if src.startswith("G1 X") and e is not None:
            got = [word(t, "E") for t in out]
            assert len(out) > 5 and got[-1] == e and all(g is not None for g in got)
            run = np.cumsum(np.linalg.norm(np.diff(np.vstack([start, ends])[:, :2], axis=0), axis=1))
            want = float(e0) + (float(e) - float(e0)) * run / run[-1]
            np.testing.assert_allclose([float(g) for g in got], want, atol=2e-5)
            e0 = e
        start = tuple(ends[-1])


@pytest.mark.parametrize(
    ("program", "u"),
    [
        # G91 makes E relative too (U written as an increment, as X is); G90 makes it absolute again
        ("G92 E0\nG91\nG1 X1 E1\nG1 X1 E1\nG90\nG1 X5 E1\n", ["U1", "U1", "U1"]),
        # M83 sets E alone: X stays absolute
        ("G92 E0\nG90\nM83\nG1 X1 E1\nG1 X2 E1\n", ["U1", "U2"]),
        # M82 after G91: E absolute (U at 1, then 3), the axes relative (U written as increments)
        ("G92 E0\nG91\nM82\nG1 X1 E1\nG1 X1 E3\n", ["U1", "U2"]),
        # G92 E sets the E coordinate: U keeps counting
        ("G92 E0\nM83\nG1 X1 E2\nG92 E10\nM82\nG1 X2 E11\n", ["U2", "U3"]),
    ],
)
def test_e_modes_follow_marlin(program, u):
    tr = ml.translate(program.encode())
    assert [re.search(r"U[\d.]+", t).group() for t in tr.straight[1:] if "U" in t] == u


@pytest.mark.parametrize(
    ("text", "line", "says"),
    [
        ("G1 X0 Y0 F100\nG5 I1 J1 P1 Q1 X5 Y5\n", 2, "Bézier"),
        ("G1 X0 Y0 F100\nM794\n", 2, "M794"),  # FABlin's I2C bus reset, not a program's
        ("G1 X0 Y0 F100\nM420 S1\n", 2, "M420"),  # bed levelling: the printer's own Z correction
        ("G1 X0 Y0 F100\nG29.2 S0\n", 2, "G29.2"),
        ("N1 G1 X0 Y0 F100*33\n", 1, "checksum"),
        ("G1 X0 Y0 U4 F100\n", 1, "U"),
        ("G1 X0 Y0 F100\nG28 E\n", 2, "E without a number"),  # (was a crash)
    ],
)
def test_refused_at_its_line(text, line, says):
    refused_at(ml.translate, text, "p.gcode", line, says)


def test_zero_correction_and_comments(tmp_path):
    p = tmp_path / "p.gcode"
    p.write_text(RELATIVE)
    c = nc.correct_file(p, tmp_path / "z.gcode", fields.Shift((0, 0, 0)), dialect="marlin")
    assert (tmp_path / "z.gcode").read_text() == RELATIVE and c.expanded["written"] == "as it is"
    c = nc.correct_file(p, tmp_path / "o.gcode", fields.Shift((0, 0, 0.05)), dialect="marlin")
    out = (tmp_path / "o.gcode").read_text().splitlines()
    # a shift raises the move that sets Z; the moves after keep it (modal), E and comments as written
    assert out[4] == "G1 X0 Y0 Z0.35 F1200" and out[5:] == RELATIVE.splitlines()[5:]
    assert c.expanded["written"] == "in place" and c.expanded["lines_rewritten"] == 1
    nc.correct_file(p, tmp_path / "b.gcode", bump, dialect="marlin")
    out = (tmp_path / "b.gcode").read_text().splitlines()
    # the first piece keeps the comment; every piece has its G1 (stock Marlin reads no modal motion)
    assert out[5].endswith("; a long extruding move") and out[6].startswith("G1 X")


@pytest.mark.parametrize(
    "name",
    [
        "cncjs__octocat.gcode",
        "cncjs__sample.gcode",
        "marlin__fab_cable_ties_nylon.gcode",
        "marlin__fab_fabtotum_logo_keychain.gcode",
    ],
)
def test_corpus_prints_keep_every_move_s_filament(name, tmp_path):
    src = CORPUS / name
    if not src.is_file():
        pytest.skip(f"no corpus at {CORPUS}")
    text = src.read_text()
    per = pieces(text, max_segment=5.0)
    mode_rel = False
    for i, line in enumerate(text.splitlines()):
        code = line.split(";")[0]
        if re.match(r"\s*M83", code) or re.match(r"\s*G91", code):
            mode_rel = True
        if re.match(r"\s*M82", code) or re.match(r"\s*G90", code):
            mode_rel = False
        e = word(code, "E")
        if e is None or not re.match(r"\s*G[0-3]\b", code):
            continue
        got = [word(t, "E") for t in per[i]]
        if mode_rel:
            assert sum(g or 0 for g in got) == e, (i + 1, line, per[i])
        else:
            assert [g for g in got if g is not None][-1] == e, (i + 1, line, per[i])


def _raised(tmp_path, text: str) -> list[str]:
    """The lines of ``text`` corrected by a 0.05 mm Z shift (through the file path, as the CLI)."""
    p = tmp_path / "p.gcode"
    p.write_text(text)
    nc.correct_file(p, tmp_path / "o.gcode", fields.Shift((0, 0, 0.05)), dialect="marlin")
    return (tmp_path / "o.gcode").read_text().splitlines()


def test_fabtotum_s_alive_code_is_copied(tmp_path):
    # FABlin's M728 (light and beeper, no motion) stays on its line; the moves around it are corrected
    out = _raised(tmp_path, "M728 ;FAB bep bep\nG90\nM82\nG1 X0 Y0 Z0.3 F1200\nM728\nG1 X5 E1\n")
    assert out[0] == "M728 ;FAB bep bep" and out[4] == "M728"
    assert out[3] == "G1 X0 Y0 Z0.35 F1200"


def test_fabtotum_s_laser_program_is_read_as_marlin(tmp_path):
    """FABtotum's laser programs (FABlin firmware) state no Marlin code a slicer writes: their
    dwell in seconds (``G4 S``, which RS274NGC and grbl refuse) shows the dialect; the head
    (M793), light (M728) and laser power (M61, M62) codes are copied, and a bare G5 too (a Bézier
    to where the head is: no motion)."""
    text = (
        ";laser test\nG4 S1 ;pause\nM728\nM793 S4\nG90\nG1 F10000\nM61 S255\n"
        "G1 X0 Y0 Z0 F10000.\nG1 X20 Y0 Z0 F800.\nG5\nM62\n"
    )
    p = tmp_path / "laser.gcode"
    p.write_text(text)
    d = dialects.resolve(p)
    assert (d.name, d.line) == ("marlin", 2)
    out = _raised(tmp_path, text)
    lines = text.splitlines()
    # every line but the moves as written; the moves raised by the shift
    assert [out[i] for i in (1, 2, 3, 6, 9, 10)] == [lines[i] for i in (1, 2, 3, 6, 9, 10)]
    assert out[7] == "G1 X0 Y0 Z0.05 F10000." and out[8] == "G1 X20 Y0 Z0.05 F800."
    # a G5 with words is a Bézier, which only a firmware built with it moves along: refused
    refused_at(ml.translate, "G1 X0 Y0 F100\nG5 X5 Y5\n", "p.gcode", 2, "Bézier")


def test_cli(tmp_path):
    p = tmp_path / "part.gcode"
    p.write_text(RELATIVE)
    r = CliRunner().invoke(main, ["correct", str(p), "--shift", "0,0,0.05", "-o", str(tmp_path / "o.gcode")])
    assert r.exit_code == 0, r.output
    assert "Marlin (3D printer G-code) (detected" in r.output and "E carried through the correction" in r.output
    r = CliRunner().invoke(main, ["inspect", str(p)])
    assert r.exit_code == 0, r.output


# ------------------------------------------------------------------------------ found in review
def test_every_piece_names_its_motion(tmp_path):
    """Stock Marlin reads no modal motion (GCODE_MOTION_MODES off): a line without G is ignored."""
    for lines in pieces(RELATIVE):
        for t in lines:
            code = t.split(";")[0].strip()
            assert not code or code[0] in "GM", t


def test_e_under_g91_is_shared_out_exactly(tmp_path):
    text = "G92 E0\nG90\nG1 X0 Y0 Z0.3 F1200\nG91\nG1 X10 Y1 E1\nG1 X2 Y2 E1\nG90\nG1 X20 Y5 E3\n"
    per = pieces(text, max_segment=1.0)
    assert len(per[4]) > 3 and sum(word(t, "E") for t in per[4]) == 1  # G91: E relative
    assert sum(word(t, "E") for t in per[5]) == 1
    assert word(per[7][-1], "E") == 3 and len(per[7]) > 3  # G90: absolute, the last piece at E3
    es = [float(word(t, "E")) for t in per[7]]
    assert es == sorted(es) and es[0] > 2  # from E2 up to E3 along the move


def test_the_first_move_after_homing_is_corrected(tmp_path):
    out = _raised(tmp_path, "M83\nG28\nG1 X10 Y3 Z0.3 E1 F1200\nG1 X20 Y3 E1\n")
    assert out[2] == "G1 X10 Y3 Z0.35 E1 F1200" and out[3] == "G1 X20 Y3 E1"


def test_a_rewritten_g92_keeps_its_e(tmp_path):
    p = tmp_path / "p.gcode"
    p.write_text("G90\nM82\nG92 E0\nG1 X0 Y0 Z0.3 F1200\nG1 X10 E1\nG92 X0 E0\nG1 X10 E1\n")
    nc.correct_file(p, tmp_path / "o.gcode", fields.Shift((0.1, 0, 0)), dialect="marlin")
    out = (tmp_path / "o.gcode").read_text().splitlines()
    g92 = [t for t in out if t.startswith("G92 X")]
    assert len(g92) == 1 and g92[0].endswith(" E0"), out


def test_an_extruding_g0_is_corrected_as_marlin_moves_it(tmp_path):
    assert _raised(tmp_path, "M83\nG1 X0 Y0 Z0.3 F1200\nG0 X10 Y3 Z0.3 E1\n")[2] == "G0 X10 Y3 Z0.35 E1"


def test_a_form_feed_in_a_comment_does_not_end_the_line():
    tr = ml.translate(b"G1 X1 Y0 Z0.2 E0.1 F100 ; note\x0cG1 X10 Y3 E1\nG1 X2\n")
    assert tr.straight[1:] == ["G1 X1 Y0 Z0.2 U0.1 F100", "G1 X2"]


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("G1 X0 Y0 F100\nG1 G91 X10 Y1 E1\n", "one code a line"),
        ("G1 X0 Y0 F100\nG2 X10 Y0 I5 J0 E2 P2\n", "ARC_P_CIRCLES"),
        ("G1 X0 Y0 F100\nG1 X10 Y3 e1\n", "lower-case"),
        ("G1 X0 Y0 F100\nG1 X10 E0.123456789012\n", "decimals"),
    ],
)
def test_refused_after_review(text, says):
    with pytest.raises(InputError, match=says) as e:
        ml.translate(text.encode())
    assert e.value.line == 2


def test_correct_and_inspect_count_the_programs_lines(tmp_path):
    """Each line of a print runs once: both say so (the straight program's preamble is not counted)."""
    p = tmp_path / "p.gcode"
    p.write_text(";FLAVOR:Marlin\nM82\nG1 X0 Y0 Z0.2 F600\nG1 X10 E1\nG1 Y10 E2\n")
    c = nc.correct_file(p, tmp_path / "o.gcode", fields.Shift((0.0, 0.0, 0.0)), dialect="marlin")
    assert c.expanded["blocks_run"] == nc.inspect_file(p, "marlin")["blocks_run"] == 5
