"""QIF 3 measured point sets (``MeasuredPointSet`` with ``Points`` and ``Normals`` lists) read as actual
points against a CAD nominal, alone and with single measured points (``PointFeatureMeasurement``,
``PointFeatureActual``).

The fixtures tests/data/plate_pointsets_{mm,inch}.qif were written by hand after the QIF 3 schema
(Features.xsd ``MeasuredPointSetType``: a ``count`` attribute, ``Points`` of 3 × count numbers,
optional ``Normals``, ``Compensated``; a feature measurement names its sets through
``PointList/WholePointSetId``). They measure the plate 2.5 × 1.5 × 1 in built here by OpenCASCADE:
a single point on the front face y = 0 − e, six points of the top face z = 1 in + e in set 51 (feature
42), four of the side x = 2.5 in + e in sets 52 and 53 (both of feature 43) and two of the front face
in set 54, named by no feature. The deviation along the outward normal is e exactly (closed form),
25.4 e mm; the inch file is the mm file's twin."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import InputError, measure
from ncadapt.cli import main

pytest.importorskip("OCP")
pytest.importorskip("lxml")

DATA = Path(__file__).parent / "data"
#: the normal offsets the fixtures were written with, inch, in document order
E_INCH = np.array(
    [0.0007, 0.0004, -0.0002, 0.0010, 0.0006, -0.0008, 0.0005, 0.0002, -0.0004, 0.0003, -0.0001, 0.0003, -0.0006]
)
E_MM = 25.4 * E_INCH
NORMALS = np.array([[0, -1, 0]] + [[0, 0, 1]] * 6 + [[1, 0, 0]] * 4 + [[0, -1, 0]] * 2, float)
IDS = ("41",) + tuple(f"42[{k}]" for k in range(1, 7)) + tuple(f"43[{k}]" for k in range(1, 5)) + ("54[1]", "54[2]")
#: the lines the points' numbers are on in the fixtures (set 53 holds its two points on one line)
LINES = [35, 58, 59, 60, 61, 62, 63, 70, 71, 76, 76, 82, 83]


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    path = tmp_path_factory.mktemp("plate") / "plate.step"
    w = STEPControl_Writer()
    w.Transfer(BRepPrimAPI_MakeBox(63.5, 38.1, 25.4).Shape(), STEPControl_AsIs)
    w.Write(str(path))
    return path


@pytest.mark.parametrize("unit", ["mm", "inch"])
def test_point_sets_give_the_normal_offsets(plate, unit):
    path = DATA / f"plate_pointsets_{unit}.qif"
    a = measure.read_actuals(path)
    assert a.ids == IDS
    assert list(a.lines) == LINES
    assert a.nominals is None
    # the numbers as written: 0.5 0.3 1.0004 in, 2.5002 0.4 0.3 in, 1.7 0.0006 0.5 in
    np.testing.assert_allclose(a.points[1], [12.7, 7.62, 25.41016], atol=1e-9)
    np.testing.assert_allclose(a.points[7], [63.50508, 10.16, 7.62], atol=1e-9)
    np.testing.assert_allclose(a.points[12], [43.18, 0.01524, 12.7], atol=1e-9)
    m = measure.against_cad(path, plate)
    np.testing.assert_allclose(m.deviation, E_MM, atol=1e-9)
    np.testing.assert_allclose(m.normal, NORMALS, atol=1e-12)
    np.testing.assert_allclose(m.nominal, m.measured - E_MM[:, None] * NORMALS, atol=1e-9)


def test_inch_point_sets_give_those_of_their_mm_twin(plate):
    mm = measure.read_actuals(DATA / "plate_pointsets_mm.qif")
    inch = measure.read_actuals(DATA / "plate_pointsets_inch.qif")
    np.testing.assert_allclose(inch.points, mm.points, atol=1e-9)
    with pytest.raises(InputError, match="disagrees with --units mm"):
        measure.read_actuals(DATA / "plate_pointsets_inch.qif", units="mm")


def test_analyze_reads_point_sets(plate, tmp_path):
    out = tmp_path / "a.json"
    r = CliRunner().invoke(
        main, ["analyze", str(DATA / "plate_pointsets_inch.qif"), "--nominal", str(plate), "--json", str(out)]
    )
    assert r.exit_code == 0, r.output
    j = json.loads(out.read_text())
    assert j["n_points"] == 13
    assert j["deviation"]["mean"] == pytest.approx(E_MM.mean(), abs=1e-9)
    assert j["deviation"]["max"] == pytest.approx(E_MM.max(), abs=1e-9)
    assert "file_nominals" not in j  # actual points only: nothing to check


def test_point_feature_actuals_and_a_point_set_together(plate, tmp_path):
    # the twelve PointFeatureActual of plate_actuals_mm.qif and a set of three points on the top face
    e = np.array([0.011, -0.007, 0.004])
    xy = np.array([[5.0, 5.0], [20.0, 33.0], [60.0, 2.0]])
    rows = "\n".join(f"{x:.3f} {y:.3f} {25.4 + d:.3f}" for (x, y), d in zip(xy, e))
    text = (DATA / "plate_actuals_mm.qif").read_text()
    sets = (
        '<MeasuredPointSets n="1">\n<MeasuredPointSet id="90" count="3">\n<Points>\n'
        f"{rows}\n</Points>\n<Compensated>true</Compensated>\n</MeasuredPointSet>\n</MeasuredPointSets>\n"
    )
    text = text.replace("</MeasuredFeatures>\n", "</MeasuredFeatures>\n" + sets, 1)
    p = tmp_path / "mixed.qif"
    p.write_text(text)
    # the offsets plate_actuals_mm.qif was written with (tests/test_cad_actuals.py), inch
    e_plate = 25.4 * np.array([4, -2, 10, 6, -8, 5, -6, 1, 9, 2, -4, 3]) * 1e-4
    m = measure.against_cad(p, plate)
    np.testing.assert_allclose(m.deviation, np.r_[e_plate, e], atol=1e-9)
    assert m.ids[-3:] == ("90[1]", "90[2]", "90[3]")
    np.testing.assert_allclose(m.measured[-3:, :2], xy, atol=1e-12)


def _edit(src: Path, dst: Path, edits) -> Path:
    text = src.read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)
    dst.write_text(text)
    return dst


def _line(path: Path, at) -> int:
    """The line of the first occurrence of ``at`` (or of ``at[0]``, plus ``at[1]``)."""
    needle, delta = (at, 0) if isinstance(at, str) else at
    return delta + next(k for k, s in enumerate(path.read_text().splitlines(), 1) if needle in s)


REFUSALS = [
    # the set says 6 points, its Points 6, the numbers are 5 points
    (
        [("              31.750000 30.480000 25.379680\n", "")],
        '<Points count="6">',
        r"MeasuredPointSet\[1\]/Points: Points holds 15 numbers, the count=6 of Points needs 3 × 6 = 18",
    ),
    # a set whose count is not its points' (no count of the Points' own): located at the set
    (
        [('<MeasuredPointSet id="52" count="2">', '<MeasuredPointSet id="52" count="3">')],
        ("63.505080 10.160000 7.620000", -1),  # the set's Points
        r"MeasuredPointSet\[2\]/Points: Points holds 6 numbers, the count=3 of MeasuredPointSet needs 3 × 3 = 9",
    ),
    (
        [('<Points count="6">', '<Points count="7">')],
        '<Points count="7">',
        "Points count=7 disagrees with the point set's count=6",
    ),
    ([('id="54" count="2"', 'id="54" count="two"')], 'id="54"', "count='two' is not a number of points"),
    (
        [("63.489840 27.940000 7.620000", "63.489840 27.940000")],
        ("63.505080 10.160000 7.620000", -1),
        "not a multiple of 3: a coordinate is missing",
    ),
    (
        [("<Normals>1 0 0 1 0 0</Normals>", "<Normals>1 0 0 1 0</Normals>")],
        "<Normals>1 0 0 1 0<",
        "Normals holds 5 numbers",
    ),
    ([("12.700000 30.480000 25.415240", "12.700000 30.48O000 25.415240")], "30.48O000", "Points: expected a number"),
    # a point of a set far from every face: refused at the line its numbers are on
    (
        [("50.800000 30.480000 25.412700", "50.800000 30.480000 28.412700")],
        "28.412700",
        "3.013 mm from the nearest face",
    ),
    ([("<Compensated>true</Compensated>", "<Compensated>maybe</Compensated>")], "maybe", "Compensated must be true"),
    (
        [
            (
                '<MeasuredPointSet id="51" count="6">',
                '<MeasuredPointSet id="51" count="6">\n<CoordinateSystemId>7</CoordinateSystemId>',
            )
        ],
        "<CoordinateSystemId>",
        "another frame",
    ),
    (
        [
            (
                '<Points count="2">\n              20.320000 -0.007620 12.700000\n              43.180000 0.015240 12.700000\n'
                "            </Points>",
                '<BinaryPoints count="2">AAAA</BinaryPoints>',
            )
        ],
        "<BinaryPoints",
        "binary arrays are not read",
    ),
    ([('<Points count="2">', '<Points count="2" linearUnit="furlong">')], "furlong", "'furlong': unknown length unit"),
]


@pytest.mark.parametrize(("edits", "at", "message"), REFUSALS)
def test_malformed_point_sets_refused_with_their_line(plate, tmp_path, edits, at, message):
    bad = _edit(DATA / "plate_pointsets_mm.qif", tmp_path / "bad.qif", edits)
    out = tmp_path / "a.json"
    r = CliRunner().invoke(main, ["analyze", str(bad), "--nominal", str(plate), "--json", str(out)])
    assert r.exit_code == 2, r.output
    assert f"{bad}:{_line(bad, at)}:" in r.output and "error:" in r.output, r.output
    with pytest.raises(InputError, match=message):
        measure.against_cad(bad, plate)
    assert not out.exists()


def test_a_set_of_tip_centres_needs_the_probe_radius(plate, tmp_path):
    # the top set measured as 2 mm probe-tip centres: each point 2 mm above its surface point along +z
    a = measure.read_actuals(DATA / "plate_pointsets_mm.qif")
    top = a.points[1:7] + [0, 0, 2.0]
    rows = "\n".join(" ".join(f"{v:.6f}" for v in q) for q in top)
    p = tmp_path / "tips.qif"
    p.write_text(
        '<?xml version="1.0"?>\n<QIFDocument xmlns="http://qifstandards.org/xsd/qif3">\n'
        '<MeasurementsResults><MeasurementResultsSet n="1"><MeasurementResults id="1">\n'
        '<MeasuredPointSets n="1">\n<MeasuredPointSet id="5" count="6">\n'
        f"<Points>\n{rows}\n</Points>\n<Compensated>false</Compensated>\n<ProbeRadius>2</ProbeRadius>\n"
        "</MeasuredPointSet>\n</MeasuredPointSets>\n</MeasurementResults></MeasurementResultsSet></MeasurementsResults>\n"
        "</QIFDocument>\n"
    )
    with pytest.raises(InputError, match=r"probe-tip centre.*ProbeRadius 2 mm.*give --probe-radius") as e:
        measure.against_cad(p, plate, max_distance=3)
    assert e.value.line == 7  # the first point's numbers
    with pytest.raises(InputError, match="states the probe radius 2 mm.*--probe-radius 1.5 disagrees"):
        measure.against_cad(p, plate, probe_radius=1.5, max_distance=3)
    m = measure.against_cad(p, plate, probe_radius=2.0, max_distance=3)
    np.testing.assert_allclose(m.deviation, E_MM[1:7], atol=1e-9)
    # and points the file says are compensated are not compensated twice
    with pytest.raises(InputError, match="already compensated"):
        measure.against_cad(DATA / "plate_pointsets_mm.qif", plate, probe_radius=2.0)


def test_a_model_point_cloud_alone_is_not_a_measurement(tmp_path):
    p = tmp_path / "cloud.qif"
    p.write_text(
        '<?xml version="1.0"?>\n<QIFDocument xmlns="http://qifstandards.org/xsd/qif3">\n<Product><TopologySet>\n'
        '<PointCloudSet n="1">\n<PointCloud id="3">\n<Points count="1">1 2 3</Points>\n</PointCloud>\n'
        "</PointCloudSet>\n</TopologySet></Product>\n</QIFDocument>\n"
    )
    with pytest.raises(InputError, match="only points are a PointCloud, which QIF 3 keeps with the product model") as e:
        measure.read_actuals(p)
    assert e.value.line == 5
    # and without --nominal the paired reader says the file holds point sets, not nominals
    with pytest.raises(InputError, match=r"measured points only \(1 measured points, 4 measured point sets\): give"):
        measure.read(DATA / "plate_pointsets_mm.qif")
