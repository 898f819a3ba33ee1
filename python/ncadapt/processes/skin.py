"""Mirror milling of thin skins: real-time wall-thickness compensation (Wu, Zhang, Yang, Cao,
Zhong, "Real-time compensation of machining error in aircraft-skin mirror milling based on the
two-point secant method").

The thin wall deflects under the axial cutting force, so the real depth is a_r = a_p − f(a_p)
for a programmed depth a_p. With target depth a_g = T_s − T_g, the error measured by the
ultrasonic gauge is δ = T − T_g = a_g − a_r. A compensator turns the latest δ_i into the next
programmed depth a_p,i+1 (the W1 axis moves the tool by a_p,i+1 − a_g along the skin normal):

- :class:`MirrorCompensator` (error mirror): a_p,i+1 = a_p,i + δ_i, a_p,1 = a_g. Linear
  convergence: the error shrinks by f'(a_p) per step.
- :class:`SecantCompensator` (two-point secant on δ(a_p) = 0):
  a_p,i+1 = a_p,i − δ_i (a_p,i − a_p,i−1)/(δ_i − δ_i−1), the second point from the mirror step.
  Order 1.618. Made safe: when |δ_i − δ_i−1| is at noise level, or the slope
  s = (δ_i − δ_i−1)/(a_p,i − a_p,i−1) has the wrong sign (δ falls as a_p grows, so s < 0) or a
  magnitude outside [s_min, s_max], the step falls back to the mirror step; every step is
  bounded to ±``max_step``; fallbacks are counted.
- :class:`KalmanCompensator` (ours, the default for a fresh-reading gauge): the deflection is
  affine in the depth near the depth in force, f(a_p) = c + s a_p — an offset c (on a wall
  pressed by constant-force supports, their push; 0 in the paper's force model) and a slope s,
  both changing along the path. The depth that cuts to the target, the root
  a* = (a_g + c)/(1 − s), carries both; one reading at a_p gives it by a Newton step,
  z = a_p + δ/(1 − ŝ). A Kalman filter tracks a* and its rate per reading (constant-velocity
  model: x = [a*, ȧ*], F = [[1, 1], [0, 1]], white-acceleration process noise
  q·[[1/4, 1/2], [1/2, 1]], q = 3·10⁻⁵ mm² — a rate that may change by about the gauge's noise
  per reading —, measurement noise (σ/(1 − ŝ))²) and commands its prediction one reading ahead —
  where the command will land (the dead time and the spot's lag are a spatial lag). The slope ŝ
  is the reading's chord κ = f/a_p = 1 − (a_g − δ)/a_p, bounded to [0, 0.9] (a clamped κ is a
  fallback): the readings of a closed loop cannot separate s from c (they lie along
  f = a_p − a_g, whatever the wall), but the slope only scales the correction δ/(1 − ŝ), which
  vanishes as the loop tracks — the root, and the command, are right at δ = 0 whatever ŝ is.
  In the paper's model (c = 0) ŝ = κ = s and one reading gives the root exactly.

All three share the interface the loop runner uses: ``step(delta) -> a_p,i+1``, ``w1_offset``,
``fallbacks`` (steps that fell back, each counted once), ``reset()``.

:class:`Interlocks` stands between the gauge and the compensator, in replay and live alike (the loop
runner, :func:`ncadapt.loop.run`, calls it on every reading):

- the paper's gauge filter ("限幅為10 mm允差為0.3 mm": limit 10 mm, tolerance 0.3 mm), read as
  a reading above the limit of 10 mm is no thickness (lost coupling, the jet off the skin), and one
  more than the tolerance of 0.3 mm from the target T_g is no thickness of this pass — the
  uncompensated error of the paper's experiment is at most 0.24 mm, and a reading farther away
  would make the compensator step by more than the deflection it exists to cancel;
- a reading that is NaN, infinite or ≤ 0, and a stuck gauge (``stuck`` identical readings in a row:
  the ``stuck``-th and every further one) are rejected;
- the W1 command is bounded to ±``w1_max`` (default min(2 a_g, T_g/2); the programmed depth
  a_g + W1 to at least a_g/2) and its change per reading to ±``w1_step_max`` (default 0.25 mm); the compensator's own depth is set to the bounded
  command, so its next step starts from what the machine does;
- on a rejected reading the last command is held and the rejection counted; after ``max_faults``
  rejected readings in a row the loop stops with W1 held (:class:`LoopStopped`).
"""

from __future__ import annotations

import math

__all__ = [
    "MirrorCompensator",
    "SecantCompensator",
    "KalmanCompensator",
    "COMPENSATORS",
    "GAUGES",
    "default_method",
    "make",
    "Interlocks",
    "LoopStopped",
    "GAUGE_LIMIT",
    "GAUGE_TOLERANCE",
    "thickness_field",
]

# physically possible slopes dδ/da_p: δ = a_g − a_p + f(a_p) with 0 ≤ f' ≤ 0.9 (the Kalman filter's
# κ_max) ⇒ −1 ≤ s ≤ −0.1; a shallower secant slope would step more than 10 × the mirror step
S_MIN = -1.0
S_MAX = -0.1


class _Base:
    name = "base"
    #: the constructor takes the gauge's noise σ (``noise=``)
    uses_noise = False

    def __init__(self, target_depth: float, *, max_step: float = 0.5):
        if not (math.isfinite(target_depth) and target_depth > 0):
            raise ValueError(f"target depth must be > 0 mm, got {target_depth}")
        if not (math.isfinite(max_step) and max_step > 0):
            raise ValueError(f"max_step must be > 0 mm, got {max_step}")
        self.target_depth = float(target_depth)
        self.max_step = float(max_step)
        self.reset()

    def reset(self) -> None:
        self.depth = self.target_depth  # a_p,1 = a_g
        self.fallbacks = 0
        self.steps = 0
        self._fell_back = False

    @property
    def w1_offset(self) -> float:
        """The W1 axis command relative to the uncompensated program: a_p − a_g, mm."""
        return self.depth - self.target_depth

    def _bounded(self, new: float) -> float:
        lo, hi = self.depth - self.max_step, self.depth + self.max_step
        if not (lo <= new <= hi):  # NaN included: then the depth in force is kept
            self._fell_back = True
            new = min(max(new, lo), hi) if new == new else self.depth
        return new

    def step(self, delta: float) -> float:
        """The next programmed depth a_p after a reading's error δ = T − T_g (mm). A step that
        falls back (a rejected secant slope, a clamped κ̂, a step over ``max_step``) is counted
        once in ``fallbacks``, however many of the rules it met."""
        self.steps += 1
        self._fell_back = False
        self.depth = self._bounded(self._next(float(delta)))
        if self._fell_back:
            self.fallbacks += 1
        return self.depth

    def _next(self, delta: float) -> float:  # pragma: no cover - abstract
        raise NotImplementedError


class MirrorCompensator(_Base):
    """a_p,i+1 = a_p,i + δ_i."""

    name = "mirror"

    def _next(self, delta: float) -> float:
        return self.depth + delta


class SecantCompensator(_Base):
    """The two-point secant with the safety rules of the module's docstring."""

    name = "secant"
    uses_noise = True

    def __init__(
        self,
        target_depth: float,
        *,
        noise: float = 0.005,
        max_step: float = 0.5,
        s_min: float = S_MIN,
        s_max: float = S_MAX,
    ):
        self.noise = float(noise)
        self.s_min, self.s_max = s_min, s_max
        super().__init__(target_depth, max_step=max_step)

    def reset(self) -> None:
        super().reset()
        self._prev: tuple[float, float] | None = None  # (a_p, δ) of the previous step

    def _next(self, delta: float) -> float:
        a = self.depth
        new = None
        if self._prev is not None:
            a0, d0 = self._prev
            dd, da = delta - d0, a - a0
            if abs(dd) > 3 * self.noise and abs(da) > 1e-12:
                s = dd / da
                if self.s_min <= s <= self.s_max:
                    new = a - delta / s
            if new is None:
                self._fell_back = True
        if new is None:
            new = a + delta  # the mirror step (also the first step, which gives the second point)
        self._prev = (a, delta)
        return new


class KalmanCompensator(_Base):
    """Ours: a Kalman filter on the root — the depth that cuts to T_g — and its rate per reading,
    predicting one reading ahead (see the module's docstring)."""

    name = "kalman"
    uses_noise = True

    def __init__(
        self,
        target_depth: float,
        *,
        noise: float = 0.005,
        q: float = 3e-5,
        max_step: float = 0.5,
        kappa_max: float = 0.9,
    ):
        self.noise, self.q, self.kappa_max = max(float(noise), 1e-6), float(q), kappa_max
        super().__init__(target_depth, max_step=max_step)

    def reset(self) -> None:
        super().reset()
        self._x: tuple[float, float] | None = None  # [a*, ȧ*]
        self._p: tuple[float, float, float] | None = None

    def _next(self, delta: float) -> float:
        # the 2 × 2 filter written out in scalars: a step costs about a microsecond
        a = self.depth
        kappa = 1.0 - (self.target_depth - delta) / a  # the chord f/a_p of this reading
        if not 0.0 <= kappa <= self.kappa_max:
            self._fell_back = True
            kappa = min(max(kappa, 0.0), self.kappa_max) if kappa == kappa else 0.0
        z = a + delta / (1.0 - kappa)  # the root by one Newton step
        r = (self.noise / (1.0 - kappa)) ** 2
        if self._x is None:
            self._x = (z, 0.0)
            self._p = (r, 0.0, 0.01)  # P00, P01, P11
        else:
            assert self._p is not None  # set with _x
            k0, k1 = self._x
            p00, p01, p11 = self._p
            q = self.q
            # predict: x ← F x, P ← F P Fᵀ + Q
            x0, x1 = k0 + k1, k1
            p00, p01, p11 = p00 + 2 * p01 + p11 + 0.25 * q, p01 + p11 + 0.5 * q, p11 + q
            # update with z = a* + noise
            s = p00 + r
            g0, g1 = p00 / s, p01 / s
            e = z - x0
            self._x = (x0 + g0 * e, x1 + g1 * e)
            self._p = ((1 - g0) * p00, (1 - g0) * p01, p11 - g1 * p01)
        return self._x[0] + self._x[1]  # one reading ahead


COMPENSATORS: dict[str, type[_Base]] = {
    "mirror": MirrorCompensator,
    "secant": SecantCompensator,
    "kalman": KalmanCompensator,
}

#: the kinds of gauge a loop may have: ``fresh`` — each reading reflects the latest W1 command
#: (the paper's: the controller reads only once the spot lies on floor cut after the command
#: landed); ``fixed-rate`` — readings at a fixed rate (20–25 Hz), most of them cut before the
#: latest command landed
GAUGES = ("fresh", "fixed-rate")


def default_method(gauge: str = "fresh") -> str:
    """The default compensator for a kind of gauge, with its reason.

    ``fresh``: ours (``kalman``) — one fresh reading gives the root, and the filter's prediction one
    reading ahead beats the mirror on the mean over 20 seeds on every testbed variant with such a
    gauge (the paper's zig-zag, a spiral-out path, 6000 mm/min with 60 ms, a first-order W1 servo),
    and on 17 to 20 of the 20 seeds each (docs/skin.md).
    ``fixed-rate``: the ``mirror`` — a reading that does not reflect the latest command cannot
    identify κ (the filter would divide by a depth the reading was not cut at, and diverges: 212 µm
    on the testbed), while the mirror's integral action needs only the error and uses four times
    as many readings (11 µm on the testbed, better than any method with fresh readings)."""
    if gauge not in GAUGES:
        raise ValueError(f"gauge must be one of {', '.join(GAUGES)}, got {gauge!r}")
    return "kalman" if gauge == "fresh" else "mirror"


def make(method: str, target_depth: float, *, noise: float | None = None, **kw):
    """A compensator by name (``mirror``, ``secant``, ``kalman``); ``noise``, the gauge's σ in mm,
    goes to those that use it (the mirror does not)."""
    try:
        cls = COMPENSATORS[method]
    except KeyError:
        raise ValueError(f"method must be one of {sorted(COMPENSATORS)}, got {method!r}") from None
    if noise is not None and cls.uses_noise:
        kw["noise"] = noise
    return cls(target_depth, **kw)


# ------------------------------------------------------------------------------ interlocks
#: the paper's gauge filter: readings above 10 mm are no thickness, and readings more than 0.3 mm
#: from the target are refused (Wu et al., section on the ultrasonic gauge)
GAUGE_LIMIT = 10.0
GAUGE_TOLERANCE = 0.3
#: identical readings in a row that make a stuck gauge
STUCK = 5
#: rejected readings in a row that stop the loop
MAX_FAULTS = 10
#: default bound of the change of W1 per reading, mm: above the largest step the testbed's loop
#: takes (0.24 mm: the noise-free secant; Kalman 0.15 mm, mirror 0.05 mm) and below the gauge's
#: tolerance (0.3 mm), the largest error a mirror step may answer
W1_STEP_MAX = 0.25


def default_w1_max(target: float, depth: float) -> float:
    """The default bound of |W1|, mm: min(2 a_g, T_g/2). 2 a_g admits a compliance ratio κ up to
    2/3 (W1 = a_g κ/(1 − κ)); T_g/2 leaves at least half the target thickness even if the wall stopped
    deflecting at once (a support, a rib)."""
    return min(2.0 * float(depth), 0.5 * float(target))


class LoopStopped(Exception):
    """Persistent gauge faults: the loop stopped with W1 held at ``w1`` (mm) after ``faults``
    rejected readings in a row, the last for ``reason``; ``index`` is the reading's 0-based index."""

    def __init__(self, faults: int, reason: str, w1: float, index: int):
        self.faults, self.reason, self.w1, self.index = faults, reason, w1, index
        super().__init__(
            f"loop stopped after {faults} rejected readings in a row (last: {reason}); W1 held at {w1:+.4f} mm"
        )


class Interlocks:
    """The guard of the live loop (see the module's docstring): which readings the compensator may
    see, and the bounds of the W1 command it may give.

    Parameters
    ----------
    target : float, mm
        T_g, the target thickness.
    depth : float, mm
        a_g, the finishing pass's planned depth (the allowance it removes).
    w1_max : float, mm
        Bound of |W1|; default :func:`default_w1_max`, min(2 a_g, T_g/2). Must be below T_g: a W1
        of T_g would cut through the wall where it stopped deflecting.
    w1_step_max : float, mm
        Bound of the change of W1 per reading; default ``W1_STEP_MAX`` (0.25 mm).
    max_faults : int
        Rejected readings in a row that stop the loop.
    """

    def __init__(
        self,
        target: float,
        depth: float,
        *,
        w1_max: float | None = None,
        w1_step_max: float | None = None,
        max_faults: int = MAX_FAULTS,
        limit: float = GAUGE_LIMIT,
        tolerance: float = GAUGE_TOLERANCE,
        stuck: int = STUCK,
    ):
        for name, v in (("target", target), ("depth", depth)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0 mm, got {v}")
        w1_max = default_w1_max(target, depth) if w1_max is None else float(w1_max)
        if not (math.isfinite(w1_max) and 0 < w1_max < target):
            raise ValueError(
                f"w1_max must be > 0 and below the target thickness {target:g} mm (a W1 of the "
                f"target would cut through the wall), got {w1_max:g}"
            )
        w1_step_max = W1_STEP_MAX if w1_step_max is None else float(w1_step_max)
        if not (math.isfinite(w1_step_max) and w1_step_max > 0):
            raise ValueError(f"w1_step_max must be > 0 mm, got {w1_step_max:g}")
        if max_faults < 1 or stuck < 2:
            raise ValueError("max_faults must be ≥ 1 and stuck ≥ 2")
        self.target, self.depth = float(target), float(depth)
        self.w1_max, self.w1_step_max = w1_max, w1_step_max
        self.w1_min = -min(w1_max, 0.5 * self.depth)
        self.max_faults, self.limit, self.tolerance, self.stuck = (
            int(max_faults),
            float(limit),
            float(tolerance),
            int(stuck),
        )
        self.reset()

    def reset(self) -> None:
        self.w1 = 0.0  # the command in force
        self.rejected = 0
        self.faults = 0  # rejected readings in a row
        self.clamped = 0  # commands the bounds changed
        self.max_abs_w1 = 0.0
        self.reasons: dict[str, int] = {}
        self._last: float | None = None
        self._same = 0

    def check(self, reading) -> str | None:
        """Why ``reading`` (mm, or None for a reading the gauge itself rejected) must not reach the
        compensator, or None when it may."""
        reason = None
        if reading is None:
            reason = "rejected by the gauge"
        else:
            t = float(reading)
            if t == self._last:
                self._same += 1
            else:
                self._last, self._same = t, 1
            if not math.isfinite(t):
                reason = "not a number"
            elif t <= 0:
                reason = "not > 0"
            elif t > self.limit:
                reason = f"above the gauge's limit of {self.limit:g} mm"
            elif abs(t - self.target) > self.tolerance:
                reason = f"more than {self.tolerance:g} mm from the target {self.target:g} mm"
            elif self._same >= self.stuck:
                reason = f"stuck gauge ({self._same} identical readings in a row)"
        return reason

    def reject(self, reason: str, index: int = 0) -> None:
        """Count a rejected reading (the command in force is held); stop after ``max_faults`` in a row."""
        self.rejected += 1
        self.faults += 1
        self.reasons[reason.split(" (")[0]] = self.reasons.get(reason.split(" (")[0], 0) + 1
        if self.faults >= self.max_faults:
            raise LoopStopped(self.faults, reason, self.w1, index)

    def bound(self, compensator) -> float:
        """Bound the compensator's new command (W1 and its step), set its depth to the bounded
        command, and return W1 (mm)."""
        self.faults = 0
        w = compensator.w1_offset
        lo = max(self.w1_min, self.w1 - self.w1_step_max)
        hi = min(self.w1_max, self.w1 + self.w1_step_max)
        if not (lo <= w <= hi):
            self.clamped += 1
            w = min(max(w, lo), hi) if w == w else self.w1
            compensator.depth = compensator.target_depth + w
        self.w1 = w
        self.max_abs_w1 = max(self.max_abs_w1, abs(w))
        return w

    def as_dict(self) -> dict:
        return {
            "rejected": self.rejected,
            "max_abs_w1": self.max_abs_w1,
            "clamped": self.clamped,
            "rejected_by_reason": dict(self.reasons),
            "w1_max": self.w1_max,
            "w1_step_max": self.w1_step_max,
            "max_faults": self.max_faults,
            "gauge_limit": self.limit,
            "gauge_tolerance": self.tolerance,
            "stuck": self.stuck,
        }


# ------------------------------------------------------------------------------ offline mode
def thickness_field(
    path, target: float, *, allowance: float = 0.0, into: str = "-z", method: str = "linear", outside: str = "error"
):
    """The correction of a finishing program from a thickness map (offline mode).

    ``path`` is a CSV with columns ``x,y,thickness`` (mm), measured after the previous pass: on a
    rectangular grid (interpolated bilinearly, or bicubically with ``method="cubic"``) or at
    scattered points (a thin-plate spline). The tool must cut deeper wherever more material is
    left than planned: the excess is e = thickness − target − allowance (``allowance`` is what
    the finishing pass was planned to remove; 0 when the map was measured after a finishing
    pass, which makes this the error-mirror step applied offline), and the displacement along the
    tool axis is e towards the material: dz = −e for ``into="-z"`` (the tool cuts downwards, the
    default), +e for ``into="+z"``.

    What this leaves: the finishing pass's own deflection f under the material it removes (on the
    testbed 0.09–0.17 mm at the pocket centre for an allowance of 0.2 mm). A second round removes
    most of it: measure the finished wall and correct the *corrected* program again from that map
    with ``allowance=0``; the re-cut engages the residual r plus the deflection f₁ the first pass had
    (r ≈ f₁), so it leaves f(r + f₁) − f₁, about (2κ − 1) r with f = κ a — less than r for any
    compliance ratio 0 < κ < 1 (``tests/test_skin.py`` shows it on the testbed).
    """
    import numpy as np

    from .. import fields

    if into not in ("-z", "+z"):
        raise ValueError(f'into must be "-z" or "+z", got {into!r}')
    for name, v in (("target", target), ("allowance", allowance)):
        if not math.isfinite(v):
            raise ValueError(f"{name} must be a finite number of mm, got {v}")
    c, lines = fields.read_columns(path, ("x", "y", "thickness"))
    bad = np.flatnonzero(~(c["thickness"] > 0))
    if len(bad):
        from ..errors import InputError

        raise InputError(
            f"column thickness: a thickness must be > 0 mm, found {c['thickness'][bad[0]]:g}",
            str(path),
            int(lines[bad[0]]),
        )
    excess = c["thickness"] - float(target) - float(allowance)
    sign = -1.0 if into == "-z" else 1.0
    return fields.from_values(
        c["x"], c["y"], sign * excess, method=method, outside=outside, source=str(path), linenos=lines
    ), excess
