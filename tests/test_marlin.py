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

from ncadapt import fields, nc, rewrite
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


RELATIVE = """G21 G90
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
    assert per[6] == ["G1 E-0.8 F2400 ; retract"]  # a retraction moves nothing the field changes


ABSOLUTE = """G21 G90
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
        # G91 makes E relative too; G90 makes it absolute again (Marlin's set_relative_mode)
        ("G92 E0\nG91\nG1 X1 E1\nG1 X1 E1\nG90\nG1 X5 E1\n", ["U1", "U2", "U1"]),
        # M83 sets E alone: X stays absolute
        ("G92 E0\nG90\nM83\nG1 X1 E1\nG1 X2 E1\n", ["U1", "U2"]),
        # M82 after G91: E absolute, the axes relative
        ("G92 E0\nG91\nM82\nG1 X1 E1\nG1 X1 E3\n", ["U1", "U3"]),
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
        ("G1 X0 Y0 F100\nM728\n", 2, "M728"),
        ("G1 X0 Y0 F100\nM420 S1\n", 2, "M420"),  # bed levelling: the printer's own Z correction
        ("G1 X0 Y0 F100\nG29.2 S0\n", 2, "G29.2"),
        ("N1 G1 X0 Y0 F100*33\n", 1, "checksum"),
        ("G1 X0 Y0 U4 F100\n", 1, "U"),
    ],
)
def test_refused_at_its_line(text, line, says):
    with pytest.raises(InputError) as e:
        ml.translate(text.encode(), "p.gcode")
    assert e.value.line == line and says in e.value.message


def test_zero_correction_and_comments(tmp_path):
    p = tmp_path / "p.gcode"
    p.write_text(RELATIVE)
    c = nc.correct_file(p, tmp_path / "z.gcode", fields.Shift((0, 0, 0)), dialect="marlin")
    assert (tmp_path / "z.gcode").read_text() == RELATIVE and c.expanded["written"] == "as it is"
    c = nc.correct_file(p, tmp_path / "o.gcode", fields.Shift((0, 0, 0.05)), dialect="marlin")
    out = (tmp_path / "o.gcode").read_text().splitlines()
    # a shift raises the move that sets Z; the moves after keep it (modal), E and comments as written
    assert out[3] == "G1 X0 Y0 Z0.35 F1200" and out[4:] == RELATIVE.splitlines()[4:]
    assert c.expanded["written"] == "in place" and c.expanded["lines_rewritten"] == 1
    nc.correct_file(p, tmp_path / "b.gcode", bump, dialect="marlin")
    out = (tmp_path / "b.gcode").read_text().splitlines()
    assert out[4].endswith("; a long extruding move") and out[5].startswith("X")  # the first piece keeps it


@pytest.mark.parametrize("name", ["cncjs__octocat.gcode", "cncjs__sample.gcode"])
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


def test_cli(tmp_path):
    p = tmp_path / "part.gcode"
    p.write_text(RELATIVE)
    r = CliRunner().invoke(main, ["correct", str(p), "--shift", "0,0,0.05", "-o", str(tmp_path / "o.gcode")])
    assert r.exit_code == 0, r.output
    assert "Marlin (3D printer G-code) (detected" in r.output and "E carried through the correction" in r.output
    r = CliRunner().invoke(main, ["inspect", str(p)])
    assert r.exit_code == 0, r.output
