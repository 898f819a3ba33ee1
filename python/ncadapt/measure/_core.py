"""The measurement set and its checks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..constants import COORD_MAX
from ..errors import InputError

if TYPE_CHECKING:
    from ._align import Alignment

# how far |n| may be from 1 before a normal is refused rather than silently rescaled
NORMAL_TOL = 1e-3


@dataclass(frozen=True)
class Measurements:
    """Nominal points (n, 3), unit outward normals (n, 3), deviations (n,) in mm.

    ``measured`` (n, 3) is the measured surface point when the input gave one (after probe-radius
    compensation), else None. ``ids`` are the point names when the input had them. ``lines`` are
    the 1-based input lines of the points, for messages. ``alignment`` is the
    :class:`~ncadapt.measure.Alignment` that moved the measured points onto a CAD nominal
    (:func:`~ncadapt.measure.against_cad`; the identity when no alignment was asked for), None
    without a CAD nominal.
    """

    nominal: np.ndarray
    normal: np.ndarray
    deviation: np.ndarray
    measured: np.ndarray | None = None
    ids: tuple[str, ...] | None = None
    lines: np.ndarray | None = None
    source: str | None = None
    alignment: Alignment | None = None

    def __len__(self) -> int:
        return len(self.deviation)

    def line_of(self, i: int) -> int:
        return int(self.lines[i]) if self.lines is not None else 0

    def require(self, n: int, what: str) -> None:
        """Refuse fewer than ``n`` points for ``what``."""
        if len(self) < n:
            raise InputError(f"{what} needs at least {n} points, the measurements have {len(self)}", self.source)


def from_arrays(
    nominal,
    normal,
    measured=None,
    deviation=None,
    *,
    ids=None,
    probe_radius: float = 0.0,
    lines=None,
    source: str | None = None,
) -> Measurements:
    """Check and combine arrays into :class:`Measurements` (give ``measured`` or ``deviation``).

    ``probe_radius`` > 0: the measured points are probe-tip centres, moved back along the normal.
    """
    p = np.asarray(nominal, dtype=float)
    nn = np.asarray(normal, dtype=float)
    n = len(p)
    ln = np.asarray(lines, dtype=np.int64) if lines is not None else np.arange(1, n + 1)

    def fail(i, msg):
        raise InputError(msg, source, int(ln[i]) if lines is not None else 0)

    if p.ndim != 2 or p.shape[1] != 3 or nn.shape != p.shape:
        raise InputError(f"nominal points and normals must be (n, 3) arrays, got {p.shape} and {nn.shape}", source)
    if (measured is None) == (deviation is None):
        raise InputError("give measured points or deviations, not both or neither", source)
    for name, a in (("nominal point", p), ("normal", nn)):
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            fail(i, f"{name} is not a number (NaN or infinite) at point {i + 1}")
    _bounded(p, "nominal point", fail)
    _, first, inverse = np.unique(p, axis=0, return_index=True, return_inverse=True)
    inverse = np.asarray(inverse).ravel()
    rep = np.flatnonzero(first[inverse] != np.arange(n))
    if len(rep):
        i = int(rep[0])
        k = int(first[inverse[i]])
        where = f"line {ln[k]}" if lines is not None else f"point {k + 1}"
        fail(i, f"point {' '.join(f'{v:g}' for v in p[i])} repeats the point at {where}")
    length = np.linalg.norm(nn, axis=1)
    bad = np.abs(length - 1) > NORMAL_TOL
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        what = "zero" if length[i] == 0 else f"not a unit vector (|n| = {length[i]:.6g})"
        fail(i, f"normal of point {i + 1} is {what}; normals must be unit outward vectors")
    nn = nn / length[:, None]
    if not 0 <= probe_radius <= COORD_MAX:
        raise InputError(f"probe radius must be in [0, {COORD_MAX:g}] mm, got {probe_radius}", source)
    m = None
    if measured is not None:
        m = np.asarray(measured, dtype=float)
        if m.shape != p.shape:
            raise InputError(f"{len(m)} measured points for {n} nominal points", source)
        bad = ~np.isfinite(m).all(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            fail(i, f"measured point is not a number (NaN or infinite) at point {i + 1}")
        _bounded(m, "measured point", fail)
        m = m - probe_radius * nn
        dev = np.einsum("ij,ij->i", m - p, nn)
    else:
        dev = np.asarray(deviation, dtype=float).ravel()
        if len(dev) != n:
            raise InputError(f"{len(dev)} deviations for {n} nominal points", source)
        bad = ~np.isfinite(dev)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            fail(i, f"deviation is not a number at point {i + 1}")
        _bounded(dev[:, None], "deviation", fail)
        dev = dev - probe_radius
    if ids is not None:
        ids = tuple(str(x) for x in ids)
        if len(ids) != n:
            raise InputError(f"{len(ids)} ids for {n} points", source)
        seen: dict[str, int] = {}
        for i, name in enumerate(ids):
            if name in seen:
                fail(i, f"duplicate id {name!r} (first at point {seen[name] + 1})")
            seen[name] = i
    return Measurements(p, nn, dev, m, ids, ln if lines is not None else None, source)


def _bounded(a: np.ndarray, name: str, fail) -> None:
    """Refuse a value beyond ``COORD_MAX`` mm: it is not a position on a machine."""
    bad = (np.abs(a) > COORD_MAX).any(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        v = a[i][np.abs(a[i]) > COORD_MAX][0]
        fail(i, f"{name} {v:g} mm at point {i + 1} is beyond ±{COORD_MAX:g} mm: not a position in millimetres")
