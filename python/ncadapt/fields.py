"""Correction fields: functions from points (n, 3) to displacements (n, 3), in millimetres.

A field is called with the points of a toolpath and returns the displacement to add at each of
them. Fields read from probe maps know their domain; outside it they either refuse
(``outside="error"``, the default), hold the border value (``"clamp"``) or extrapolate
(``"extrapolate"``).

Readers
-------
- :func:`read_grid_csv`: columns ``x,y,dz`` on a rectangular grid, rows in any order.
- :func:`read_scattered_csv`: columns ``x,y,z,dx,dy,dz`` at any points.
- :func:`read_bcnc_probe`: bCNC's ``.probe`` autolevel files.
- :func:`read_probe_log`: LinuxCNC ``(PROBEOPEN file)`` logs of G38 probe points.
- :func:`read`: any of these by file name and contents.

Examples
--------
>>> import numpy as np
>>> f = GridField([0, 10], [0, 10], [[0.0, 0.1], [0.2, 0.3]])
>>> round(float(f(np.array([[5.0, 5.0, 0.0]]))[0, 2]), 6)
0.15
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from . import constants
from ._io import csv_column, csv_reader, plain_csv, read_text
from .constants import COORD_MAX
from .errors import InputError, RefusedError, cut

__all__ = [
    "Field",
    "Shift",
    "GridField",
    "ScatteredField",
    "OutsideError",
    "OUTSIDE",
    "read",
    "read_grid_csv",
    "read_scattered_csv",
    "read_bcnc_probe",
    "read_probe_log",
    "read_columns",
    "from_values",
]

#: What a field does with points outside its domain.
OUTSIDE = constants.OUTSIDE
_EPS = 1e-9


class OutsideError(RefusedError):
    """Points fell outside a field's domain while ``outside="error"``.

    ``indices`` are the rows of the points outside, ``domain`` describes the domain.
    """

    def __init__(self, indices: np.ndarray, domain: str):
        self.indices = np.asarray(indices)
        self.domain = domain
        super().__init__(f"{len(self.indices)} point(s) outside the field's domain {domain}")


def _points(points) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {p.shape}")
    return p


def _check_outside(outside: str) -> str:
    if outside not in OUTSIDE:
        raise ValueError(f'Parameter "outside" must be one of {", ".join(OUTSIDE)}; got {outside!r}')
    return outside


def _collinear(xy: np.ndarray) -> bool:
    """Points (x, y) that span no area (all on one line, within 1e-9 of their extent)."""
    c = xy - xy.mean(axis=0)
    sv = np.linalg.svd(c, compute_uv=False)
    return len(sv) < 2 or not sv[0] > 0 or sv[1] <= 1e-9 * sv[0]


def _scattered(points, displacements, linenos, source, outside) -> ScatteredField:
    """A :class:`ScatteredField` from read points, with located errors: at least 3 points, no
    (x, y) given twice, not all on one line."""
    pts = np.asarray(points, dtype=np.float64)
    src = None if source is None else str(source)
    if len(pts) < 3:
        raise InputError(f"a scattered field needs at least 3 points, found {len(pts)}", src)
    _, first, counts = np.unique(pts[:, :2], axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        k = int(first[np.flatnonzero(counts > 1)[0]])
        m = next(m for m in range(len(pts)) if m != k and (pts[m, :2] == pts[k, :2]).all())
        raise InputError(
            f"point x={pts[k, 0]:g} y={pts[k, 1]:g} repeats the point at line {linenos[k]}", src, int(linenos[m]), 1
        )
    if _collinear(pts[:, :2]):
        raise InputError(
            f"the {len(pts)} points lie on one line (from line {linenos[0]} to {linenos[-1]}); "
            "a field needs points that span an area",
            src,
        )
    return ScatteredField(pts, displacements, outside=outside, source=src)


class Field:
    """Base of correction fields: ``field(points (n, 3)) -> displacements (n, 3)``, mm.

    Attributes
    ----------
    bounds : (xmin, xmax, ymin, ymax) or None
        The rectangle the field was measured on (None: everywhere).
    grid_lines : (xs, ys) or None
        Cell lines along which moves are split before the field is applied.
    """

    bounds: tuple[float, float, float, float] | None = None
    grid_lines: tuple[np.ndarray, np.ndarray] | None = None
    outside: str = "error"

    def __call__(self, points) -> np.ndarray:
        return self._eval(_points(points))

    def _eval(self, p: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> str:
        """How the field interpolates, for a summary."""
        return repr(self)


class Shift(Field):
    """The same displacement everywhere.

    Parameters
    ----------
    d : (3,) float, mm
    """

    def __init__(self, d):
        self.d = np.asarray(d, dtype=np.float64).reshape(3)
        if not np.isfinite(self.d).all():
            raise ValueError(f"shift must be finite, got {self.d.tolist()}")

    def _eval(self, p):
        return np.broadcast_to(self.d, p.shape).copy()

    def describe(self) -> str:
        """How the field interpolates, for a summary."""
        return "a constant shift"

    def __repr__(self):
        return f"Shift({self.d.tolist()})"


class GridField(Field):
    """A Z displacement ``dz(x, y)`` on a rectangular grid.

    Parameters
    ----------
    xs : (nx,) float, mm, strictly increasing
    ys : (ny,) float, mm, strictly increasing
    dz : (ny, nx) float, mm
        ``dz[j, i]`` is the displacement at ``(xs[i], ys[j])``.
    method : {"linear", "cubic"}
        Bilinear (default) or bicubic spline interpolation.
    outside : {"error", "clamp", "extrapolate"}
    """

    def __init__(self, xs, ys, dz, method: str = "linear", outside: str = "error", source: str | None = None):
        self.xs = np.asarray(xs, dtype=np.float64)
        self.ys = np.asarray(ys, dtype=np.float64)
        self.dz = np.asarray(dz, dtype=np.float64)
        self.source = source
        if self.xs.ndim != 1 or self.ys.ndim != 1 or len(self.xs) < 2 or len(self.ys) < 2:
            raise ValueError("a grid needs at least 2 distinct x and 2 distinct y values")
        if self.dz.shape != (len(self.ys), len(self.xs)):
            raise ValueError(f"dz must have shape (ny, nx) = {(len(self.ys), len(self.xs))}, got {self.dz.shape}")
        if np.any(np.diff(self.xs) <= 0) or np.any(np.diff(self.ys) <= 0):
            raise ValueError("grid coordinates must be strictly increasing")
        if not np.isfinite(self.dz).all():
            raise ValueError("dz must be finite")
        if method not in ("linear", "cubic"):
            raise ValueError(f'Parameter "method" must be either "linear" or "cubic"; got {method!r}')
        if method == "cubic" and (len(self.xs) < 4 or len(self.ys) < 4):
            raise ValueError("bicubic interpolation needs at least 4 x 4 grid points")
        self.method = method
        self.outside = _check_outside(outside)
        self.bounds = (float(self.xs[0]), float(self.xs[-1]), float(self.ys[0]), float(self.ys[-1]))
        self.grid_lines = (self.xs, self.ys)
        self._steps = (_step(self.xs), _step(self.ys))
        self._spline = None

    def _eval(self, p):
        x, y = p[:, 0], p[:, 1]
        x0, x1, y0, y1 = self.bounds
        out = (x < x0 - _EPS) | (x > x1 + _EPS) | (y < y0 - _EPS) | (y > y1 + _EPS)
        if self.outside == "error" and out.any():
            raise OutsideError(np.flatnonzero(out), f"x {x0:g}..{x1:g}, y {y0:g}..{y1:g} mm")
        if self.outside == "clamp":
            x, y = np.clip(x, x0, x1), np.clip(y, y0, y1)
        d = np.zeros_like(p)
        if self.method == "linear":
            d[:, 2] = _bilinear(self.xs, self.ys, self._steps, self.dz, x, y)
        elif self.outside == "extrapolate" and out.any():
            from scipy.interpolate import RegularGridInterpolator  # imported where needed: it is slow to import

            rgi = RegularGridInterpolator(
                (self.xs, self.ys), self.dz.T, method="cubic", bounds_error=False, fill_value=None
            )
            d[:, 2] = rgi(np.column_stack([x, y]))
        else:
            if self._spline is None:
                from scipy.interpolate import RectBivariateSpline

                self._spline = RectBivariateSpline(self.xs, self.ys, self.dz.T, kx=3, ky=3, s=0)
            d[:, 2] = self._spline.ev(x, y)
        return d

    def describe(self) -> str:
        """How the field interpolates, for a summary."""
        how = "bilinear" if self.method == "linear" else "bicubic"
        return f"grid {len(self.xs)} x {len(self.ys)} ({how}), outside the grid: {self.outside}"

    def __repr__(self):
        return f"GridField({len(self.xs)}x{len(self.ys)}, {self.method}, outside={self.outside!r})"


def _step(grid: np.ndarray) -> float | None:
    """The spacing of a uniform grid (equal steps to 1e-12), None for an irregular one."""
    step = (grid[-1] - grid[0]) / (len(grid) - 1)
    return float(step) if np.allclose(np.diff(grid), step, rtol=1e-12, atol=0) else None


def _cell(grid: np.ndarray, step: float | None, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cell index and fraction of x along a grid of spacing ``step`` (None: irregular); the edge
    cells continue outside."""
    n = len(grid)
    if step is not None:
        u = (x - grid[0]) / step
        i = np.clip(np.floor(u), 0, n - 2).astype(np.intp)
        return i, u - i
    i = np.clip(np.searchsorted(grid, x, side="right") - 1, 0, n - 2)
    return i, (x - grid[i]) / (grid[i + 1] - grid[i])


def _bilinear(xs, ys, steps, v, x, y):
    """Bilinear interpolation of v (ny, nx) at (x, y) on a grid of spacings ``steps`` (see
    :func:`_step`); outside, the edge cells are extended linearly."""
    i, a = _cell(xs, steps[0], x)
    j, b = _cell(ys, steps[1], y)
    flat = v.ravel()
    k = j * len(xs) + i
    v00, v01 = flat[k], flat[k + 1]
    k += len(xs)
    v10, v11 = flat[k], flat[k + 1]
    lo = v00 + a * (v01 - v00)
    hi = v10 + a * (v11 - v10)
    return lo + b * (hi - lo)


class ScatteredField(Field):
    """A displacement measured at scattered points, interpolated smoothly.

    A thin-plate-spline radial basis function (:class:`scipy.interpolate.RBFInterpolator`) through
    the points' (x, y): it reproduces the measured values exactly and bends as little as possible
    between them. The domain is the convex hull of the points in (x, y); ``outside="clamp"`` holds
    the value of the nearest measured point.

    Parameters
    ----------
    points : (m, 3) float, mm
    displacements : (m, 3) float, mm
    outside : {"error", "clamp", "extrapolate"}
    neighbors : int, optional
        Use only this many nearest points per evaluation (for large m); default all up to 2000.
    """

    def __init__(self, points, displacements, outside: str = "error", neighbors: int | None = None, source=None):
        self.points = _points(points)
        self.displacements = _points(displacements)
        self.source = source
        if len(self.points) != len(self.displacements):
            raise ValueError("points and displacements must have the same number of rows")
        if len(self.points) < 3:
            raise ValueError("a scattered field needs at least 3 points")
        xy = self.points[:, :2]
        if len(np.unique(xy, axis=0)) != len(xy):
            raise ValueError("scattered field points must have distinct (x, y)")
        if not (np.isfinite(self.points).all() and np.isfinite(self.displacements).all()):
            raise ValueError("scattered field points and displacements must be finite")
        if _collinear(xy):
            raise ValueError("scattered field points span no area: they lie on one line")
        self.outside = _check_outside(outside)
        if neighbors is None and len(xy) > 2000:
            neighbors = 64
        from scipy.interpolate import RBFInterpolator
        from scipy.spatial import Delaunay, cKDTree

        self._rbf = RBFInterpolator(xy, self.displacements, kernel="thin_plate_spline", neighbors=neighbors)
        try:
            self._hull = Delaunay(xy)
        except Exception as e:  # collinear points
            raise ValueError(f"scattered field points span no area: {e}") from None
        self._tree = cKDTree(xy)
        self.bounds = (float(xy[:, 0].min()), float(xy[:, 0].max()), float(xy[:, 1].min()), float(xy[:, 1].max()))

    def _eval(self, p):
        xy = p[:, :2]
        out = self._hull.find_simplex(xy, tol=_EPS) < 0
        if self.outside == "error" and out.any():
            raise OutsideError(np.flatnonzero(out), "the convex hull of the measured points")
        d = self._rbf(xy) if len(xy) else np.zeros((0, 3))
        if self.outside == "clamp" and out.any():
            _, k = self._tree.query(xy[out])
            d[out] = self.displacements[k]
        return d

    def describe(self) -> str:
        """How the field interpolates, for a summary."""
        return f"scattered, {len(self.points):,} points (thin-plate spline)"

    def __repr__(self):
        return f"ScatteredField({len(self.points)} points, outside={self.outside!r})"


# --------------------------------------------------------------------------------- readers
def _read_csv(path: Path, required: tuple[str, ...]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Read a CSV with a header; return the required columns as floats and their line numbers."""
    rows = csv_reader(path)
    fast = _read_plain_csv(rows.text, required) if rows.delimiter == "," else None
    if fast is not None:
        return fast
    header = None
    cols: dict[str, list[float]] = {}
    linenos: list[int] = []
    for row in rows:
        lineno = rows.line_num
        if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
            continue
        if header is None:
            header = [c.strip().lower() for c in row]
            missing = [c for c in required if c not in header]
            if missing:
                raise InputError(
                    f"missing column(s) {', '.join(missing)}; the header must name {', '.join(required)}",
                    str(path),
                    lineno,
                    1,
                )
            idx = [header.index(c) for c in required]
            cols = {c: [] for c in required}
            continue
        if len(row) != len(header):
            raise InputError(f"expected {len(header)} fields, found {len(row)}", str(path), lineno, 1)
        for c, k in zip(required, idx):
            try:
                v = float(row[k])
            except ValueError:
                raise InputError(
                    f"column {c}: expected a number, found {cut(row[k].strip())}", str(path), lineno, csv_column(row, k)
                ) from None
            if not math.isfinite(v):
                raise InputError(
                    f"column {c}: value is not finite ({row[k].strip()})", str(path), lineno, csv_column(row, k)
                )
            if abs(v) > COORD_MAX:
                raise InputError(
                    f"column {c}: {v:g} is beyond ±{COORD_MAX:g}, larger than any machine value",
                    str(path),
                    lineno,
                    csv_column(row, k),
                )
            cols[c].append(v)
        linenos.append(lineno)
    if header is None:
        raise InputError("empty file; expected a header line", str(path))
    return {c: np.asarray(v, dtype=np.float64) for c, v in cols.items()}, np.asarray(linenos)


def _read_plain_csv(text: str, required: tuple[str, ...]) -> tuple[dict[str, np.ndarray], np.ndarray] | None:
    """:func:`_read_csv` at once for a plain file (:func:`ncadapt._io.plain_csv`: the header on
    line 1, numbers only) whose values are all finite and within ±COORD_MAX; None for any other,
    which the row-by-row reader then reads and locates."""
    first = text.split("\n", 1)[0]
    header = [c.strip().lower() for c in first.split(",")]
    if any(c not in header for c in required):
        return None
    got = plain_csv(text, len(header), [header.index(c) for c in required])
    if got is None:
        return None
    a, _, lines = got
    if not (np.isfinite(a).all() and (np.abs(a) <= COORD_MAX).all()):
        return None
    return {c: np.ascontiguousarray(a[:, k]) for k, c in enumerate(required)}, lines


def _distinct(a: np.ndarray) -> np.ndarray:
    """The sorted distinct values of a 1-D array of finite numbers (``np.unique`` imports
    ``numpy.ma``, 7 ms of a command's start-up)."""
    a = np.sort(a)
    return a[np.concatenate(([True], a[1:] != a[:-1]))] if len(a) else a


def _grid_from_points(x, y, dz, linenos, path, method, outside) -> GridField:
    xs = _distinct(x)
    ys = _distinct(y)
    if len(xs) < 2 or len(ys) < 2:
        raise InputError("a grid needs at least 2 distinct x and 2 distinct y values", str(path))
    grid = np.full((len(ys), len(xs)), np.nan)
    i = np.searchsorted(xs, x)
    j = np.searchsorted(ys, y)
    cell = j * len(xs) + i
    if len(_distinct(cell)) == len(cell):
        grid.ravel()[cell] = dz
    else:
        # a point given twice: found in file order, to name both lines
        seen = np.zeros_like(grid, dtype=np.int64)
        for k in range(len(x)):
            if seen[j[k], i[k]]:
                raise InputError(
                    f"duplicate grid point x={x[k]:g} y={y[k]:g} (first on line {seen[j[k], i[k]]})",
                    str(path),
                    int(linenos[k]),
                    1,
                )
            seen[j[k], i[k]] = linenos[k]
            grid[j[k], i[k]] = dz[k]
    if np.isnan(grid).any():
        jj, ii = np.argwhere(np.isnan(grid))[0]
        n_missing = int(np.isnan(grid).sum())
        raise InputError(
            f"not a rectangular grid: {n_missing} of {grid.size} points missing, e.g. x={xs[ii]:g} y={ys[jj]:g}",
            str(path),
        )
    if method == "cubic" and (len(xs) < 4 or len(ys) < 4):
        raise InputError(
            f"bicubic interpolation (--interp cubic) needs a grid of at least 4 x 4 points; this one "
            f"has {len(xs)} x {len(ys)}: use --interp linear",
            str(path),
        )
    return GridField(xs, ys, grid, method=method, outside=outside, source=str(path))


def read_columns(path, names) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Read the named columns of a CSV with a header line as floats, with the line number of each
    row; errors name the file, line and column."""
    return _read_csv(Path(path), tuple(n.lower() for n in names))


def from_values(x, y, dz, *, method: str = "linear", outside: str = "error", source=None, linenos=None) -> Field:
    """A Z displacement known at points (x, y): a :class:`GridField` when the points fill a
    rectangular grid, otherwise a :class:`ScatteredField` (thin-plate spline)."""
    x, y, dz = (np.asarray(v, dtype=np.float64).ravel() for v in (x, y, dz))
    if linenos is None:
        linenos = np.arange(1, len(x) + 1)
    xs, ys = np.unique(x), np.unique(y)
    pairs = len(np.unique(np.column_stack([x, y]), axis=0))
    if len(xs) >= 2 and len(ys) >= 2 and pairs == len(x) == len(xs) * len(ys):
        return _grid_from_points(x, y, dz, linenos, "<map>" if source is None else source, method, outside)
    zeros = np.zeros_like(x)
    return _scattered(np.column_stack([x, y, zeros]), np.column_stack([zeros, zeros, dz]), linenos, source, outside)


def read_grid_csv(path, method: str = "linear", outside: str = "error") -> GridField:
    """Read a grid field from a CSV with columns ``x,y,dz`` (mm), rows in any order."""
    path = Path(path)
    c, ln = _read_csv(path, ("x", "y", "dz"))
    return _grid_from_points(c["x"], c["y"], c["dz"], ln, path, method, outside)


def read_scattered_csv(path, outside: str = "error") -> ScatteredField:
    """Read a scattered field from a CSV with columns ``x,y,z,dx,dy,dz`` (mm)."""
    path = Path(path)
    c, ln = _read_csv(path, ("x", "y", "z", "dx", "dy", "dz"))
    pts = np.column_stack([c["x"], c["y"], c["z"]])
    d = np.column_stack([c["dx"], c["dy"], c["dz"]])
    return _scattered(pts, d, ln, path, outside)


def _numbers(path: Path):
    """Yield (line number, floats) for each non-blank line of a whitespace-separated number file."""
    text = read_text(path)
    for n, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s:
            continue
        try:
            values = [float(v) for v in s.split()]
        except ValueError:
            bad = next(v for v in s.split() if not _is_float(v))
            raise InputError(f"expected numbers, found {cut(bad)}", str(path), n, line.find(bad) + 1) from None
        for v, word in zip(values, s.split()):
            if not math.isfinite(v):
                raise InputError(f"value is not finite ({cut(word)})", str(path), n, line.find(word) + 1)
            if abs(v) > COORD_MAX:
                raise InputError(f"{v:g} mm is beyond ±{COORD_MAX:g} mm", str(path), n, line.find(word) + 1)
        yield n, values


def _is_float(v: str) -> bool:
    try:
        float(v)
        return True
    except ValueError:
        return False


def read_bcnc_probe(path, method: str = "linear", outside: str = "error") -> GridField:
    """Read a bCNC autolevel ``.probe`` file.

    The file holds ``xmin xmax xn``, ``ymin ymax yn``, ``zmin zmax feed`` and then one ``x y z``
    line per probed point. As in bCNC, the probed Z is the displacement added to the program's Z.
    """
    path = Path(path)
    rows = list(_numbers(path))
    if len(rows) < 3:
        raise InputError("a .probe file starts with three header lines (x range, y range, z range)", str(path))
    (_, hx), (_, hy) = rows[0], rows[1]
    for n, r in rows[:3]:
        if len(r) != 3:
            raise InputError(f"header line needs 3 numbers, found {len(r)}", str(path), n, 1)
    xn, yn = int(hx[2]), int(hy[2])
    pts = rows[3:]
    for n, r in pts:
        if len(r) != 3:
            raise InputError(f"expected 'x y z', found {len(r)} numbers", str(path), n, 1)
    if len(pts) != xn * yn:
        raise InputError(f"header announces {xn} x {yn} points, file has {len(pts)}", str(path))
    a = np.asarray([r for _, r in pts])
    ln = np.asarray([n for n, _ in pts])
    return _grid_from_points(a[:, 0], a[:, 1], a[:, 2], ln, path, method, outside)


def read_probe_log(path, method: str = "linear", outside: str = "error") -> Field:
    """Read a LinuxCNC probe log written between ``(PROBEOPEN file)`` and ``(PROBECLOSE)``.

    Each line holds the trip position of one G38 probe move (X Y Z and, in LinuxCNC 2.6 and
    later, A B C U V W). The probed Z is the displacement. Points on a full rectangular grid give a
    :class:`GridField`; other layouts a :class:`ScatteredField` (Z displacement only).
    """
    path = Path(path)
    rows = list(_numbers(path))
    if not rows:
        raise InputError("no probe points", str(path))
    for n, r in rows:
        if len(r) < 3:
            raise InputError(f"expected at least 'x y z', found {len(r)} number(s)", str(path), n, 1)
    a = np.asarray([r[:3] for _, r in rows])
    ln = np.asarray([n for n, _ in rows])
    xr = np.round(a[:, 0], 6)
    yr = np.round(a[:, 1], 6)
    nx, ny = len(np.unique(xr)), len(np.unique(yr))
    if nx >= 2 and ny >= 2 and nx * ny == len(a) and len(np.unique(np.column_stack([xr, yr]), axis=0)) == len(a):
        return _grid_from_points(xr, yr, a[:, 2], ln, path, method, outside)
    d = np.zeros_like(a)
    d[:, 2] = a[:, 2]
    return _scattered(a, d, ln, path, outside)


def read(path, method: str = "linear", outside: str = "error") -> Field:
    """Read a field, choosing the reader by extension and header.

    ``.probe`` → bCNC; ``.csv`` with ``dx`` → scattered, with ``dz`` only → grid; ``.hmap`` →
    OpenCNCPilot, ``.map`` → Candle; ``.txt``/``.log`` or a file of numbers → grbl ``[PRB:…]``
    reports when it holds any, Fanuc ``DPRNT`` lines when it starts ``X…``, else LinuxCNC probe
    log (:mod:`ncadapt.heightmaps`).
    """
    path = Path(path)
    _check_outside(outside)
    ext = path.suffix.lower()
    if ext == ".probe":
        return read_bcnc_probe(path, method, outside)
    if ext == ".csv":
        head = next((ln for ln in io.StringIO(read_text(path)) if ln.strip() and not ln.lstrip().startswith("#")), "")
        names = [c.strip().lower() for c in head.replace(";", ",").replace("\t", ",").split(",")]
        if "dx" in names:
            return read_scattered_csv(path, outside)
        return read_grid_csv(path, method, outside)
    if ext in (".hmap", ".map"):  # OpenCNCPilot, Candle (ncadapt.heightmaps)
        from . import heightmaps

        return (heightmaps.read_hmap if ext == ".hmap" else heightmaps.read_candle_map)(path, method, outside)
    if ext in (".txt", ".log", ".xyz", ""):
        from . import heightmaps

        text = read_text(path)
        if heightmaps.is_grbl_log(text):  # grbl [PRB:…] reports (a sender's console log)
            return heightmaps.read_grbl_log(path, method, outside)
        if heightmaps.is_worded_log(text):  # Fanuc DPRNT lines X… Y… Z…
            return heightmaps.read_worded_log(path, method, outside)
        return read_probe_log(path, method, outside)
    raise InputError(
        f"unknown field format {ext!r}; expected .csv (x,y,dz or x,y,z,dx,dy,dz), .probe (bCNC), .hmap "
        "(OpenCNCPilot), .map (Candle), or a LinuxCNC probe log or grbl [PRB:…] log (.txt, .log)",
        str(path),
    )
