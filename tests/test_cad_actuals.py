"""Actual points only against a CAD nominal: DMIS ``FA(label)=FEAT/POINT`` outputs and QIF 3
``PointFeatureActual`` results (tests/data/plate_actuals_*), in millimetres and in inches.

The fixtures measure a plate 2.5 × 1.5 × 1 in (63.5 × 38.1 × 25.4 mm, one corner at the origin, built
here by OpenCASCADE): nine points on the top face z = 1 in + e, two on the side x = 2.5 in + e and one
on the front y = 0 − e, e the chosen normal offsets in ``E_INCH``. The deviation along the outward
normal is e exactly (closed form), 25.4 e mm; the inch files are the mm files' twins."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import InputError, measure
from ncadapt.cli import main

pytest.importorskip("OCP")
pytest.importorskip("lxml")

DATA = Path(__file__).parent / "data"
LABELS = ("T1", "T2", "T3", "T4", "T5", "T6", "T7", "T8", "T9", "S1", "S2", "F1")
#: the normal offsets the fixtures were written with, inch (top ×9, side x = 2.5 in ×2, front y = 0)
E_INCH = np.array([0.0004, -0.0002, 0.0010, 0.0006, -0.0008, 0.0005, -0.0006, 0.0001, 0.0009, 0.0002, -0.0004, 0.0003])
E_MM = 25.4 * E_INCH
NORMALS = np.array([[0, 0, 1]] * 9 + [[1, 0, 0]] * 2 + [[0, -1, 0]], float)
FILES = ("plate_actuals_mm.dmo", "plate_actuals_inch.dmo", "plate_actuals_mm.qif", "plate_actuals_inch.qif")


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    path = tmp_path_factory.mktemp("plate") / "plate.step"
    w = STEPControl_Writer()
    w.Transfer(BRepPrimAPI_MakeBox(63.5, 38.1, 25.4).Shape(), STEPControl_AsIs)
    w.Write(str(path))
    return path


@pytest.mark.parametrize("name", FILES)
def test_deviations_of_actual_points_are_the_normal_offsets(plate, name):
    m = measure.against_cad(DATA / name, plate)
    np.testing.assert_allclose(m.deviation, E_MM, atol=1e-9)
    np.testing.assert_allclose(m.normal, NORMALS, atol=1e-12)
    # the nominal point is the actual moved back by e along the normal: on the face
    np.testing.assert_allclose(m.nominal, m.measured - E_MM[:, None] * NORMALS, atol=1e-9)
    np.testing.assert_allclose(m.nominal[:9, 2], 25.4, atol=1e-9)
    if name.endswith(".dmo"):
        assert m.ids == LABELS
    else:
        assert m.ids == tuple(str(21 + k) for k in range(12))


@pytest.mark.parametrize("kind", ["dmo", "qif"])
def test_inch_file_gives_the_deviations_of_its_mm_twin(plate, kind):
    mm = measure.against_cad(DATA / f"plate_actuals_mm.{kind}", plate)
    inch = measure.against_cad(DATA / f"plate_actuals_inch.{kind}", plate)
    np.testing.assert_allclose(inch.deviation, mm.deviation, atol=1e-9)
    np.testing.assert_allclose(inch.measured, mm.measured, atol=1e-9)
    a = measure.read_actuals(DATA / f"plate_actuals_inch.{kind}")
    assert a.points[0] == pytest.approx([12.7, 7.62, 25.41016], abs=1e-9)  # 0.5, 0.3, 1.0004 in
    # the file's own unit is the truth: --units may only agree with it
    with pytest.raises(InputError, match="disagrees with --units mm"):
        measure.read_actuals(DATA / f"plate_actuals_inch.{kind}", units="mm")
    assert measure.read_actuals(DATA / f"plate_actuals_inch.{kind}", units="inch").points == pytest.approx(a.points)


def _cylinder_actuals(tmp_path):
    """A sixth of a cylinder (R 40 mm, 50 mm high) as STEP, and actual points at radius 40 mm + e on
    it written in inches as DMIS and as QIF; returns the paths, e (mm) and the angles."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    step = tmp_path / "cyl.step"
    w = STEPControl_Writer()
    shape = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 40.0, 50.0, math.radians(60)).Shape()
    w.Transfer(shape, STEPControl_AsIs)
    w.Write(str(step))
    th, z = np.meshgrid(np.radians(np.arange(8, 53, 6.0)), np.arange(8, 43, 7.0), indexing="ij")
    th, z = th.ravel(), z.ravel()
    e = 0.03 * np.sin(th * 5) + 0.0004 * (z - 25)
    r = 40.0 + e
    pts = [[float(v) for v in q] for q in np.column_stack([r * np.cos(th), r * np.sin(th), z]) / 25.4]
    lines = ["DMISMN/'cylinder segment',05.0", "UNITS/INCH,ANGDEC"]
    lines += [f"FA(P{k})=FEAT/POINT,CART,{x!r},{y!r},{q!r}" for k, (x, y, q) in enumerate(pts)]
    dmis = tmp_path / "a.dmi"
    dmis.write_text("\n".join(lines + ["ENDFIL"]) + "\n")
    acts = "".join(
        f'<PointFeatureActual id="P{k}"><Location>{x!r} {y!r} {q!r}</Location></PointFeatureActual>\n'
        for k, (x, y, q) in enumerate(pts)
    )
    qif = tmp_path / "a.qif"
    qif.write_text(
        '<?xml version="1.0"?>\n<QIFDocument xmlns="http://qifstandards.org/xsd/qif3">\n<FileUnits><PrimaryUnits>'
        "<LinearUnit><SIUnitName>meter</SIUnitName><UnitName>inch</UnitName></LinearUnit></PrimaryUnits></FileUnits>\n"
        f'<MeasurementsResults><MeasurementResultsSet><MeasurementResults id="1"><MeasuredFeatures><FeatureActuals>\n'
        f"{acts}</FeatureActuals></MeasuredFeatures></MeasurementResults></MeasurementResultsSet></MeasurementsResults>"
        "</QIFDocument>\n"
    )
    return step, dmis, qif, e, th


def test_actuals_in_inch_on_a_cylinder_segment(tmp_path):
    # points at radius 40 mm + e on a sixth of a cylinder, written in inches: the deviation is e
    step, dmis, qif, e, th = _cylinder_actuals(tmp_path)
    for path in (dmis, qif):
        m = measure.against_cad(path, step, faces=[1])
        np.testing.assert_allclose(m.deviation, e, atol=1e-9)
        np.testing.assert_allclose(m.normal, np.column_stack([np.cos(th), np.sin(th), 0 * th]), atol=1e-9)


def test_analyze_reads_dmis_and_qif_actuals(tmp_path):
    step, dmis, qif, e, _ = _cylinder_actuals(tmp_path)
    for path in (dmis, qif):
        out = tmp_path / f"{path.suffix}.json"
        r = CliRunner().invoke(main, ["analyze", str(path), "--nominal", str(step), "--json", str(out)])
        assert r.exit_code == 0, r.output
        j = json.loads(out.read_text())
        assert j["deviation"]["mean"] == pytest.approx(e.mean(), abs=1e-9)
        assert j["deviation"]["rms"] == pytest.approx(np.sqrt(np.mean(e**2)), abs=1e-9)
        assert j["faces"] == [{"id": 1, "name": None, "n_points": len(e)}]
        assert "face 1" in r.output


def _edit(src: Path, dst: Path, edits) -> Path:
    text = src.read_text()
    for old, new in edits:
        assert old in text
        text = text.replace(old, new, 1)
    dst.write_text(text)
    return dst


def _line(path: Path, needle: str) -> int:
    """The line of the last occurrence of ``needle``."""
    return [k for k, s in enumerate(path.read_text().splitlines(), 1) if needle in s][-1]


DMIS_REFUSALS = [
    ([("UNITS/MM,ANGDEC,TEMPC", "UNITS/FURLONG,ANGDEC")], "UNITS/FURLONG", "UNITS/FURLONG: unknown length unit"),
    (
        [
            (
                "FA(T2)=FEAT/POINT,CART,25.40000,7.62000,25.39492,0.000000,0.000000,1.000000",
                "FA(T2)=FEAT/POINT,CART,25.4,7.62",
            )
        ],
        "FA(T2)",
        "needs its three coordinates x,y,z .*got 2",
    ),
    (
        [("FA(T4)=", "F(T4)=FEAT/POINT,CART,50.8,30.48,25.4,0,0,1\nFA(T4)=")],
        "F(T4)",
        r"mixed content: F\(T4\) is a nominal point while FA\(T1\) at line 8 has none",
    ),
    ([("FA(S2)=", "FA(T4)=")], "FA(T4)", r"duplicate label 'T4': FA\(T4\) again \(first at line 12\)"),
    ([("FA(F1)=FEAT/POINT,CART", "FA(F1)=FEAT/POINT,POL")], "FA(F1)", "only Cartesian"),
]


@pytest.mark.parametrize(("edits", "at", "message"), DMIS_REFUSALS)
def test_dmis_actuals_refused_with_their_line(plate, tmp_path, edits, at, message):
    bad = _edit(DATA / "plate_actuals_mm.dmo", tmp_path / "bad.dmo", edits)
    out = tmp_path / "a.json"
    r = CliRunner().invoke(main, ["analyze", str(bad), "--nominal", str(plate), "--json", str(out)])
    assert r.exit_code == 2, r.output
    assert f"{bad}:{_line(bad, at)}:" in r.output and "error:" in r.output, r.output
    with pytest.raises(InputError, match=message):
        measure.read_actuals(bad)
    assert not out.exists()


def test_dmis_with_its_own_nominals_on_the_cad_is_read_with_a_cad_nominal(plate, tmp_path):
    a = measure.read_actuals(DATA / "plate_actuals_mm.dmo")
    nominal = a.points - E_MM[:, None] * NORMALS  # on the faces

    def pairs(path, nominal):
        lines = ["DMISMN/'pairs',05.0", "UNITS/MM,ANGDEC"]
        for label, q, m, n in zip(a.ids, nominal, a.points, NORMALS):
            lines.append(f"F({label})=FEAT/POINT,CART,{','.join(repr(float(v)) for v in (*q, *n))}")
            lines.append(f"FA({label})=FEAT/POINT,CART,{','.join(repr(float(v)) for v in (*m, *n))}")
        path.write_text("\n".join(lines + ["ENDFIL"]) + "\n")
        return path

    p = pairs(tmp_path / "pairs.dmo", nominal)
    np.testing.assert_allclose(measure.read(p).deviation, E_MM, atol=1e-9)  # read without --nominal
    got = measure.read_actuals(p)
    np.testing.assert_allclose(got.points, a.points, atol=1e-12)
    np.testing.assert_allclose(got.nominals, nominal, atol=1e-12)
    assert list(got.lines) == list(range(4, 28, 2)) and list(got.nominal_lines) == list(range(3, 27, 2))
    proj = measure.project_on_cad(p, plate)
    np.testing.assert_allclose(proj.measurements.deviation, E_MM, atol=1e-9)
    assert proj.file_nominals["points"] == 12 and proj.file_nominals["max_distance"] < 1e-9
    # the nominal of T5 0.5 mm above the top face: refused at its F statement's line
    off = nominal.copy()
    off[4, 2] += 0.5
    bad = pairs(tmp_path / "off.dmo", off)
    with pytest.raises(InputError, match="nominal point is 0.5 mm off the CAD") as e:
        measure.against_cad(bad, plate, max_distance=0.3)
    assert e.value.line == _line(bad, "F(T5)=") == 11
    # and a file of actuals only is not read without the CAD model
    with pytest.raises(InputError, match=r"actual points only \(12 FA\(label\)\): give the CAD model"):
        measure.read(DATA / "plate_actuals_mm.dmo")


QIF_REFUSALS = [
    ([("<UnitName>mm</UnitName>", "<UnitName>furlong</UnitName>")], "<LinearUnit>", "'furlong': unknown length unit"),
    ([("<Factor>0.001</Factor>", "<Factor>0.0254</Factor>")], "<Factor>0.0254", "disagrees with its UnitConversion"),
    (
        [("<Location>25.40000 7.62000 25.39492</Location>", "<Location>25.40000 7.62000</Location>")],
        "<Location>25.40000 7.62000</Location>",
        r"PointFeatureActual\[2\]/Location: Location needs three coordinates x y z, got 2",
    ),
    ([('<PointFeatureActual id="23">', '<PointFeatureActual id="21">')], 'id="21"', "duplicate id '21'"),
    (
        [("<FeatureItemId>14</FeatureItemId>", "<FeatureItemId>12</FeatureItemId>")],
        '<PointFeatureActual id="24">',
        "feature item 12 measured twice",
    ),
    (
        [
            (
                "<FeatureItems n=",
                '<FeatureNominals><PointFeatureNominal id="5"><Location>38.1 19.05 25.4</Location>'
                "</PointFeatureNominal></FeatureNominals>\n    <FeatureItems n=",
            ),
            ('<PointFeatureItem id="13">\n', '<PointFeatureItem id="13">\n<FeatureNominalId>5</FeatureNominalId>\n'),
        ],
        '<PointFeatureActual id="23">',
        r"PointFeatureActual\[3\]: mixed content: this measured point has a nominal Location",
    ),
]


@pytest.mark.parametrize(("edits", "at", "message"), QIF_REFUSALS)
def test_qif_actuals_refused_with_their_line_and_element(plate, tmp_path, edits, at, message):
    bad = _edit(DATA / "plate_actuals_mm.qif", tmp_path / "bad.qif", edits)
    out = tmp_path / "a.json"
    r = CliRunner().invoke(main, ["analyze", str(bad), "--nominal", str(plate), "--json", str(out)])
    assert r.exit_code == 2, r.output
    assert f"{bad}:{_line(bad, at)}:" in r.output and "error:" in r.output, r.output
    with pytest.raises(InputError, match=message):
        measure.read_actuals(bad)
    assert not out.exists()


def test_qif_with_its_own_nominals_on_the_cad_is_read_with_a_cad_nominal(plate, tmp_path):
    a = measure.read_actuals(DATA / "plate_actuals_mm.qif")
    nominal = a.points - E_MM[:, None] * NORMALS  # on the faces

    def pairs(path, nominal):
        noms = "".join(
            f'<PointFeatureNominal id="{k + 1}"><Location>{" ".join(repr(float(v)) for v in q)}</Location>'
            f"<Normal>{' '.join(str(int(v)) for v in n)}</Normal></PointFeatureNominal>\n"
            for k, (q, n) in enumerate(zip(nominal, NORMALS))
        )
        text = (DATA / "plate_actuals_mm.qif").read_text()
        text = text.replace("<FeatureItems n=", f"<FeatureNominals>\n{noms}</FeatureNominals>\n    <FeatureItems n=")
        for k in range(12):
            text = text.replace(
                f'<PointFeatureItem id="{11 + k}">\n',
                f'<PointFeatureItem id="{11 + k}">\n        <FeatureNominalId>{k + 1}</FeatureNominalId>\n',
            )
        path.write_text(text)
        return path

    p = pairs(tmp_path / "pairs.qif", nominal)
    np.testing.assert_allclose(measure.read(p).deviation, E_MM, atol=1e-9)  # read without --nominal
    got = measure.read_actuals(p)
    np.testing.assert_allclose(got.nominals, nominal, atol=1e-12)
    assert got.ids == a.ids
    proj = measure.project_on_cad(p, plate)
    np.testing.assert_allclose(proj.measurements.deviation, E_MM, atol=1e-9)
    assert proj.file_nominals["points"] == 12 and proj.file_nominals["max_distance"] < 1e-9
    # the nominal of the 4th point 0.5 mm above the top face: refused at its PointFeatureNominal
    off = nominal.copy()
    off[3, 2] += 0.5
    bad = pairs(tmp_path / "off.qif", off)
    with pytest.raises(InputError, match="nominal point is 0.5 mm off the CAD") as e:
        measure.against_cad(bad, plate, max_distance=0.3)
    assert e.value.line == _line(bad, '<PointFeatureNominal id="4">')
    with pytest.raises(InputError, match=r"measured points only \(12 measured points\): give the CAD model"):
        measure.read(DATA / "plate_actuals_mm.qif")
