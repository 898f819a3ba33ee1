"""Turning slender shafts: a stiffness-matrix deflection model and feed (or X) trajectories that
keep the diameter constant (Zakovorotny, Flek, Pham Dinh Tung, "Synergetic concept in construction
of accuracy control systems for manufacturing parts of complex geometric forms").

Everything inside is SI (m, N, N/m, Pa, s); the configuration is read in the paper's units and
converted on reading: 1 kgf = 9.80665 N, so stiffness kgf/mm × 9806.65 → N/m and ρ kgf/mm² ×
9.80665·10⁶ → Pa; mm × 10⁻³ → m. Results are reported in mm, mm/rev and rpm.

Coordinates: X₁ radial (positive away from the axis), X₂ tangential (cutting speed), X₃ along the
axis; the tool travels from the tailstock towards the chuck, x3 is the distance from the tailstock
centre. r = X₁ + x₁ + y₁: the tool's x₁ and the workpiece's y₁ radial deflections both leave the
radius larger than programmed.

Model
-----
- Workpiece subsystem compliance at the contact point (3 × 3): the shaft as an Euler–Bernoulli beam
  (EI = E·πd⁴/64, EA = E·πd²/4) on the chuck and tailstock supports, each support taking the share
  of the load given by the lever rule (w_c = x3/L at the chuck, w_t = 1 − x3/L at the tailstock) in
  every direction: S_Y = w_c² C_chuck⁻¹ + w_t² C_tail⁻¹ + diag(b, b, e), with the pinned–pinned beam
  b = u²(L−u)²/(3EIL) and the bar fixed at both ends e = u(L−u)/(EA·L), u = L − x3.
  c^(Y)(x3) = S_Y⁻¹. The tool subsystem's c^(X) is constant.
- Cutting force F₀ = ρ(V_p)·S, S = S_p t_p − ζ S_p², ζ = ½ tan φ tan φ₁ / (tan φ + tan φ₁), along
  λ = (λ₁, λ₂, λ₃): F = F₀ λ. ρ(V_p) is interpolated linearly in the paper's table.
- Per revolution, the linearised system C_Σ x = F (the paper's eq. 7) in x = (x₁, x₂, x₃, y₁, y₂, y₃):
  each subsystem c x = λ F₀ with the chip area reduced by the radial deflection and changed by the
  axial deflection against the previous revolution,
  F₀ = ρ [t_p S_p − ζ S_p² + t_p (x₃ + y₃)(prev) − t_p (x₃ + y₃) − S_p (x₁ + y₁)];
  moving the deflection terms to the left gives the paper's C_Σ (the −ζS_p² term, which the
  paper's linearisation drops from F, is kept).
- The depth of cut is taken from the programmed radius (the paper's eq. 5): t = r₀ − X₁ − (x₁ + y₁),
  r₀ the radius before the cut. With the program's radial offset o = X₁ − R from the nominal final
  radius R = r₀ − t_p, the depth is t_p − o − (x₁ + y₁).
- Steady state (x₃ = x₃(prev)): with g = e₁ᵀ(S_X + S_Y) λ the radial compliance along λ,
  F₀ = ρ(S_p(t_p − o) − ζS_p²)/(1 + ρ S_p g) and w = x₁ + y₁ = g F₀ — the closed form the inverse
  uses; the factor 1/(1 + ρS_p g) is the depth lost to the deflection.

Inverse problem
---------------
The invariant X₁ − (x₁ + y₁) = const (eq. 8): the radius r = R + o + w stays R when o = −w. Then
the depth is t_p again and the deflection is the nominal one, without the feedback factor:
w = g ρ (S_p t_p − ζ S_p²). **Path mode**: X₁(x3) = R − g ρ (S t_p − ζS²) at a constant feed —
exact on the model. **Feed mode**: a constant offset o = −δ and S_p(x3) the smaller root of
g ρ ζ S² − g ρ t_p S + δ = 0 within the feed bounds; δ is chosen as large as the bounds allow
everywhere (least machining time for the least variation); where the stiff ends cannot reach δ even
at the largest feed, the deflection there (with the feedback) is the floor of the variation. The
constant offset finally programmed is the mid-range of the deflection it gives (a fixed point: the
offset changes the depth, so the deflection).
**Entry**: the revolution that enters the stock has no axial deflection before it (S_p = S − a), so
the first ``ENTRY_REVOLUTIONS`` revolutions get their own X, solved revolution by revolution
(:meth:`Model.entry`, :func:`entry_revolutions`) to leave the steady state's radius error.

Choosing one trajectory: dynamic programming over stations along x3 and the spindle speeds of
the family, minimising machining time Σ Δx3 / (S_p n) (plus, optionally, tool wear by Taylor's law
V Tᵐ = C: wear cost w Σ Δt / T(V)) with |ΔS_p| and |Δn| per revolution bounded.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._io import read_text
from ..errors import InputError, cut

KGF = 9.80665  # N
# revolutions at the entry into the stock given their own program offsets: the transient falls by
# a factor of about 60 per revolution (a₋₁ = 0, then a_k − a_(k−1) shrinks by g₃ρt_p/(1 + g₃ρt_p)),
# so after three it is below 10⁻⁵ of the first (docs/turning.md)
ENTRY_REVOLUTIONS = 3
__all__ = ["Config", "DIALECTS", "load", "Model", "Plan", "plan", "program"]


def _sym(v, scale: float) -> np.ndarray:
    """The paper's six numbers C11, C22, C33, C21, C31, C32 as a symmetric 3 × 3 matrix."""
    c11, c22, c33, c21, c31, c32 = (float(x) * scale for x in v)
    return np.array([[c11, c21, c31], [c21, c22, c32], [c31, c32, c33]])


@dataclass
class Config:
    """A turning job read from its TOML file (SI units inside: m, Pa, N): the shaft, the machine's
    stiffness model, the cut and the plan's bounds."""

    diameter: float  # m
    length: float  # m
    youngs: float  # Pa
    depth: float  # m
    phi: float  # rad
    phi1: float
    lam: np.ndarray
    rho_speed: np.ndarray  # m/min
    rho: np.ndarray  # Pa
    chuck: np.ndarray  # N/m
    tail: np.ndarray
    tool: np.ndarray
    feed_bounds: tuple  # m/rev
    rpm_bounds: tuple
    feed_change: float  # m/rev per rev
    rpm_change: float  # rpm per rev
    start: float  # m
    end: float
    step: float
    speeds: int
    source: str = ""
    nose_radius: float | None = None  # m, [cut] nose_radius (optional)
    rz_max: float | None = None  # m, [bounds] rz_max (optional): Rz = S²/(8 r_ε) ≤ rz_max
    finish_depth: float | None = None  # m, [plan] finish_depth: the finishing pass of the rough + finish baseline
    feed_max_rough: float | None = None  # m/rev: the largest feed before the roughness bound
    stepped: bool = False  # [model] stepped: the part already turned has the turned diameter
    chuck_support: str = "pinned"  # [model] chuck: "pinned" (the paper's supports) or "clamped"


def roughness(feed, nose_radius):
    """Theoretical peak-to-valley height of a turned profile, Rz = S²/(8 r_ε) (the circular-nose
    approximation, valid while S < r_ε; e.g. Sandvik Coromant's turning formulas), same units."""
    return np.asarray(feed, float) ** 2 / (8 * nose_radius)


#: Physical bounds of the configuration (the paper's units): ρ (kgf/mm², the paper's 210–290; ten
#: times the hardest steels' specific cutting force), its speeds (m/min), the force shares λ, the
#: stiffness entries (kgf/mm; the paper's are 10³–10⁵), feed (mm/rev) and spindle speed (rpm).
RHO_MAX = 5_000.0
RHO_SPEED_MAX = 10_000.0
LAMBDA_MAX = 10.0
STIFFNESS_MAX = 1e9
FEED_MAX = 5.0
RPM_MAX = 100_000.0

#: Bounds of the planning work: stations along the shaft, spindle speeds of the family, and both.
STATIONS_MAX = 100_000
SPEEDS_MAX = 1_000
WORK_MAX = 5_000_000  # stations x spindle speeds of the planning family


def load(path) -> Config:
    """Read a turning configuration (TOML, the paper's units) and convert it to SI. A missing key,
    a value of the wrong type, a number that is not finite or out of its bounds is an
    :class:`InputError` at the key's line."""
    path = Path(path)
    text = read_text(path)
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(
            f"not valid TOML: {e}", str(path), getattr(e, "lineno", 0) or 0, getattr(e, "colno", 0) or 0
        ) from None
    lines = text.splitlines()

    def where(section, key) -> int:
        """The line of ``key = …`` in ``[section]`` (0 when not found)."""
        inside = False
        for n, ln in enumerate(lines, 1):
            t = ln.strip()
            if t.startswith("["):
                inside = t.split("]")[0].strip("[ ") == section
            elif inside and t.split("=")[0].strip() == key:
                return n
        return 0

    def fail(section, key, msg):
        raise InputError(f"[{section}] {key} {msg}", str(path), where(section, key), 1)

    def raw(section, key):
        sec = d.get(section)
        if not isinstance(sec, dict) or key not in sec:
            raise InputError(f"missing [{section}] {key}", str(path))
        return sec[key]

    def number(section, key, lo=None, hi=None, v=None, positive=False):
        v = raw(section, key) if v is None else v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            fail(section, key, f"must be a number, got {cut(v)}")
        v = float(v)
        if not math.isfinite(v):
            fail(section, key, f"must be finite, got {v}")
        if positive and not v > 0:
            fail(section, key, f"must be > 0, got {v:g}")
        if lo is not None and v < lo:
            fail(section, key, f"must be >= {lo:g}, got {v:g}")
        if hi is not None and v > hi:
            fail(section, key, f"must be <= {hi:g}, got {v:g}")
        return v

    def numbers(section, key, n=None, **bounds):
        v = raw(section, key)
        if not isinstance(v, list) or (n is not None and len(v) != n) or (n is None and len(v) < 2):
            fail(section, key, f"must be a list of {n if n is not None else 'at least 2'} numbers")
        return [number(section, key, v=x, **bounds) for x in v]

    def integer(section, key, lo, hi):
        v = raw(section, key)
        if isinstance(v, bool) or not isinstance(v, int):
            fail(section, key, f"must be a whole number, got {cut(v)}")
        if not lo <= v <= hi:
            fail(section, key, f"must be within {lo}..{hi}, got {cut(v)}")
        return v

    mm = 1e-3
    rs = np.asarray(numbers("cut", "rho_speed", positive=True, hi=RHO_SPEED_MAX))
    rho = np.asarray(numbers("cut", "rho", positive=True, hi=RHO_MAX))
    if len(rs) != len(rho) or np.any(np.diff(rs) <= 0):
        fail("cut", "rho_speed", "must increase and match rho in length")
    diameter = number("shaft", "diameter", positive=True, hi=1e4)
    length = number("shaft", "length", positive=True, hi=1e5)
    start, end = number("plan", "start", lo=0), number("plan", "end", lo=0)
    step = number("plan", "step", positive=True)
    speeds = integer("plan", "speeds", 2, SPEEDS_MAX)
    if not 0 <= start < end <= length:
        fail("plan", "end", "needs 0 <= start < end <= shaft length")
    stations = (end - start) / step
    if stations > STATIONS_MAX or stations * speeds > WORK_MAX:
        fail(
            "plan",
            "step",
            f"gives {stations:,.0f} stations x {speeds} speeds; at most {STATIONS_MAX:,} "
            f"stations and {WORK_MAX:,} stations x speeds",
        )
    if stations < 1:
        fail("plan", "step", f"must be at most end - start = {end - start:g} mm (two stations at least)")
    depth = number("cut", "depth", positive=True)
    if not depth < diameter / 2:
        fail("cut", "depth", f"must be < {diameter / 2:g} mm, the bar's radius, got {depth:g}")
    lam = numbers("cut", "lambda", 3, hi=LAMBDA_MAX)
    if not (lam[0] > 0 and lam[1] > 0 and lam[2] >= 0):
        fail(
            "cut",
            "lambda",
            "must be (radial > 0, tangential > 0, axial >= 0): the radial force pushes the tool "
            f"away from the work and the tangential force opposes the cut, got {lam}",
        )
    stiff = {
        key: numbers("stiffness", key, 6, lo=-STIFFNESS_MAX, hi=STIFFNESS_MAX) for key in ("chuck", "tailstock", "tool")
    }
    feed_bounds = numbers("bounds", "feed", 2, positive=True, hi=FEED_MAX)
    rpm_bounds = numbers("bounds", "spindle_rpm", 2, positive=True, hi=RPM_MAX)
    cfg = Config(
        diameter=diameter * mm,
        length=length * mm,
        youngs=number("shaft", "youngs_modulus", positive=True, hi=1e7) * 1e6,
        depth=depth * mm,
        phi=math.radians(number("cut", "plan_angle", positive=True, hi=179)),
        phi1=math.radians(number("cut", "trailing_angle", positive=True, hi=179)),
        lam=np.asarray(lam, float),
        rho_speed=rs,
        rho=rho * KGF * 1e6,
        chuck=_sym(stiff["chuck"], KGF / mm),
        tail=_sym(stiff["tailstock"], KGF / mm),
        tool=_sym(stiff["tool"], KGF / mm),
        feed_bounds=tuple(x * mm for x in feed_bounds),
        rpm_bounds=tuple(rpm_bounds),
        feed_change=number("bounds", "feed_change", positive=True, hi=FEED_MAX) * mm,
        rpm_change=number("bounds", "rpm_change", positive=True, hi=RPM_MAX) * 1.0,
        start=start * mm,
        end=end * mm,
        step=step * mm,
        speeds=speeds,
        source=str(path),
    )
    if not 0 < cfg.feed_bounds[0] < cfg.feed_bounds[1] or not 0 < cfg.rpm_bounds[0] <= cfg.rpm_bounds[1]:
        fail("bounds", "feed", "and spindle_rpm must be increasing positive pairs")
    # the roughness bound: Rz = S²/(8 r_ε) ≤ rz_max caps the feed at √(8 r_ε rz_max)
    if "rz_max" in d.get("bounds", {}):
        rz = number("bounds", "rz_max", positive=True, hi=1000) * 1e-6  # µm
        if "nose_radius" not in d.get("cut", {}):
            fail("bounds", "rz_max", "needs [cut] nose_radius (mm): Rz = S²/(8 r_ε)")
        re_ = number("cut", "nose_radius", positive=True, hi=10) * mm
        s_rz = math.sqrt(8 * re_ * rz)
        if s_rz <= cfg.feed_bounds[0]:
            fail(
                "bounds",
                "rz_max",
                f"allows feeds up to {s_rz * 1e3:.4f} mm/rev (Rz = S²/(8 r_ε)), not above the "
                f"smallest feed of the bounds {cfg.feed_bounds[0] * 1e3:g} mm/rev",
            )
        cfg.nose_radius, cfg.rz_max = re_, rz
        cfg.feed_max_rough = cfg.feed_bounds[1]
        cfg.feed_bounds = (cfg.feed_bounds[0], min(cfg.feed_bounds[1], s_rz))
    elif "nose_radius" in d.get("cut", {}):
        cfg.nose_radius = number("cut", "nose_radius", positive=True, hi=10) * mm
    model = d.get("model", {})
    if not isinstance(model, dict):
        fail("model", "", 'must be a table: [model] with stepped = true|false, chuck = "pinned"|"clamped"')
    for key in model:
        if key not in ("stepped", "chuck"):
            fail("model", key, "is not a model option (stepped, chuck)")
    if "stepped" in model:
        if not isinstance(model["stepped"], bool):
            fail("model", "stepped", f"must be true or false, got {cut(model['stepped'])}")
        cfg.stepped = model["stepped"]
    if "chuck" in model:
        if model["chuck"] not in ("pinned", "clamped"):
            fail("model", "chuck", f'must be "pinned" or "clamped", got {cut(model["chuck"])}')
        cfg.chuck_support = model["chuck"]
    if "finish_depth" in d.get("plan", {}):
        fd = number("plan", "finish_depth", positive=True)
        if not fd < depth:
            fail("plan", "finish_depth", f"must be < the depth of cut {depth:g} mm")
        cfg.finish_depth = fd * mm
    else:
        cfg.finish_depth = default_finish_depth(cfg.depth)
    if cfg.phi + cfg.phi1 >= math.pi:
        fail("cut", "trailing_angle", "and plan_angle must add up to less than 180 degrees")
    for name, key in (("chuck", "chuck"), ("tail", "tailstock"), ("tool", "tool")):
        if np.any(np.linalg.eigvalsh(getattr(cfg, name)) <= 0):
            fail("stiffness", key, "is not positive definite")
    # the radial compliance along the force must be positive everywhere along the shaft, or the
    # force would pull the tool into the work (the off-diagonal terms can do that)
    x3 = np.linspace(0, cfg.length, 201)
    g = Model(cfg).radial_compliance(x3)
    if not np.all(g > 0):
        fail(
            "cut",
            "lambda",
            f"with these stiffness matrices gives a radial compliance <= 0 at x3 = "
            f"{x3[np.argmin(g)] * 1e3:g} mm: the force would pull the tool into the work",
        )
    return cfg


class Model:
    """The cutting system of a configuration: compliances, force and the per-revolution solver."""

    def __init__(self, cfg: Config, *, rho_scale: float = 1.0, stiffness_scale: float = 1.0):
        self.cfg = cfg
        d, E = cfg.diameter, cfg.youngs
        self.EI = E * math.pi * d**4 / 64
        self.EA = E * math.pi * d**2 / 4
        df = d - 2 * cfg.depth  # the turned diameter
        self.EI_f = E * math.pi * df**4 / 64
        self.EA_f = E * math.pi * df**2 / 4
        self.stepped = cfg.stepped
        self.chuck_clamped = cfg.chuck_support == "clamped"
        self._cache: dict = {}  # x3 bytes → S_Y: the planner asks for the same stations many times
        self.s_chuck = np.linalg.inv(cfg.chuck * stiffness_scale)
        self.s_tail = np.linalg.inv(cfg.tail * stiffness_scale)
        self.c_tool = cfg.tool * stiffness_scale
        self.s_tool = np.linalg.inv(self.c_tool)
        tp, tp1 = math.tan(cfg.phi), math.tan(cfg.phi1)
        self.zeta = 0.5 * tp * tp1 / (tp + tp1)
        self.rho_scale = rho_scale

    # --- compliances
    def _bending(self, a: float) -> tuple[float, float]:
        """Bending compliance at the load point x3 = a (rigid supports) and the tailstock's share of
        the load, for the model's options: the part already turned, [start, a), at the turned
        diameter (``stepped``), and the chuck end pinned or clamped. Unit-load (Mohr) integrals of
        the moment lines over the segments of constant EI, exact by 2-point Gauss on each (the
        integrands are quadratics); the clamped chuck by the force method with the tailstock
        reaction as the redundant."""
        cfg, L = self.cfg, self.cfg.length
        cuts = sorted({0.0, min(max(cfg.start, 0.0), a), a, L}) if self.stepped else sorted({0.0, a, L})
        gx = np.array([-1, 1]) / math.sqrt(3)

        def integral(f):
            tot = 0.0
            for lo, hi in zip(cuts[:-1], cuts[1:]):
                if hi <= lo:
                    continue
                xs = 0.5 * (lo + hi) + 0.5 * (hi - lo) * gx
                ei = self.EI_f if (self.stepped and cfg.start <= 0.5 * (lo + hi) < a) else self.EI
                tot += 0.5 * (hi - lo) * float(np.sum(f(xs))) / ei
            return tot

        if not self.chuck_clamped:  # pinned–pinned: statically determinate, M(x) of a unit load at a

            def m(x):
                return np.where(x < a, x * (L - a) / L, a * (L - x) / L)

            return integral(lambda x: m(x) ** 2), 1.0 - a / L
        # clamped at the chuck (x = L), pinned at the tailstock (x = 0): cantilever from the chuck
        d00 = integral(lambda x: x * x)
        d0a = integral(lambda x: x * np.maximum(x - a, 0))
        daa = integral(lambda x: np.maximum(x - a, 0) ** 2)
        r = d0a / d00  # the tailstock's reaction to a unit load at a
        return daa - d0a * r, r

    def workpiece_compliance(self, x3) -> np.ndarray:
        """S_Y (3 × 3, m/N) at distance x3 from the tailstock centre; (n, 3, 3) for an array."""
        x3 = np.atleast_1d(np.asarray(x3, float))
        key = x3.tobytes()
        if key not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = self._workpiece_compliance(x3)
        return self._cache[key].copy()

    def _workpiece_compliance(self, x3: np.ndarray) -> np.ndarray:
        L = self.cfg.length
        u = L - x3  # from the chuck
        if self.stepped or self.chuck_clamped:
            bw = np.array([self._bending(float(a)) for a in x3])
            b, wt = bw[:, 0], bw[:, 1]
            wc = 1.0 - wt
        else:
            wc, wt = x3 / L, 1.0 - x3 / L
            b = u**2 * (L - u) ** 2 / (3 * self.EI * L)
        if self.stepped:  # axially: the two ends in parallel, the tailstock side partly turned
            turned = np.clip(x3 - self.cfg.start, 0, None)
            s1, s2 = (x3 - turned) / self.EA + turned / self.EA_f, u / self.EA
            e = s1 * s2 / np.maximum(s1 + s2, 1e-300)
        else:
            e = u * (L - u) / (self.EA * L)
        s = wc[:, None, None] ** 2 * self.s_chuck + wt[:, None, None] ** 2 * self.s_tail
        s[:, 0, 0] += b
        s[:, 1, 1] += b
        s[:, 2, 2] += e
        return s

    def workpiece_stiffness(self, x3) -> np.ndarray:
        return np.linalg.inv(self.workpiece_compliance(x3))

    def radial_compliance(self, x3) -> np.ndarray:
        """g = e₁ᵀ (S_X + S_Y) λ, m/N: the radial deflection x₁ + y₁ per newton of F₀."""
        s = self.s_tool[None] + self.workpiece_compliance(x3)
        return s[:, 0, :] @ self.cfg.lam

    def axial_compliance(self, x3) -> np.ndarray:
        """g₃ = e₃ᵀ (S_X + S_Y) λ, m/N: the axial deflection x₃ + y₃ per newton of F₀."""
        s = self.s_tool[None] + self.workpiece_compliance(x3)
        return s[:, 2, :] @ self.cfg.lam

    # --- cutting
    def rho(self, rpm) -> np.ndarray:
        v = math.pi * self.cfg.diameter * np.asarray(rpm, float)  # m/min
        return np.interp(v, self.cfg.rho_speed, self.cfg.rho) * self.rho_scale

    def chip_area(self, feed, depth=None) -> np.ndarray:
        """S = S_p t − ζ S_p² (eq. 4), m², at depth t (default the nominal t_p)."""
        s = np.asarray(feed, float)
        t = self.cfg.depth if depth is None else np.asarray(depth, float)
        return s * t - self.zeta * s**2

    def nominal_deflection(self, x3, feed, rpm) -> np.ndarray:
        """w = g ρ (S_p t_p − ζ S_p²), m: the radial deflection when the depth of cut is the
        nominal t_p — which it is where the program's X pre-distortion equals the deflection."""
        return self.radial_compliance(x3) * self.rho(rpm) * self.chip_area(feed)

    def deflection(self, x3, feed, rpm, offset=0.0, depth=None) -> np.ndarray:
        """Steady-state radial deflection w = x₁ + y₁, m (closed form), when the program's radius is
        ``offset`` (m, + away from the axis) off the nominal final radius: the depth of cut is
        t_p − offset − w (eq. 5), so w = g ρ (S (t_p − offset) − ζ S²) / (1 + ρ S g); ``depth``
        replaces the nominal t_p (a finishing pass)."""
        g, r, s = self.radial_compliance(x3), self.rho(rpm), np.asarray(feed, float)
        tp = self.cfg.depth if depth is None else depth
        area = np.maximum(self.chip_area(s, tp - np.asarray(offset, float)), 0.0)  # no contact: no force
        return g * r * area / (1 + r * s * g)

    def feed_for(self, x3, rpm, delta) -> np.ndarray:
        """The feed per revolution whose nominal deflection is δ (the program offset by −δ, so the
        depth is t_p): the smaller root of g ρ ζ S² − g ρ t_p S + δ = 0, m/rev; NaN where no feed
        reaches δ."""
        g, r, tp = self.radial_compliance(x3), self.rho(rpm), self.cfg.depth
        A, B, C = g * r * self.zeta, -g * r * tp, delta + 0 * g
        disc = B * B - 4 * A * C
        with np.errstate(invalid="ignore"):
            return np.where(disc >= 0, (-B - np.sqrt(np.maximum(disc, 0))) / (2 * A), np.nan)

    def constant_offset(self, x3, feed, rpm, *, depth=None, left=0.0) -> tuple[float, np.ndarray]:
        """The constant program offset −c whose deflection w(−c) has c as its mid-range (the best
        constant offset: the radius error w − c is symmetric), and that deflection. ``left`` (m):
        the radius a previous pass left over its aim along the stations (adds to the depth)."""
        c = 0.0
        for _ in range(200):  # dw/dc = ρSg/(1 + ρSg) < 1: a contraction
            w = self.deflection(x3, feed, rpm, -c - left, depth)
            c_new = 0.5 * float(np.max(w) + np.min(w))
            if abs(c_new - c) <= 1e-15:
                break
            c = c_new
        return c, self.deflection(x3, feed, rpm, -c - left, depth)

    # --- the paper's 6 × 6 system, revolution by revolution
    def c_sigma(self, x3: float, feed: float, rpm: float) -> tuple[np.ndarray, float]:
        cfg = self.cfg
        r = float(self.rho(rpm))
        cy = self.workpiece_stiffness(x3)[0]
        lam = cfg.lam
        m = np.zeros((6, 6))
        m[:3, :3] = self.c_tool.T
        m[3:, 3:] = cy.T
        for blk in (0, 3):
            for i in range(3):
                for k0 in (0, 3):
                    m[blk + i, k0 + 0] += lam[i] * r * feed
                    m[blk + i, k0 + 2] += lam[i] * r * cfg.depth
        return m, r

    def solve_revolution(self, x3: float, feed: float, rpm: float, prev_axial: float) -> np.ndarray:
        """x = (x₁, x₂, x₃, y₁, y₂, y₃) from C_Σ x = F with the previous revolution's x₃ + y₃."""
        m, r = self.c_sigma(x3, feed, rpm)
        f0 = r * (float(self.chip_area(feed)) + self.cfg.depth * prev_axial)
        rhs = f0 * np.concatenate([self.cfg.lam, self.cfg.lam])
        return np.linalg.solve(m, rhs)

    def entry(self, x3, feed, rpm, error) -> tuple[np.ndarray, np.ndarray]:
        """The program offsets o_k (m) for the revolutions that enter the stock at ``x3`` (m, where
        each starts, at ``feed`` (m/rev) and ``rpm``, one per revolution or one for all) so that each
        leaves the radius error ``error`` (m, the steady state's), and their radial deflections w_k (m).

        The revolution that enters has no axial deflection before it, so its feed is
        S_p = S + a_(k−1) − a_k with a₋₁ = 0 and a = g₃F₀ (eq. 5's S_p); its radius error
        e = o + w fixes its depth, t = t_p − e (eq. 5), so F₀ = ρ(S_p t − ζS_p²) is one quadratic
        in F₀: ρζg₃²F₀² + (1 + ρg₃(t − 2ζu))F₀ − ρ(ut − ζu²) = 0, u = S + a_(k−1), whose positive
        root gives w = gF₀ and o = e − w. Where a_(k−1) = a_k (the steady state) this is the
        nominal deflection at depth t."""
        x3 = np.atleast_1d(np.asarray(x3, float))
        e, s, n = (np.broadcast_to(np.asarray(v, float), x3.shape) for v in (error, feed, rpm))
        g, g3, r = self.radial_compliance(x3), self.axial_compliance(x3), self.rho(n)
        off, w = np.empty(len(x3)), np.empty(len(x3))
        a_prev = 0.0
        for k in range(len(x3)):
            t, u = self.cfg.depth - e[k], s[k] + a_prev
            qa = r[k] * self.zeta * g3[k] ** 2
            qb = 1 + r[k] * g3[k] * (t - 2 * self.zeta * u)
            qc = -r[k] * (u * t - self.zeta * u * u)
            f0 = 2 * -qc / (qb + math.sqrt(qb * qb - 4 * qa * qc))  # the positive root, without cancellation
            w[k] = g[k] * f0
            off[k] = e[k] - w[k]
            a_prev = g3[k] * f0
        return off, w


@dataclass(frozen=True)
class Entry:
    """The revolutions that enter the stock, each programmed as its own block (SI): where each
    starts, its program offset (programmed radius − nominal final radius), feed and speed."""

    x3: np.ndarray  # m
    offset: np.ndarray  # m
    feed: np.ndarray  # m/rev
    rpm: np.ndarray


@dataclass
class Plan:
    """A trajectory and its figures on the model. Every error is a **diameter** measure, mm in
    :meth:`as_dict`: ``diameter_error_max`` = max |D − D_target| along the shaft, ``diameter_variation``
    = max D − min D; the constant-feed comparison uses the best constant X offset."""

    mode: str
    x3: np.ndarray  # m, stations
    feed: np.ndarray  # m/rev
    rpm: np.ndarray
    deflection: np.ndarray  # m, steady radial deflection at the stations
    x1_offset: np.ndarray  # m: programmed radius − nominal final radius (path mode: −deflection)
    constant_feed: float  # m/rev, the comparison program's feed
    constant_rpm: float
    constant_offset: float  # m: the comparison program's best constant radius offset
    diameter_error_max: float  # m, on the model: max |D − D_target|
    diameter_variation: float  # m: max D − min D
    diameter_error_constant_feed: float
    diameter_variation_constant_feed: float
    machining_time_s: float
    machining_time_constant_feed_s: float
    constant_feed_same_error: float  # m/rev: the constant feed that gives the same diameter variation
    machining_time_same_error_s: float
    family_rpm: np.ndarray
    family_feed: np.ndarray  # (speeds, stations) m/rev, NaN outside the bounds
    delta: float
    baselines: tuple = ()  # dicts: what a programmer without the model would run (see plan)
    entry: Entry | None = None  # the entry revolutions' own X (None: the stations' from the first)

    def as_dict(self) -> dict:
        mm = 1e3
        same = self.diameter_variation > 1e-9  # a constant feed can match a non-zero variation only
        return {
            "mode": self.mode,
            "measure": "diameter, mm (error: max |D - D_target|; variation: max D - min D)",
            "diameter_error_max": self.diameter_error_max * mm,
            "diameter_variation": self.diameter_variation * mm,
            "diameter_error_constant_feed": self.diameter_error_constant_feed * mm,
            "diameter_variation_constant_feed": self.diameter_variation_constant_feed * mm,
            "diameter_variation_ratio": (
                self.diameter_variation / self.diameter_variation_constant_feed
                if self.diameter_variation_constant_feed
                else 0.0
            ),
            "machining_time_s": self.machining_time_s,
            "machining_time_constant_feed_s": self.machining_time_constant_feed_s,
            "constant_feed": self.constant_feed * mm,
            "constant_rpm": self.constant_rpm,
            "constant_offset": self.constant_offset * mm,
            "constant_feed_same_error": self.constant_feed_same_error * mm if same else None,
            "machining_time_same_error_s": self.machining_time_same_error_s if same else None,
            "deflection_target": self.delta * mm,
            "baselines": [dict(b) for b in self.baselines],
            "entry": [
                {"x3": float(a * mm), "x1_offset": float(o * mm), "feed": float(f * mm), "spindle_rpm": float(n)}
                for a, o, f, n in (
                    zip(self.entry.x3, self.entry.offset, self.entry.feed, self.entry.rpm) if self.entry else ()
                )
            ],
            "profile": [
                {
                    "x3": float(a * mm),
                    "feed": float(s * mm),
                    "spindle_rpm": float(n),
                    "deflection": float(d * mm),
                    "x1_offset": float(o * mm),
                }
                for a, s, n, d, o in zip(self.x3, self.feed, self.rpm, self.deflection, self.x1_offset)
            ],
        }

    def constant_feed_plan(self) -> Plan:
        """The comparison: this plan's stations at the constant feed and speed, with the best
        constant X offset (what a careful programmer without the model would get; no entry
        offsets)."""
        n = len(self.x3)
        return dataclasses.replace(
            self,
            mode="constant",
            feed=np.full(n, self.constant_feed),
            rpm=np.full(n, self.constant_rpm),
            x1_offset=np.full(n, -self.constant_offset),
            entry=None,
        )


def _block_at(x3, feed, rpm, a) -> tuple[float, float]:
    """The feed and speed the program cuts at ``a`` with: the lower feed and the higher speed of
    the two stations around it (see :func:`program`)."""
    j = int(np.clip(np.searchsorted(x3, a, side="right"), 1, len(x3) - 1))
    return float(min(feed[j - 1], feed[j])), float(max(rpm[j - 1], rpm[j]))


def entry_revolutions(m: Model, x3, feed, rpm, offset, revolutions: int = ENTRY_REVOLUTIONS) -> Entry:
    """The first ``revolutions`` revolutions of a trajectory (stations ``x3``, m, with their feed,
    speed and program ``offset``) with the X that gives each the radius error the steady state
    leaves there (:meth:`Model.entry`): each starts where the one before ends, at the feed and
    speed of the block it is in."""
    a, pos, feeds, rpms = float(x3[0]), [], [], []
    for _ in range(revolutions):
        if a >= x3[-1]:
            break
        f, n = _block_at(x3, feed, rpm, a)
        pos.append(a)
        feeds.append(f)
        rpms.append(n)
        a += f
    e_x3, e_f, e_n = np.array(pos), np.array(feeds), np.array(rpms)
    o_st = np.interp(e_x3, x3, offset)
    off, _ = m.entry(e_x3, e_f, e_n, o_st + m.deflection(e_x3, e_f, e_n, o_st))
    return Entry(e_x3, off, e_f, e_n)


def _time(x3, feed, rpm) -> float:
    """Σ Δx3 / (S n) over the stations (the feed and speed of a station hold up to the next), s."""
    dx = np.diff(x3)
    return float(np.sum(dx / (feed[:-1] * rpm[:-1] / 60.0)))


def _dp(cost, feeds, rpms, dx, feed_change, rpm_change, progress=None):
    """Dynamic programming over stations: states are (speed, feed) candidates; the least total
    cost path whose feed and speed change by at most ``feed_change`` and ``rpm_change`` per
    revolution between stations (the revolutions between two stations: Δx3 over the larger of
    their feeds — the fewer). ``cost`` and ``feeds`` are (states, stations), ``rpms`` (states,);
    cost = inf where a state is not allowed. Returns the state per station or None."""
    nk, ns = cost.shape
    acc = cost[:, 0].copy()
    back = np.zeros((nk, ns), dtype=np.int64)
    dn_ok = np.abs(rpms[:, None] - rpms[None, :])
    for j in range(1, ns):
        if progress is not None and j % 16 == 0:
            progress(j / (ns - 1))
        fj, fp = feeds[:, j][:, None], feeds[:, j - 1][None, :]
        revs = dx[j - 1] / np.maximum(fj, fp)
        ok = (np.abs(fj - fp) <= feed_change * revs + 1e-15) & (dn_ok <= rpm_change * revs + 1e-9)
        tot = np.where(ok, acc[None, :], np.inf)
        back[:, j] = np.argmin(tot, axis=1)
        acc = tot[np.arange(nk), back[:, j]] + cost[:, j]
    k = int(np.argmin(acc))
    if not np.isfinite(acc[k]):
        return None
    path = [k]
    for j in range(ns - 1, 0, -1):
        k = int(back[k, j])
        path.append(k)
    return np.array(path[::-1])


def plan(
    cfg: Config,
    mode: str = "feed",
    *,
    wear_weight: float = 0.0,
    taylor_c: float = 300.0,
    taylor_m: float = 0.25,
    progress=None,
) -> Plan:
    """Plan the trajectory (``mode`` "feed": S_p(x3) and n(x3); "path": X₁(x3) at constant feed)."""
    if mode not in ("feed", "path"):
        raise ValueError(f'mode must be "feed" or "path", got {mode!r}')
    m = Model(cfg)
    x3 = np.arange(cfg.start, cfg.end + 1e-12, cfg.step)
    smin, smax = cfg.feed_bounds
    rpms = np.linspace(cfg.rpm_bounds[0], cfg.rpm_bounds[1], max(cfg.speeds, 1))
    # the deflection target: as large as the bounds allow at every station, at some speed
    d_min = np.array([m.nominal_deflection(x3, smin, n) for n in rpms])  # (speeds, stations)
    delta = float(np.max(d_min.min(axis=0)))  # the most compliant station at its best speed, feed at minimum
    d_max = np.array([m.deflection(x3, smax, n, -delta) for n in rpms])  # the program offset by −δ
    family = np.array([m.feed_for(x3, n, delta) for n in rpms])
    # no root: δ is out of reach of any feed here (a stiff station), so the largest feed; below the
    # smallest feed: this speed cannot keep δ here (NaN, not a candidate)
    family = np.where(~np.isfinite(family) | (family > smax), smax, family)
    family = np.where(family >= smin * (1 - 1e-9), family, np.nan)

    # the comparison: constant feed and speed with the same mean feed and speed (set below)
    if mode == "feed":
        # states: per speed, the family's feed and a geometric grid of lower feeds; a state is
        # allowed where its deflection (program offset −δ) stays inside [floor, δ] — floor: the
        # least deflection the stiffest station reaches at the largest feed — so the rate bounds
        # can be met near the ends without adding to the variation
        floor = float(np.min(d_max.max(axis=0)))
        grid = np.geomspace(smin, smax, 24)
        st_rpm = np.repeat(rpms, len(grid) + 1)
        st_feed = np.empty((len(st_rpm), len(x3)))
        for k in range(len(rpms)):
            st_feed[k * (len(grid) + 1)] = np.nan_to_num(family[k], nan=smin)
            st_feed[k * (len(grid) + 1) + 1 : (k + 1) * (len(grid) + 1)] = grid[:, None]
        dfl_states = np.array([m.deflection(x3, st_feed[i], st_rpm[i], -delta) for i in range(len(st_rpm))])
        allowed = (dfl_states <= delta * (1 + 1e-9)) & (dfl_states >= floor * (1 - 1e-9))
        allowed[:: len(grid) + 1] &= np.isfinite(family)
        dx = np.gradient(x3)
        v = math.pi * cfg.diameter * st_rpm  # m/min
        life = (taylor_c / v) ** (1 / taylor_m) * 60.0  # s: Taylor's tool life V T^m = C
        t = dx[None, :] / (st_feed * st_rpm[:, None] / 60.0)
        cost = np.where(allowed, t * (1 + wear_weight / life[:, None]), np.inf)
        path = _dp(cost, st_feed, st_rpm, np.diff(x3), cfg.feed_change, cfg.rpm_change, progress=progress)
        if path is None:
            raise InputError("no trajectory satisfies the feed and speed bounds and their rates of change", cfg.source)
        feed = st_feed[path, np.arange(len(x3))]
        rpm = st_rpm[path]
        # the deflection is held (nearly) constant: a constant X offset takes out its mid-range
        c, dfl = m.constant_offset(x3, feed, rpm)
        x1 = np.full_like(x3, -c)
    else:
        feed = np.full_like(x3, 0.5 * (smin + smax))
        rpm = np.full_like(x3, rpms[len(rpms) // 2])
        dfl = m.nominal_deflection(x3, feed, rpm)
        x1 = -dfl  # pre-distortion: X₁ = R − g ρ (S t_p − ζS²); the depth stays t_p
    s_bar, n_bar = float(np.mean(feed)), float(np.mean(rpm))
    # diameter errors: D − D_target = 2 (o + w), the model's own w at the program's offset
    r_err = x1 + m.deflection(x3, feed, rpm, x1)
    err, var = 2 * float(np.max(np.abs(r_err))), 2 * float(np.ptp(r_err))
    c_const, w_const = m.constant_offset(x3, s_bar, n_bar)
    err_const, var_const = 2 * float(np.max(np.abs(w_const - c_const))), 2 * float(np.ptp(w_const))

    # the constant feed giving the same diameter variation (at the mean speed): bisection
    def variation(s):
        return 2 * float(np.ptp(m.constant_offset(x3, s, n_bar)[1]))

    lo, hi = 1e-6 * smin, smax
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if variation(mid) > var:
            hi = mid
        else:
            lo = mid
    s_same = lo
    return Plan(
        mode,
        x3,
        feed,
        rpm,
        dfl,
        x1,
        s_bar,
        n_bar,
        c_const,
        err,
        var,
        err_const,
        var_const,
        _time(x3, feed, rpm),
        _time(x3, np.full_like(x3, s_bar), np.full_like(x3, n_bar)),
        s_same,
        _time(x3, np.full_like(x3, s_same), np.full_like(x3, n_bar)),
        rpms,
        family,
        delta,
        baselines(cfg, m, x3, n_bar),
        entry_revolutions(m, x3, feed, rpm, x1),
    )


def default_finish_depth(depth: float) -> float:
    """The finishing pass of the rough + finish baseline when the configuration names none, m:
    0.25 mm, at most half the depth of cut."""
    return min(0.25e-3, depth / 2)


def baselines(cfg: Config, m: Model, x3, rpm: float) -> tuple:
    """What a programmer without the model would run, on the same model, each with its best
    constant X offset, at the speed ``rpm``: (1) a constant-feed finish at the largest feed of the
    bounds (with ``rz_max``: the roughness-limited feed) over the whole depth; (2) rough + finish:
    a roughing pass of depth t_p − t_f at the largest feed (of the configuration, before the
    roughness bound) whose barrel leaves the finish at least t_f/2 everywhere (its radial range
    at most t_f), then the constant-feed finish of depth t_f, whose depth varies by what the
    roughing left (its barrel, copied at the ratio ρSg/(1 + ρSg)). Diameters, mm; times, s."""
    mm = 1e3
    s_fin = cfg.feed_bounds[1]
    s_rough = cfg.feed_max_rough or s_fin
    n = np.full_like(x3, rpm)
    c1, w1 = m.constant_offset(x3, s_fin, rpm)
    t_fin = _time(x3, np.full_like(x3, s_fin), n)
    tf = cfg.finish_depth if cfg.finish_depth is not None else default_finish_depth(cfg.depth)

    def rough(s):
        return m.constant_offset(x3, s, rpm, depth=cfg.depth - tf)

    if np.ptp(rough(s_rough)[1]) > tf:  # bisection: the largest rough feed whose barrel the finish cleans up
        lo, hi = cfg.feed_bounds[0], s_rough
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.ptp(rough(mid)[1]) <= tf else (lo, mid)
        s_rough = lo
    cr, wr = rough(s_rough)
    left = wr - cr  # the radius the roughing left over its aim
    cf, wf = m.constant_offset(x3, s_fin, rpm, depth=tf, left=left)
    t_r = _time(x3, np.full_like(x3, s_rough), n)
    return (
        {
            "name": "constant-feed finish",
            "feed": s_fin * mm,
            "spindle_rpm": rpm,
            "passes": 1,
            "diameter_variation": 2 * float(np.ptp(w1)) * mm,
            "machining_time_s": t_fin,
        },
        {
            "name": "rough + finish",
            "feed": s_rough * mm,
            "finish_feed": s_fin * mm,
            "finish_depth": tf * mm,
            "spindle_rpm": rpm,
            "passes": 2,
            "diameter_variation": 2 * float(np.ptp(wf)) * mm,
            "rough_diameter_variation": 2 * float(np.ptp(wr)) * mm,
            "machining_time_s": t_r + t_fin,
        },
    )


#: The controllers a lathe program is written for.
DIALECTS = ("linuxcnc", "fanuc", "sinumerik")


def program(
    p: Plan, cfg: Config, *, diameter_mode: bool = True, css: bool = False, tool: int = 1, dialect: str = "linuxcnc"
) -> str:
    """Lathe G-code for a plan, for ``dialect``:

    - ``linuxcnc``: G18 G21 G90 G40 G80 G54, G7 (diameter) or G8 (radius), G95 feed per revolution,
      ``T<tool> M6 G43``; G96 with a ``D`` rpm limit or G97; M2 at the end (checked by rs274);
    - ``fanuc`` (lathe, G-code system A): ``%``, ``O1000``, G18 G21 G40 G54 G99 (feed per
      revolution), ``T<tool><tool>`` (tool and its offset, e.g. T0101), ``G50 S<limit>`` (the
      spindle limit) before G96/G97, diameter programming (the Fanuc lathe default; radius
      programming is a parameter, so ``diameter_mode=False`` is refused), M30 and ``%``;
    - ``sinumerik``: G18 G71 G90 G40 G54, DIAMON (diameter) or DIAMOF (radius), G95, ``T<tool> D1``,
      ``LIMS=<limit>`` and G96/G97, M30.

    The same in every dialect: spindle on, coolant on (M8), the approach with X clear of the bar
    first (a radial move away from the work is safe from any position), then Z to the start, a rapid
    to 1 mm above the bar and a radial plunge at the smallest feed of the bounds to the X of the
    first entry revolution; one G1 per entry revolution (:attr:`Plan.entry`: each block ends
    where the next revolution starts, at that revolution's X), then one G1 per station with the
    plan's F (feed mode) or pre-distorted X (path mode), a block at the lower feed and the
    higher speed of its two stations, so the deflection stays at or under the target along it. Speed:
    G97 with an S word (rpm) where it changes, or, with ``css``, G96 with the limit (the largest
    speed of the bounds) and an S word (m/min) per block computed at the tool's own diameter at the
    block's end, so the controller turns at the planned rpm. Retract: X clear, then Z back to the
    start (away from the chuck), coolant and spindle off. Z0 is the tailstock centre, the chuck at
    Z−L."""
    if dialect not in DIALECTS:
        raise ValueError(f"dialect must be one of {', '.join(DIALECTS)}, got {dialect!r}")
    if dialect == "fanuc" and not diameter_mode:
        raise InputError(
            "a Fanuc lathe programs X as a diameter (radius programming is a machine parameter, not a "
            "G code): drop --radius-mode for --dialect fanuc"
        )
    mm = 1e3
    r_final = (cfg.diameter / 2 - cfg.depth) * mm
    r_clear = cfg.diameter / 2 * mm + 2
    xw = (lambda r: 2 * r) if diameter_mode else (lambda r: r)
    limit = max(cfg.rpm_bounds[1], float(np.max(p.rpm)))
    what = (
        f"ncadapt turning plan: {p.mode} mode, {'diameter' if diameter_mode else 'radius'} mode"
        f"{', constant surface speed' if css else ''}"
    )
    if dialect == "linuxcnc":
        out = [f"({what})", "G18 G21 G90 G40 G80 G54", "G7" if diameter_mode else "G8", "G95", f"T{tool} M6 G43"]
    elif dialect == "fanuc":
        out = ["%", f"O1000 ({what.upper()})", "G18 G21 G40 G54 G99", f"T{tool:02d}{tool:02d}", f"G50 S{limit:.0f}"]
    else:
        out = [
            f"; {what}",
            "G18 G71 G90 G40 G54",
            "DIAMON" if diameter_mode else "DIAMOF",
            "G95",
            f"T{tool} D1",
            f"LIMS={limit:.0f}",
        ]

    dp = 3 if dialect == "fanuc" else 4  # Fanuc IS-B: least input increment 0.001 mm

    # the cutting blocks (x3 at the end, m; program offset there, m; feed, m/rev; rpm): the entry
    # revolutions, one block each, then one block per station, at the lower feed and the higher
    # speed of its two stations
    blocks = []
    e = p.entry
    x0 = e.offset[0] if e is not None else p.x1_offset[0]
    after = p.x3[0]
    if e is not None:  # block k ends where revolution k + 1 starts, at its X; the last at the stations' X
        ends = e.x3 + e.feed
        offs = np.append(e.offset[1:], np.interp(ends[-1], p.x3, p.x1_offset))
        blocks += [(a, o, f, n) for a, o, f, n in zip(ends, offs, e.feed, e.rpm) if a < p.x3[-1]]
        after = blocks[-1][0] if blocks else after
    for j in range(1, len(p.x3)):
        if p.x3[j] > after + 1e-9:
            blocks.append((p.x3[j], p.x1_offset[j], min(p.feed[j - 1], p.feed[j]), max(p.rpm[j - 1], p.rpm[j])))

    def surface_speed(o, n):  # m/min at the tool's diameter with program offset o
        return math.pi * 2 * (r_final + o * mm) * n / 1000

    n0 = p.rpm[0]
    m3 = "M03" if dialect == "fanuc" else "M3"
    if css:
        last_s = round(surface_speed(x0, n0), 2)
        out.append(f"G96 D{limit:.0f} S{last_s:.2f} M3" if dialect == "linuxcnc" else f"G96 S{last_s:.2f} {m3}")
    else:
        last_s = round(n0)
        out.append(f"G97 S{n0:.0f} {m3}")
    out += [
        "M08" if dialect == "fanuc" else "M8",
        f"G0 X{xw(r_clear):.{dp}f}",
        f"G0 Z{-p.x3[0] * mm:.{dp}f}",
        f"G0 X{xw(r_clear - 1):.{dp}f}",
    ]
    out.append(f"G1 X{xw(r_final + x0 * mm):.{dp}f} F{cfg.feed_bounds[0] * mm:.4f}")
    for a, o, f, n in blocks:
        words = [f"G1 X{xw(r_final + o * mm):.{dp}f} Z{-a * mm:.{dp}f} F{f * mm:.4f}"]
        sv = round(surface_speed(o, n), 2) if css else round(n)
        if sv != last_s:
            words.append(f"S{sv:.2f}" if css else f"S{sv:.0f}")
            last_s = sv
        out.append(" ".join(words))
    out += [f"G0 X{xw(r_clear):.{dp}f}", f"G0 Z{-p.x3[0] * mm:.{dp}f}"]
    if dialect == "linuxcnc":
        out += ["M9", "M5", "M2"]
    elif dialect == "fanuc":
        out += ["M09", "M05", "M30", "%"]
    else:
        out += ["M9", "M5", "M30"]
    return "\n".join(out) + "\n"
