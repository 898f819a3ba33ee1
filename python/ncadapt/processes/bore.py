"""Precision bores, H9 → H6 by corrective finishing passes with on-machine probing (Nosov,
Kondakov, "Correction of tool position to ensure manufacturing quality of precision surfaces on
multi-purpose CNC machines", Engineering Journal: Science and Innovation, 2015, issue 9).

The bore is pre-finished to H9 with a last pass of depth t₀ that left radial deviations δ_A (near
face A, where the tool enters) and δ_B (near face B) — material left, so the bore is smaller there.
The rest of the allowance z is removed in i passes of equal depth t, each with the tool shifted
"into the body" by the deviation measured before it. The model behind the plan: the radial error
is the elastic deflection of the tool, proportional to the real depth of cut, with a compliance
that varies along the bore but not around it.

Plan (all radial, mm):

- applicable when |δ_A − δ_B| ≤ 0.25·ΔD(pre-finish) (condition (3); the taper either way);
- t ≤ t_max = t₀·k·ΔD(final)/ΔD(pre-finish) (10); i = ⌈z / t_max⌉; t = z / i;
- predicted deflection near A, the paper's (6): δ_A1 = δ_A (t + 2δ_A)/t₀ — compliance δ_A/t₀ times
  the real depth t + δ_A (left) + δ_K1 (the shift). From pass 2 on the real depth is
  t + (δ_A,i−1 − δ_K,i−1) + δ_K,i = t + 2δ_A,i−1 − δ_A,i−2: what the last pass left against its aim
  plus the new shift. The paper's (7)–(8) write t + 2δ_A,i−1 (they leave out that the previous
  shift was cut already); the plan uses the real depth, and agrees with the testbed to far below
  0.1 µm noise-free (test); the paper's values are kept as ``predicted_paper``. Its closed form
  (9) is (7) with (6) substituted — the same number;
- near B the tool is shifted by the same δ_K: δ_B,i = (δ_B/t₀)·(t + δ_B,i−1 − δ_K,i−1 + δ_K,i);
- the first shift δ_K1 is the largest deviation after the pre-finish (of A and B in the plan);
- final check, condition (4): δ_A − δ_B after the last pass ≤ (k/2)·ΔD(final) (the paper's
  0.1 … 0.125 for k = 0.2 … 0.25: its (2) on the diameter, halved for the radius), and the diameter
  D_target − 2δ inside the final class.

What a deviation is after a corrected pass: the tool was set δ_K,i into the body, so the bore's
radius left short of the tool's setting, δ_i = (R_i + δ_K,i) − r_i, is the pass's elastic
deflection — the quantity the recurrence above predicts. The bore's error against the aimed
radius R_i is δ_i − δ_K,i. So the predicted final diameter is D_target − 2(δ_n − δ_K,n), and the
final form error is δ_A,n − δ_B,n.

Pass by pass: after pass i the measured deviations give the next correction δ_K,i+1 = δ_A,i — after
the pre-finish (pass 0) and for hardened material the largest deviation over the three planes,
otherwise the plane near face A. Hardened material: the first corrective pass is made without
correction at minimal depth and the compliance along the bore is identified from it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

import numpy as np

from .. import iso286
from .._io import csv_reader, read_text
from ..errors import InputError, cut

APPLICABILITY_SHARE = 0.25  # (3): |δ_A − δ_B| ≤ 0.25·ΔD(pre-finish) — the paper's (2) with k = 0.5 for H9, halved
# (4): δ_A − δ_B ≤ (k/2)·ΔD(final) after the last pass — the paper's 0.1 … 0.125 for k = 0.2 … 0.25 (Plan.form_limit)
MIN_POINTS_PER_PLANE = 3


# ------------------------------------------------------------------------------------ measuring
@dataclass(frozen=True)
class Circle:
    """A least-squares circle through the probe points of one plane."""

    plane: str
    z: float
    centre: tuple[float, float]
    diameter: float
    roundness: float  # max − min radial residual (least-squares reference circle), mm
    n: int

    def as_dict(self) -> dict:
        return {
            "plane": self.plane,
            "z": self.z,
            "centre": list(self.centre),
            "diameter": self.diameter,
            "roundness": self.roundness if math.isfinite(self.roundness) else None,
            "points": self.n,
        }


def fit_circle(x, y, plane: str = "", z: float = 0.0) -> Circle:
    """Geometric least-squares circle (minimises Σ(r_i − R)²): Kåsa's algebraic fit as the start,
    then Gauss–Newton by :func:`scipy.optimize.least_squares`."""
    from scipy.optimize import least_squares

    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if len(x) < MIN_POINTS_PER_PLANE:
        raise InputError(f"plane {plane or z}: a circle needs at least {MIN_POINTS_PER_PLANE} points, got {len(x)}")
    a = np.column_stack([x, y, np.ones_like(x)])
    sol, *_ = np.linalg.lstsq(a, x * x + y * y, rcond=None)
    cx, cy = sol[0] / 2, sol[1] / 2
    r0 = math.sqrt(max(sol[2] + cx * cx + cy * cy, 0.0))
    if not np.isfinite(r0) or r0 == 0 or np.linalg.matrix_rank(a) < 3:
        raise InputError(f"plane {plane or z}: the points are collinear or coincide; no circle")
    res = least_squares(lambda q: np.hypot(x - q[0], y - q[1]) - q[2], [cx, cy, r0], xtol=1e-15, ftol=1e-15, gtol=1e-15)
    cx, cy, r = res.x
    if not (np.all(np.isfinite(res.x)) and r > 0):
        raise InputError(f"plane {plane or z}: no circle fits these points")
    d = np.hypot(x - cx, y - cy) - r
    return Circle(plane, float(z), (float(cx), float(cy)), float(2 * r), float(d.max() - d.min()), len(x))


@dataclass(frozen=True)
class BoreMeasurement:
    """Circles ordered from face A (the tool's entry) to face B."""

    circles: tuple[Circle, ...]
    source: str | None = None

    @property
    def diameters(self) -> np.ndarray:
        return np.array([c.diameter for c in self.circles])

    @property
    def taper(self) -> float:
        """D_A − D_B, mm (negative: smaller at the entry)."""
        return self.circles[0].diameter - self.circles[-1].diameter

    @property
    def barrel(self) -> float:
        """Middle plane's diameter minus the mean of the end planes, mm (> 0: barrel)."""
        if len(self.circles) < 3:
            return 0.0
        d = self.diameters
        return float(d[len(d) // 2] - (d[0] + d[-1]) / 2)

    def deviations(self, target_diameter: float) -> np.ndarray:
        """Radial deviations δ = (D_target − D)/2 per plane, A first (> 0: material left)."""
        return (target_diameter - self.diameters) / 2

    def as_dict(self, target_diameter: float | None = None) -> dict:
        out = {"planes": [c.as_dict() for c in self.circles], "taper": self.taper, "barrel": self.barrel}
        if target_diameter is not None:
            out["deviations"] = self.deviations(target_diameter).tolist()
        return out


#: Probe points without a plane column belong to one plane while their z values are closer than
#: this to the next (mm): a probe's z scatter is µm, the planes of a bore are millimetres apart.
PLANE_GAP = 0.5


def read_probe(path, entry: str = "top") -> BoreMeasurement:
    """CSV ``plane,x,y,z`` (or ``x,y,z``: planes told apart by z, a gap over :data:`PLANE_GAP`
    between sorted z values starting a new one), one probe point a row; comma, semicolon or tab
    delimited. One plane is enough where the method needs one (near face A before passes 2 …).

    Face A is the plane nearest the tool's entry: the highest z for ``entry="top"`` (a vertical
    spindle boring downwards), the lowest for ``"bottom"``."""
    path = str(path)
    rows = list(csv_reader(path))
    if not rows:
        raise InputError("empty file", path, 1)
    head = [h.strip().lower() for h in rows[0]]
    for need in ("x", "y", "z"):
        if need not in head:
            raise InputError(f"missing column {need!r} (expected plane,x,y,z or x,y,z)", path, 1)
    ix, iy, iz = head.index("x"), head.index("y"), head.index("z")
    ip = head.index("plane") if "plane" in head else None
    groups: dict[str, list] = {}
    points = []
    for ln, r in enumerate(rows[1:], start=2):
        if not r or all(not c.strip() for c in r):
            continue
        try:
            x, y, z = float(r[ix]), float(r[iy]), float(r[iz])
        except (ValueError, IndexError):
            raise InputError("expected numbers in x, y, z", path, ln) from None
        if not all(map(math.isfinite, (x, y, z))) or max(abs(x), abs(y), abs(z)) > 1e6:
            raise InputError("x, y, z must be finite numbers within ±1e6 mm", path, ln)
        if ip is not None:
            groups.setdefault(r[ip].strip() if ip < len(r) else "", []).append((x, y, z, ln))
        else:
            points.append((x, y, z, ln))
    if ip is None:
        return _planes_from_points(points, path, entry)
    return _fit_planes(groups, path, entry)


def _planes_from_points(points, path: str, entry: str) -> BoreMeasurement:
    """Points (x, y, z, line) without a plane name: planes told apart by gaps in z."""
    groups: dict[str, list] = {}
    if points:
        points = sorted(points, key=lambda q: q[2])
        cluster = [points[0]]
        for q in points[1:]:
            if q[2] - cluster[-1][2] > PLANE_GAP:
                groups[f"z={np.mean([c[2] for c in cluster]):.2f}"] = sorted(cluster, key=lambda c: c[3])
                cluster = []
            cluster.append(q)
        groups[f"z={np.mean([c[2] for c in cluster]):.2f}"] = sorted(cluster, key=lambda c: c[3])
    return _fit_planes(groups, path, entry)


def _fit_planes(groups: dict, path: str, entry: str) -> BoreMeasurement:
    if not groups:
        raise InputError("no probe points", path)
    circles = []
    for key, pts in groups.items():
        a = np.array([p[:3] for p in pts])
        if len(a) < MIN_POINTS_PER_PLANE:
            raise InputError(
                f"plane {key!r} has {len(a)} points; a circle needs {MIN_POINTS_PER_PLANE}", path, pts[0][3]
            )
        try:
            circles.append(fit_circle(a[:, 0], a[:, 1], key, float(a[:, 2].mean())))
        except InputError as err:
            raise InputError(err.message, path, pts[0][3]) from None
    if entry not in ("top", "bottom"):
        raise ValueError(f"entry must be 'top' or 'bottom', got {entry!r}")
    circles.sort(key=lambda c: -c.z if entry == "top" else c.z)
    return BoreMeasurement(tuple(circles), path)


_DMIS_CIRCLE = re.compile(
    r"^\s*(FA|F)\(([^)]*)\)\s*=\s*FEAT\s*/\s*CIRCLE\s*,\s*(INNER|OUTER)\s*,\s*CART\s*,(.*)$", re.I
)
_PCDMIS_HEAD = re.compile(r"LOCATION\s+OF\s+CIRCLE\s+(\S+)", re.I)


def _finite(text: str, path: str, ln: int, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"expected a number for {what}, got {cut(text.strip())}", path, ln) from None
    if not math.isfinite(v) or abs(v) > 1e6:
        raise InputError(f"{what} must be a finite number within ±1e6 mm, got {cut(text.strip())}", path, ln)
    return v


def _circles(items, path: str, entry: str) -> BoreMeasurement:
    """``items``: (line, name, x, y, z, diameter) per plane → a measurement ordered from face A."""
    if not items:
        raise InputError("no bore circles", path)
    circles = []
    for ln, name, x, y, z, dia in items:
        if not dia > 0:
            raise InputError(f"the diameter of {name!r} must be > 0, got {dia:g}", path, ln)
        circles.append(Circle(name, z, (x, y), dia, float("nan"), 0))  # roundness unknown
    if entry not in ("top", "bottom"):
        raise ValueError(f"entry must be 'top' or 'bottom', got {entry!r}")
    circles.sort(key=lambda c: -c.z if entry == "top" else c.z)
    return BoreMeasurement(tuple(circles), path)


def read_dmis_circles(path, entry: str = "top") -> BoreMeasurement:
    """The bore per plane from DMIS output: ``FA(label)=FEAT/CIRCLE,INNER,CART,x,y,z,i,j,k,diam``
    actuals (the nominal ``F(label)=…`` statements are not needed; a trailing ``$`` continues a
    statement). The circle's centre is (x, y), its plane z."""
    path = str(path)
    text = read_text(path)
    items: list = []
    seen: dict[str, int] = {}
    buf, start = "", 0
    for ln, raw in enumerate(text.splitlines(), 1):
        line = raw.rstrip()
        if not buf:
            start = ln
        if line.endswith("$"):
            buf += line[:-1]
            continue
        st, buf = buf + line, ""
        m = _DMIS_CIRCLE.match(st)
        if not m or m.group(1).upper() != "FA":
            continue
        if m.group(3).upper() != "INNER":
            raise InputError(f"circle {m.group(2)!r} is OUTER (a shaft); a bore is an INNER circle", path, start)
        parts = [v for v in m.group(4).split(",") if v.strip()]
        if len(parts) != 7:
            raise InputError(f"FEAT/CIRCLE needs x,y,z,i,j,k,diameter (7 numbers), got {len(parts)}", path, start)
        x, y, z, i, j, k, dia = (_finite(v, path, start, "a circle value") for v in parts)
        if abs(k) < 0.999 * math.sqrt(i * i + j * j + k * k):
            raise InputError(f"circle {m.group(2)!r}: its axis ({i:g}, {j:g}, {k:g}) is not along z", path, start)
        label = m.group(2).strip()
        if label in seen:
            raise InputError(f"circle {label!r} repeats (first at line {seen[label]})", path, start)
        seen[label] = start
        items.append((start, label, x, y, z, dia))
    if buf:
        raise InputError("statement continued with $ at the end of the file", path, start)
    if not items:
        raise InputError("no FA(label)=FEAT/CIRCLE,INNER,CART actual circles", path)
    return _circles(items, path, entry)


def read_pcdmis_circles(path, entry: str = "top") -> BoreMeasurement:
    """The bore per plane from a PC-DMIS-style text report: for each ``… LOCATION OF CIRCLE name``
    dimension, the rows ``X``, ``Y``, ``Z`` and ``D`` (or ``DF``) read in the ``MEAS`` column of the
    ``AX NOMINAL … MEAS …`` header."""
    path = str(path)
    lines = read_text(path).splitlines()
    items = []
    k = 0
    while k < len(lines):
        m = _PCDMIS_HEAD.search(lines[k])
        if not m:
            k += 1
            continue
        name, start = m.group(1), k + 1
        col, vals = None, {}
        k += 1
        while k < len(lines) and not _PCDMIS_HEAD.search(lines[k]):
            words = lines[k].split()
            if words and words[0].upper() == "AX":
                heads = [w.upper() for w in words]
                if "MEAS" not in heads:
                    raise InputError("the AX header has no MEAS column", path, k + 1)
                col = heads.index("MEAS")
            elif words and col is not None and words[0].upper() in ("X", "Y", "Z", "D", "DF"):
                if len(words) <= col:
                    raise InputError(f"row {words[0]} has no MEAS value (column {col + 1})", path, k + 1)
                vals[words[0].upper().replace("DF", "D")] = (k + 1, _finite(words[col], path, k + 1, "MEAS"))
            k += 1
        missing = [a for a in "XYZD" if a not in vals]
        if missing:
            raise InputError(f"circle {name!r} lacks the row(s) {', '.join(missing)}", path, start)
        items.append((start, name, vals["X"][1], vals["Y"][1], vals["Z"][1], vals["D"][1]))
    if not items:
        raise InputError("no 'LOCATION OF CIRCLE' dimensions", path)
    return _circles(items, path, entry)


def read_circle_table(path, entry: str = "top") -> BoreMeasurement:
    """CSV ``plane,z,diameter`` (and optionally ``x,y``: the centre), one row per plane — a CMM's or
    a probing cycle's result table; comma, semicolon or tab delimited."""
    path = str(path)
    rows = list(csv_reader(path))
    head = [h.strip().lower() for h in rows[0]]
    for need in ("z", "diameter"):
        if need not in head:
            raise InputError(f"missing column {need!r} (expected plane,z,diameter[,x,y])", path, 1)
    iz, idia = head.index("z"), head.index("diameter")
    ip = head.index("plane") if "plane" in head else None
    ix, iy = (head.index("x"), head.index("y")) if "x" in head and "y" in head else (None, None)
    items = []
    for ln, r in enumerate(rows[1:], start=2):
        if not r or all(not c.strip() for c in r):
            continue
        try:
            get = [r[iz], r[idia]] + ([r[ix], r[iy]] if ix is not None else [])
        except IndexError:
            raise InputError("a row with fewer fields than the header", path, ln) from None
        z, dia = _finite(get[0], path, ln, "z"), _finite(get[1], path, ln, "diameter")
        x, y = (_finite(get[2], path, ln, "x"), _finite(get[3], path, ln, "y")) if ix is not None else (0.0, 0.0)
        items.append((ln, r[ip].strip() if ip is not None and ip < len(r) else f"z={z:g}", x, y, z, dia))
    return _circles(items, path, entry)


_NUMBERS_LINE = re.compile(
    r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(\s+[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?){2,}\s*$"
)


def read_probe_log(path, entry: str = "top") -> BoreMeasurement:
    """A probe log of whitespace-separated numbers, x y z first on each line — LinuxCNC's
    ``(PROBEOPEN)`` log (x y z a b c u v w per G38 touch) or a Fanuc ``DPRNT`` of the skip
    positions #5061–#5063; planes told apart by gaps in z."""
    path = str(path)
    points = []
    for ln, raw in enumerate(read_text(path).splitlines(), 1):
        if not raw.strip():
            continue
        words = raw.split()
        if len(words) < 3:
            raise InputError(f"expected x y z (whitespace-separated), got {len(words)} number(s)", path, ln)
        x, y, z = (_finite(w, path, ln, "a probe coordinate") for w in words[:3])
        points.append((x, y, z, ln))
    return _planes_from_points(points, path, entry)


def read_measurement(path, entry: str = "top") -> BoreMeasurement:
    """The bore after a pass, from any of: probe points (CSV ``plane,x,y,z`` / ``x,y,z``), a table
    of circles (CSV ``plane,z,diameter[,x,y]``), DMIS ``FEAT/CIRCLE`` actuals, a PC-DMIS-style text
    report (``LOCATION OF CIRCLE``). The kind is told by the content."""
    text = read_text(path)
    if re.search(r"FEAT\s*/\s*CIRCLE", text, re.I):
        return read_dmis_circles(path, entry)
    if _PCDMIS_HEAD.search(text):
        return read_pcdmis_circles(path, entry)
    first = next((ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")), "")
    if "diameter" in first.lower():
        return read_circle_table(path, entry)
    if _NUMBERS_LINE.match(first):
        return read_probe_log(path, entry)
    return read_probe(path, entry)


def probing_program(
    diameter: float,
    planes,
    *,
    dialect: str = "linuxcnc",
    points: int = 8,
    clearance: float = 2.0,
    feed: float = 100.0,
    safe_z: float = 5.0,
) -> str:
    """A program probing the bore in the planes ``planes`` (z, mm, face A first) with ``points``
    touches each: from the bore's centre (X0 Y0, the work offset at the bore's axis) the probe moves
    radially towards the wall, stopping on contact — LinuxCNC ``G38.2`` (the position is logged by
    ``(PROBEOPEN file)`` … ``(PROBECLOSE)``, x y z per touch: the CSV ``x,y,z`` reader's input after
    a header line), Fanuc ``G31`` skip (the skip position in #5061/#5062, written by ``DPRNT``). The
    probe targets 1 mm past the nominal wall and comes back to the centre between touches."""
    if dialect not in ("linuxcnc", "fanuc"):
        raise ValueError(f"dialect must be linuxcnc or fanuc, got {dialect!r}")
    if not (math.isfinite(diameter) and diameter > 2 * clearance):
        raise InputError(f"the bore must be wider than twice the clearance {clearance:g} mm, got Ø{diameter:g}")
    if not 3 <= points <= 360:
        raise InputError(f"points per plane must be 3 … 360, got {points}")
    r = diameter / 2 + 1.0
    out = []
    if dialect == "linuxcnc":
        out += [
            "(ncadapt bore probing: G38.2 from the bore's centre, X0 Y0 on its axis)",
            "G21 G90 G17 G40 G54",
            "(PROBEOPEN bore_probe.txt)",
            f"G0 Z{safe_z:.3f}",
            "G0 X0 Y0",
        ]
    else:
        out += [
            "%",
            "O2000 (NCADAPT BORE PROBING: G31 SKIP, X0 Y0 ON THE AXIS)",
            "G21 G90 G17 G40 G54",
            "POPEN",
            f"G0 Z{safe_z:.3f}",
            "G0 X0 Y0",
        ]
    for z in planes:
        z = float(z)
        if not math.isfinite(z):
            raise InputError(f"plane z must be finite, got {z!r}")
        out.append(f"G1 Z{z:.3f} F{feed:.0f}")
        for k in range(points):
            a = 2 * math.pi * k / points
            x, y = r * math.cos(a), r * math.sin(a)
            if dialect == "linuxcnc":
                out.append(f"G38.2 X{x:.3f} Y{y:.3f} F{feed:.0f}")
            else:
                out += [f"G31 X{x:.3f} Y{y:.3f} F{feed:.0f}", "DPRNT[*#5061[44]*#5062[44]*#5063[44]]"]
            out.append("G1 X0 Y0 F1000")
        out.append(f"G0 Z{safe_z:.3f}")
    if dialect == "linuxcnc":
        out += ["(PROBECLOSE)", "M2"]
    else:
        out += ["PCLOS", "M30", "%"]
    return "\n".join(out) + "\n"


# ------------------------------------------------------------------------------------ the plan
def class_limits(diameter: float, cls: str) -> tuple[float, float]:
    """The (lower, upper) deviations of ISO 286 class ``cls`` (e.g. "H6") at ``diameter``, mm."""
    lo, hi = iso286.deviations(*iso286.parse(f"{diameter:g}{cls}"))
    return lo, hi


def _hole_class(cls: str, what: str) -> None:
    if not isinstance(cls, str) or not cls[:1].isalpha() or not cls[:1].isupper():
        raise InputError(
            f"{what} class {cls!r} is not a hole class: a bore takes upper-case letters (H6, H9); "
            "lower case (h6) is a shaft class"
        )


@dataclass(frozen=True)
class Plan:
    """A plan of corrective passes: the bore, its classes, the pre-finish and allowance, the
    measured taper δA/δB, the tolerances and the predicted passes (mm), and the pass history."""

    diameter: float
    final: str
    prefinish: str
    t0: float
    allowance: float
    delta_a: float
    delta_b: float
    k: float
    target_diameter: float
    it_final: float
    it_prefinish: float
    final_limits: tuple[float, float]  # deviations, mm
    t_max: float
    passes: int
    depth_per_pass: float
    predicted: list = field(default_factory=list)  # δ_A (deflection near A) after each pass
    predicted_b: list = field(default_factory=list)
    predicted_paper: list = field(default_factory=list)  # the paper's recurrence (8), for reference
    warnings: tuple = ()
    history: tuple = ()  # the passes measured so far (dicts, see ``bore next``)

    @property
    def form_before(self) -> float:
        """|δ_A − δ_B| after the pre-finish: the taper either way, mm (radial)."""
        return abs(self.delta_a - self.delta_b)

    @property
    def applicability_limit(self) -> float:
        return APPLICABILITY_SHARE * self.it_prefinish

    @property
    def applicable(self) -> bool:
        """Condition (3): |δ_A − δ_B| ≤ 0.25·IT(pre-finish)."""
        return self.form_before <= self.applicability_limit + 1e-12

    @property
    def form_limit(self) -> float:
        """Condition (4): (k/2)·IT(final) — the paper's (2) Δ_φ = 2(δ_A − δ_B) ≤ k·IT on the radius;
        k = 0.2 … 0.25 gives its 0.1 … 0.125."""
        return self.k / 2 * self.it_final

    @property
    def predicted_form(self) -> float:
        return self.predicted[-1] - self.predicted_b[-1]

    @property
    def first_shift(self) -> float:
        """δ_K,1: the largest deviation after the pre-finish (of the two faces the plan knows)."""
        return max(self.delta_a, self.delta_b)

    @property
    def last_shift(self) -> float:
        """δ_K of the last pass: the deflection near A predicted for the pass before it."""
        return self.predicted[-2] if self.passes >= 2 else self.first_shift

    @property
    def predicted_diameters(self) -> tuple[float, float]:
        """(near A, near B) after the last pass: D_target − 2(δ_n − δ_K,n)."""
        return (
            self.target_diameter - 2 * (self.predicted[-1] - self.last_shift),
            self.target_diameter - 2 * (self.predicted_b[-1] - self.last_shift),
        )

    @property
    def predicted_ok(self) -> bool:
        lo, hi = self.final_limits
        inside = all(self.diameter + lo - 1e-12 <= d <= self.diameter + hi + 1e-12 for d in self.predicted_diameters)
        return inside and abs(self.predicted_form) <= self.form_limit + 1e-12

    def nominal_diameter_after(self, i: int) -> float:
        """The diameter pass i aims at without correction (pass 0: the pre-finish)."""
        return self.target_diameter - 2 * self.depth_per_pass * (self.passes - i)

    def as_dict(self) -> dict:
        return {
            "diameter": self.diameter,
            "final": self.final,
            "prefinish": self.prefinish,
            "t0": self.t0,
            "allowance": self.allowance,
            "delta_a": self.delta_a,
            "delta_b": self.delta_b,
            "k": self.k,
            "target_diameter": self.target_diameter,
            "it_final": self.it_final,
            "it_prefinish": self.it_prefinish,
            "final_limits": list(self.final_limits),
            "form_before": self.form_before,
            "applicable": self.applicable,
            "applicability_limit": self.applicability_limit,
            "t_max": self.t_max,
            "passes": self.passes,
            "depth_per_pass": self.depth_per_pass,
            "predicted": self.predicted,
            "predicted_b": self.predicted_b,
            "predicted_paper": self.predicted_paper,
            "predicted_form": self.predicted_form,
            "predicted_form_limit": self.form_limit,
            "predicted_diameters": list(self.predicted_diameters),
            "predicted_ok": self.predicted_ok,
            "warnings": list(self.warnings),
            "history": list(self.history),
        }

    @classmethod
    def from_dict(cls, d, source: str | None = None) -> Plan:
        """The plan from its JSON (as :meth:`as_dict` writes it): the inputs are read and checked,
        the figures recomputed; the recorded passes (``history``) are kept."""
        if not isinstance(d, dict):
            raise InputError(f"not a bore plan: expected a JSON object, got {type(d).__name__}", source, 1, 1)

        def num(key, *, optional=False):
            if key not in d:
                if optional:
                    return None
                raise InputError(f"not a bore plan: missing key {key!r}", source)
            v = d[key]
            if v is None and optional:
                return None
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
                raise InputError(f"not a bore plan: {key!r} must be a finite number, got {cut(v)}", source)
            return float(v)

        def text(key):
            if key not in d:
                raise InputError(f"not a bore plan: missing key {key!r}", source)
            if not isinstance(d[key], str):
                raise InputError(f'not a bore plan: {key!r} must be a class such as "H6", got {cut(d[key])}', source)
            return d[key]

        hist = d.get("history", [])
        if not isinstance(hist, list) or not all(isinstance(h, dict) for h in hist):
            raise InputError("not a bore plan: 'history' must be a list of objects", source)
        for i, h in enumerate(hist):
            for key in ("pass", "correction"):
                v = h.get(key)
                if key == "correction" and v is None and "finished" in h:  # the finished bore: no next pass
                    continue
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
                    raise InputError(f"not a bore plan: history[{i}].{key} must be a finite number", source)
                if key == "correction" and abs(v) > DEVIATION_MAX:
                    raise InputError(
                        f"not a bore plan: history[{i}].correction must be within ±{DEVIATION_MAX:g} mm, got {v:g}",
                        source,
                    )
            if h["pass"] != i:
                raise InputError(f"not a bore plan: history[{i}] records pass {h['pass']}, expected {i}", source)
        try:
            p = plan(
                num("diameter"),
                text("final"),
                text("prefinish"),
                num("t0"),
                num("allowance"),
                num("delta_a"),
                num("delta_b"),
                k=num("k"),
                target_diameter=num("target_diameter", optional=True),
            )
        except InputError as err:
            raise InputError(f"not a usable bore plan: {err.message}", source) from None
        return replace(p, history=tuple(hist))


def predict(delta_a: float, delta_b: float, t: float, t0: float, passes: int) -> tuple[list, list]:
    """Predicted deflections (δ_A, δ_B) after each of ``passes`` corrective passes of depth t.

    The deflection is compliance × real depth, the compliance of a face the same in every pass
    (the paper's assumptions 2–5): δ_i = c·a_i with c = δ₀/t₀. The real depth of pass i is the
    nominal t, plus the material the last pass left against its aim, δ_i−1 − δ_K,i−1, plus the
    shift δ_K,i: a_i = t + δ_i−1 − δ_K,i−1 + δ_K,i. The shift is δ_K,1 = max(δ_A, δ_B) and then
    δ_K,i = δ_A,i−1 (near B too: one tool). Near A from pass 2 on that is
    a_i = t + 2δ_A,i−1 − δ_A,i−2 — the paper's (7)–(8) take t + 2δ_A,i−1, leaving out that the
    previous pass's shift δ_A,i−2 was cut already (its first step, t + 2δ_A, is the same).
    """
    ca, cb = delta_a / t0, delta_b / t0
    a, b = [], []
    left_a, left_b = delta_a, delta_b  # what the pre-finish left against its aim (it was not corrected)
    shift = max(delta_a, delta_b)
    for _ in range(passes):
        na = ca * (t + left_a + shift)
        nb = cb * (t + left_b + shift)
        a.append(na)
        b.append(nb)
        left_a, left_b = na - shift, nb - shift
        shift = na
    return a, b


def predict_paper(delta_a: float, t: float, t0: float, passes: int) -> list:
    """The paper's (6)–(8) near A: δ_A1 = δ_A (t + 2δ_A)/t₀, δ_Ai = δ_A,i−1 (t + 2δ_A,i−1)/(t + 2δ_A,i−2).
    Its closed form (9) for δ_A2 is (7) with (6) substituted (the same number)."""
    a = [delta_a]
    for i in range(passes):
        a.append(a[-1] * (t + 2 * a[-1]) / (t0 if i == 0 else t + 2 * a[-2]))
    return a[1:]


#: The most corrective passes a plan may have (each is a finishing pass with probing).
MAX_PASSES = 100
#: Physical bounds of the plan's inputs (mm): a radial deviation after pre-finishing of a bore, and
#: the depth of the last pre-finish pass (a finishing cut, not a roughing one).
DEVIATION_MAX = 1.0
T0_MIN, T0_MAX = 0.001, 10.0
K_MIN = 0.01


def plan(
    diameter: float,
    final: str = "H6",
    prefinish: str = "H9",
    t0: float = 0.1,
    allowance: float = 0.1,
    delta_a: float = 0.0,
    delta_b: float = 0.0,
    *,
    k: float = 0.25,
    target_diameter: float | None = None,
) -> Plan:
    """The corrective-pass plan (all lengths mm, deviations and depths radial).

    ``final``, ``prefinish``: hole classes ("H6", "H9"); ``t0``: depth of the last pre-finish pass;
    ``allowance``: z, the radial stock left after pre-finishing; ``delta_a``, ``delta_b``: radial
    deviations near faces A and B after pre-finishing (material left: > 0); ``k``: the share of the
    final tolerance allowed for form error; ``target_diameter``: default the middle of the final
    class, and inside it.

    Refused with the reason: a shaft class, a final class not finer than the pre-finish, a target
    outside the final class, deviations over 1 mm, a recurrence that does not converge (the first
    pass's refinement coefficient (t + 2δ)/t₀ ≥ 1: each pass would leave more than the last).
    Warned (``Plan.warnings``): a negative deviation (no material left there: the bore is over the
    pre-finish aim), deviations larger than IT(pre-finish), condition (3) not holding.
    """
    for name, v in (("diameter", diameter), ("t0", t0), ("allowance", allowance), ("k", k)):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a positive number, got {v!r}")
    if not k <= 1:
        raise InputError(f"k is a share of the tolerance, at most 1, got {k}")
    if k < K_MIN:
        raise InputError(f"k must be at least {K_MIN:g} (the paper: 0.2 … 0.25 for H6), got {k:g}")
    if not T0_MIN <= t0 <= T0_MAX:
        raise InputError(f"t0 must be within {T0_MIN:g} … {T0_MAX:g} mm (a finishing depth), got {t0:g}")
    for name, v in (("delta_a", delta_a), ("delta_b", delta_b)):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)):
            raise InputError(f"{name} must be a number, got {v!r}")
        if abs(v) > DEVIATION_MAX:
            raise InputError(
                f"{name} must be within ±{DEVIATION_MAX:g} mm (a radial deviation after pre-finishing), got {v:g}"
            )
    _hole_class(final, "the final")
    _hole_class(prefinish, "the pre-finish")
    lo_f, hi_f = class_limits(diameter, final)
    lo_p, hi_p = class_limits(diameter, prefinish)
    it_f, it_p = hi_f - lo_f, hi_p - lo_p
    if it_f >= it_p:
        raise InputError(
            f"the final class {final} ({it_f * 1000:g} µm) must be finer than the pre-finish {prefinish} "
            f"({it_p * 1000:g} µm)"
        )
    if target_diameter is None:
        target = diameter + (lo_f + hi_f) / 2
    else:
        target = float(target_diameter)
        if not (math.isfinite(target) and diameter + lo_f - 1e-12 <= target <= diameter + hi_f + 1e-12):
            raise InputError(
                f"the target diameter {target:g} mm is outside Ø{diameter:g} {final} "
                f"({diameter + lo_f:.4f} … {diameter + hi_f:.4f} mm)"
            )
    t_max = t0 * k * it_f / it_p
    if allowance / t_max > MAX_PASSES:
        raise InputError(
            f"an allowance of {allowance:g} mm needs {allowance / t_max:.3g} corrective passes of at most "
            f"{t_max * 1000:.3g} µm; at most {MAX_PASSES} are planned: pre-finish closer to size"
        )
    if allowance >= diameter / 2:
        raise InputError(f"the allowance {allowance:g} mm (radial) is not smaller than the radius {diameter / 2:g} mm")
    passes = max(1, math.ceil(allowance / t_max - 1e-9))
    t = allowance / passes
    shift = max(delta_a, delta_b)
    for name, dv in (("delta_a", delta_a), ("delta_b", delta_b)):
        coeff = (t + dv + shift) / t0
        if dv > 0 and coeff >= 1:
            raise InputError(
                f"the correction does not converge: {name} = {dv * 1000:.1f} µm with t₀ = {t0:g} mm and "
                f"passes of {t * 1000:.1f} µm gives the refinement coefficient (t + δ + δ_K)/t₀ = "
                f"{coeff:.2f} >= 1, so each pass would leave a larger deviation than the last; "
                "pre-finish closer to size (a smaller deviation) or with a deeper last pass"
            )
    warn = []
    for name, dv in (("δA", delta_a), ("δB", delta_b)):
        if dv < 0:
            warn.append(
                f"{name} = {dv * 1000:.1f} µm is negative: the bore is over the pre-finish aim there (no "
                "material left); the method assumes material left"
            )
        if abs(dv) > it_p:
            warn.append(
                f"|{name}| = {abs(dv) * 1000:.1f} µm is larger than IT({prefinish}) = {it_p * 1000:g} µm: "
                f"the bore is not a pre-finished {prefinish} one"
            )
    pa, pb = predict(delta_a, delta_b, t, t0, passes)
    p = Plan(
        float(diameter),
        final,
        prefinish,
        float(t0),
        float(allowance),
        float(delta_a),
        float(delta_b),
        float(k),
        target,
        it_f,
        it_p,
        (lo_f, hi_f),
        t_max,
        passes,
        t,
        pa,
        pb,
        predict_paper(delta_a, t, t0, passes),
    )
    if not p.applicable:
        warn.append(
            f"condition (3) does not hold: |δA − δB| = {p.form_before * 1000:.1f} µm > "
            f"{p.applicability_limit * 1000:.1f} µm; the plan's predictions are not reliable"
        )
    if not all(math.isfinite(v) for v in pa + pb):  # cannot happen within the bounds above
        raise InputError("the predicted deviations are not finite for these inputs")
    return replace(p, warnings=tuple(warn))


def plan_from_measurement(
    diameter: float,
    meas: BoreMeasurement,
    *,
    final: str = "H6",
    prefinish: str = "H9",
    t0: float,
    allowance: float,
    k: float = 0.25,
    target_diameter: float | None = None,
) -> Plan:
    """A plan with δ_A, δ_B taken from the probed pre-finished bore: δ = (D_aimed − D)/2 at the
    planes nearest faces A and B, D_aimed = D_target − 2z the diameter the pre-finish aimed at."""
    if len(meas.circles) < 2:
        raise InputError(
            f"the plan needs the bore probed near faces A and B (two planes at least), got {len(meas.circles)}",
            meas.source,
        )
    lo_f, hi_f = class_limits(diameter, final)
    target = diameter + (lo_f + hi_f) / 2 if target_diameter is None else float(target_diameter)
    dev = meas.deviations(target - 2 * allowance)
    p = plan(diameter, final, prefinish, t0, allowance, float(dev[0]), float(dev[-1]), k=k, target_diameter=target)
    warn = list(p.warnings)
    if len(dev) >= 3 and float(dev.max()) > max(dev[0], dev[-1]) + 1e-12:
        warn.append(
            f"the largest deviation ({float(dev.max()) * 1000:.1f} µm) is mid-bore: the first correction "
            "takes it, the plan's prediction uses the faces' values"
        )
    return replace(p, warnings=tuple(warn))


# ------------------------------------------------------------------------------------ pass by pass
@dataclass(frozen=True)
class Correction:
    """The correction of the next pass from the measured bore after ``pass_done``: errors and
    deflections per plane (face A first) and the tool setting δK for the next pass."""

    pass_done: int  # the pass just measured (0: the pre-finish)
    next_pass: int
    errors: list  # (D_aimed − D)/2 per plane, A first: against the pass's aimed diameter
    deviations: list  # δ = errors + the correction the pass was made with: its deflection
    correction: float  # δ_K for the next pass: the tool's radial shift into the body, mm
    rule: str
    radial_position: float  # the cutting edge's radius for the next pass, mm: D_next/2 + δ_K
    stiffness_ratio: float | None = None  # hardened material: compliance before / now, from pass 1

    def as_dict(self) -> dict:
        return {
            "pass_done": self.pass_done,
            "next_pass": self.next_pass,
            "errors": self.errors,
            "deviations": self.deviations,
            "correction": self.correction,
            "rule": self.rule,
            "radial_position": self.radial_position,
            "stiffness_ratio": self.stiffness_ratio,
        }


def next_correction(
    p: Plan, meas: BoreMeasurement, pass_done: int = 0, *, applied: float = 0.0, hardened: bool = False
) -> Correction:
    """δ_K,i+1 from the bore measured after pass ``pass_done`` (0: after the pre-finish), which was
    made with the tool shifted by ``applied`` (its δ_K; 0 for the pre-finish).

    Hardened material: three planes every time; the first corrective pass is made without
    correction, and after it the stiffness ratio (compliance at the pre-finish / compliance now,
    near face A) is identified: (δ_A0 / t₀) / (δ_A1 / (t + δ_A0)).
    """
    if not 0 <= pass_done < p.passes:
        raise InputError(
            f"pass must be 0 … {p.passes - 1} (the plan has {p.passes} corrective passes; after pass "
            f"{p.passes} the bore is finished: see judge), got {pass_done}",
            meas.source,
        )
    err = meas.deviations(p.nominal_diameter_after(pass_done))
    dev = err + applied
    ratio = None
    if pass_done == 0 or hardened:
        if len(dev) < 3:
            raise InputError(
                f"{'hardened material' if hardened else 'the first corrective pass'} needs three planes "
                f"measured (near A, middle, near B), got {len(dev)}",
                meas.source,
            )
        dk, rule = float(dev.max()), "largest deviation of the three planes"
        if hardened and pass_done == 0:
            dk, rule = 0.0, "hardened: the first corrective pass without correction"
        elif hardened and pass_done == 1 and dev[0] > 0 and p.delta_a > 0:
            ratio = float((p.delta_a / p.t0) / (dev[0] / (p.depth_per_pass + p.delta_a)))
    else:
        dk, rule = float(dev[0]), "deviation near face A"
    nxt = pass_done + 1
    return Correction(
        pass_done, nxt, err.tolist(), dev.tolist(), dk, rule, p.nominal_diameter_after(nxt) / 2 + dk, ratio
    )


@dataclass(frozen=True)
class Finished:
    """The bore after the last corrective pass, judged as the paper does: condition (4) on the form
    |δ_A − δ_B| ≤ (k/2)·IT(final) and every measured diameter inside the final class."""

    diameters: list  # per plane, A first, mm
    limits: tuple  # (min, max) diameter of the final class, mm
    form: float  # δ_A − δ_B = (D_B − D_A)/2, mm (radial)
    form_limit: float
    predicted_diameters: tuple
    predicted_form: float

    @property
    def inside(self) -> bool:
        lo, hi = self.limits
        return all(lo - 1e-12 <= d <= hi + 1e-12 for d in self.diameters)

    @property
    def form_ok(self) -> bool:
        return abs(self.form) <= self.form_limit + 1e-12

    @property
    def ok(self) -> bool:
        return self.inside and self.form_ok

    def as_dict(self) -> dict:
        return {
            "finished": True,
            "diameters": self.diameters,
            "limits": list(self.limits),
            "inside": self.inside,
            "form": self.form,
            "form_limit": self.form_limit,
            "form_ok": self.form_ok,
            "ok": self.ok,
            "predicted_diameters": list(self.predicted_diameters),
            "predicted_form": self.predicted_form,
        }


def judge(p: Plan, meas: BoreMeasurement) -> Finished:
    """The finished bore (after pass ``p.passes``) against the final class and condition (4)."""
    d = [float(v) for v in meas.diameters]
    lo, hi = p.final_limits
    form = (d[-1] - d[0]) / 2 if len(d) >= 2 else 0.0
    return Finished(d, (p.diameter + lo, p.diameter + hi), form, p.form_limit, p.predicted_diameters, p.predicted_form)


#: The controllers an offset block is written for (see :func:`offset_block`).
CONTROLLERS = ("linuxcnc", "fanuc", "fanuc-geometry", "fanuc-lathe", "sinumerik", "plain")


def offset_block(
    correction: float,
    *,
    controller: str = "linuxcnc",
    tool: int = 1,
    radius: float | None = None,
    previous: float = 0.0,
) -> str:
    """The correction δ_K (the tool's radial shift into the body, mm) as a controller block.

    Milling (a bore programmed on its contour with cutter-radius compensation G41/G42, so the tool
    moves δ_K into the body when its radius offset shrinks by δ_K); every block but Fanuc lathe's
    sets an absolute value, so the corrections of successive passes never add up:

    - ``linuxcnc``: ``G10 L1 P<tool> R<radius − δ_K>`` — the tool table's radius, from the tool's
      **nominal** radius (as preset, without any correction; needs ``radius``);
    - ``fanuc``: ``G10 L13 P<tool> R<−δ_K>`` — the cutter-radius wear offset D<tool> (offset memory C);
    - ``fanuc-geometry``: ``G10 L12 P<tool> R<radius − δ_K>`` — the geometry offset D (needs the
      nominal ``radius``);
    - ``sinumerik``: ``$TC_DP15[<tool>,1]=<−δ_K>`` — the wear of the radius (``$TC_DP6`` is its
      geometry; D1 of the tool);
    - ``fanuc-lathe`` (a bore turned on a lathe or mill-turn, diameter programming): ``G10 P<tool>
      U<2(δ_K − δ_K,previous)>`` — an increment of the X wear offset, on the diameter, by the change
      from the correction the last pass was made with (``previous``), so the wear holds δ_K;
    - ``plain``: the value to subtract from the radius offset, for any other controller.
    """
    if not math.isfinite(correction):
        raise InputError(f"the correction is not a finite number: {correction!r}")
    if controller in ("linuxcnc", "fanuc-geometry"):
        if radius is None:
            raise InputError(
                f"the {controller} block sets the tool's radius: give the tool's nominal radius (--tool-radius)"
            )
        if radius - correction <= 0:
            raise InputError(f"the tool radius {radius:g} mm less the correction {correction:g} mm is not positive")
        return f"G10 {'L1' if controller == 'linuxcnc' else 'L12'} P{tool} R{radius - correction:.4f}"
    if controller == "fanuc":
        return f"G10 L13 P{tool} R{-correction:.4f}"
    if controller == "sinumerik":
        return f"$TC_DP15[{tool},1]={-correction:.4f}"
    if controller == "fanuc-lathe":
        return f"G10 P{tool} U{2 * (correction - previous):.4f}"
    if controller == "plain":
        return f"radius offset {-correction:+.4f} mm (bore {2 * correction:+.4f} mm on diameter)"
    raise InputError(f"controller must be one of {', '.join(CONTROLLERS)}, got {controller!r}")
