"""Shared checks for the tests."""

from __future__ import annotations

import subprocess
import sys

import numpy as np


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


def match_path(predicted: np.ndarray, starts: np.ndarray, ends: np.ndarray, tol: float) -> None:
    """Assert that the polyline of segments (starts[i] -> ends[i]) passes through the predicted
    points in order, and that every segment ends on a predicted point.

    Pieces that lie on one straight line are written as one move, so several predicted points may
    lie on one segment; every segment end must be one of them. Distances are per axis (the largest
    coordinate difference), as rounding to written decimals is.
    """
    j = 0
    n = len(predicted)
    for i, (a, b) in enumerate(zip(starts, ends)):
        ab = b - a
        L2 = float(ab @ ab)
        last = None
        while j < n:
            p = predicted[j]
            if np.abs(p - b).max() <= tol:
                last = j
                j += 1
                break
            t = 0.0 if L2 == 0 else float(np.clip((p - a) @ ab / L2, 0, 1))
            if np.abs(a + t * ab - p).max() > tol:
                break
            last = j
            j += 1
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
