"""A virtual boring testbed: finishing H9 bores to H6 on a mill-turn, seeded.

Two models of the machine (``model=``):

``"beam"`` (the default) — physics the planner does not share
----------------------------------------------------------------
The planner (Nosov and Kondakov) assumes the deflection is proportional to the depth of cut with
a compliance δ_A/t₀ carried over from the pre-finish. This testbed computes the force from a
cutting-force law on the real chip of a nose-radius insert and the deflection from a beam, so the
radial force is *not* proportional to depth at finishing depths, and the compliance per unit depth
of the pre-finish (t₀ = 0.5 mm, past the nose arc) is not that of the corrective passes (25 µm).

Radial lengths in mm, forces in N; ζ ∈ [0, 1] along the bore from face A (the tool's entry) to B.

1. The chip (a finishing insert with nose radius r_ε = 0.4 mm, the "04" of ISO 1832's insert
   code; entering angle κ_r = 95°, a common boring-bar holder; feed f = 0.05 mm/rev, the set-up's
   choice). The nose arc of the pass before, shifted by f, meets the arc at
   the trailing half-angle α_s = arcsin(f / 2r_ε), height y_s = r_ε(1 − cos α_s) (the feed
   mark). For a depth a_p > y_s the engaged edge runs from α_s on the trailing side to the angle
   θ = arccos(1 − a_p/r_ε) on the leading side (on the arc while a_p ≤ r_ε(1 − cos κ_r), then
   along the straight edge at κ_r):

   - engaged edge length b = r_ε(θ + α_s) (past the arc: r_ε(κ_r + α_s) + s, s = (a_p −
     r_ε(1 − cos κ_r))/sin κ_r);
   - chip area A = f(a_p − y_s) + r_ε²(α_s − sin α_s cos α_s) (the strip of width f above the
     feed mark plus the groove's circular segment below it; for a_p ≤ y_s the segment of height
     a_p alone, b = 2r_ε·arccos(1 − a_p/r_ε));
   - equivalent chip thickness h = A / b;
   - Colwell's equivalent entering angle κ_e: the chip flows normal to the chord joining the
     ends of the engaged edge, (−f/2, y_s) and (x_a, a_p), x_a = r_ε sin θ (past the arc
     r_ε sin κ_r + s cos κ_r): κ_e = atan2(a_p − y_s, x_a + f/2).

   Colwell, L. V., "Predicting the angle of chip flow for single-point cutting tools", Trans.
   ASME 76 (1954) 199–204.

2. The forces. Kienzle's law F_c = k_c1.1 · b · h^(1 − m_c) (Kienzle, O., VDI-Z 94 (1952)
   299–305), k_c1.1 and m_c per ISO material group as Sandvik Coromant tabulates k_c1 (the
   specific cutting force at h = 1 mm, rake 0°) and m_c (Metal cutting technology training
   handbook, "Workpiece materials" and "Formulas and definitions"; sandvik.coromant.com
   "Specific cutting force"): steel (P) 2000, 0.25; titanium alloy (S) 1400, 0.23; aluminium
   alloy (N) 700, 0.25; hardened steel (H) 3200, 0.25. The thrust F_T (the resultant of feed and
   passive force, normal to the cutting speed) is F_T = μ_T F_c with μ_T = tan(β − γ) = 0.5
   (Merchant's relation, Merchant, M. E., J. Appl. Phys. 16 (1945) 267–275, with a friction
   angle β ≈ 27° and rake γ = 0°: an assumption, the same for all materials, not fitted to the
   planner), acting normal to Colwell's chord: the passive (radial) force F_p = F_T cos κ_e and
   the feed force F_f = F_T sin κ_e. At 5 µm … 0.1 mm F_p/a_p falls from 208 to 133 N/mm on
   steel; at the 0.5 mm pre-finish it is 75 N/mm.

3. The boring bar (the set-up's choice): a steel cantilever (E = 210 GPa), Ø16 mm, overhang
   L = 100 mm (6.25 × D, a
   long reach for a steel bar: Sandvik recommends up to 4 × D, so the bar dominates the
   compliance, as in the paper's case) clamped in the turret of a mill-turn; radial compliance
   at the tip c_bar = L³/(3EI), I = πd⁴/64 (4.93·10⁻⁴ mm/N, 0.49 µm/N). The overhang is set
   once for the whole bore, so the bar's compliance does not change along it; its clamping
   scatters per part by a log-normal factor, σ = 15 %.

4. The part: held in the chuck, face B 20 mm and face A 80 mm from the jaws (a 60 mm bore).
   The chuck and spindle tilt under the radial force, so the wall gives way by x²/k_θ at a
   distance x from the jaws: c_w(ζ) = c_A (x(ζ)/x_A)², x(ζ) = 80 − 60ζ, with the stiffness at
   face A 1/c_A ~ U(8, 30) N/µm per part (assumed, not from a source: a three-jaw chuck holding
   a housing by a short spigot; it sets the taper, 6–20 % of the deflection at face A). This
   is the paper's taper with the smaller diameter at the tool's entry, from a physical cause;
   the paper's barrel shape has no cause in this set-up and is not modelled.
   The part's own wall (Ø40 bore in a thick housing) bends by far less than 0.01 µm/N: left out.

5. The cut: at each of 41 points along ζ the tool is set at radius R_set; the nominal depth is
   a = R_set − r_prev; the tool and the wall give way by d, the static equilibrium
   d = c(ζ) · F_p(a − d), c = c_bar + c_w(ζ), solved by bisection (F_p grows with depth, so the
   root is unique); the new radius is r = R_set − d. The tangential deflection c_bar F_c
   changes the radius by (c_bar F_c)²/2R (0.08 µm at the 117 N pre-finish): left out.
   k_c1.1 varies from pass to pass by a normal factor σ = 5 % (wear, hardness); the tool's
   setting repeats to σ = 0.5 µm. Hardened parts were pre-finished soft (steel's k_c1.1).

``"linear"`` — the paper's own assumption, kept for comparison
--------------------------------------------------------------
d(ζ) = c(ζ)·a(ζ), c(ζ) = c₀(1 + τ(1 − ζ) − 4βζ(1 − ζ)), c₀ = k_r k_c f / k_s (k_r 0.4, f 0.05,
k_s 1000 N/mm log-normal σ 15 %), τ ~ U(0.2, 0.8), β ~ U(0, 0.3). The planner predicts this
testbed exactly when noise-free; it proves the algebra of the recurrence, not the method.

Both: probing 8 points per plane at ζ = 0.08, 0.5, 0.92 with σ = 0.5 µm radial noise, Kåsa's
algebraic circle (for evenly spread points and µm noise it equals the geometric fit of
:func:`ncadapt.processes.bore.fit_circle` to far below 1 nm). Defaults: Ø40, H9 → H6, t₀ =
0.5 mm, z = 0.1 mm, k = 0.25. A part is inside tolerance when the real bore, sampled at 41 points
along ζ, is inside H6 and its form error (max − min diameter) is at most k·IT6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..processes import bore as pb

MODELS = ("beam", "linear")
MATERIALS = {"steel": 2000.0, "titanium": 1400.0, "aluminium": 700.0, "hardened": 3200.0}  # k_c1.1, N/mm²
M_C = {"steel": 0.25, "titanium": 0.23, "aluminium": 0.25, "hardened": 0.25}  # Kienzle's exponent m_c
NOSE_RADIUS = 0.4  # r_ε, mm
ENTERING_ANGLE = 95.0  # κ_r, degrees (boring bar)
FEED = 0.05  # mm/rev
THRUST_RATIO = 0.5  # μ_T = F_T / F_c = tan(β − γ), β ≈ 27°, γ = 0
BAR_MODULUS = 210_000.0  # N/mm², steel (cemented carbide: about 580,000)
BAR_DIAMETER = 16.0  # mm
BAR_OVERHANG = 100.0  # mm
FACE_A_FROM_CHUCK = 80.0  # mm
BORE_LENGTH = 60.0  # mm
CHUCK_STIFFNESS_A = (8_000.0, 30_000.0)  # N/mm at face A, uniform per part
K_R = 0.4  # linear model
STIFFNESS = 1000.0  # N/mm, linear model
STIFFNESS_SIGMA = 0.15
PASS_SIGMA = 0.05
SETTING_SIGMA = 0.0005  # mm
PROBE_SIGMA = 0.0005  # mm
PROBE_POINTS = 8
PLANES = (0.08, 0.5, 0.92)
ZETA = np.linspace(0.0, 1.0, 41)


# ------------------------------------------------------------------------------ force and beam
@dataclass(frozen=True)
class Chip:
    """The uncut chip of a nose-radius insert at depth ``depth`` (arrays of one shape)."""

    depth: np.ndarray  # a_p, mm
    length: np.ndarray  # b, engaged edge, mm
    area: np.ndarray  # A, mm²
    lead_angle: np.ndarray  # Colwell's equivalent entering angle κ_e, rad

    @property
    def thickness(self) -> np.ndarray:
        """Equivalent chip thickness h = A / b, mm (0 where there is no chip)."""
        b = np.where(self.length > 0, self.length, 1.0)
        return np.where(self.length > 0, self.area / b, 0.0)


def chip(depth, feed: float = FEED, nose_radius: float = NOSE_RADIUS, entering_angle: float = ENTERING_ANGLE) -> Chip:
    """The chip's engaged edge length, area and Colwell's equivalent entering angle.

    Parameters
    ----------
    depth : float or (n,) ndarray, mm
        Real radial depth of cut a_p (≤ 0: no contact).
    feed : float, mm/rev
    nose_radius : float, mm
    entering_angle : float, degrees (κ_r of the insert's straight edge, 90 … 180)
    """
    a = np.asarray(depth, dtype=float)
    r, f, kap = nose_radius, feed, math.radians(entering_angle)
    al = math.asin(f / (2 * r))
    ys = r * (1 - math.cos(al))
    yk = r * (1 - math.cos(kap))
    seg = r * r * (al - math.sin(al) * math.cos(al))
    ac = np.clip(a, 0.0, None)
    # a_p ≤ y_s: the groove's circular segment of height a_p
    psi = np.arccos(np.clip(1 - np.minimum(ac, ys) / r, -1, 1))
    b_low, a_low = 2 * r * psi, r * r * (psi - np.sin(psi) * np.cos(psi))
    # above the feed mark: on the arc up to y_k, then on the straight edge
    th = np.arccos(np.clip(1 - np.minimum(ac, yk) / r, -1, 1))
    s = np.clip(ac - yk, 0.0, None) / math.sin(kap)
    b_up = r * (th + al) + s
    x_a = r * np.sin(th) + s * math.cos(kap)
    a_up = f * (ac - ys) + seg
    lead_up = np.arctan2(ac - ys, x_a + f / 2)
    low = ac <= ys
    length = np.where(a <= 0, 0.0, np.where(low, b_low, b_up))
    area = np.where(a <= 0, 0.0, np.where(low, a_low, a_up))
    lead = np.where(low, 0.0, lead_up)
    return Chip(a, length, area, lead)


def forces(depth, k_c11: float, m_c: float, **chip_kw) -> tuple[np.ndarray, np.ndarray]:
    """(F_c, F_p), N: Kienzle's cutting force k_c1.1·b·h^(1−m_c) and the passive (radial) force
    μ_T F_c cos κ_e, at real depth ``depth`` (mm)."""
    c = chip(depth, **chip_kw)
    h = c.thickness
    fc = np.where(c.length > 0, k_c11 * c.length * np.power(np.where(h > 0, h, 1.0), 1 - m_c), 0.0)
    return fc, THRUST_RATIO * fc * np.cos(c.lead_angle)


def bar_compliance(diameter: float | None = None, overhang: float | None = None, modulus: float | None = None) -> float:
    """Radial compliance of a solid round cantilever at its tip, L³/(3EI), I = πd⁴/64 (mm/N);
    by default the testbed's bar (``BAR_DIAMETER``, ``BAR_OVERHANG``, ``BAR_MODULUS``)."""
    d = BAR_DIAMETER if diameter is None else diameter
    length = BAR_OVERHANG if overhang is None else overhang
    e = BAR_MODULUS if modulus is None else modulus
    return length**3 / (3 * e * math.pi * d**4 / 64)


def deflection(nominal_depth, compliance, k_c11: float, m_c: float, iterations: int = 48) -> np.ndarray:
    """The static give-way d (mm) with d = c·F_p(a − d): the tool set for a nominal depth a
    cuts a − d. Bisection on [0, max(a, 0)] (F_p grows with the depth: one root)."""
    a = np.asarray(nominal_depth, dtype=float)
    c = np.broadcast_to(np.asarray(compliance, dtype=float), a.shape)
    lo, hi = np.zeros_like(a), np.clip(a, 0.0, None)
    for _ in range(iterations):
        mid = (lo + hi) / 2
        g = mid - c * forces(a - mid, k_c11, m_c)[1]
        lo, hi = np.where(g < 0, mid, lo), np.where(g < 0, hi, mid)
    return (lo + hi) / 2


# ------------------------------------------------------------------------------------- the parts
@dataclass
class Part:
    """The linear model's part (the paper's assumption)."""

    c0: float  # compliance of the corrective passes
    c0_prefinish: float
    tau: float
    beta: float

    def compliance(self, zeta, c0):
        return c0 * (1 + self.tau * (1 - zeta) - self.beta * 4 * zeta * (1 - zeta))

    def cut(self, setting, r_prev, scatter: float, prefinish: bool = False):
        c = self.compliance(ZETA, self.c0_prefinish if prefinish else self.c0) * scatter
        return setting - c * (setting - r_prev)


@dataclass
class BeamPart:
    """The beam model's part: bar compliance, the chuck's at face A, the materials' Kienzle constants."""

    c_bar: float  # mm/N
    c_chuck_a: float  # mm/N at face A
    k_c11: float  # corrective passes
    k_c11_prefinish: float
    m_c: float

    def compliance(self, zeta):
        x = FACE_A_FROM_CHUCK - BORE_LENGTH * np.asarray(zeta, dtype=float)
        return self.c_bar + self.c_chuck_a * (x / FACE_A_FROM_CHUCK) ** 2

    def cut(self, setting, r_prev, scatter: float, prefinish: bool = False):
        kc = (self.k_c11_prefinish if prefinish else self.k_c11) * scatter
        return setting - deflection(setting - r_prev, self.compliance(ZETA), kc, self.m_c)


def random_part(rng, material: str = "steel", model: str = "beam"):
    if material not in MATERIALS:
        raise ValueError(f"material must be one of {sorted(MATERIALS)}, got {material!r}")
    if model not in MODELS:
        raise ValueError(f"model must be one of {list(MODELS)}, got {model!r}")
    pre = "steel" if material == "hardened" else material
    if model == "linear":
        ks = STIFFNESS * np.exp(rng.normal(0, STIFFNESS_SIGMA))
        c = K_R * MATERIALS[material] * FEED / ks
        c_pre = K_R * MATERIALS[pre] * FEED / ks
        return Part(c, c_pre, rng.uniform(0.2, 0.8), rng.uniform(0.0, 0.3))
    c_bar = bar_compliance() * np.exp(rng.normal(0, STIFFNESS_SIGMA))
    c_a = 1 / rng.uniform(*CHUCK_STIFFNESS_A)
    return BeamPart(float(c_bar), float(c_a), MATERIALS[material], MATERIALS[pre], M_C[material])


def probe(rng, radius_at, zetas=PLANES, z_length: float = BORE_LENGTH) -> pb.BoreMeasurement:
    """Probe the bore (radius as a function of ζ) in planes at ``zetas``: Kåsa circles."""
    circles = []
    phi = np.linspace(0, 2 * np.pi, PROBE_POINTS, endpoint=False)
    for zeta in zetas:
        r = radius_at(zeta) + rng.normal(0, PROBE_SIGMA, PROBE_POINTS)
        x, y = r * np.cos(phi), r * np.sin(phi)
        a = np.column_stack([x, y, np.ones_like(x)])
        sol = np.linalg.lstsq(a, x * x + y * y, rcond=None)[0]
        cx, cy = sol[0] / 2, sol[1] / 2
        rr = np.sqrt(sol[2] + cx * cx + cy * cy)
        dev = np.hypot(x - cx, y - cy) - rr
        circles.append(
            pb.Circle(f"{zeta:g}", z_length * (1 - zeta), (cx, cy), 2 * rr, float(dev.max() - dev.min()), PROBE_POINTS)
        )
    return pb.BoreMeasurement(tuple(circles))


@dataclass
class PartResult:
    applicable: bool
    passes: int
    diameters: np.ndarray  # the real bore along ZETA after the corrected passes
    one_pass: np.ndarray  # the real bore after one uncorrected pass of the whole allowance
    ok: bool
    ok_one_pass: bool
    stiffness_ratio: float | None


def run_part(
    rng,
    *,
    diameter: float = 40.0,
    final: str = "H6",
    prefinish: str = "H9",
    t0: float = 0.5,
    allowance: float = 0.1,
    k: float = 0.25,
    material: str = "steel",
    model: str = "beam",
) -> PartResult:
    """One part: pre-finish (depth t₀, uncorrected), the plan from the probed bore, the corrective
    passes each set by :func:`ncadapt.processes.bore.next_correction` from the probed result of
    the pass before; beside it, the whole allowance in one uncorrected pass."""
    part = random_part(rng, material, model)
    lo, hi = pb.class_limits(diameter, final)
    target = diameter + (lo + hi) / 2
    hardened = material == "hardened"
    # the pre-finish pass: aimed at D_target − 2z, depth t₀, not corrected
    r_aim = target / 2 - allowance
    r = part.cut(r_aim, np.full_like(ZETA, r_aim - t0), 1.0, prefinish=True)
    meas = probe(rng, lambda zz: np.interp(zz, ZETA, r))
    try:
        plan = pb.plan_from_measurement(
            diameter, meas, final=final, prefinish=prefinish, t0=t0, allowance=allowance, k=k, target_diameter=target
        )
    except InputError:  # the plan refuses this part (a correction that would not converge): not machined
        return PartResult(False, 0, r, r, False, False, None)
    r_pre = r.copy()
    applied = 0.0
    ratio = None
    for i in range(plan.passes):
        corr = pb.next_correction(plan, meas, i, applied=applied, hardened=hardened)
        if corr.stiffness_ratio is not None:
            ratio = corr.stiffness_ratio
        dk = corr.correction
        setting = plan.nominal_diameter_after(i + 1) / 2 + dk + rng.normal(0, SETTING_SIGMA)
        r = part.cut(setting, r, 1 + rng.normal(0, PASS_SIGMA))
        applied = dk
        meas = probe(rng, lambda zz, r=r: np.interp(zz, ZETA, r))
    d = 2 * r
    # without correction: the whole allowance in one pass aimed at the target
    setting = target / 2 + rng.normal(0, SETTING_SIGMA)
    d1 = 2 * part.cut(setting, r_pre, 1 + rng.normal(0, PASS_SIGMA))
    it_f = hi - lo

    def ok(dd):
        return bool(np.all(dd >= diameter + lo) and np.all(dd <= diameter + hi) and dd.max() - dd.min() <= k * it_f)

    return PartResult(plan.applicable, plan.passes, d, d1, ok(d), ok(d1), ratio)


def simulate(
    parts: int = 1000, seed: int = 1, *, material: str = "steel", model: str = "beam", progress=None, **kw
) -> dict:
    """``parts`` parts for which the plan's applicability condition holds (others are drawn and
    counted, not machined further). Returns the summary as a dict."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {list(MODELS)}, got {model!r}")
    rng = np.random.default_rng(seed)
    done, drawn = [], 0
    while len(done) < parts:
        drawn += 1
        res = run_part(rng, material=material, model=model, **kw)
        if res.applicable:
            done.append(res)
            if progress and len(done) % 100 == 0:
                progress(f"{len(done)}/{parts} parts", len(done), parts)
        if drawn > 20 * parts:
            raise InputError(
                f"condition (3) held for {len(done)} of the {drawn} parts drawn with these settings "
                f"(t0 = {kw.get('t0', 0.5):g} mm: the pre-finish deflection grows with t0); use a "
                "smaller --t0"
            )
    d = np.array([r.diameters for r in done])
    diameter, final = kw.get("diameter", 40.0), kw.get("final", "H6")
    target = diameter + sum(pb.class_limits(diameter, final)) / 2
    d1 = np.array([r.one_pass for r in done])
    ratios = [r.stiffness_ratio for r in done if r.stiffness_ratio is not None]
    return {
        "parts": parts,
        "seed": seed,
        "material": material,
        "model": model,
        "drawn": drawn,
        "applicable_share": parts / drawn,
        "within_tolerance": float(np.mean([r.ok for r in done])),
        "mean_passes": float(np.mean([r.passes for r in done])),
        "max_passes": int(max(r.passes for r in done)),
        "form_error_mean": float(np.mean(d.max(axis=1) - d.min(axis=1))),
        "diameter_error_mean": float(np.mean(d) - target),
        "without_correction": {
            "within_tolerance": float(np.mean([r.ok_one_pass for r in done])),
            "passes": 1,
            "form_error_mean": float(np.mean(d1.max(axis=1) - d1.min(axis=1))),
            "diameter_error_mean": float(np.mean(d1) - target),
        },
        "stiffness_ratio_mean": float(np.mean(ratios)) if ratios else None,
    }
