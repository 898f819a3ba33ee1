"""Run the Sinumerik-flavoured interpreter ``nc-gcode-interpreter`` (PyPI) and read the axis
positions it reports at the end of each block, the way :mod:`rs274` reads LinuxCNC's motion.

``nc_to_dataframe(text)`` gives one row per block with the X, Y, Z it ends at (frames such as
``TRANS`` included, forward-filled; null before an axis is first written). The interpreter keeps
its numbers in single precision: positions agree to about 1e-7 of their size.
"""

from __future__ import annotations

import numpy as np

try:
    import nc_gcode_interpreter as _nci
except ImportError:  # pragma: no cover - a test dependency
    _nci = None

AVAILABLE = _nci is not None


def ends(text: str, start=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(n, 3) the X Y Z where each block that moves ends, in order (an axis not yet written is at
    ``start``), consecutive repeats removed."""
    df, _ = _nci.nc_to_dataframe(text, iteration_limit=1_000_000)
    cols = [np.asarray(df[a].to_numpy(), dtype=float) if a in df.columns else np.full(len(df), np.nan) for a in "XYZ"]
    p = np.column_stack(cols) if len(df) else np.zeros((0, 3))
    for k in range(3):
        p[np.isnan(p[:, k]), k] = start[k]
    return distinct(p, start)


def distinct(p: np.ndarray, start=(0.0, 0.0, 0.0)) -> np.ndarray:
    """``p`` (n, 3) without consecutive repeats, nor rows at ``start`` before the first move."""
    p = np.asarray(p, dtype=float)[:, :3]
    q = np.vstack([np.asarray(start, dtype=float), p])
    keep = np.any(np.abs(np.diff(q, axis=0)) > 0, axis=1)
    return p[keep]


def tolerance(p: np.ndarray) -> float:
    """How far apart two reports of the same position may be: single precision at their size."""
    return 4e-7 * max(1.0, float(np.abs(p).max(initial=0.0))) + 1e-6


def contains_in_order(big: np.ndarray, small: np.ndarray, tol: float) -> tuple[bool, str]:
    """Whether every row of ``small`` is found in ``big`` within ``tol``, in order; where not."""
    j = 0
    for k, q in enumerate(small):
        while j < len(big) and np.abs(big[j] - q).max() > tol:
            j += 1
        if j == len(big):
            return False, f"position {k} {q.tolist()} not found after the ones before it"
        j += 1
    return True, ""
