"""On-machine probing: the points to probe, the program that probes them, and the plan that pairs
the machine's log with the nominal points.

Two kinds of program:

- **grid** (autoleveling, :func:`grid_points`, :func:`grid_program`): a rectangular grid in
  serpentine order; at each point the probe goes down along Z from the safe height until it
  touches, and back up.
- **points** (inspection from the CAD model, :func:`face_points`, :func:`points_program`): points
  on a face, each probed along its outward normal n from p + approach·n towards p − overtravel·n.
  Positions are those of the stylus-ball centre (the tool length offset must reach the ball's
  centre): at contact it is at p + r n, so the surface point is the logged centre moved back by r
  along n (:func:`read_log_with_plan`).

Dialects (a probe that does not touch stops the program in every one):

- ``linuxcnc``: ``G38.2`` (an error when the move ends without contact), results logged by
  ``(PROBEOPEN file)`` … ``(PROBECLOSE)``: one line ``x y z a b c u v w`` per probe move. With a
  second, slow touch the log would get two lines per point; the program then logs the slow
  touch alone with ``(LOGOPEN,file)`` and ``(LOG,#5061 #5062 #5063)`` … ``(LOGCLOSE)``.
- ``grbl``: ``G38.2`` (ALARM:4/5 without contact); grbl reports each touch as ``[PRB:x,y,z:1]``,
  which senders show in their console (:mod:`ncadapt.heightmaps` reads them). Only grbl's grammar:
  no O-words, no parameters, no expressions.
- ``fanuc``: ``G31`` skip; the skip position ``#5063`` (``#5061``–``#5063`` for a point) equal to
  the end of the move means no contact: ``#3000=1`` raises the alarm. Results by ``POPEN`` /
  ``DPRNT`` / ``PCLOS`` (custom macro B).
- ``sinumerik``: ``MEAS=1`` with ``G1``; ``STOPRE`` and ``$AC_MEA[1]==0`` (no trigger) jumps to an
  alarm (``SETAL(65000)``, ``M0``). Results by ``WRITE`` of ``$AA_MW`` (workpiece coordinates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = [
    "DIALECTS",
    "GridPlan",
    "FacePoints",
    "Plan",
    "grid_points",
    "grid_program",
    "face_points",
    "points_program",
    "plan_text",
    "read_plan",
    "companion_inputs",
    "read_log",
    "read_log_with_plan",
    "is_plan",
    "PLAN_MAGIC",
    "MAX_POINTS",
]

DIALECTS = ("linuxcnc", "grbl", "fanuc", "sinumerik")
#: Most points one program probes.
MAX_POINTS = 100_000
#: First line of a plan file.
PLAN_MAGIC = "# ncadapt probe plan"
#: How far the probe backs off after a fast touch before the slow one, mm.
BACKOFF = 1.0


def _f(v: float) -> str:
    """A coordinate word's number: 4 decimals (0.1 µm), no negative zero."""
    s = f"{v:.4f}"
    return "0.0000" if s == "-0.0000" else s


def _feed(v: float) -> str:
    return f"{v:.1f}"


# ------------------------------------------------------------------------------------- grid
@dataclass(frozen=True)
class GridPlan:
    """The points of a probing grid in probing order: ``points`` (n, 2) mm, ``nx`` x ``ny``."""

    points: np.ndarray
    nx: int
    ny: int
    extent: tuple[float, float, float, float]


def grid_points(extent, step: float | None = None, nx: int | None = None, ny: int | None = None) -> GridPlan:
    """A grid over ``extent`` (xmin, xmax, ymin, ymax, mm) in serpentine order: rows along x, y
    increasing, every other row backwards. ``step`` (mm): the fewest points with spacing at most
    ``step`` (as OpenCNCPilot: ceil(width/step) + 1); or ``nx`` and ``ny`` points."""
    x0, x1, y0, y1 = (float(v) for v in extent)
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f"the extent must have xmin < xmax and ymin < ymax, got {extent}")
    if step is not None:
        if not step > 0:
            raise ValueError(f"step must be positive, got {step}")
        fx, fy = math.ceil((x1 - x0) / step - 1e-9) + 1.0, math.ceil((y1 - y0) / step - 1e-9) + 1.0
        if not fx * fy <= MAX_POINTS:
            raise ValueError(
                f"a spacing of {step:g} mm over {x1 - x0:g} x {y1 - y0:g} mm needs {fx:.0f} x {fy:.0f} "
                f"points: more than {MAX_POINTS:,}; use a larger step"
            )
        nx, ny = int(fx), int(fy)
        nx, ny = max(nx, 2), max(ny, 2)
    if nx is None or ny is None or nx < 2 or ny < 2:
        raise ValueError("a grid needs at least 2 x 2 points")
    if nx * ny > MAX_POINTS:
        raise ValueError(f"{nx} x {ny} = {nx * ny:,} points: more than {MAX_POINTS:,}; use a larger step")
    xs = np.linspace(x0, x1, nx)
    ys = np.linspace(y0, y1, ny)
    if np.any(np.diff(xs) <= 0) or np.any(np.diff(ys) <= 0):
        raise ValueError("the extent is too small for that many points")
    rows = [np.column_stack([xs if j % 2 == 0 else xs[::-1], np.full(nx, y)]) for j, y in enumerate(ys)]
    return GridPlan(np.vstack(rows), nx, ny, (x0, x1, y0, y1))


def _header(dialect: str, what: str) -> list[str]:
    if dialect == "sinumerik":
        return [f"; {what}", "DEF INT _ERR", "G71 G90 G17 G94"]
    if dialect == "fanuc":
        return ["%", "O1000", f"({what.upper()})", "G21 G90 G17 G94"]
    return [f"({what})", "G21 G90 G17 G94"]


def _log_open(dialect: str, log: str, two_touch: bool) -> list[str]:
    if dialect == "linuxcnc":
        return [f"(LOGOPEN,{log})"] if two_touch else [f"(PROBEOPEN {log})"]
    if dialect == "fanuc":
        return ["POPEN"]
    return []


def _log_close(dialect: str, two_touch: bool) -> list[str]:
    if dialect == "linuxcnc":
        return ["(LOGCLOSE)"] if two_touch else ["(PROBECLOSE)"]
    if dialect == "fanuc":
        return ["PCLOS"]
    return []


def _probe(dialect: str, target: dict[str, float], feed: float, log: str, record: bool, two_touch: bool) -> list[str]:
    """One probe move to ``target`` (axis → value) that stops the program without contact, and
    its record in the log."""
    words = " ".join(f"{a}{_f(v)}" for a, v in target.items())
    if dialect in ("linuxcnc", "grbl"):
        out = [f"G38.2 {words} F{_feed(feed)}"]
        if record and dialect == "linuxcnc" and two_touch:
            out.append("(LOG,#5061 #5062 #5063)")
        return out
    if dialect == "fanuc":
        # the skip position equal to the programmed end point: the move ended without contact
        skip = {"X": 5061, "Y": 5062, "Z": 5063}
        cond = "AND".join(f"[ABS[#{skip[a]}-[{_f(v)}]]LT0.0001]" for a, v in target.items())
        out = [f"G31 {words} F{_feed(feed)}", f"IF[{cond}]GOTO9000"]
        if record:
            out.append("DPRNT[X#5061[54]*Y#5062[54]*Z#5063[54]]")
        return out
    # sinumerik
    out = [f"MEAS=1 G1 {words} F{_feed(feed)}", "STOPRE", "IF $AC_MEA[1]==0 GOTOF NOCONTACT"]
    if record:
        out.append(f'WRITE(_ERR,"{log}",$AA_MW[X]<<" "<<$AA_MW[Y]<<" "<<$AA_MW[Z])')
    return out


def _footer(dialect: str, safe_z: float) -> list[str]:
    if dialect == "fanuc":
        return [f"G0 Z{_f(safe_z)}", "M30", "N9000 #3000=1(PROBE NO CONTACT)", "M30", "%"]
    if dialect == "sinumerik":
        return [f"G0 Z{_f(safe_z)}", "M30", "NOCONTACT:", "SETAL(65000)", "M0", "M30"]
    return [f"G0 Z{_f(safe_z)}", "M2"]


def _touch(dialect, target, feed, fast_feed, log, two_touch, back):
    """The touch(es) at one point: fast then slow after backing off ``back`` (axis → value, in
    G91), or one."""
    if fast_feed is None:
        return _probe(dialect, target, feed, log, True, False)
    out = _probe(dialect, target, fast_feed, log, False, True)
    out += ["G91 G0 " + " ".join(f"{a}{_f(v)}" for a, v in back.items()), "G90"]
    out += _probe(dialect, target, feed, log, True, True)
    return out


def grid_program(
    plan: GridPlan,
    *,
    safe_z: float,
    depth: float,
    feed: float,
    fast_feed: float | None = None,
    dialect: str = "linuxcnc",
    log: str = "probe-log.txt",
) -> str:
    """The probing program of a grid: retract to ``safe_z``, move over each point, probe down to
    ``depth`` at ``feed`` mm/min (first at ``fast_feed`` and again slowly when given), back to
    ``safe_z``. Absolute millimetres (G21 G90), work coordinates."""
    _check_dialect(dialect)
    if not depth < safe_z:
        raise ValueError(f"--depth ({depth:g}) must be below --safe-z ({safe_z:g})")
    two = fast_feed is not None
    lines = _header(
        dialect,
        f"ncadapt probe grid: {plan.nx} x {plan.ny} points, serpentine, X "
        f"{_f(plan.extent[0])}..{_f(plan.extent[1])} Y {_f(plan.extent[2])}..{_f(plan.extent[3])}",
    )
    lines += _log_open(dialect, log, two)
    lines.append(f"G0 Z{_f(safe_z)}")
    back = {"Z": min(BACKOFF, safe_z - depth)}
    for x, y in plan.points:
        lines.append(f"G0 X{_f(x)} Y{_f(y)}")
        lines += _touch(dialect, {"Z": depth}, feed, fast_feed, log, two, back)
        lines.append(f"G0 Z{_f(safe_z)}")
    lines += _log_close(dialect, two)
    lines += _footer(dialect, safe_z)
    return "\n".join(lines) + "\n"


def _check_dialect(dialect):
    if dialect not in DIALECTS:
        raise ValueError(f'Parameter "dialect" must be one of {", ".join(DIALECTS)}; got {dialect!r}')


# ------------------------------------------------------------------------------------- points
@dataclass(frozen=True)
class FacePoints:
    """Points on a face: ``points`` (n, 3) mm, unit outward ``normals`` (n, 3), ``curvature`` (n,)
    1/mm (largest absolute principal curvature), ``edge_distance`` (n,) mm to the nearest edge."""

    points: np.ndarray
    normals: np.ndarray
    curvature: np.ndarray
    edge_distance: np.ndarray
    top: float  # an upper bound of the face's Z (its bounding box), mm


def _admissible(face, uu, vv, edges_tree, margin):
    from . import cad

    inside = cad.face_inside(face, uu, vv)
    p, n, k = cad.face_evaluate(face, uu, vv)
    d, _ = edges_tree.query(p)
    ok = inside & np.isfinite(n).all(axis=1) & (d >= margin)
    return ok, p, n, k, d


def face_points(face, n: int, *, margin: float, adaptive: bool = False, seed: int = 0) -> FacePoints:
    """``n`` points on an OpenCASCADE face, none closer than ``margin`` mm to an edge: a grid
    uniform in (u, v), or (``adaptive``) drawn with weights 0.2 + κ/mean(κ) from a fine grid, κ the
    largest absolute principal curvature, so that points gather where the face bends most."""
    from scipy.spatial import cKDTree

    from . import cad

    if n < 1 or n > MAX_POINTS:
        raise ValueError(f"--n must be 1 to {MAX_POINTS:,}, got {n}")
    u0, u1, v0, v1 = cad.face_uv_bounds(face)
    edges = cad.face_edge_points(face)
    if not len(edges):
        raise ValueError("the face has no edges")
    tree = cKDTree(edges)
    # the face's lengths along u and v (mid lines), for a grid of square-ish cells
    um, vm = (u0 + u1) / 2, (v0 + v1) / 2
    lu = np.linalg.norm(
        np.diff(cad.face_evaluate(face, np.linspace(u0, u1, 33), np.full(33, vm))[0], axis=0), axis=1
    ).sum()
    lv = np.linalg.norm(
        np.diff(cad.face_evaluate(face, np.full(33, um), np.linspace(v0, v1, 33))[0], axis=0), axis=1
    ).sum()
    aspect = max(lu, 1e-9) / max(lv, 1e-9)
    top = max(float(edges[:, 2].max()), cad.face_top(face))

    def grid(m, a0, a1, b0, b1, pad=True):
        nu, nv = _grid_shape(m, aspect)
        if pad:  # cell centres: no point on the parameter box's border
            us = a0 + (np.arange(nu) + 0.5) * (a1 - a0) / nu
            vs = b0 + (np.arange(nv) + 0.5) * (b1 - b0) / nv
        else:
            us, vs = np.linspace(a0, a1, nu), np.linspace(b0, b1, nv)
        U, V = np.meshgrid(us, vs, indexing="ij")
        return U.ravel(), V.ravel()

    # the admissible part of the parameter box, from a fine grid
    fu, fv = grid(max(4 * n, 2500), u0, u1, v0, v1)
    ok, p, nn, kk, dd = _admissible(face, fu, fv, tree, margin)
    if not ok.any():
        raise ValueError(f"no point of the face is {margin:g} mm or more from its edges: the stylus does not fit")
    if adaptive:
        kmean = float(kk[ok].mean())
        w = 0.2 + (kk[ok] / kmean if kmean > 0 else 0.8)
        if ok.sum() < n:
            raise ValueError(
                f"the face has room for {int(ok.sum())} points {margin:g} mm from its edges, fewer than {n}"
            )
        rng = np.random.default_rng(seed)
        keys = rng.random(int(ok.sum())) ** (1.0 / w)
        pick = np.sort(np.argsort(-keys)[:n])
        idx = np.flatnonzero(ok)[pick]
        tu, tv = fu[idx], fv[idx]
    else:
        a0, a1, b0, b1 = _tight_box(
            face, tree, margin, fu[ok].min(), fu[ok].max(), fv[ok].min(), fv[ok].max(), (u0, u1, v0, v1)
        )
        m = n
        for _ in range(40):
            gu, gv = (
                grid(m, a0, a1, b0, b1, pad=False) if n > 1 else (np.array([(a0 + a1) / 2]), np.array([(b0 + b1) / 2]))
            )
            gok, *_ = _admissible(face, gu, gv, tree, margin)
            if gok.sum() >= n:
                break
            m = int(m * 1.2) + 1
        else:
            raise ValueError(f"could not place {n} points {margin:g} mm from the face's edges")
        idx = np.flatnonzero(gok)
        idx = idx[np.round(np.linspace(0, len(idx) - 1, n)).astype(int)] if len(idx) > n else idx
        tu, tv = gu[idx], gv[idx]
    ok, p, nn, kk, dd = _admissible(face, tu, tv, tree, margin)
    assert ok.all()
    return FacePoints(p, nn, kk, dd, top=max(top, float(p[:, 2].max())))


def _tight_box(face, tree, margin, a0, a1, b0, b1, bounds):
    """Widen the admissible parameter box found on a grid towards the face's parameter bounds, each
    side by bisection, while a line of points along that side stays ``margin`` from the edges."""
    from . import cad

    box = [a0, a1, b0, b1]
    for side, limit in enumerate(bounds):

        def fine(t, side=side):
            q = list(box)
            q[side] = t
            if side < 2:
                uu, vv = np.full(101, t), np.linspace(q[2], q[3], 101)
            else:
                uu, vv = np.linspace(q[0], q[1], 101), np.full(101, t)
            p, _, _ = cad.face_evaluate(face, uu, vv)
            d, _ = tree.query(p)
            return bool((d >= margin).all())

        good, bad = box[side], limit
        for _ in range(30):
            mid = (good + bad) / 2
            if fine(mid):
                good = mid
            else:
                bad = mid
        box[side] = good
    return tuple(box)


def _grid_shape(m: int, aspect: float) -> tuple[int, int]:
    """nu x nv, at least 2 each, with nu·nv ≥ m, as few extra points and as near the aspect as can be."""
    best: tuple[float, int, int] | None = None
    for nu in range(2, max(3, 4 * int(math.sqrt(m * max(aspect, 1.0))) + 3)):
        nv = max(2, -(-m // nu))
        score = 10.0 * (nu * nv - m) / m + abs(math.log(nu / nv / aspect))
        if best is None or score < best[0]:
            best = (score, nu, nv)
    assert best is not None  # nu = 2 is always tried
    return best[1], best[2]


def points_program(
    points,
    normals,
    *,
    approach: float,
    overtravel: float,
    feed: float,
    safe_z: float,
    stylus_radius: float,
    dialect: str = "linuxcnc",
    log: str = "probe-log.txt",
    fast_feed: float | None = None,
) -> str:
    """The inspection program: for each nominal point p (outward normal n) a rapid over
    p + approach·n at ``safe_z``, down to it, a probe move towards p − overtravel·n (the ball
    centre), back to p + approach·n and up to ``safe_z``."""
    _check_dialect(dialect)
    p = np.asarray(points, float)
    nn = np.asarray(normals, float)
    if not approach > stylus_radius:
        raise ValueError(
            f"--approach ({approach:g} mm) must exceed the stylus radius ({stylus_radius:g} mm): the "
            "ball must start clear of the surface"
        )
    start = p + approach * nn
    end = p - overtravel * nn
    if not safe_z >= start[:, 2].max():
        raise ValueError(f"--safe-z ({safe_z:g}) is below the highest start point ({start[:, 2].max():.4f})")
    two = fast_feed is not None
    lines = _header(
        dialect, f"ncadapt probe points: {len(p)} points along their normals, stylus radius {_f(stylus_radius)} mm"
    )
    lines += _log_open(dialect, log, two)
    lines.append(f"G0 Z{_f(safe_z)}")
    for s, e, n in zip(start, end, nn):
        lines.append(f"G0 X{_f(s[0])} Y{_f(s[1])}")
        lines.append(f"G0 Z{_f(s[2])}")
        back = {a: BACKOFF * c for a, c in zip("XYZ", n)}
        lines += _touch(dialect, dict(zip("XYZ", e)), feed, fast_feed, log, two, back)
        lines.append(f"G0 X{_f(s[0])} Y{_f(s[1])} Z{_f(s[2])}")
        lines.append(f"G0 Z{_f(safe_z)}")
    lines += _log_close(dialect, two)
    lines += _footer(dialect, safe_z)
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------- plan
def plan_text(points, normals, *, stylus_radius: float, log: str, ids=None, touches: int = 1) -> str:
    """The plan file: the nominal points in probing order, paired line by line with the log
    (``touches`` = 2: the log has two entries per point, a fast and a slow touch, as grbl reports
    them; the second counts)."""
    p = np.asarray(points, float)
    nn = np.asarray(normals, float)
    ids = ids or [f"P{k + 1}" for k in range(len(p))]
    rows = [f"{PLAN_MAGIC}: point k is line k of the probe log", f"# log={log}", f"# stylus_radius={stylus_radius:.6f}"]
    if touches != 1:
        rows.append(f"# touches={touches}")
    rows.append("id,x,y,z,i,j,k")
    rows += [f"{i}," + ",".join(f"{v:.6f}" for v in (*q, *m)) for i, q, m in zip(ids, p, nn)]
    return "\n".join(rows) + "\n"


def is_plan(head: str) -> bool:
    """Whether a file's first bytes ``head`` are those of a probing plan (its magic first line)."""
    return head.lstrip("\ufeff").startswith(PLAN_MAGIC)


@dataclass(frozen=True)
class Plan:
    """A probing plan read back: point ids, nominal points and outward normals (n, 3) in mm, the
    plan file's lines of them, the stylus radius, the log file it names and the touches per point."""

    ids: tuple[str, ...]
    nominal: np.ndarray
    normal: np.ndarray
    lines: np.ndarray
    stylus_radius: float
    log: str | None
    source: str
    touches: int = 1


def read_plan(path) -> Plan:
    """Read a plan file (see :func:`plan_text`); errors are located."""
    from ._io import read_text
    from .heightmaps import _num

    path = Path(path)
    src = str(path)
    lines = read_text(path).splitlines()
    if not lines or not is_plan(lines[0]):
        raise InputError(f"not an ncadapt probe plan: the first line must start with {PLAN_MAGIC!r}", src, 1, 1)
    radius, log, touches = None, None, 1
    ids, vals, lns = [], [], []
    header_seen = False
    for n, raw in enumerate(lines, 1):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s[1:].strip()
            if body.startswith("stylus_radius="):
                radius = _num(body.split("=", 1)[1], src, n, raw.find("=") + 2, "stylus_radius")
                if radius < 0:
                    raise InputError(f"stylus_radius must not be negative, found {radius:g}", src, n, 1)
            elif body.startswith("touches="):
                t = body.split("=", 1)[1].strip()
                if t not in ("1", "2"):
                    raise InputError(f"touches must be 1 or 2, found {t!r}", src, n, 1)
                touches = int(t)
            elif body.startswith("log="):
                log = body.split("=", 1)[1].strip() or None
            continue
        parts = s.split(",")
        if not header_seen:
            if [c.strip().lower() for c in parts] != ["id", "x", "y", "z", "i", "j", "k"]:
                raise InputError("the plan's header must be id,x,y,z,i,j,k", src, n, 1)
            header_seen = True
            continue
        if len(parts) != 7:
            raise InputError(f"expected 7 fields (id,x,y,z,i,j,k), found {len(parts)}", src, n, 1)
        col = len(parts[0]) + 2
        row = []
        for name, w in zip("xyzijk", parts[1:]):
            row.append(_num(w, src, n, col, name))
            col += len(w) + 1
        ids.append(parts[0].strip())
        vals.append(row)
        lns.append(n)
    if radius is None:
        raise InputError("the plan has no '# stylus_radius=R' line", src, 1, 1)
    if not vals:
        raise InputError("the plan has no points", src)
    a = np.asarray(vals)
    return Plan(tuple(ids), a[:, :3], a[:, 3:], np.asarray(lns), radius, log, src, touches)


def read_log(path) -> tuple[np.ndarray, np.ndarray]:
    """The probed positions of a log in order: (m, 3) mm and their lines. A LinuxCNC PROBEOPEN
    (or LOG) file or a Sinumerik WRITE file — lines of numbers, x y z first —, grbl ``[PRB:…]``
    reports, or Fanuc DPRNT lines ``X… Y… Z…``."""
    from ._io import read_text
    from .heightmaps import _num, is_grbl_log, is_worded_log, prb_reports, worded_points

    path = Path(path)
    src = str(path)
    text = read_text(path)
    if is_grbl_log(text):
        reps = prb_reports(path)
        return np.asarray([p for _, p in reps]).reshape(-1, 3), np.asarray([n for n, _ in reps], dtype=np.int64)
    if is_worded_log(text):
        return worded_points(path)
    out, lns = [], []
    for n, raw in enumerate(text.splitlines(), 1):
        words = raw.split()
        if not words:
            continue
        if len(words) < 3:
            raise InputError(f"expected at least 'x y z', found {len(words)} value(s)", src, n, 1)
        row, col = [], raw.find(words[0]) + 1
        for w in words[:3]:
            col = raw.find(w, col - 1) + 1
            row.append(_num(w, src, n, col, "probe position"))
        for w in words[3:]:
            _num(w, src, n, raw.find(w) + 1, "probe position")
        out.append(row)
        lns.append(n)
    return np.asarray(out).reshape(-1, 3), np.asarray(lns, dtype=np.int64)


def companion_inputs(path) -> dict[str, Path]:
    """The other files a measurement input reads: for a probe plan, the log it names (for a
    command's check that no output replaces an input); empty for any other file."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            head = f.read(4096).decode("utf-8", "replace")
    except OSError:
        return {}
    if not is_plan(head):
        return {}
    m = next((ln for ln in head.splitlines()[1:4] if ln.startswith("# log=")), None)
    name = m.split("=", 1)[1].strip() if m else ""
    return {"probe log": p.parent / name} if name else {}


def read_log_with_plan(plan_path, log_path=None, probe_radius: float = 0.0):
    """:class:`ncadapt.measure.Measurements` of a probing run: point k of the plan and line k of
    its log (``log_path``, else the plan's ``log=`` beside the plan). The logged positions are
    stylus-ball centres: the plan's stylus radius is taken off along the normal."""
    from .measure import from_arrays

    plan = read_plan(plan_path)
    if log_path is None:
        if plan.log is None:
            raise InputError("the plan names no log ('# log=FILE'); give the log", plan.source, 1, 1)
        log_path = Path(plan.source).parent / plan.log
        if not Path(log_path).is_file():
            raise InputError(
                f"the plan's log {plan.log!r} is not beside the plan ({log_path}); copy the probe log "
                "from the machine there",
                plan.source,
                2,
                1,
            )
    if probe_radius not in (0.0, plan.stylus_radius):
        raise InputError(
            f"the plan records the stylus radius {plan.stylus_radius:g} mm; --probe-radius "
            f"{probe_radius:g} disagrees (leave it out)",
            plan.source,
            3,
            1,
        )
    measured, lns = read_log(log_path)
    if plan.touches == 2:  # a fast and a slow touch per point: the slow one counts
        if len(measured) % 2:
            raise InputError(
                f"the plan has two touches per point and the log {len(measured)} entries, an odd number: "
                "the probing stopped between the two touches",
                str(log_path),
            )
        measured, lns = measured[1::2], lns[1::2]
    k, n = len(measured), len(plan.nominal)
    if k < n:
        raise InputError(
            f"the log has {k} probed point(s), the plan {n}: the probing stopped before point "
            f"{plan.ids[k]} (plan line {plan.lines[k]})",
            str(log_path),
        )
    if k > n:
        raise InputError(
            f"the log has {k} probed points, the plan only {n}: not this plan's log", str(log_path), int(lns[n]), 1
        )
    return from_arrays(
        plan.nominal,
        plan.normal,
        measured=measured,
        ids=plan.ids,
        probe_radius=plan.stylus_radius,
        lines=plan.lines,
        source=plan.source,
    )
