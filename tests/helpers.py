"""Shared checks for the tests."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from rs274 import Move


def skin_server(*args, env=None) -> subprocess.Popen:
    """``ncadapt skin serve ARGS`` in a process of its own (the controller of the OPC UA pair);
    its first line on stderr says where it serves."""
    return subprocess.Popen(
        [sys.executable, "-c", "from ncadapt.cli import main; main()", "skin", "serve", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def match_path(
    predicted: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    tol: float,
    chords: np.ndarray | None = None,
    tol_arc: float = 0.0,
) -> None:
    """Assert that the polyline of segments (starts[i] -> ends[i]) passes through the predicted
    points in order, and that every segment ends on a predicted point.

    Pieces that lie on one straight line are written as one move, so several predicted points may
    lie on one segment; every segment end must be one of them. Distances are per axis (the largest
    coordinate difference), as rounding to written decimals is.

    Segments flagged in `chords` are fine chords of an arc the program writes as an arc: the
    predicted points on them need only be within `tol_arc` (an arc kept an arc is within the
    chord tolerance of the displaced path), and a chord need not end on one.
    """
    j = 0
    n = len(predicted)
    for i, (a, b) in enumerate(zip(starts, ends)):
        ab = b - a
        L2 = float(ab @ ab)
        last = None
        chord = chords is not None and bool(chords[i])
        while j < n:
            p = predicted[j]
            if np.abs(p - b).max() <= tol:
                last = j
                j += 1
                break
            t = 0.0 if L2 == 0 else float(np.clip((p - a) @ ab / L2, 0, 1))
            if np.abs(a + t * ab - p).max() > (tol_arc if chord else tol):
                break
            last = j
            j += 1
        if chord:
            continue
        assert last is not None and np.abs(predicted[last] - b).max() <= tol, (
            f"segment {i} {a.round(5)} -> {b.round(5)} does not end on the predicted path "
            f"(next predicted {predicted[min(j, n - 1)].round(5)})"
        )
    assert j == n, f"{n - j} predicted point(s) not reached, first {predicted[j].round(5)}"


def endpoints_agree(blocks, canon, what: str) -> int:
    """Assert that every block end the engine traces (``Program.blocks``) equals rs274's canonical
    move end (``rs274.Canon``): lengths to rs274's 4 printed decimals (5e-5 mm, or 1.27e-3 mm in
    inch), A/B/C to 5e-5 degree. Returns the number of blocks compared."""
    assert len(canon.ends) == len(blocks), f"{what}: {len(blocks)} blocks, rs274 printed {len(canon.ends)} moves"
    ours = blocks.end[:, :6]
    known = np.isfinite(ours)
    tol = np.full(6, canon.resolution_mm + 1e-9)
    tol[3:] = 5e-5 + 1e-9
    diff = np.where(known, np.abs(ours - canon.ends), 0.0)
    bad = np.argwhere(diff > tol)
    assert not len(bad), (
        f"{what}: line {blocks.line[bad[0][0]]} axis {'XYZABC'[bad[0][1]]}: engine {ours[tuple(bad[0])]:.6f}, "
        f"rs274 {canon.ends[tuple(bad[0])]:.6f}"
    )
    return int(known.any(axis=1).sum())


def match_moves(predicted: np.ndarray, mv: list[Move], tol: float, tol_arc: float, names) -> None:
    """rs274's moves `mv` (``rs274.moves``) pass through the predicted points in order, within `tol`
    per axis on straight moves and `tol_arc` on arcs, and every move ends on one of them (an arc:
    at its last turn). Pieces on one straight line are written as one move, so several predicted
    points may lie on one move; `names(i)` names move i in a failure."""
    j, n = 0, len(predicted)
    for i, m in enumerate(mv):
        if (
            np.abs(m.end[:3] - m.start[:3]).max() <= tol
            and m.arc is None
            and (j == n or np.abs(predicted[j] - m.end[:3]).max() > tol)
        ):
            continue  # a move that goes nowhere need not be predicted (its start was checked)
        last, t = None, 0.0
        while j < n:
            p = predicted[j]
            d, t = m.locate(p, t)
            at_end = np.abs(p - m.end[:3]).max() <= tol
            if at_end and (m.arc is None or t * m.sweep * max(m.rs, m.re) >= m.sweep * max(m.rs, m.re) - 2 * tol_arc):
                last = j
                j += 1
                break
            if d > (tol if m.arc is None else tol_arc):
                break
            last = j
            j += 1
        assert last is not None and np.abs(predicted[last] - m.end[:3]).max() <= tol, (
            f"{names(i)}: rs274's {m.kind} {m.start[:3].round(5)} -> {m.end[:3].round(5)} does not end on the "
            f"predicted path (next predicted {predicted[min(j, n - 1)].round(5)}, "
            f"{m.dist(predicted[min(j, n - 1)]):.6f} mm off the move)"
        )
    assert j == n, f"{n - j} predicted point(s) not reached by rs274's motion, first {predicted[j].round(5)}"


# ------------------------------------------------------------------------------ CAD parts
def along(shape, points, normals, reach=1.0):
    """The signed distance from each point along its normal to the nearest crossing of the shape."""
    from OCP.gp import gp_Dir, gp_Lin, gp_Pnt
    from OCP.IntCurvesFace import IntCurvesFace_ShapeIntersector

    it = IntCurvesFace_ShapeIntersector()
    it.Load(shape, 1e-9)
    out = np.full(len(points), np.nan)
    for k, (p, n) in enumerate(zip(points, normals)):
        it.Perform(gp_Lin(gp_Pnt(*map(float, p)), gp_Dir(*map(float, n))), -reach, reach)
        ts = [it.WParameter(i) for i in range(1, it.NbPnt() + 1)]
        if ts:
            out[k] = min(ts, key=abs)
    return out


def xyz_csv(path, pts):
    path.write_text("x,y,z\n" + "".join(f"{float(x)!r},{float(y)!r},{float(z)!r}\n" for x, y, z in pts))
    return path


def refused_at(read, text: str, name: str, line: int, says: str, *args) -> None:
    """``read(data, name, *args)`` refuses the program at ``line`` with a message containing ``says``."""
    from ncadapt.errors import InputError

    with pytest.raises(InputError) as e:
        read(text.encode(), name, *args)
    assert (e.value.line, says in e.value.message) == (line, True), e.value


def rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def write_step(shape, path):
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    w = STEPControl_Writer()
    w.Transfer(shape, STEPControl_AsIs)
    w.Write(str(path))
    return path


def read_step(path):
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader

    r = STEPControl_Reader()
    assert r.ReadFile(str(path)) == IFSelect_RetDone
    r.TransferRoots()
    return r.OneShape()
