"""STEP and IGES export of B-spline surfaces through OpenCASCADE (PyPI ``cadquery-ocp-novtk``).

The surface goes to OpenCASCADE exactly as :meth:`ncadapt.surfaces.Surface.bspline` gives it
(knots, multiplicities, poles, degree 3 × 3), as one face; the writers are OpenCASCADE's own
(``STEPControl_Writer``, AP214, and ``IGESControl_Writer``), in millimetres.

A CAD part is read back by OpenCASCADE's own readers (:func:`read_part`: a STEP file through the
XCAF reader, which also gives the faces' names; an IGES file by ids only), and its faces are
projected onto, evaluated and rebuilt here.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._io import atomic_path
from .errors import InputError

FORMATS = {".step": "step", ".stp": "step", ".igs": "iges", ".iges": "iges"}


def _occ_surface(surface):
    from OCP.collections import Array1_double, Array1_int, Array2_gp_Pnt
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt

    tu, tv, ctrl = surface.bspline()

    def knots(t):
        vals, mult = np.unique(np.round(t, 12), return_counts=True)
        k = Array1_double(1, len(vals))
        m = Array1_int(1, len(vals))
        for i, (a, b) in enumerate(zip(vals, mult), 1):
            k.SetValue(i, float(a))
            m.SetValue(i, int(b))
        return k, m

    nu, nv, _ = ctrl.shape
    poles = Array2_gp_Pnt(1, nu, 1, nv)
    for i in range(nu):
        for j in range(nv):
            poles.SetValue(i + 1, j + 1, gp_Pnt(*map(float, ctrl[i, j])))
    ku, mu = knots(tu)
    kv, mv = knots(tv)
    return Geom_BSplineSurface(poles, ku, kv, mu, mv, 3, 3)


@contextlib.contextmanager
def _quiet():
    """OpenCASCADE's translators print statistics on the C stdout; send them to /dev/null."""
    import sys

    sys.stdout.flush()
    saved = os.dup(1)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


def face(surface):
    """An OpenCASCADE face of the surface."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace

    return BRepBuilderAPI_MakeFace(_occ_surface(surface), 1e-6).Face()


def block(surface, bottom: float):
    """A solid under a height-field surface: the surface's B-spline face on top (its (u, v) are the
    surface's), four vertical planar sides through the face's boundary curves, a flat bottom at
    z = ``bottom`` mm; sewn (``BRepBuilderAPI_Sewing``) and oriented outward. The surface must be a
    height field over its (x, y) rectangle lying above ``bottom`` (a :class:`ValueError` otherwise)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import (
        BRepBuilderAPI_MakeEdge,
        BRepBuilderAPI_MakeFace,
        BRepBuilderAPI_MakeSolid,
        BRepBuilderAPI_MakeWire,
        BRepBuilderAPI_Sewing,
    )
    from OCP.BRepLib import BRepLib
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_SHELL
    from OCP.TopExp import TopExp, TopExp_Explorer
    from OCP.TopoDS import TopoDS

    g = np.asarray(surface.grid, float)
    if float(g[..., 2].min()) <= bottom:
        raise ValueError(f"the surface reaches down to z {g[..., 2].min():g} mm, not above the bottom {bottom:g} mm")
    top = BRepBuilderAPI_MakeFace(_occ_surface(surface), 1e-7).Face()
    sew = BRepBuilderAPI_Sewing(1e-6)
    sew.Add(top)
    ex = TopExp_Explorer(top, TopAbs_EDGE)
    while ex.More():
        e = TopoDS.Edge(ex.Current())
        ex.Next()
        p0 = BRep_Tool.Pnt_s(TopExp.FirstVertex_s(e))
        p1 = BRep_Tool.Pnt_s(TopExp.LastVertex_s(e))
        q0, q1 = gp_Pnt(p0.X(), p0.Y(), bottom), gp_Pnt(p1.X(), p1.Y(), bottom)
        w = BRepBuilderAPI_MakeWire(
            e,
            BRepBuilderAPI_MakeEdge(p1, q1).Edge(),
            BRepBuilderAPI_MakeEdge(q1, q0).Edge(),
            BRepBuilderAPI_MakeEdge(q0, p0).Edge(),
        )
        if not w.IsDone():
            raise ValueError("a side of the block does not close")
        sew.Add(BRepBuilderAPI_MakeFace(w.Wire(), True).Face())
    x0, x1, y0, y1 = float(g[0, 0, 0]), float(g[-1, 0, 0]), float(g[0, 0, 1]), float(g[0, -1, 1])
    sew.Add(BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0.0, 0.0, bottom), gp_Dir(0.0, 0.0, 1.0)), x0, x1, y0, y1).Face())
    sew.Perform()
    ex = TopExp_Explorer(sew.SewedShape(), TopAbs_SHELL)
    if not ex.More():
        raise ValueError("the faces of the block do not sew into a shell")
    solid = BRepBuilderAPI_MakeSolid(TopoDS.Shell(ex.Current())).Solid()
    BRepLib.OrientClosedSolid_s(solid)
    return solid


def write(surface, path: str | os.PathLike) -> Path:
    """Write the surface as STEP (``.step``/``.stp``) or IGES (``.igs``/``.iges``), atomically."""
    return write_shape(face(surface), path)


def write_shape(shape, path: str | os.PathLike, names=()) -> Path:
    """Write an OpenCASCADE shape (a face, a compound of faces, a solid) as STEP (AP214) or IGES,
    atomically, in millimetres. ``names``: (face, name) pairs written as the STEP file's face names
    (through OpenCASCADE's XCAF writer, as :func:`read_part` reads them)."""
    p = Path(path)
    kind = FORMATS.get(p.suffix.lower())
    if kind is None:
        raise InputError(f"unknown CAD format {p.suffix!r}; use .step, .stp, .igs or .iges", str(p))
    f = shape
    names = [(face, n) for face, n in names if n]
    with atomic_path(p) as tmp:
        if kind == "step" and names:
            ok = _write_named_step(f, names, tmp)
        elif kind == "step":
            from OCP.IFSelect import IFSelect_RetDone
            from OCP.Interface import Interface_Static
            from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

            with _quiet():
                w = STEPControl_Writer()
                Interface_Static.SetCVal_s("write.step.unit", "MM")
                w.Transfer(f, STEPControl_AsIs)
                ok = w.Write(tmp) == IFSelect_RetDone
        else:
            from OCP.IGESControl import IGESControl_Writer

            with _quiet():
                w = IGESControl_Writer("MM", 0)
                w.AddShape(f)
                w.ComputeModel()
                ok = w.Write(tmp)
        if not ok:
            raise OSError(f"OpenCASCADE could not write {p}")
    return p


def _write_named_step(shape, names, path) -> bool:
    """STEP through the XCAF writer: ``shape`` with each face of ``names`` a named sub-shape."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.Interface import Interface_Static
    from OCP.STEPCAFControl import STEPCAFControl_Writer
    from OCP.STEPControl import STEPControl_AsIs
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDocStd import TDocStd_Document
    from OCP.XCAFDoc import XCAFDoc_DocumentTool

    with _quiet():
        doc = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
        tool = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
        label = tool.AddShape(shape, False)
        for face, name in names:
            TDataStd_Name.Set_s(tool.AddSubShape(label, face), TCollection_ExtendedString(name))
        w = STEPCAFControl_Writer()
        w.SetNameMode(True)
        Interface_Static.SetCVal_s("write.step.unit", "MM")
        Interface_Static.SetIVal_s("write.stepcaf.subshapes.name", 1)
        if not w.Transfer(doc, STEPControl_AsIs):
            return False
        return w.Write(str(path)) == IFSelect_RetDone


def read_surface_points(path: str | os.PathLike, u, v) -> np.ndarray:
    """Read the first face of a STEP or IGES file back and evaluate its surface at (u, v)."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    p = Path(path)
    kind = FORMATS.get(p.suffix.lower())
    if kind == "step":
        from OCP.STEPControl import STEPControl_Reader as Reader
    else:
        from OCP.IGESControl import IGESControl_Reader as Reader
    with _quiet():
        r = Reader()
        r.ReadFile(str(p))
        r.TransferRoots()
        shape = r.OneShape()
    ex = TopExp_Explorer(shape, TopAbs_FACE)
    if not ex.More():
        raise InputError("no face in the file", str(p))
    s = BRep_Tool.Surface_s(TopoDS.Face(ex.Current()))
    out = []
    for a, b in zip(np.ravel(u), np.ravel(v)):
        q = s.Value(float(a), float(b))
        out.append((q.X(), q.Y(), q.Z()))
    return np.array(out)


# ------------------------------------------------------------------------ reading a STEP face
#: Longest time OpenCASCADE may take to read a CAD file, s.
READ_TIMEOUT = 300.0


def _step_names(shape, doc) -> list[str | None]:
    """The name of each face of ``shape`` (None for an unnamed one) from the XCAF document the STEP
    reader filled: the ``TDataStd_Name`` of the sub-shape labels of the shape tool (the STEP
    ``ADVANCED_FACE`` name strings), matched to the faces by their shared topology (``IsPartner``)."""
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDF import TDF_ChildIterator
    from OCP.TopAbs import TopAbs_FACE
    from OCP.XCAFDoc import XCAFDoc_DocumentTool, XCAFDoc_ShapeTool

    tool = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
    fs = faces(shape)
    out: list[str | None] = [None] * len(fs)
    it = TDF_ChildIterator(tool.Label(), True)
    while it.More():
        label = it.Value()
        it.Next()
        if not XCAFDoc_ShapeTool.IsSubShape_s(label):
            continue
        sub = XCAFDoc_ShapeTool.GetShape_s(label)
        attr = TDataStd_Name()
        if sub.ShapeType() != TopAbs_FACE or not label.FindAttribute(TDataStd_Name.GetID_s(), attr):
            continue
        name = attr.Get().ToExtString().strip()
        if not name:
            continue
        for k, f in enumerate(fs):
            if out[k] is None and f.IsPartner(sub):
                out[k] = name
    return out


def _read_child(path: str, kind: str, out: str, msg: str, names: bool = True) -> None:
    """In a child process: read the file with OpenCASCADE and write its shape as a BRep file and
    its faces' names (JSON, beside it; see :func:`_step_names`), or a message; a crash of the
    translator on a malformed file ends only the child. ``names`` False: a STEP file through the
    plain reader (``STEPControl_Reader``), its faces unnamed."""
    import json

    from OCP.BRepTools import BRepTools
    from OCP.IFSelect import IFSelect_RetDone

    try:
        with _quiet():
            if kind == "step" and names:
                from OCP.Interface import Interface_Static
                from OCP.STEPCAFControl import STEPCAFControl_Reader
                from OCP.TCollection import TCollection_ExtendedString
                from OCP.TDocStd import TDocStd_Document

                r = STEPCAFControl_Reader()
                # the names of sub-shapes (faces) too; set after the reader exists, which resets it
                Interface_Static.SetIVal_s("read.stepcaf.subshapes.name", 1)
                r.SetNameMode(True)
                for mode in (r.SetColorMode, r.SetLayerMode, r.SetPropsMode, r.SetGDTMode, r.SetMatMode):
                    mode(False)
                if r.ReadFile(path) != IFSelect_RetDone:
                    Path(msg).write_text("not a readable STEP file (OpenCASCADE could not read it)")
                    return
                doc = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
                r.Transfer(doc)
                shape = r.Reader().OneShape()
            else:
                from OCP.IGESControl import IGESControl_Reader
                from OCP.STEPControl import STEPControl_Reader

                r = STEPControl_Reader() if kind == "step" else IGESControl_Reader()
                if r.ReadFile(path) != IFSelect_RetDone:
                    Path(msg).write_text(f"not a readable {kind.upper()} file (OpenCASCADE could not read it)")
                    return
                r.TransferRoots()
                shape = r.OneShape()
            if shape is None or shape.IsNull() or not faces(shape):
                Path(msg).write_text("no face in the file")
                return
            named = _step_names(shape, doc) if kind == "step" and names else [None] * len(faces(shape))
            BRepTools.Write_s(shape, out)
            Path(out + ".names.json").write_text(json.dumps(named))
    except Exception as e:  # noqa: BLE001 - OpenCASCADE's own failures: the file is not readable
        Path(msg).write_text(f"not a readable {kind.upper()} file (OpenCASCADE: {type(e).__name__})")


@dataclass(frozen=True)
class Part:
    """A CAD part read by :func:`read_part`: its OpenCASCADE ``shape``, its ``faces`` in
    OpenCASCADE's exploration order (face id k is ``faces[k - 1]``), their ``names`` (the STEP file's
    face names, None for an unnamed face and for every face of an IGES file) and the file
    (``source``)."""

    shape: object
    faces: tuple
    names: tuple[str | None, ...]
    source: str

    def name_of(self, face_id: int) -> str | None:
        """The name of face ``face_id`` (1-based), None when it has none."""
        return self.names[face_id - 1]

    def select(self, wanted, option: str = "--face") -> list[int]:
        """The 1-based ids of the faces ``wanted`` names (all, in order, for None or empty): each an
        id (an int, or a string of digits) or a face name of the file (exact, case-sensitive).
        Refused (:class:`InputError` naming the file and listing the names): an id out of range, a
        name no face has or several faces have, digits that are one face's id and another's name."""
        if not wanted:
            return list(range(1, len(self.faces) + 1))
        out: list[int] = []
        for w in wanted:
            k = self._one(w, option)
            if k not in out:
                out.append(k)
        return out

    def _one(self, w, option: str) -> int:
        n = len(self.faces)
        text = str(w).strip()
        named = [k for k, name in enumerate(self.names, 1) if name == text]
        if isinstance(w, int) or text.isdigit():
            k = int(text)
            if not 1 <= k <= n:
                raise InputError(f"{option} {k}: the CAD file has faces 1 to {n}", self.source)
            if named and named != [k]:
                raise InputError(
                    f"{option} {k}: face {k} by its id, but {self._said(named)} by its name; rename the face in the "
                    "CAD model",
                    self.source,
                )
            return k
        if len(named) == 1:
            return named[0]
        if named:
            raise InputError(
                f"{option} {text!r}: the name is given to {self._said(named)}; choose one by its id. "
                + self.available(),
                self.source,
            )
        raise InputError(f"{option} {text!r}: no face has that name. " + self.available(), self.source)

    @staticmethod
    def _said(ids) -> str:
        return f"face {ids[0]}" if len(ids) == 1 else "faces " + ", ".join(map(str, ids))

    def available(self) -> str:
        """A sentence listing the face names with their ids (or saying the file names none)."""
        by: dict[str, list[int]] = {}
        for k, name in enumerate(self.names, 1):
            if name is not None:
                by.setdefault(name, []).append(k)
        if not by:
            return f"The CAD file names none of its faces: choose them by id, 1 to {len(self.faces)}."
        listed = "; ".join(f"{name!r} ({self._said(ids)})" for name, ids in by.items())
        return f"The faces named in the CAD file: {listed} (ids 1 to {len(self.faces)})."


def read_part(path: str | os.PathLike) -> Part:
    """The shape of a STEP (``.step``/``.stp``) or IGES file, read by OpenCASCADE, with its faces and
    their names (STEP: the XCAF reader, ``STEPCAFControl_Reader`` with names and sub-shape names on;
    each face labelled with a ``TDataStd_Name``, the ``ADVANCED_FACE`` name string); an unreadable
    file or one without a face is an :class:`InputError` naming it. A STEP file the XCAF reader
    cannot read is read again by the plain ``STEPControl_Reader`` (the same faces, unnamed).

    The translator runs in a child process (forked): on some malformed files it crashes the
    process, which then ends the child only and becomes an input error here. The shape comes back
    as an OpenCASCADE BRep file, which is read back exactly (the faces in the same order)."""
    import json
    import multiprocessing
    import tempfile

    from OCP.BRep import BRep_Builder
    from OCP.BRepTools import BRepTools
    from OCP.TopoDS import TopoDS_Shape

    p = Path(path)
    kind = FORMATS.get(p.suffix.lower())
    if kind is None:
        raise InputError(f"unknown CAD format {p.suffix!r}; use .step, .stp, .igs or .iges", str(p))
    try:
        with open(p, "rb"):
            pass
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror}", str(p)) from None
    with tempfile.TemporaryDirectory(prefix="ncadapt-cad-") as d:
        out, msg = Path(d) / "shape.brep", Path(d) / "message.txt"
        for names in (True, False):  # the names are the XCAF reader's; should it fail, the plain reader
            proc = multiprocessing.get_context("fork").Process(
                target=_read_child, args=(str(p), kind, str(out), str(msg), names)
            )
            proc.start()
            proc.join(READ_TIMEOUT)
            if proc.is_alive():
                proc.kill()
                proc.join()
                raise InputError(f"OpenCASCADE did not finish reading the file in {READ_TIMEOUT:g} s", str(p))
            if proc.exitcode == 0 and not msg.exists() or kind != "step":
                break
            msg.unlink(missing_ok=True)
            out.unlink(missing_ok=True)
        if proc.exitcode != 0:
            raise InputError(f"not a readable {kind.upper()} file (OpenCASCADE's translator crashed on it)", str(p))
        if msg.exists():
            raise InputError(msg.read_text(), str(p))
        shape = TopoDS_Shape()
        if not out.exists() or not BRepTools.Read_s(shape, str(out), BRep_Builder()):
            raise InputError(f"not a readable {kind.upper()} file (no shape came back from OpenCASCADE)", str(p))
        names = json.loads(Path(str(out) + ".names.json").read_text())
    fs = tuple(faces(shape))
    if len(names) != len(fs):
        raise InputError(f"the {kind.upper()} file's faces changed on the way back from OpenCASCADE", str(p))
    return Part(shape, fs, tuple(names), str(p))


def read_shape(path: str | os.PathLike):
    """The shape of a STEP or IGES file (:func:`read_part` without the faces' names)."""
    return read_part(path).shape


def faces(shape) -> list:
    """The faces of a shape, in OpenCASCADE's exploration order (face 1 is the first)."""
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    out = []
    ex = TopExp_Explorer(shape, TopAbs_FACE)
    while ex.More():
        out.append(TopoDS.Face(ex.Current()))
        ex.Next()
    return out


def face_uv_bounds(face) -> tuple[float, float, float, float]:
    """(umin, umax, vmin, vmax) of a face's parameters."""
    from OCP.BRepTools import BRepTools

    u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
    return float(u0), float(u1), float(v0), float(v1)


def face_evaluate(face, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (n, 3), unit normals (n, 3) pointing out of the face's material side (the surface
    normal, reversed for a reversed face) and the largest absolute principal curvature (n,), 1/mm,
    of a face at parameters (u, v)."""
    from OCP.BRep import BRep_Tool
    from OCP.GeomLProp import GeomLProp_SLProps
    from OCP.TopAbs import TopAbs_REVERSED

    s = BRep_Tool.Surface_s(face)
    sign = -1.0 if face.Orientation() == TopAbs_REVERSED else 1.0
    uu, vv = np.ravel(u).astype(float), np.ravel(v).astype(float)
    pts = np.empty((len(uu), 3))
    nrm = np.full((len(uu), 3), np.nan)
    kap = np.zeros(len(uu))
    props = GeomLProp_SLProps(s, 2, 1e-9)
    for k, (a, b) in enumerate(zip(uu, vv)):
        props.SetParameters(float(a), float(b))
        q = props.Value()
        pts[k] = (q.X(), q.Y(), q.Z())
        if props.IsNormalDefined():
            d = props.Normal()
            nrm[k] = (sign * d.X(), sign * d.Y(), sign * d.Z())
        if props.IsCurvatureDefined():
            kap[k] = max(abs(props.MaxCurvature()), abs(props.MinCurvature()))
    return pts, nrm, kap


def face_inside(face, u, v, tol: float = 1e-7, *, edges: bool = False) -> np.ndarray:
    """Whether each (u, v) lies strictly inside the face (its trimming wires; on an edge: no, or
    yes with ``edges``)."""
    from OCP.BRepClass import BRepClass_FaceClassifier
    from OCP.gp import gp_Pnt2d
    from OCP.TopAbs import TopAbs_IN, TopAbs_ON

    keep = (TopAbs_IN, TopAbs_ON) if edges else (TopAbs_IN,)
    out = np.zeros(np.size(u), dtype=bool)
    for k, (a, b) in enumerate(zip(np.ravel(u), np.ravel(v))):
        out[k] = BRepClass_FaceClassifier(face, gp_Pnt2d(float(a), float(b)), tol).State() in keep
    return out


def face_edge_points(face, per_edge: int = 2000) -> np.ndarray:
    """Points (m, 3) along every edge of a face, ``per_edge`` on each, evenly in the parameter."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    out = []
    ex = TopExp_Explorer(face, TopAbs_EDGE)
    while ex.More():
        e = TopoDS.Edge(ex.Current())
        ex.Next()
        if BRep_Tool.Degenerated_s(e):
            continue
        c = BRepAdaptor_Curve(e)
        for t in np.linspace(c.FirstParameter(), c.LastParameter(), per_edge):
            q = c.Value(float(t))
            out.append((q.X(), q.Y(), q.Z()))
    return np.asarray(out).reshape(-1, 3)


def face_project(face, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nearest points (n, 3) of a face's surface to ``points``, the face's outward normals
    there (n, 3) and the distances (n,), mm."""
    uv, dist = face_parameters(face, points)
    p, n, _ = face_evaluate(face, uv[:, 0], uv[:, 1])
    return p, n, dist


def face_parameters(face, points) -> tuple[np.ndarray, np.ndarray]:
    """The (u, v) (n, 2) of the nearest points of a face's surface to ``points`` and the distances
    (n,), mm; inf where the nearest point is off the face's trimmed area (or none was found)."""
    from OCP.BRep import BRep_Tool
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.gp import gp_Pnt

    s = BRep_Tool.Surface_s(face)
    q = np.asarray(points, float).reshape(-1, 3)
    uv = np.zeros((len(q), 2))
    dist = np.full(len(q), np.inf)
    for k, (x, y, z) in enumerate(q):
        proj = GeomAPI_ProjectPointOnSurf(gp_Pnt(float(x), float(y), float(z)), s)
        if proj.NbPoints() > 0:
            a, b = proj.LowerDistanceParameters()
            uv[k] = (a, b)
            dist[k] = proj.LowerDistance()
    inside = face_inside(face, uv[:, 0], uv[:, 1])
    dist[~inside] = np.inf
    return uv, dist


def face_top(face) -> float:
    """An upper bound of a face's Z, mm (OpenCASCADE's bounding box, which may be a little above)."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.Add_s(face, box)
    return float(box.CornerMax().Z())


# ------------------------------------------------------------------- rebuilding a face in a part
def face_rebuild_problem(face) -> str | None:
    """Why a face cannot be rebuilt as one B-spline surface over its (u, v) box (None when it can):
    a face closed on itself (a seam edge: a full turn of a cylinder) or with a degenerate edge
    (a pole or an apex) has no such surface that keeps its trimming curves."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    ex = TopExp_Explorer(face, TopAbs_EDGE)
    while ex.More():
        e = TopoDS.Edge(ex.Current())
        ex.Next()
        if BRep_Tool.IsClosed_s(e, face):
            return "it closes on itself (a seam edge, a full turn): split it into faces that do not"
        if BRep_Tool.Degenerated_s(e):
            return "it has a degenerate edge (a pole or an apex of its surface)"
    return None


def face_on_surface(face, surface):
    """A face on the B-spline surface of ``surface`` (a :class:`~ncadapt.surfaces.Surface` over
    the same (u, v) as ``face``), bounded by ``face``'s own trimming curves in (u, v) and oriented
    as ``face``: the same face with its surface replaced."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeWire
    from OCP.BRepLib import BRepLib
    from OCP.BRepTools import BRepTools, BRepTools_WireExplorer
    from OCP.ShapeFix import ShapeFix_Face
    from OCP.TopAbs import TopAbs_FORWARD, TopAbs_REVERSED, TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    g = _occ_surface(surface)
    fwd = TopoDS.Face(face.Oriented(TopAbs_FORWARD))
    outer = BRepTools.OuterWire_s(fwd)

    def rebuilt(wire):
        mw = BRepBuilderAPI_MakeWire()
        ex = BRepTools_WireExplorer(wire, fwd)
        while ex.More():
            e = ex.Current()
            ex.Next()
            c2d = BRep_Tool.CurveOnSurface_s(e, fwd, 0.0, 0.0)
            a, b = BRep_Tool.Range_s(e, fwd)
            ne = BRepBuilderAPI_MakeEdge(c2d, g, a, b).Edge()
            BRepLib.BuildCurves3d_s(ne, 1e-7)
            mw.Add(TopoDS.Edge(ne.Reversed()) if e.Orientation() == TopAbs_REVERSED else ne)
        if not mw.IsDone():
            raise ValueError("the face's trimming curves do not form a wire on the new surface")
        return mw.Wire()

    mf = BRepBuilderAPI_MakeFace(g, rebuilt(outer), True)
    ex = TopExp_Explorer(fwd, TopAbs_WIRE)
    while ex.More():
        w = TopoDS.Wire(ex.Current())
        ex.Next()
        if not w.IsSame(outer):
            mf.Add(rebuilt(w))
    fix = ShapeFix_Face(mf.Face())
    fix.Perform()
    out = TopoDS.Face(fix.Face())
    return TopoDS.Face(out.Reversed()) if face.Orientation() == TopAbs_REVERSED else out


def is_valid(shape) -> bool:
    """OpenCASCADE's own check of a shape's topology and geometry (``BRepCheck_Analyzer``)."""
    from OCP.BRepCheck import BRepCheck_Analyzer

    return bool(BRepCheck_Analyzer(shape).IsValid())


def _count(shape, kind) -> int:
    from OCP.TopExp import TopExp_Explorer

    n, ex = 0, TopExp_Explorer(shape, kind)
    while ex.More():
        n += 1
        ex.Next()
    return n


def max_tolerance(shape) -> float:
    """The largest tolerance of an edge or a vertex of a shape, mm: the widest gap it papers over."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_VERTEX
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    t = 0.0
    for kind, get, tol in (
        (TopAbs_EDGE, TopoDS.Edge, BRep_Tool.Tolerance_s),
        (TopAbs_VERTEX, TopoDS.Vertex, BRep_Tool.Tolerance_s),
    ):
        ex = TopExp_Explorer(shape, kind)
        while ex.More():
            t = max(t, float(tol(get(ex.Current()))))
            ex.Next()
    return t


def replace_faces(shape, new: dict[int, object], tolerance: float):
    """``shape`` with its faces ``new`` {1-based id: face} put in place of the old ones, and the
    part sewn again (``BRepBuilderAPI_Sewing`` at ``tolerance`` mm: an edge of a moved face and
    the unmoved neighbour's edge are one edge again, its tolerance the gap between them).

    Returns (the new shape, {id: the face in it} for every face, replaced or not). A solid stays a
    solid (its shell closed and oriented outward); the caller checks the result with
    :func:`is_valid`."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeSolid, BRepBuilderAPI_Sewing
    from OCP.BRepLib import BRepLib
    from OCP.TopAbs import TopAbs_SHELL, TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    old = faces(shape)
    if len(old) == 1:
        return new.get(1, old[0]), {1: new.get(1, old[0])}
    sew = BRepBuilderAPI_Sewing(tolerance)
    for i, f in enumerate(old, 1):
        sew.Add(new.get(i, f))
    sew.Perform()
    out = sew.SewedShape()
    placed = {}
    for i, f in enumerate(old, 1):
        g = new.get(i, f)
        placed[i] = sew.Modified(g) if sew.IsModified(g) else g
    if _count(shape, TopAbs_SOLID) == 1 and _count(out, TopAbs_SHELL) == 1:
        ex = TopExp_Explorer(out, TopAbs_SHELL)
        solid = BRepBuilderAPI_MakeSolid(TopoDS.Shell(ex.Current())).Solid()
        BRepLib.OrientClosedSolid_s(solid)
        out = solid
    placed = {i: _same_face(out, f) for i, f in placed.items()}
    return out, placed


def _same_face(shape, face):
    """The face of ``shape`` that is ``face`` (the same TShape), in its orientation there."""
    for f in faces(shape):
        if f.IsSame(face):
            return f
    raise ValueError("a replaced face is missing from the sewn part")


def part_summary(shape) -> dict:
    """Counts of solids, shells and faces and whether every shell is closed."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_FACE, TopAbs_SHELL, TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer

    closed = True
    ex = TopExp_Explorer(shape, TopAbs_SHELL)
    while ex.More():
        closed = closed and bool(BRep_Tool.IsClosed_s(ex.Current()))
        ex.Next()
    return {
        "solids": _count(shape, TopAbs_SOLID),
        "shells": _count(shape, TopAbs_SHELL),
        "faces": _count(shape, TopAbs_FACE),
        "closed": closed,
    }


def compound(shapes):
    """One compound of several shapes (the compensated faces written alone)."""
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Compound

    b, c = BRep_Builder(), TopoDS_Compound()
    b.MakeCompound(c)
    for s in shapes:
        b.Add(c, s)
    return c


def signed_distances(face, points, normals) -> tuple[np.ndarray, np.ndarray]:
    """From each point along its unit normal to the nearest point of ``face``'s surface: the signed
    distance (n,) mm (> 0 along the normal) and the distance across the normal (n,) mm."""
    from OCP.BRep import BRep_Tool
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.gp import gp_Pnt

    s = BRep_Tool.Surface_s(face)
    q = np.asarray(points, float).reshape(-1, 3)
    nn = np.asarray(normals, float).reshape(-1, 3)
    near = np.full((len(q), 3), np.nan)
    for k, (x, y, z) in enumerate(q):
        proj = GeomAPI_ProjectPointOnSurf(gp_Pnt(float(x), float(y), float(z)), s)
        if proj.NbPoints() > 0:
            r = proj.NearestPoint()
            near[k] = (r.X(), r.Y(), r.Z())
    d = near - q
    along = np.einsum("ij,ij->i", d, nn)
    across = np.linalg.norm(d - along[:, None] * nn, axis=1)
    return along, across


def line_crossings(shape, points, direction, reach: float) -> list[np.ndarray]:
    """Where the lines P + t·d through ``points`` (n, 3) along the unit ``direction`` (3,) cross the
    faces of ``shape`` within |t| ≤ ``reach`` mm: for each point, the parameters t (mm) of its
    crossings (OpenCASCADE's ``IntCurvesFace_ShapeIntersector``)."""
    from OCP.gp import gp_Dir, gp_Lin, gp_Pnt
    from OCP.IntCurvesFace import IntCurvesFace_ShapeIntersector

    it = IntCurvesFace_ShapeIntersector()
    it.Load(shape, 1e-9)
    d = gp_Dir(*map(float, direction))
    out = []
    for p in np.asarray(points, float).reshape(-1, 3):
        it.Perform(gp_Lin(gp_Pnt(*map(float, p)), d), -float(reach), float(reach))
        out.append(np.array([it.WParameter(i) for i in range(1, it.NbPnt() + 1)]))
    return out
