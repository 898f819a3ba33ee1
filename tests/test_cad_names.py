"""Faces chosen by their names in the STEP file (``--face NAME``).

The block is written here by OpenCASCADE's XCAF writer (``STEPCAFControl_Writer``), each face a
sub-shape label with a ``TDataStd_Name`` that the writer puts in its ``ADVANCED_FACE`` name string.
The name each face gets comes from its geometry (its centre, by OpenCASCADE's ``BRepGProp``), so
the test knows which face a name must select whatever order the faces are read in."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import InputError, cad, measure
from ncadapt.cli import main

pytest.importorskip("OCP")

L, W, H = 60.0, 40.0, 20.0


def _centre(face) -> tuple[float, float, float]:
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    g = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, g)
    c = g.CentreOfMass()
    return c.X(), c.Y(), c.Z()


def _name_by_centre(c) -> str:
    """The name a face of the block gets from its centre; both x walls are 'side'."""
    x, y, z = c
    if abs(z - H) < 1e-9:
        return "top"
    if abs(z) < 1e-9:
        return "bottom"
    if abs(y) < 1e-9:
        return "front"
    if abs(y - W) < 1e-9:
        return "back"
    return "side"


@pytest.fixture(scope="module")
def named_block(tmp_path_factory):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.Interface import Interface_Static
    from OCP.STEPCAFControl import STEPCAFControl_Writer
    from OCP.STEPControl import STEPControl_AsIs
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDocStd import TDocStd_Document
    from OCP.XCAFDoc import XCAFDoc_DocumentTool

    box = BRepPrimAPI_MakeBox(L, W, H).Shape()
    doc = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
    tool = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
    label = tool.AddShape(box, False)
    TDataStd_Name.Set_s(label, TCollection_ExtendedString("block"))
    for f in cad.faces(box):
        TDataStd_Name.Set_s(tool.AddSubShape(label, f), TCollection_ExtendedString(_name_by_centre(_centre(f))))
    w = STEPCAFControl_Writer()
    w.SetNameMode(True)
    Interface_Static.SetIVal_s("write.stepcaf.subshapes.name", 1)
    assert w.Transfer(doc, STEPControl_AsIs)
    path = tmp_path_factory.mktemp("named") / "block.step"
    w.Write(str(path))
    return path


def test_face_names_are_read_from_the_step_file(named_block):
    text = named_block.read_text()
    assert sorted(re.findall(r"ADVANCED_FACE\('([^']*)'", text)) == sorted(
        ["top", "bottom", "front", "back", "side", "side"]
    )
    part = cad.read_part(named_block)
    assert len(part.faces) == 6
    for face, name in zip(part.faces, part.names):
        assert name == _name_by_centre(_centre(face))
    top = part.select(["top"])
    assert len(top) == 1 and _centre(part.faces[top[0] - 1])[2] == pytest.approx(H)
    assert part.select(["top", "front", top[0]]) == [top[0], part.names.index("front") + 1]
    assert part.select(None) == [1, 2, 3, 4, 5, 6]


@pytest.mark.parametrize(
    ("wanted", "message"),
    [
        ("side", r"--face 'side': the name is given to faces \d, \d; choose one by its id"),
        ("Top", r"--face 'Top': no face has that name\. The faces named in the CAD file: .*'top' \(face \d\)"),
        ("7", "--face 7: the CAD file has faces 1 to 6"),
    ],
)
def test_a_name_that_selects_no_face_or_several_is_refused(named_block, wanted, message):
    part = cad.read_part(named_block)
    with pytest.raises(InputError, match=message) as e:
        part.select([wanted])
    if not wanted.isdigit():
        for name in ("top", "bottom", "front", "back", "side"):
            assert f"'{name}'" in e.value.message


def test_digits_that_are_one_faces_id_and_anothers_name_are_refused():
    part = cad.Part(None, ("f1", "f2", "f3"), ("2", None, None), "p.step")
    assert part.select(["1"]) == [1]
    with pytest.raises(InputError, match="face 2 by its id, but face 1 by its name"):
        part.select(["2"])
    unnamed = cad.Part(None, ("f1", "f2"), (None, None), "p.step")
    with pytest.raises(InputError, match="names none of its faces: choose them by id, 1 to 2"):
        unnamed.select(["top"])


def _top_points(e_of, n=12):
    x, y = np.meshgrid(np.linspace(4, L - 4, n), np.linspace(4, W - 4, n), indexing="ij")
    x, y = x.ravel(), y.ravel()
    e = e_of(x, y)
    return np.column_stack([x, y, H + e]), e


def _csv(path, pts):
    path.write_text("id,x,y,z\n" + "".join(f"P{k},{x!r},{y!r},{z!r}\n" for k, (x, y, z) in enumerate(pts.tolist())))
    return path


def test_analyze_and_compensate_choose_a_face_by_name(named_block, tmp_path):
    part = cad.read_part(named_block)
    top = part.names.index("top") + 1
    pts, e = _top_points(lambda x, y: 0.02 * np.sin(x / 12) + 0.01 * np.cos(y / 9))
    a = _csv(tmp_path / "a.csv", pts)
    m = measure.against_cad(a, named_block, faces=["top"])
    np.testing.assert_allclose(m.deviation, e, atol=1e-9)
    out = tmp_path / "a.json"
    r = CliRunner().invoke(
        main, ["analyze", str(a), "--nominal", str(named_block), "--face", "top", "--json", str(out)]
    )
    assert r.exit_code == 0, r.output
    j = json.loads(out.read_text())
    assert j["faces"] == [{"id": top, "name": "top", "n_points": len(e)}]
    assert j["deviation"]["mean"] == pytest.approx(e.mean(), abs=1e-9)
    assert f"face {top} 'top'" in r.output
    out = tmp_path / "c.json"
    args = ["compensate", str(a), "--nominal", str(named_block), "--face", "top", "--json", str(out)]
    r = CliRunner().invoke(main, [*args, "--part", str(tmp_path / "c.step")])
    assert r.exit_code == 0, r.output
    j = json.loads(out.read_text())
    assert j["faces"] == [top] and j["face_names"] == ["top"]
    assert [(b["face"], b["name"]) for b in j["by_face"]] == [(top, "top")]
    # the compensated part keeps the names: read back, each face's name is the one its place on
    # the block gives (the compensated top moved by microns, its centre still at z = H)
    written = cad.read_part(tmp_path / "c.step")
    assert len(written.faces) == 6
    for f, name in zip(written.faces, written.names):
        assert name == _name_by_centre(_centre(f)) or (name == "top" and abs(_centre(f)[2] - H) < 0.01)


@pytest.mark.parametrize(
    ("face", "said"),
    [
        ("side", r"the name is given to faces \d, \d"),
        ("nosuch", "no face has that name"),
    ],
)
def test_cli_refuses_a_name_listing_the_names(named_block, tmp_path, face, said):
    pts, _ = _top_points(lambda x, y: 0 * x)
    a = _csv(tmp_path / "a.csv", pts)
    out = tmp_path / "a.json"
    r = CliRunner().invoke(main, ["analyze", str(a), "--nominal", str(named_block), "--face", face, "--json", str(out)])
    assert r.exit_code == 2, r.output
    assert f"{named_block}: error: --face '{face}': " in r.output and re.search(said, r.output), r.output
    assert "'top' (face " in r.output and "'side' (faces " in r.output
    assert not out.exists()


def test_a_step_without_face_names(tmp_path):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    step = cad.write_shape(BRepPrimAPI_MakeBox(L, W, H).Shape(), tmp_path / "plain.step")
    part = cad.read_part(step)
    assert part.names == (None,) * 6
    pts, _ = _top_points(lambda x, y: 0 * x)
    a = _csv(tmp_path / "a.csv", pts)
    r = CliRunner().invoke(main, ["analyze", str(a), "--nominal", str(step), "--face", "top"])
    assert r.exit_code == 2 and "names none of its faces: choose them by id, 1 to 6" in r.output, r.output


def test_face_ids_are_those_of_opencascades_plain_step_reader(named_block):
    # the ids stay those of STEPControl_Reader (the reader before names were read), face for face
    from pathlib import Path

    from OCP.STEPControl import STEPControl_Reader

    demo = Path(cad.__file__).parent / "data" / "demo_part.step"
    for path in (named_block, demo):
        r = STEPControl_Reader()
        r.ReadFile(str(path))
        r.TransferRoots()
        plain = cad.faces(r.OneShape())
        part = cad.read_part(path)
        assert len(plain) == len(part.faces)
        for a, b in zip(plain, part.faces):
            assert _centre(a) == pytest.approx(_centre(b), abs=1e-9)
            assert a.Orientation() == b.Orientation()


def test_a_step_file_the_xcaf_reader_fails_on_is_read_without_names(named_block, monkeypatch):
    def fails(shape, doc):
        raise RuntimeError("the XCAF reader failed")

    monkeypatch.setattr(cad, "_step_names", fails)  # the forked reader inherits it
    part = cad.read_part(named_block)
    assert part.names == (None,) * 6 and len(part.faces) == 6


PROBE = ["--stylus-radius", "1.5", "--approach", "3", "--overtravel", "1", "--feed", "100"]


def test_probe_points_take_a_face_by_name(named_block, tmp_path):
    """``probe points --face NAME``: the points are placed on the face the name selects (the top,
    z = H), as by its id."""
    part = cad.read_part(named_block)
    (top,) = part.select(["top"])
    outs = []
    for face in ("top", str(top)):
        out = tmp_path / f"p_{face}.ngc"
        js = tmp_path / f"p_{face}.json"
        args = ["probe", "points", "--nominal", str(named_block), "--face", face, "--n", "9", "-o", str(out)]
        r = CliRunner().invoke(main, [*args, *PROBE, "--json", str(js)])
        assert r.exit_code == 0, r.output
        outs.append(out.read_text())
    assert outs[0] == outs[1]
    r = CliRunner().invoke(
        main,
        [
            "probe",
            "points",
            "--nominal",
            str(named_block),
            "--face",
            "side",
            "--n",
            "9",
            "-o",
            str(tmp_path / "x"),
            *PROBE,
        ],
    )
    assert r.exit_code == 2 and "the name is given to faces" in r.output
