"""Program.correct: identities, safety checks and output style."""

from __future__ import annotations

import numpy as np
import pytest

from ncadapt import InputError, RefusedError, correction, fields, nc

PART = "G21 G90 G0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X10.0000 Y0.0000 (edge)\nG2 X20 Y0 I5 J0\nG0 Z5\nM30\n"


def test_zero_field_is_byte_identical():
    prog = nc.parse(PART.replace("\n", "\r\n"))
    out = prog.correct(fields.Shift((0, 0, 0)))
    assert out.data == prog.data
    assert out.correction.blocks_changed == 0 and out.correction.lines_added == 0


def test_changed_block_keeps_words_order_and_comment():
    out = nc.parse(PART).correct(lambda p: np.column_stack([0 * p[:, 0], 0 * p[:, 0], 1e-4 * p[:, 0] ** 2]))
    lines = out.text.splitlines()
    # the block carries its first 1 mm piece and its comment; the program's 4 fixed decimals kept
    assert lines[2] == "G1 X1.0000 Y0.0000 Z-0.9999 (edge)"
    assert lines[3] == "X2.0000 Z-0.9996"
    assert any(ln.endswith("(edge)") for ln in lines)
    assert "G2 " not in out.text and out.correction.arcs_linearised == 1
    assert lines[-2:] == ["G0 Z5", "M30"]


def test_comments_in_an_8bit_encoding_survive_byte_for_byte(tmp_path):
    # a Latin-1 shop program: 'é' and 'µ' are single bytes that are not UTF-8
    src = b"G21 G90\nG0 X0 Y0 Z5 (caf\xe9)\nG1 Z-1 F100 (prof \xb5m)\nG1 X10\nM30\n"
    (tmp_path / "p.ngc").write_bytes(src)
    out = nc.read(tmp_path / "p.ngc").correct(fields.Shift((0, 0, 0.01)))
    out.write(tmp_path / "o.ngc")
    assert (tmp_path / "o.ngc").read_bytes() == src.replace(b"Z-1 F100", b"Z-0.99 F100")


def test_a_cutting_move_after_a_return_to_reference_is_reported_not_guessed():
    # Z is unknown after G28 until a move sets it: the feed move on line 3 cannot be corrected
    prog = nc.parse("G21 G90 G0 X1 Y2 Z3\nG91 G28 Z0\nG90 G1 X5 F100\nG0 Z5\nG1 Z-1\nX10\nM30\n")
    out = prog.correct(fields.Shift((0, 0, 0.02)))
    assert out.text.splitlines()[:4] == ["G21 G90 G0 X1 Y2 Z3", "G91 G28 Z0", "G90 G1 X5 F100", "G0 Z5"]
    assert out.text.splitlines()[4:6] == ["G1 Z-0.98", "X10"]
    (w,) = out.correction.warnings
    assert w.startswith(
        "1 cutting move(s) not corrected because the position is unknown (first at line 3: the end of Z unknown"
    )


@pytest.mark.parametrize("streamed", [False, True], ids=["in memory", "streamed"])
def test_a_g1_that_names_no_axis_is_no_unknown_move(tmp_path, streamed):
    # pcb2gcode sets its feed with `G01 F360` before any move: that G1 goes nowhere, so it is not
    # a cutting move left uncorrected; a G1 that names an axis from an unknown position still is
    src = "G20 G90\nG01 F360 ( Feedrate. )\nG0 Z1\nG0 X0 Y0\nG1 Z-0.1\nM2\n"
    field = fields.Shift((0, 0, 0.01))
    if streamed:
        (tmp_path / "p.ngc").write_text(src)
        warnings = nc.correct_file(tmp_path / "p.ngc", tmp_path / "o.ngc", field).warnings
    else:
        warnings = nc.parse(src).correct(field).correction.warnings
    assert warnings == ()
    src2 = "G20 G90\nG01 F360\nG1 X1\nG0 X0 Y0 Z1\nM2\n"
    (w,) = nc.parse(src2).correct(field).correction.warnings
    assert w.startswith("1 cutting move(s) not corrected because the position is unknown (first at line 3")


def test_an_axis_unknown_at_its_start_is_named_as_such():
    # A is given on line 2 but never before: the move cannot be interpolated in A, it is kept
    prog = nc.parse("G21 G90 G0 X0 Y0 Z0\nG1 X10 A90 F100\nM30\n")
    out = prog.correct(fields.Shift((0, 0, 0.02)))
    assert out.text.splitlines()[1] == "G1 X10 A90 F100"
    (w,) = out.correction.warnings
    assert "(first at line 2: the start of A unknown" in w


def test_limit_refuses_and_lists_worst_points():
    with pytest.raises(RefusedError, match="exceeds the limit 0.5 mm") as e:
        nc.parse(PART).correct(lambda p: np.tile([0, 0, 0.0], (len(p), 1)) + [[0, 0, 0.6]] * (p[:, [0]] > 15))
    worst = e.value.details[0]
    assert worst["line"] == 4 and worst["magnitude"] == pytest.approx(0.6)


def test_unsupported_refused_unless_kept():
    src = "G0 X0 Y0 Z5\nG88 X5 Y5 Z-1 R1 P1 F100\nG80\nG1 X10 Z-1 F100\n"
    with pytest.raises(RefusedError, match="1 unsupported construct") as e:
        nc.parse(src).correct(fields.Shift((0, 0, 0.1)))
    assert e.value.details[0]["construct"].startswith("canned cycle G88 (the operator retracts by hand")
    out = nc.parse(src).correct(fields.Shift((0, 0, 0.1)), keep_unsupported=True)
    assert out.text.splitlines()[1] == "G88 X5 Y5 Z-1 R1 P1 F100"
    assert out.text.splitlines()[3] == "G1 X10 Z-0.9 F100"
    assert "kept unchanged" in out.correction.warnings[0]


def test_outside_field_refused():
    f = fields.GridField([0, 5], [-1, 1], np.zeros((2, 2)))
    with pytest.raises(RefusedError, match="outside the field's domain") as e:
        nc.parse(PART).correct(f)
    assert e.value.details[0]["line"] == 3


def test_write_refuses_the_input_and_is_atomic(tmp_path):
    p = tmp_path / "part.ngc"
    p.write_text(PART)
    prog = nc.read(p)
    with pytest.raises(InputError, match="refusing to overwrite the input"):
        prog.write(p)
    out = prog.correct(fields.Shift((0, 0, 0.01)))
    out.write(tmp_path / "out.ngc")
    assert p.read_text() == PART
    assert sorted(x.name for x in tmp_path.iterdir()) == ["out.ngc", "part.ngc"]


def test_rapid_clearance_warning():
    f = fields.GridField([-5, 25], [-5, 5], np.zeros((2, 2)))
    out = nc.parse("G0 X0 Y0 Z5\nG0 Z0.5\nG1 Z-1 F10\nX10\nG0 Z5\n").correct(f, clearance=1.0)
    assert out.correction.warnings == (
        "line 2: rapid ends at Z0.5000, below the clearance Z1 inside the field's area, and is not corrected",
    )


def test_grid_lines_split_moves():
    f = fields.GridField([0, 2.5, 5, 7.5, 10], [-1, 1], np.array([[0, 0.01, 0, 0.01, 0]] * 2))
    out = nc.parse("G0 X0 Y0 Z0\nG1 X10 F100\n").correct(f, max_segment=100)
    assert out.text.splitlines()[1:] == ["G1 X2.5 Z0.01 F100", "X5.0 Z0.0", "X7.5 Z0.01", "X10.0 Z0.0"]


def _bowl(p):
    return np.column_stack([1e-3 * p[:, 1], -1e-3 * p[:, 0], 1e-4 * (p[:, 0] ** 2 + p[:, 1] ** 2)])


@pytest.mark.parametrize("piece", [1, 7, 30, 1 << 16])
@pytest.mark.parametrize("from_file", [False, True])
def test_correct_to_streams_the_same_program(tmp_path, monkeypatch, piece, from_file):
    """Reading and writing in pieces (of any size, from memory or from the file) gives the bytes
    and figures of the program corrected in one piece."""
    src = tmp_path / "p.ngc"
    src.write_text(PART.replace("G0 Z5\nM30", "G91 G1 X2 Y1\nG3 X-4 Y0 I-2 J0\nG90 G0 Z5\nM30"))
    prog = nc.read(src)
    monkeypatch.setattr(nc, "_PIECE_BYTES", 1 << 30)
    monkeypatch.setattr(correction, "_PIECE_BYTES", 1 << 30)
    whole = prog.correct(_bowl)
    monkeypatch.setattr(nc, "_PIECE_BYTES", piece)
    monkeypatch.setattr(correction, "_PIECE_BYTES", piece)
    if from_file:
        c = nc.correct_file(src, tmp_path / "out.ngc", _bowl)
    else:
        c = prog.correct_to(tmp_path / "out.ngc", _bowl)
    assert (tmp_path / "out.ngc").read_bytes() == whole.data
    assert nc.inspect_file(src) == prog.inspect() | {"file": str(src)}
    assert c.points is None and c.n_points == len(whole.correction.points)
    for key in ("lines_out", "blocks_changed", "lines_added", "arcs_linearised"):
        assert getattr(c, key) == getattr(whole.correction, key)
    assert c.max_displacement == pytest.approx(whole.correction.max_displacement)
    assert c.mean_displacement == pytest.approx(np.linalg.norm(whole.correction.displacements, axis=1).mean())
    assert oct((tmp_path / "out.ngc").stat().st_mode & 0o777) != "0o600"  # not mkstemp's private mode


def test_correct_to_refusal_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(nc, "_PIECE_BYTES", 1)
    monkeypatch.setattr(correction, "_PIECE_BYTES", 1)
    out = tmp_path / "out.ngc"
    out.write_text("old\n")
    with pytest.raises(RefusedError, match="exceeds the limit"):
        nc.parse(PART).correct_to(out, lambda p: np.tile([0, 0, 0.7], (len(p), 1)))
    assert out.read_text() == "old\n" and sorted(x.name for x in tmp_path.iterdir()) == ["out.ngc"]
    field = fields.GridField([0, 5], [0, 5], np.zeros((2, 2)))
    with pytest.raises(RefusedError, match="outside the field's domain"):
        nc.parse(PART).correct_to(out, field)
    assert out.read_text() == "old\n" and sorted(x.name for x in tmp_path.iterdir()) == ["out.ngc"]


# ---------------------------------------------------------------------------- approach rapids
APPROACH = "G21 G90\nG0 X5 Y5 Z5\nG0 Z0.1\n(plunge)\nG1 Z-0.1 F100\nG1 X10\nG0 Z5\nM2\n"


def _up(dz):
    # the measured surface is dz above the nominal one everywhere on a 20 mm square
    return fields.GridField([0.0, 20.0], [0.0, 20.0], np.full((2, 2), dz))


@pytest.mark.parametrize("piece", [1 << 30, 1])
@pytest.mark.parametrize("native", [True, False])
def test_a_rapid_that_would_run_into_the_raised_part_is_refused(tmp_path, monkeypatch, piece, native):
    """The rapid ends at Z0.1, the plunge after it descends 0.2 mm: a surface raised by 0.3 mm puts
    the corrected plunge's end at Z0.2, above the rapid's end, which is then inside the material
    (hand-derived). Refused, nothing written, whether the two blocks share a piece or not, and
    whether the engine or Python evaluates the field."""
    monkeypatch.setattr(nc, "_PIECE_BYTES", piece)
    monkeypatch.setattr(correction, "_PIECE_BYTES", piece)
    src = tmp_path / "p.ngc"
    src.write_text(APPROACH)
    out = tmp_path / "o.ngc"
    field = _up(0.3) if native else (lambda p: np.column_stack([0 * p[:, 0], 0 * p[:, 0], 0 * p[:, 0] + 0.3]))
    with pytest.raises(
        RefusedError,
        match=r"rapid at line 3 ends at Z0\.1000.*plunge after it \(line 5\) ends once corrected \(Z0\.2000\)",
    ):
        nc.correct_file(src, out, field)
    assert not out.exists()


def test_an_approach_with_clearance_left_or_corrected_rapids_is_written(tmp_path):
    prog = nc.parse(APPROACH)
    # raised by 0.15 mm: the corrected plunge ends at Z0.05, below the rapid's end (not refused; the
    # clearance left, 0.1 − 0.15 above the nominal surface, is what --clearance reports)
    out = prog.correct(_up(0.15))
    assert "G1 Z0.05 F100" in out.text and "G0 Z0.1\n" in out.text
    # --rapids moves the approach with the surface
    out = prog.correct(_up(0.3), rapids=True)
    assert "G0 Z0.4\n" in out.text and "G1 Z0.2 F100" in out.text
    # a cut that rises from the rapid's end is no approach
    assert "G1 Z0.5" in nc.parse(APPROACH.replace("Z-0.1 F100", "Z0.2 F100")).correct(_up(0.3)).text
    # nor is a side entry beside the part, even one that descends a little as it moves in
    side = "G21 G90\nG0 X-5 Y5 Z5\nG0 Z-1\nG1 X10 Z-1.1 F100\nM2\n"
    assert nc.parse(side).correct(fields.Shift((0, 0, 0.3))).text.splitlines()[-2].endswith("Z-0.8")
