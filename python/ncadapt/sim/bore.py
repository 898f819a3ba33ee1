"""A virtual boring testbed: an elastic boring bar finishing H9 bores to H6, seeded.

Equations (radial, mm; ζ ∈ [0, 1] along the bore from face A, the tool's entry, to face B):

- the bar deflects by its compliance times the real depth of cut (force ∝ depth, Nosov and
  Kondakov's assumption): d(ζ) = c(ζ)·a(ζ);
- c(ζ) = c₀ (1 + τ (1 − ζ) − β·4ζ(1 − ζ)) — taper (more compliant at the entry, so the bore is
  smaller there) plus barrel (less deflection mid-bore, the bore is larger there), the shapes the
  paper reports for bores bored to H9;
- c₀ = k_r k_c f / k_s: radial/tangential force ratio k_r = 0.4, the material's specific cutting
  force k_c, feed f = 0.05 mm/rev, the bar's radial stiffness k_s = 1000 N/mm (a slender bar,
  overhang about 4 D), per part log-normal with σ = 15 %;
- k_c (N/mm², Sandvik's k_c1 ranges for the ISO material groups): steel 2000 (P), titanium alloy
  1400 (S), aluminium alloy 700 (N), hardened steel 3200 (H);
- τ ~ U(0.2, 0.8), β ~ U(0, 0.3) per part; the compliance varies from pass to pass by a normal
  factor of σ = 5 % (wear, hardness scatter); the tool's setting repeats to σ = 0.5 µm;
- a pass set δ_K into the body on the aimed radius R leaves r(ζ) = R + δ_K − d(ζ), with real depth
  a(ζ) = R + δ_K − r_prev(ζ);
- probing: 8 points per plane at ζ = 0.08, 0.5, 0.92 with σ = 0.5 µm radial noise; the circle is
  Kåsa's algebraic least-squares fit (for evenly spread points and µm noise it equals the
  geometric fit of :func:`ncadapt.processes.bore.fit_circle` to far below 1 nm);
- hardened parts were pre-finished before hardening: the pre-finish pass cut with steel's k_c,
  the corrective passes cut with the hardened k_c.

Defaults: Ø40, H9 → H6, pre-finish depth t₀ = 0.5 mm, radial allowance z = 0.1 mm, k = 0.25.
A part is inside tolerance when the real bore, sampled at 41 points along ζ, is inside H6 and its
form error (max − min diameter) is at most k·IT6.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..processes import bore as pb

MATERIALS = {"steel": 2000.0, "titanium": 1400.0, "aluminium": 700.0, "hardened": 3200.0}  # k_c, N/mm²
K_R = 0.4
FEED = 0.05  # mm/rev
STIFFNESS = 1000.0  # N/mm
STIFFNESS_SIGMA = 0.15
PASS_SIGMA = 0.05
SETTING_SIGMA = 0.0005  # mm
PROBE_SIGMA = 0.0005  # mm
PROBE_POINTS = 8
PLANES = (0.08, 0.5, 0.92)
ZETA = np.linspace(0.0, 1.0, 41)


@dataclass
class Part:
    c0: float  # compliance of the corrective passes
    c0_prefinish: float
    tau: float
    beta: float

    def compliance(self, zeta, c0):
        return c0 * (1 + self.tau * (1 - zeta) - self.beta * 4 * zeta * (1 - zeta))


def random_part(rng, material: str = "steel") -> Part:
    if material not in MATERIALS:
        raise ValueError(f"material must be one of {sorted(MATERIALS)}, got {material!r}")
    ks = STIFFNESS * np.exp(rng.normal(0, STIFFNESS_SIGMA))
    c = K_R * MATERIALS[material] * FEED / ks
    c_pre = K_R * MATERIALS["steel" if material == "hardened" else material] * FEED / ks
    return Part(c, c_pre, rng.uniform(0.2, 0.8), rng.uniform(0.0, 0.3))


def probe(rng, radius_at, zetas=PLANES, z_length: float = 60.0) -> pb.BoreMeasurement:
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
        circles.append(pb.Circle(f"{zeta:g}", z_length * (1 - zeta), (cx, cy), 2 * rr, float(dev.max() - dev.min()),
                                 PROBE_POINTS))
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


def run_part(rng, *, diameter: float = 40.0, final: str = "H6", prefinish: str = "H9", t0: float = 0.5,
             allowance: float = 0.1, k: float = 0.25, material: str = "steel") -> PartResult:
    part = random_part(rng, material)
    lo, hi = pb.class_limits(diameter, final)
    target = diameter + (lo + hi) / 2
    hardened = material == "hardened"
    # the pre-finish pass: aimed at D_target − 2z, depth t₀, not corrected
    r_aim = target / 2 - allowance
    r = r_aim - part.compliance(ZETA, part.c0_prefinish) * t0
    meas = probe(rng, lambda zz: np.interp(zz, ZETA, r))
    try:
        plan = pb.plan_from_measurement(diameter, meas, final=final, prefinish=prefinish, t0=t0, allowance=allowance,
                                        k=k, target_diameter=target)
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
        c = part.compliance(ZETA, part.c0) * (1 + rng.normal(0, PASS_SIGMA))
        r = setting - c * (setting - r)
        applied = dk
        meas = probe(rng, lambda zz, r=r: np.interp(zz, ZETA, r))
    d = 2 * r
    # without correction: the whole allowance in one pass aimed at the target
    setting = target / 2 + rng.normal(0, SETTING_SIGMA)
    d1 = 2 * (setting - part.compliance(ZETA, part.c0) * (1 + rng.normal(0, PASS_SIGMA)) * (setting - r_pre))
    it_f = hi - lo

    def ok(dd):
        return bool(np.all(dd >= diameter + lo) and np.all(dd <= diameter + hi) and dd.max() - dd.min() <= k * it_f)

    return PartResult(plan.applicable, plan.passes, d, d1, ok(d), ok(d1), ratio)


def simulate(parts: int = 1000, seed: int = 1, *, material: str = "steel", progress=None, **kw) -> dict:
    """``parts`` parts for which the plan's applicability condition holds (others are drawn and
    counted, not machined further). Returns the summary as a dict."""
    rng = np.random.default_rng(seed)
    done, drawn = [], 0
    while len(done) < parts:
        drawn += 1
        res = run_part(rng, material=material, **kw)
        if res.applicable:
            done.append(res)
            if progress and len(done) % 100 == 0:
                progress(f"{len(done)}/{parts} parts", len(done), parts)
        if drawn > 20 * parts:
            raise InputError(f"condition (3) held for {len(done)} of the {drawn} parts drawn with these settings "
                             f"(t0 = {kw.get('t0', 0.5):g} mm: the pre-finish deflection grows with t0); use a "
                             "smaller --t0")
    d = np.array([r.diameters for r in done])
    diameter, final = kw.get("diameter", 40.0), kw.get("final", "H6")
    target = diameter + sum(pb.class_limits(diameter, final)) / 2
    d1 = np.array([r.one_pass for r in done])
    ratios = [r.stiffness_ratio for r in done if r.stiffness_ratio is not None]
    return {
        "parts": parts, "seed": seed, "material": material, "drawn": drawn,
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
