"""STEP and IGES export of B-spline surfaces through OpenCASCADE (PyPI ``cadquery-ocp-novtk``).

The surface goes to OpenCASCADE exactly as :meth:`ncadapt.surfaces.Surface.bspline` gives it
(knots, multiplicities, poles, degree 3 × 3), as one face; the writers are OpenCASCADE's own
(``STEPControl_Writer``, AP214, and ``IGESControl_Writer``), in millimetres.
"""

from __future__ import annotations

import contextlib
import os
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


def write(surface, path: str | os.PathLike) -> Path:
    """Write the surface as STEP (``.step``/``.stp``) or IGES (``.igs``/``.iges``), atomically."""
    p = Path(path)
    kind = FORMATS.get(p.suffix.lower())
    if kind is None:
        raise InputError(f"unknown CAD format {p.suffix!r}; use .step, .stp, .igs or .iges", str(p))
    f = face(surface)
    with atomic_path(p) as tmp:
        if kind == "step":
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
