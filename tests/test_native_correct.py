"""The engine's own evaluation of shift and grid fields (``_nc.correct_native``, used by
``correct_file`` and ``Program.correct_to``) against the Python/numpy evaluation: the same
displacements to the bit, the same output bytes, figures, warnings and refusals."""

from __future__ import annotations

import numpy as np
import pytest

from ncadapt import InputError, RefusedError, _nc, correction, fields, nc

PROGRAM = (
    "%\n(native)\nG21 G90 G17\nG0 X1.0000 Y1.0000 Z5.0000\nG1 Z-0.5000 F300\n"
    "G1 X9.5000 Y2.2500 Z-0.6000\nG2 X9.5000 Y2.2500 I-0.2500 J0.0000\nG1 X3.1250 Y8.7500\n"
    "G91 G1 X1.0000 Y-1.0000\nG3 X-2.0000 Y0.0000 I-1.0000 J0.0000\nG90 G0 Z5.0000\nM30\n%\n"
)


class PyGrid(fields.GridField):
    """A grid the engine does not evaluate itself (a subclass): the Python evaluation."""


class PyShift(fields.Shift):
    """A shift evaluated in Python."""


def _python_twin(field):
    if isinstance(field, fields.Shift):
        return PyShift(field.d)
    return PyGrid(field.xs, field.ys, field.dz, outside=field.outside)


@pytest.fixture(autouse=True)
def _twins_sampled_as_the_engine_samples(monkeypatch):
    """The engine samples an arc a bilinear grid leaves flat at its end only; the Python twin of a
    grid is sampled the same way (its evaluation stays Python's), so the figures compare."""
    spec = correction._grid_spec

    def twin_spec(field):
        if type(field) is PyGrid:
            return spec(fields.GridField(field.xs, field.ys, field.dz, outside=field.outside))
        return spec(field)

    monkeypatch.setattr(correction, "_grid_spec", twin_spec)


def _grids():
    rng = np.random.default_rng(7)
    xs = np.linspace(0, 10, 11)
    ys = np.linspace(0, 10, 6)
    uniform = rng.normal(0, 0.01, (len(ys), len(xs)))
    irregular_x = np.array([0, 0.5, 2, 2.1, 6, 10.0])
    irregular_y = np.array([0, 3, 3.3, 10.0])
    irregular = rng.normal(0, 0.01, (len(irregular_y), len(irregular_x)))
    # a uniform grid whose spacing is not a binary fraction (steps equal to 1e-12, not exactly)
    thirds = np.linspace(0, 10, 31)
    return [
        (xs, ys, uniform),
        (irregular_x, irregular_y, irregular),
        (thirds, thirds, rng.normal(0, 0.01, (31, 31))),
        (np.array([0, 10.0]), np.array([0, 10.0]), irregular[:2, :2]),
    ]


def _points(xs, ys):
    """Nodes, cell lines, edges, points within and beyond the 1e-9 tolerance outside, far points."""
    rng = np.random.default_rng(3)
    x0, x1, y0, y1 = xs[0], xs[-1], ys[0], ys[-1]
    pts = [np.column_stack([rng.uniform(x0, x1, 500), rng.uniform(y0, y1, 500), rng.uniform(-1, 1, 500)])]
    X, Y = np.meshgrid(xs, ys)
    pts.append(np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)]))
    for d in (0.0, 5e-10, -5e-10, 2e-9, -2e-9, 0.5, -0.5, 1e3, -1e3):
        e = np.array([x0 - d, x1 + d, x0 + d, x1 - d])
        pts.append(np.column_stack([np.repeat(e, 4), np.tile([y0 - d, y1 + d, y0, y1], 4), np.zeros(16)]))
    pts.append(
        np.array(
            [
                [np.nextafter(x1, np.inf), y0, 0.0],
                [np.nextafter(x0, -np.inf), y1, 0.0],
                [-0.0, -0.0, 0.0],
                [x0, np.nextafter(y1, -np.inf), 0.0],
            ]
        )
    )
    return np.concatenate(pts)


def _spec(field):
    spec = correction._native_field(field)
    assert spec is not None
    return spec


@pytest.mark.parametrize("outside", fields.OUTSIDE)
@pytest.mark.parametrize("k", range(4))
def test_grid_displacements_are_numpys_to_the_bit(outside, k):
    xs, ys, dz = _grids()[k]
    field = fields.GridField(xs, ys, dz, outside=outside)
    pts = _points(xs, ys)
    inside = ~(
        (pts[:, 0] < xs[0] - 1e-9)
        | (pts[:, 0] > xs[-1] + 1e-9)
        | (pts[:, 1] < ys[0] - 1e-9)
        | (pts[:, 1] > ys[-1] + 1e-9)
    )
    sets = [pts, pts[inside]] if outside == "error" else [pts]
    for p in sets:
        got = _nc.eval_field(_spec(field), np.ascontiguousarray(p).tobytes())
        try:
            want = field(p)
        except fields.OutsideError:
            assert got is None
            continue
        got = np.frombuffer(got, dtype="<f8").reshape(-1, 3)
        np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64))


def test_shift_and_non_finite_points():
    field = fields.Shift((0.01, -0.02, 0.03))
    p = np.array([[1.0, 2, 3], [-1e9, 0, 0]])
    got = np.frombuffer(_nc.eval_field(_spec(field), p.tobytes()), dtype="<f8").reshape(-1, 3)
    np.testing.assert_array_equal(got, field(p))
    grid = fields.GridField([0, 1], [0, 1], np.zeros((2, 2)), outside="extrapolate")
    assert _nc.eval_field(_spec(grid), np.array([[np.nan, 0, 0]]).tobytes()) is None
    # a grid of huge values extrapolated far away overflows: refused as the Python evaluation does
    huge = fields.GridField([0, 1], [0, 1], [[0, 1e308], [0, 1e308]], outside="extrapolate")
    assert _nc.eval_field(_spec(huge), np.array([[10.0, 0, 0]]).tobytes()) is None


def test_only_plain_shift_and_linear_grid_are_native():
    grid = fields.GridField(np.arange(4.0), np.arange(4.0), np.zeros((4, 4)))
    assert correction._native_field(grid) is not None and correction._native_field(fields.Shift((0, 0, 1))) is not None
    assert (
        correction._native_field(fields.GridField(np.arange(4.0), np.arange(4.0), np.zeros((4, 4)), method="cubic"))
        is None
    )
    assert correction._native_field(PyGrid(np.arange(4.0), np.arange(4.0), np.zeros((4, 4)))) is None
    assert correction._native_field(lambda p: p * 0) is None


def _run(tmp_path, field, src=PROGRAM, name="out.ngc", **options):
    prog = tmp_path / "p.ngc"
    prog.write_text(src)
    out = tmp_path / name
    try:
        c = nc.correct_file(prog, out, field, **options)
    except (RefusedError, InputError) as e:
        return ("refused", type(e), str(e), getattr(e, "details", None), out.exists())
    return out.read_bytes(), c


FIELDS = [
    fields.Shift((0.0, 0.0, 0.0)),
    fields.Shift((0.003, -0.001, 0.05)),
    fields.GridField(
        np.linspace(0, 12, 13), np.linspace(0, 12, 7), 0.01 * np.sin(np.arange(91.0)).reshape(7, 13), outside="error"
    ),
    fields.GridField(
        [0, 0.5, 2, 2.1, 6, 12.0], [0, 3, 3.3, 12.0], 0.01 * np.cos(np.arange(24.0)).reshape(4, 6), outside="clamp"
    ),
    fields.GridField([2, 5, 8], [2, 5, 8], 0.01 * np.arange(9.0).reshape(3, 3), outside="extrapolate"),
    fields.GridField([2, 5, 8], [2, 5, 8], 0.01 * np.arange(9.0).reshape(3, 3), outside="error"),
    fields.GridField([0, 12], [0, 12], [[0, 0.2], [0.3, 0.6]], outside="error"),
]


@pytest.mark.parametrize("piece", [7, 100, 1 << 18])
@pytest.mark.parametrize("k", range(len(FIELDS)))
def test_outputs_figures_and_refusals_are_the_python_evaluations(tmp_path, monkeypatch, piece, k):
    monkeypatch.setattr(nc, "_PIECE_BYTES", piece)
    monkeypatch.setattr(correction, "_PIECE_BYTES", piece)
    field = FIELDS[k]
    for options in ({"max_segment": 1.0}, {"max_segment": 0.5, "limit": 0.25, "clearance": 6.0}):
        native = _run(tmp_path, field, name="native.ngc", **options)
        python = _run(tmp_path, _python_twin(field), name="python.ngc", **options)
        if native[0] == "refused":
            assert native[1:] == python[1:], native
            continue
        assert native[0] == python[0]
        assert native[1] == python[1]


@pytest.mark.parametrize(
    "src",
    [
        # unknown positions (a warning) and an unsupported construct kept
        "G21 G90 G0 X1 Y1\nG1 X5 Y5 F100\nG0 Z5\nG1 Z-1\nG68 X0 Y0 R10\nG1 X4 Y4\nG69\nG0 X2 Y2\nG1 X6\nM30\n",
        # a later piece writes more decimals and keeps trailing zeros: the output is written in the
        # whole program's style, which the first piece does not show (a second pass)
        "G21 G90 G0 X1 Y1 Z5\nG1 Z-1 F100\nG1 X7 Y3\nG1 X2 Y9\n" + "G1 X3 Y3\n" * 20 + "G1 X4.12500 Y4.50000\nM30\n",
        # CRLF in the later pieces only, and compact words
        "G21G90G0X1Y1Z5\nG1Z-1F100\nG1X7Y3\n" + "G1X3Y3\r\n" * 30 + "M30\r\n",
        # a parse error after the first pieces
        "G21 G90 G0 X1 Y1 Z5\nG1 Z-1 F100\n" + "G1 X3 Y3\n" * 20 + "G1 X\nM30\n",
    ],
)
@pytest.mark.parametrize("keep", [False, True])
def test_style_warnings_and_errors_as_in_python(tmp_path, monkeypatch, src, keep):
    monkeypatch.setattr(nc, "_PIECE_BYTES", 16)
    monkeypatch.setattr(correction, "_PIECE_BYTES", 16)
    done = []
    engine = correction._nc_correct
    monkeypatch.setattr(correction, "_nc_correct", lambda *a: done.append(engine(*a)) or done[-1])
    for field in (fields.Shift((0, 0, 0.0125)), FIELDS[2]):
        done.clear()
        native = _run(tmp_path, field, src, name="native.ngc", keep_unsupported=keep, clearance=0.0)
        python = _run(tmp_path, _python_twin(field), src, name="python.ngc", keep_unsupported=keep, clearance=0.0)
        if native[0] == "refused":
            assert native[1:] == python[1:]
        else:
            assert native == python
            # the engine did it (no refusal to hand over to the Python evaluation)
            assert len(done) == 1 and done[0] is not None


def test_correct_to_from_memory_is_native_too(tmp_path):
    prog = nc.parse(PROGRAM)
    c = prog.correct_to(tmp_path / "a.ngc", FIELDS[2])
    whole = prog.correct(FIELDS[2])
    assert (tmp_path / "a.ngc").read_bytes() == whole.data
    assert c.max_displacement == whole.correction.max_displacement
    assert c.n_points == whole.correction.n_points


@pytest.mark.parametrize(
    "src",
    [
        PROGRAM,
        # a later piece writes more decimals: the first pass, read ahead, is run again
        "G21 G90 G0 X1 Y1 Z5\nG1 Z-1 F100\nG1 X7 Y3\nG1 X2 Y9\n" + "G1 X3 Y3\n" * 20 + "G1 X4.12500 Y4.50000\nM30\n",
        # refused by the engine (an unsupported construct): the Python evaluation reports it
        "G21 G90 G0 X1 Y1\nG1 X5 Y5 F100\nG68 X0 Y0 R10\nG1 X4 Y4\nM30\n",
    ],
)
def test_a_program_read_ahead_is_corrected_as_one_read_then(tmp_path, monkeypatch, src):
    """The command line starts reading the program before it imports numpy and reads the field
    (``_nc.read_ahead``); the correction that takes those pieces writes the same bytes and figures,
    refuses the same way, and one started on another file or with another piece size is not used."""
    monkeypatch.setattr(correction, "_PIECE_BYTES", 64)
    prog = tmp_path / "p.ngc"
    prog.write_text(src)
    other = tmp_path / "other.ngc"
    other.write_text("G21 G90 G0 X0 Y0 Z1\nG1 Z0 F10\nX3\nM2\n")
    field = FIELDS[2]
    want = _run(tmp_path, field, src, name="plain.ngc", max_segment=1.0)
    for path, piece, room, used in (
        (prog, 64, 2, True),
        (prog, 64, 32, True),
        (other, 64, 32, False),
        (prog, 4096, 32, True),
    ):
        ahead = _nc.read_ahead(str(path), piece, "linuxcnc", room)
        try:
            c = nc.correct_file(prog, tmp_path / "ahead.ngc", field, max_segment=1.0, read_ahead=ahead)
            got = ((tmp_path / "ahead.ngc").read_bytes(), c)
        except (RefusedError, InputError) as e:
            got = ("refused", type(e), str(e))
        if want[0] == "refused":
            assert got[1:3] == want[1:3]
        else:
            assert got == want
        # taken by the engine (another piece size is then dropped by it)
        assert ahead.taken == used
    # a field the engine does not evaluate: the Python evaluation reads the program itself and
    # the pieces read ahead are dropped
    ahead = _nc.read_ahead(str(prog), 64, "linuxcnc")
    try:
        c = nc.correct_file(prog, tmp_path / "twin.ngc", _python_twin(field), max_segment=1.0, read_ahead=ahead)
        assert (tmp_path / "twin.ngc").read_bytes() == want[0]
    except (RefusedError, InputError) as e:
        assert want[0] == "refused" and str(e) == want[2]
    assert ahead.taken
