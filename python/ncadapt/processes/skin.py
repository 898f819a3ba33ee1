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
- :class:`KalmanCompensator` (ours, the default of ``ncadapt skin simulate``): the paper's model
  has the force, and so the deflection, proportional to the depth, f(a_p) = κ a_p with κ the
  local compliance ratio, so one reading identifies κ: z = 1 − (a_g − δ)/a_p. A Kalman filter
  tracks κ and its rate per reading (constant-velocity model: x = [κ, κ̇], F = [[1, 1], [0, 1]],
  white-acceleration process noise q·[[1/4, 1/2], [1/2, 1]], measurement noise (σ/a_p)²); the next
  depth is a_p = a_g / (1 − κ̂) with κ̂ predicted one reading ahead — where the command will land
  (the dead time and the spot's lag are a spatial lag) — bounded to 0 ≤ κ̂ ≤ 0.9 and by
  ``max_step``. A prediction outside the bounds is clamped and counted as a fallback.

All three share the interface the loop runner uses: ``step(delta) -> a_p,i+1``, ``w1_offset``,
``fallbacks``, ``reset()``.
"""

from __future__ import annotations

import math

__all__ = ["MirrorCompensator", "SecantCompensator", "KalmanCompensator", "COMPENSATORS", "make", "thickness_field"]

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
        self.target_depth = float(target_depth)
        self.max_step = float(max_step)
        self.reset()

    def reset(self) -> None:
        self.depth = self.target_depth  # a_p,1 = a_g
        self.fallbacks = 0
        self.steps = 0

    @property
    def w1_offset(self) -> float:
        """The W1 axis command relative to the uncompensated program: a_p − a_g, mm."""
        return self.depth - self.target_depth

    def _bounded(self, new: float) -> float:
        lo, hi = self.depth - self.max_step, self.depth + self.max_step
        if new < lo or new > hi:
            self.fallbacks += 1
            new = min(max(new, lo), hi)
        return new

    def step(self, delta: float) -> float:  # pragma: no cover - abstract
        raise NotImplementedError


class MirrorCompensator(_Base):
    """a_p,i+1 = a_p,i + δ_i."""

    name = "mirror"

    def step(self, delta: float) -> float:
        self.steps += 1
        self.depth = self._bounded(self.depth + float(delta))
        return self.depth


class SecantCompensator(_Base):
    """The two-point secant with the safety rules of the module's docstring."""

    name = "secant"
    uses_noise = True

    def __init__(self, target_depth: float, *, noise: float = 0.005, max_step: float = 0.5,
                 s_min: float = S_MIN, s_max: float = S_MAX):
        self.noise = float(noise)
        self.s_min, self.s_max = s_min, s_max
        super().__init__(target_depth, max_step=max_step)

    def reset(self) -> None:
        super().reset()
        self._prev = None  # (a_p, δ) of the previous step

    def step(self, delta: float) -> float:
        self.steps += 1
        delta = float(delta)
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
                self.fallbacks += 1
        if new is None:
            new = a + delta  # the mirror step (also the first step, which gives the second point)
        self._prev = (a, delta)
        self.depth = self._bounded(new)
        return self.depth


class KalmanCompensator(_Base):
    """Ours: a Kalman filter on the local compliance ratio κ, predicting one reading ahead."""

    name = "kalman"
    uses_noise = True

    def __init__(self, target_depth: float, *, noise: float = 0.005, q: float = 1e-4, max_step: float = 0.5,
                 kappa_max: float = 0.9):
        self.noise, self.q, self.kappa_max = max(float(noise), 1e-6), float(q), kappa_max
        super().__init__(target_depth, max_step=max_step)

    def reset(self) -> None:
        super().reset()
        self._x = None  # [κ, κ̇]
        self._p = None

    def step(self, delta: float) -> float:
        # the 2 × 2 filter written out in scalars: a step costs about a microsecond
        self.steps += 1
        a = self.depth
        z = 1.0 - (self.target_depth - float(delta)) / a
        r = (self.noise / a) ** 2
        if self._x is None:
            self._x = (z, 0.0)
            self._p = (r, 0.0, 0.01)  # P00, P01, P11
        else:
            k0, k1 = self._x
            p00, p01, p11 = self._p
            q = self.q
            # predict: x ← F x, P ← F P Fᵀ + Q
            x0, x1 = k0 + k1, k1
            p00, p01, p11 = p00 + 2 * p01 + p11 + 0.25 * q, p01 + p11 + 0.5 * q, p11 + q
            # update with z = κ + noise
            s = p00 + r
            g0, g1 = p00 / s, p01 / s
            e = z - x0
            self._x = (x0 + g0 * e, x1 + g1 * e)
            self._p = ((1 - g0) * p00, (1 - g0) * p01, p11 - g1 * p01)
        kappa = self._x[0] + self._x[1]  # one reading ahead
        if not 0.0 <= kappa <= self.kappa_max:
            self.fallbacks += 1
            kappa = min(max(kappa, 0.0), self.kappa_max)
        self.depth = self._bounded(self.target_depth / (1.0 - kappa))
        return self.depth


COMPENSATORS = {"mirror": MirrorCompensator, "secant": SecantCompensator, "kalman": KalmanCompensator}


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


# ------------------------------------------------------------------------------ offline mode
def thickness_field(path, target: float, *, allowance: float = 0.0, into: str = "-z", method: str = "linear",
                    outside: str = "error"):
    """The correction of a finishing program from a thickness map (offline mode).

    ``path`` is a CSV with columns ``x,y,thickness`` (mm), measured after the previous pass: on a
    rectangular grid (interpolated bilinearly, or bicubically with ``method="cubic"``) or at
    scattered points (a thin-plate spline). The tool must cut deeper wherever more material is
    left than planned: the excess is e = thickness − target − allowance (``allowance`` is what
    the finishing pass was planned to remove; 0 when the map was measured after a finishing
    pass, which makes this the error-mirror step applied offline), and the displacement along the
    tool axis is e towards the material: dz = −e for ``into="-z"`` (the tool cuts downwards, the
    default), +e for ``into="+z"``.
    """
    from .. import fields

    if into not in ("-z", "+z"):
        raise ValueError(f'into must be "-z" or "+z", got {into!r}')
    c, lines = fields.read_columns(path, ("x", "y", "thickness"))
    excess = c["thickness"] - float(target) - float(allowance)
    sign = -1.0 if into == "-z" else 1.0
    return fields.from_values(c["x"], c["y"], sign * excess, method=method, outside=outside, source=str(path),
                              linenos=lines), excess
