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

- applicable when δ_A − δ_B ≤ 0.25·ΔD(pre-finish class);
- t ≤ t_max = t₀·k·ΔD(final)/ΔD(pre-finish); i = ⌈z / t_max⌉; t = z / i;
- predicted deviation near A: δ_A1 = δ_A (t + 2δ_A)/t₀, then
  δ_Ai = δ_A,i−1 (t + 2δ_A,i−1)/(t + 2δ_A,i−2) — the real depth at A in pass i is t + δ_A,i−1 (the
  material left) + δ_A,i−1 (the correction), and the compliance at A is the last deviation over the
  last real depth. The paper's closed form for δ_A2 puts t₀ in the second denominator, which
  disagrees with this, its own recurrence; the recurrence is implemented.
- near B the tool is shifted by the same δ_K = δ_A, so the real depth is t + δ_B + δ_A:
  δ_B1 = δ_B (t + δ_A + δ_B)/t₀, δ_Bi = δ_B,i−1 (t + δ_A,i−1 + δ_B,i−1)/(t + δ_A,i−2 + δ_B,i−2)
  (the same assumptions carried to face B; for the prediction of the final form error);
- final check: δ_A − δ_B after the last pass ≤ 0.125·ΔD(final) (the paper's 0.1 … 0.125), and the
  diameter D_target − 2δ inside the final class.

What a deviation is after a corrected pass: the tool was set δ_K,i into the body, so the bore's
radius left short of the tool's setting, δ_i = (R_i + δ_K,i) − r_i, is the pass's elastic
deflection — the quantity the recurrence above predicts (its first step, real depth t + 2δ_A,
follows exactly). The bore's error against the aimed radius R_i is δ_i − δ_K,i: the change of the
deflection from one pass to the next, small once the depth per pass is small. So the predicted
final diameter is D_target − 2(δ_n − δ_K,n) with δ_K,n = δ_A,n−1 (δ_A for a single pass), and the
final form error is δ_A,n − δ_B,n.

Pass by pass: after pass i the measured deviations give the next correction δ_K,i+1 = δ_A,i — after
the pre-finish (pass 0) and for hardened material the largest deviation over the three planes,
otherwise the plane near face A. Hardened material: the first corrective pass is made without
correction at minimal depth and the compliance along the bore is identified from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import iso286
from .._io import csv_reader
from ..errors import InputError

APPLICABILITY_SHARE = 0.25  # δ_A − δ_B ≤ 0.25·ΔD(pre-finish)
FINAL_FORM_SHARE = 0.125  # predicted δ_A − δ_B ≤ 0.125·ΔD(final) (the paper: 0.1 … 0.125)
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
        return {"plane": self.plane, "z": self.z, "centre": list(self.centre), "diameter": self.diameter,
                "roundness": self.roundness, "points": self.n}


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


def read_probe(path, entry: str = "top") -> BoreMeasurement:
    """CSV ``plane,x,y,z`` (or ``x,y,z``: planes told apart by z to 0.01 mm), one probe point a row.

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
    for ln, r in enumerate(rows[1:], start=2):
        if not r or all(not c.strip() for c in r):
            continue
        try:
            x, y, z = float(r[ix]), float(r[iy]), float(r[iz])
        except (ValueError, IndexError):
            raise InputError("expected numbers in x, y, z", path, ln) from None
        if not all(map(math.isfinite, (x, y, z))):
            raise InputError("x, y, z must be finite", path, ln)
        key = r[ip].strip() if ip is not None else f"z={round(z, 2):g}"
        groups.setdefault(key, []).append((x, y, z, ln))
    if len(groups) < 2:
        raise InputError(f"need probe points in at least 2 planes (near faces A and B), got {len(groups)}", path)
    circles = []
    for key, pts in groups.items():
        a = np.array([p[:3] for p in pts])
        if len(a) < MIN_POINTS_PER_PLANE:
            raise InputError(f"plane {key!r} has {len(a)} points; a circle needs {MIN_POINTS_PER_PLANE}", path, pts[0][3])
        try:
            circles.append(fit_circle(a[:, 0], a[:, 1], key, float(a[:, 2].mean())))
        except InputError as err:
            raise InputError(err.message, path, pts[0][3]) from None
    if entry not in ("top", "bottom"):
        raise ValueError(f"entry must be 'top' or 'bottom', got {entry!r}")
    circles.sort(key=lambda c: -c.z if entry == "top" else c.z)
    return BoreMeasurement(tuple(circles), path)


# ------------------------------------------------------------------------------------ the plan
def class_limits(diameter: float, cls: str) -> tuple[float, float]:
    lo, hi = iso286.deviations(*iso286.parse(f"{diameter:g}{cls}"))
    return lo, hi


@dataclass(frozen=True)
class Plan:
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
    predicted: list = field(default_factory=list)  # δ_A after each pass
    predicted_b: list = field(default_factory=list)

    @property
    def applicable(self) -> bool:
        return self.delta_a - self.delta_b <= APPLICABILITY_SHARE * self.it_prefinish + 1e-12

    @property
    def predicted_form(self) -> float:
        return self.predicted[-1] - self.predicted_b[-1]

    @property
    def last_shift(self) -> float:
        """δ_K of the last pass: the deflection near A predicted for the pass before it."""
        return self.predicted[-2] if self.passes >= 2 else self.delta_a

    @property
    def predicted_diameters(self) -> tuple[float, float]:
        """(near A, near B) after the last pass: D_target − 2(δ_n − δ_K,n)."""
        return (self.target_diameter - 2 * (self.predicted[-1] - self.last_shift),
                self.target_diameter - 2 * (self.predicted_b[-1] - self.last_shift))

    @property
    def predicted_ok(self) -> bool:
        lo, hi = self.final_limits
        inside = all(self.diameter + lo - 1e-12 <= d <= self.diameter + hi + 1e-12 for d in self.predicted_diameters)
        return inside and abs(self.predicted_form) <= FINAL_FORM_SHARE * self.it_final + 1e-12

    def nominal_diameter_after(self, i: int) -> float:
        """The diameter pass i aims at without correction (pass 0: the pre-finish)."""
        return self.target_diameter - 2 * self.depth_per_pass * (self.passes - i)

    def as_dict(self) -> dict:
        return {
            "diameter": self.diameter, "final": self.final, "prefinish": self.prefinish, "t0": self.t0,
            "allowance": self.allowance, "delta_a": self.delta_a, "delta_b": self.delta_b, "k": self.k,
            "target_diameter": self.target_diameter,
            "it_final": self.it_final, "it_prefinish": self.it_prefinish,
            "final_limits": list(self.final_limits),
            "applicable": self.applicable,
            "applicability_limit": APPLICABILITY_SHARE * self.it_prefinish,
            "t_max": self.t_max, "passes": self.passes, "depth_per_pass": self.depth_per_pass,
            "predicted": self.predicted, "predicted_b": self.predicted_b,
            "predicted_form": self.predicted_form, "predicted_form_limit": FINAL_FORM_SHARE * self.it_final,
            "predicted_diameters": list(self.predicted_diameters), "predicted_ok": self.predicted_ok,
        }

    @classmethod
    def from_dict(cls, d: dict, source: str | None = None) -> "Plan":
        try:
            return plan(d["diameter"], d["final"], d["prefinish"], d["t0"], d["allowance"], d["delta_a"], d["delta_b"],
                        k=d["k"], target_diameter=d["target_diameter"])
        except KeyError as err:
            raise InputError(f"not a bore plan: missing key {err.args[0]!r}", source) from None


def predict(delta_a: float, delta_b: float, t: float, t0: float, passes: int) -> tuple[list, list]:
    """Predicted (δ_A, δ_B) after each of ``passes`` corrective passes of depth t (see the module)."""
    a, b = [delta_a], [delta_b]
    for i in range(passes):
        if i == 0:
            na = delta_a * (t + 2 * delta_a) / t0
            nb = delta_b * (t + delta_a + delta_b) / t0
        else:
            na = a[-1] * (t + 2 * a[-1]) / (t + 2 * a[-2])
            nb = b[-1] * (t + a[-1] + b[-1]) / (t + a[-2] + b[-2])
        a.append(na)
        b.append(nb)
    return a[1:], b[1:]


#: The most corrective passes a plan may have (each is a finishing pass with probing).
MAX_PASSES = 100


def plan(diameter: float, final: str = "H6", prefinish: str = "H9", t0: float = 0.1, allowance: float = 0.1,
         delta_a: float = 0.0, delta_b: float = 0.0, *, k: float = 0.25, target_diameter: float | None = None) -> Plan:
    """The corrective-pass plan (all lengths mm, deviations and depths radial).

    ``final``, ``prefinish``: hole classes ("H6", "H9"); ``t0``: depth of the last pre-finish pass;
    ``allowance``: z, the radial stock left after pre-finishing; ``delta_a``, ``delta_b``: radial
    deviations near faces A and B after pre-finishing; ``k``: the share of the final tolerance
    allowed for form error; ``target_diameter``: default the middle of the final class.
    """
    for name, v in (("diameter", diameter), ("t0", t0), ("allowance", allowance), ("k", k)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a positive number, got {v!r}")
    if not k <= 1:
        raise InputError(f"k is a share of the tolerance, at most 1, got {k}")
    for name, v in (("delta_a", delta_a), ("delta_b", delta_b)):
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise InputError(f"{name} must be a number, got {v!r}")
    lo_f, hi_f = class_limits(diameter, final)
    lo_p, hi_p = class_limits(diameter, prefinish)
    it_f, it_p = hi_f - lo_f, hi_p - lo_p
    if it_f >= it_p:
        raise InputError(f"the final class {final} ({it_f * 1000:g} µm) must be finer than the pre-finish {prefinish} "
                         f"({it_p * 1000:g} µm)")
    target = diameter + (lo_f + hi_f) / 2 if target_diameter is None else float(target_diameter)
    t_max = t0 * k * it_f / it_p
    if allowance / t_max > MAX_PASSES:
        raise InputError(f"an allowance of {allowance:g} mm needs {allowance / t_max:.3g} corrective passes of at most "
                         f"{t_max * 1000:.3g} µm; at most {MAX_PASSES} are planned: pre-finish closer to size")
    if allowance >= diameter / 2:
        raise InputError(f"the allowance {allowance:g} mm (radial) is not smaller than the radius {diameter / 2:g} mm")
    passes = max(1, math.ceil(allowance / t_max - 1e-9))
    t = allowance / passes
    pa, pb = predict(delta_a, delta_b, t, t0, passes)
    return Plan(float(diameter), final, prefinish, float(t0), float(allowance), float(delta_a), float(delta_b), float(k),
                target, it_f, it_p, (lo_f, hi_f), t_max, passes, t, pa, pb)


def plan_from_measurement(diameter: float, meas: BoreMeasurement, *, final: str = "H6", prefinish: str = "H9",
                          t0: float, allowance: float, k: float = 0.25,
                          target_diameter: float | None = None) -> Plan:
    """A plan with δ_A, δ_B taken from the probed pre-finished bore: δ = (D_aimed − D)/2 at the
    planes nearest faces A and B, D_aimed = D_target − 2z the diameter the pre-finish aimed at."""
    lo_f, hi_f = class_limits(diameter, final)
    target = diameter + (lo_f + hi_f) / 2 if target_diameter is None else float(target_diameter)
    dev = meas.deviations(target - 2 * allowance)
    return plan(diameter, final, prefinish, t0, allowance, float(dev[0]), float(dev[-1]), k=k, target_diameter=target)


# ------------------------------------------------------------------------------------ pass by pass
@dataclass(frozen=True)
class Correction:
    pass_done: int  # the pass just measured (0: the pre-finish)
    next_pass: int
    errors: list  # (D_aimed − D)/2 per plane, A first: against the pass's aimed diameter
    deviations: list  # δ = errors + the correction the pass was made with: its deflection
    correction: float  # δ_K for the next pass: the tool's radial shift into the body, mm
    rule: str
    radial_position: float  # the cutting edge's radius for the next pass, mm: D_next/2 + δ_K
    stiffness_ratio: float | None = None  # hardened material: compliance before / now, from pass 1

    def as_dict(self) -> dict:
        return {"pass_done": self.pass_done, "next_pass": self.next_pass, "errors": self.errors,
                "deviations": self.deviations, "correction": self.correction, "rule": self.rule,
                "radial_position": self.radial_position, "stiffness_ratio": self.stiffness_ratio}


def next_correction(p: Plan, meas: BoreMeasurement, pass_done: int = 0, *, applied: float = 0.0,
                    hardened: bool = False) -> Correction:
    """δ_K,i+1 from the bore measured after pass ``pass_done`` (0: after the pre-finish), which was
    made with the tool shifted by ``applied`` (its δ_K; 0 for the pre-finish).

    Hardened material: three planes every time; the first corrective pass is made without
    correction, and after it the stiffness ratio (compliance at the pre-finish / compliance now,
    near face A) is identified: (δ_A0 / t₀) / (δ_A1 / (t + δ_A0)).
    """
    if not 0 <= pass_done < p.passes:
        raise InputError(f"pass must be 0 … {p.passes - 1} (the plan has {p.passes} corrective passes; after pass "
                         f"{p.passes} the bore is finished), got {pass_done}", meas.source)
    err = meas.deviations(p.nominal_diameter_after(pass_done))
    dev = err + applied
    ratio = None
    if pass_done == 0 or hardened:
        if len(dev) < 3:
            raise InputError(f"{'hardened material' if hardened else 'the first corrective pass'} needs three planes "
                             f"measured (near A, middle, near B), got {len(dev)}", meas.source)
        dk, rule = float(dev.max()), "largest deviation of the three planes"
        if hardened and pass_done == 0:
            dk, rule = 0.0, "hardened: the first corrective pass without correction"
        elif hardened and pass_done == 1 and dev[0] > 0 and p.delta_a > 0:
            ratio = float((p.delta_a / p.t0) / (dev[0] / (p.depth_per_pass + p.delta_a)))
    else:
        dk, rule = float(dev[0]), "deviation near face A"
    nxt = pass_done + 1
    return Correction(pass_done, nxt, err.tolist(), dev.tolist(), dk, rule, p.nominal_diameter_after(nxt) / 2 + dk, ratio)


def offset_block(correction: float, *, controller: str = "linuxcnc", tool: int = 1, radius: float | None = None) -> str:
    """The correction as a controller block.

    The finishing passes are programmed on the bore's contour with cutter-radius compensation
    (G41/G42), so the tool moves δ_K into the body when its radius offset shrinks by δ_K.

    - ``linuxcnc``: ``G10 L1 P<tool> R<radius − δ_K>`` — the tool table's radius (needs the current
      ``radius``);
    - ``fanuc``: ``G10 L13 P<tool> R<−δ_K>`` — the cutter-radius wear offset D<tool> (offset memory C);
    - ``plain``: the value to subtract from the radius offset, for any other controller.
    """
    if controller == "linuxcnc":
        if radius is None:
            raise InputError("the LinuxCNC block sets the tool-table radius: give the tool's current radius")
        return f"G10 L1 P{tool} R{radius - correction:.4f}"
    if controller == "fanuc":
        return f"G10 L13 P{tool} R{-correction:.4f}"
    if controller == "plain":
        return f"radius offset {-correction:+.4f} mm (bore {2 * correction:+.4f} mm on diameter)"
    raise InputError(f"controller must be linuxcnc, fanuc or plain, got {controller!r}")
