"""Virtual 3-axis ball-end finishing of a freeform part, with a systematic machine error.

The testbed plays the machine for the freeform method:

1. **Part.** A height field z = f(x, y) (:func:`demo_part`), a bicubic B-spline surface.
2. **Program.** A raster finishing program for a ball-end tool of radius R, computed by "drop
   cutter": the tool tip height at (x, y) is max over surface points q within R of
   (q_z + √(R² − |q_xy − (x, y)|²)) − R, a grey dilation of the surface grid by the ball
   (:func:`finishing_program`).
3. **Machining.** The program's toolpath (read by the NC engine, pieces ≤ ``step`` mm) is cut into a
   z-map: every cell keeps min over tool positions c of c_z + R − √(R² − d²), d the distance from
   the cell to c in (x, y) (the ball's lower surface). The machine does not go where it is told: it
   adds a systematic error E(x, y) along the surface normal at every tool position, c' = c + E n,
   a function of the surface that repeats on every part cut (:class:`ErrorModel`); or the machine's
   own errors (:class:`MachineError`); or a tool that yields in proportion to the depth it really
   cuts (:class:`DepthDeflection`), so that a corrected program, cutting deeper, is cut with a
   different error — what rounds of compensation must converge on.
4. **Measurement.** A nominal point p with outward normal n is measured where the line p + t n meets
   the z-map (bilinear), plus normal noise of ``noise`` mm along n, seeded.

Error models (the freeform paper's (4)–(9)): uniform dF = A; polynomial of degree n in u, v
normalised to [−1, 1]; curvature dF = A_m (i_H − 0.5), i_H = (H − H_min) / (H_max − H_min) with H
the mean curvature. Random parts: uniform or normal. Every function takes a seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from ..surfaces import Surface


def demo_part(nx: int = 61, ny: int = 41) -> Surface:
    """The demo's freeform test part: 80 × 60 mm, a dome on a wave, 0–9 mm high."""

    def f(x, y):
        dome = 6.0 * np.exp(-((x - 44.0) ** 2) / 500.0 - ((y - 28.0) ** 2) / 300.0)
        wave = 1.2 * np.sin(x / 9.0) * np.cos(y / 11.0)
        return 2.0 + dome + wave + 0.02 * x

    return Surface.height(f, (0.0, 80.0), (0.0, 60.0), nx, ny)


# --------------------------------------------------------------------------------------- errors
@dataclass(frozen=True)
class ErrorModel:
    """A systematic error dF(x, y) in mm along the outward normal (> 0: material left over).

    ``terms`` is a list of (kind, parameters): ``("uniform", A)``, ``("polynomial", coeffs)`` with
    ``coeffs[(i, j)]`` the coefficient of u_n^i v_n^j, ``("curvature", A_m)``.
    """

    surface: Surface
    terms: tuple = field(default_factory=tuple)

    def __call__(self, x, y) -> np.ndarray:
        x = np.asarray(x, float)
        y = np.asarray(y, float)
        s = self.surface
        out = np.zeros(np.broadcast(x, y).shape)
        for kind, par in self.terms:
            if kind == "uniform":
                out = out + float(par)
            elif kind == "polynomial":
                un = 2 * (x - s.u[0]) / (s.u[-1] - s.u[0]) - 1
                vn = 2 * (y - s.v[0]) / (s.v[-1] - s.v[0]) - 1
                for (i, j), c in dict(par).items():
                    out = out + c * un**i * vn**j
            elif kind == "curvature":
                out = out + float(par) * (self._ih(x, y) - 0.5)
            else:
                raise ValueError(f"unknown error term {kind!r}")
        return out

    def _ih(self, x, y):
        s = self.surface
        uu, vv = np.meshgrid(np.linspace(s.u[0], s.u[-1], 161), np.linspace(s.v[0], s.v[-1], 121), indexing="ij")
        h = s.mean_curvature(uu, vv)
        lo, hi = float(h.min()), float(h.max())
        return (s.mean_curvature(x, y) - lo) / (hi - lo)


@dataclass(frozen=True)
class MachineError:
    """A machine's own errors, in its axes — not the corrector's model of an error along the part's
    normal. Geometric (ISO 230-1 terms, values of a worn mid-size mill):

    - a positioning (scale) error of X, δx = ε_x (x − x_c): ``scale_x`` mm/mm (150 µm/m);
    - a straightness error of X in Z, a sag δz = s ((x − x_c) / (L/2))²: ``sag`` mm at the ends;
    - a roll of the table about X, δz = ρ (y − y_c): ``roll`` rad (0.3 mrad: 18 µm over 60 mm);

    and a tool deflection away from the surface along its normal, δ = C (1 + R H), the ball's
    engagement growing in concave regions (H the mean curvature, > 0 concave seen from the tool):
    ``deflection`` C mm. x_c, y_c are the part's centre, L its length in x. On a sloped surface the
    X error moves the surface by δx n_x along its normal, and the Z terms by δz n_z.
    """

    surface: Surface
    scale_x: float = 150e-6
    sag: float = 0.012
    roll: float = 0.3e-3
    deflection: float = 0.010
    tool_radius: float = 4.0

    def displacement(self, c: np.ndarray) -> np.ndarray:
        """Where a tool position ``c`` (m, 3) really goes, minus where it was told to go."""
        s = self.surface
        xc, yc, half = (s.u[0] + s.u[-1]) / 2, (s.v[0] + s.v[-1]) / 2, (s.u[-1] - s.u[0]) / 2
        x = np.clip(c[:, 0], s.u[0], s.u[-1])
        y = np.clip(c[:, 1], s.v[0], s.v[-1])
        d = np.zeros_like(c)
        d[:, 0] = self.scale_x * (c[:, 0] - xc)
        d[:, 2] = self.sag * ((c[:, 0] - xc) / half) ** 2 + self.roll * (c[:, 1] - yc)
        d += (self.deflection * (1 + self.tool_radius * s.mean_curvature(x, y)))[:, None] * s.normal(x, y)
        return d


@dataclass(frozen=True)
class DepthDeflection:
    """A finishing cut whose tool yields in proportion to the depth it really cuts.

    The semi-finishing pass left stock a(x, y) = ``stock`` + ``stock_taper`` (x − x_c)/(L/2) mm over the
    nominal along its normal (a pass that left a taper). A tool position c (the ball's tip) lies
    T(c_x, c_y) − c_z below the tip that just touches the nominal surface at its (x, y) (T: the drop-cutter
    tip heights of :func:`tip_heights`), so along the normal n it cuts the depth

        d = a + (T(c_x, c_y) − c_z) n_z      (n, n_z at the tool's (x, y); d ≥ 0)

    and the cutting force, which grows with d, pushes the tool (and the part) away from the surface by

        δ = κ(x, y) d,    κ = ``compliance`` (1 + ``compliance_growth`` ((y − y_c)/(W/2))²)

    along n (the part clamped along its middle in y, more compliant towards its free edges in y).
    A correction that moves the tool dF deeper makes it cut d + dF and yield κ (d + dF): each round
    leaves κ times the error of the one before, so a single round does not remove it.

    The constants are of the order of an 8 mm carbide ball end 40 mm out of its holder finishing
    steel: a cantilever stiffness 3EI/L³ ≈ 2.3 N/µm (E 600 GPa, a core of 6.4 mm) against finishing
    forces that grow by some 0.3 N/µm of depth gives δ/d ≈ 0.12; they are chosen, not measured. With
    0.3 ± 0.1 mm of stock, δ is 24–72 µm (the freeform paper's parts had 35–40 µm of error).
    """

    surface: Surface
    tool_radius: float = 4.0
    stock: float = 0.30
    stock_taper: float = 0.10
    compliance: float = 0.12
    compliance_growth: float = 0.5
    h: float = 0.125

    def displacement(self, c: np.ndarray) -> np.ndarray:
        """Where a tool position ``c`` (m, 3) really goes, minus where it was told to go."""
        s = self.surface
        xc, yc = (s.u[0] + s.u[-1]) / 2, (s.v[0] + s.v[-1]) / 2
        hx, hy = (s.u[-1] - s.u[0]) / 2, (s.v[-1] - s.v[0]) / 2
        x = np.clip(c[:, 0], s.u[0], s.u[-1])
        y = np.clip(c[:, 1], s.v[0], s.v[-1])
        xs, ys, tip = _tips(s, self.tool_radius, self.h)
        t = ndimage.map_coordinates(tip, [(x - xs[0]) / self.h, (y - ys[0]) / self.h], order=1, mode="nearest")
        n = s.normal(x, y)
        a = self.stock + self.stock_taper * (x - xc) / hx
        depth = np.maximum(a + (t - c[:, 2]) * n[:, 2], 0.0)
        kappa = self.compliance * (1 + self.compliance_growth * ((y - yc) / hy) ** 2)
        return (kappa * depth)[:, None] * n


_TIPS: dict = {}


def _tips(surface: Surface, tool_radius: float, h: float):
    key = (id(surface), tool_radius, h)
    if key not in _TIPS:
        _TIPS.clear()
        _TIPS[key] = tip_heights(surface, tool_radius, h)
    return _TIPS[key]


def random_error(n: int, amplitude: float, kind: str = "normal", seed: int = 0) -> np.ndarray:
    """Random error: ``normal`` (std = amplitude) or ``uniform`` (±amplitude)."""
    rng = np.random.default_rng(seed)
    if kind == "normal":
        return rng.normal(0.0, amplitude, n)
    if kind == "uniform":
        return rng.uniform(-amplitude, amplitude, n)
    raise ValueError(f"random kind must be normal or uniform, got {kind!r}")


# --------------------------------------------------------------------------------------- program
def _ball(radius: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    k = int(np.ceil(radius / h))
    o = np.arange(-k, k + 1) * h
    d2 = o[:, None] ** 2 + o[None, :] ** 2
    inside = d2 <= radius * radius
    return np.where(inside, np.sqrt(np.maximum(radius * radius - d2, 0.0)), 0.0), inside


def tip_heights(surface: Surface, tool_radius: float, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drop cutter: the ball's tip height over a grid of (x, y) h mm apart covering the surface (its
    axes xs, ys and the heights (len(xs), len(ys)), mm): max over surface points q within R of
    q_z + √(R² − |q_xy − (x, y)|²) − R, the surface continued flat beyond its border."""
    xs = np.arange(surface.u[0], surface.u[-1] + 1e-9, h)
    ys = np.arange(surface.v[0], surface.v[-1] + 1e-9, h)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    Z = surface.point(X, Y)[..., 2]
    cap, inside = _ball(tool_radius, h)
    return xs, ys, ndimage.grey_dilation(Z, footprint=inside, structure=cap, mode="nearest") - tool_radius


def finishing_program(
    surface: Surface,
    tool_radius: float = 4.0,
    stepover: float = 0.5,
    step: float = 0.5,
    feed: float = 1200.0,
    clearance: float = 20.0,
) -> str:
    """A zig-zag raster finishing program (G21 G90) along x for a ball-end tool, by drop cutter."""
    h = min(step, stepover) / 2
    # outside the part the surface is continued flat at its border height
    xs, ys, tip = tip_heights(surface, tool_radius, h)
    ix = np.round(np.arange(surface.u[0], surface.u[-1] + 1e-9, step) / h).astype(int) - int(round(surface.u[0] / h))
    iy = np.round(np.arange(surface.v[0], surface.v[-1] + 1e-9, stepover) / h).astype(int) - int(
        round(surface.v[0] / h)
    )
    ix = ix[ix < len(xs)]
    lines = [
        "%",
        f"(ncadapt demo: ball-end finishing, R {tool_radius:.3f} mm, stepover {stepover:.3f} mm)",
        "G21 G90 G17 G94",
        "T1 M6",
        "S12000 M3",
        f"G0 Z{clearance:.4f}",
    ]
    for r, j in enumerate(iy):
        cols = ix if r % 2 == 0 else ix[::-1]
        x0 = xs[cols[0]]
        if r == 0:
            lines.append(f"G0 X{x0:.4f} Y{ys[j]:.4f}")
            lines.append(f"G1 Z{tip[cols[0], j]:.4f} F{feed / 2:.0f}")
            lines.append(f"F{feed:.0f}")
        else:
            lines.append(f"G1 Y{ys[j]:.4f} Z{tip[cols[0], j]:.4f}")
        for i in cols[1:]:
            lines.append(f"X{xs[i]:.4f} Z{tip[i, j]:.4f}")
    lines += [f"G0 Z{clearance:.4f}", "M5", "M30", "%"]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------- machining
@dataclass(frozen=True)
class ZMap:
    """A machined height field: ``z[i, j]`` at (x0 + i h, y0 + j h)."""

    x0: float
    y0: float
    h: float
    z: np.ndarray

    def height(self, x, y) -> np.ndarray:
        """Bilinear height at (x, y)."""
        return ndimage.map_coordinates(
            self.z, [(np.asarray(x) - self.x0) / self.h, (np.asarray(y) - self.y0) / self.h], order=1, mode="nearest"
        )


def machine(
    program,
    surface: Surface,
    error: ErrorModel | MachineError | None,
    tool_radius: float,
    cell: float = 0.25,
    step: float = 0.25,
) -> ZMap:
    """Cut ``program`` (an :class:`ncadapt.nc.Program`) into a z-map of the part's area, the tool
    displaced by ``error``: an :class:`ErrorModel` along the normal, or a :class:`MachineError` or
    :class:`DepthDeflection` (anything with ``displacement(c)``)."""
    tp = program.toolpath(max_segment=step, rapids=False)
    c = tp.points[np.isfinite(tp.points).all(axis=1)]
    if isinstance(error, (MachineError, DepthDeflection)):
        c = c + error.displacement(c)
    elif error is not None:
        # the machine's systematic error, along the part's normal where the tool works
        x = np.clip(c[:, 0], surface.u[0], surface.u[-1])
        y = np.clip(c[:, 1], surface.v[0], surface.v[-1])
        c = c + error(x, y)[:, None] * surface.normal(x, y)
    x0, y0 = surface.u[0], surface.v[0]
    nx = int(round((surface.u[-1] - x0) / cell)) + 1
    ny = int(round((surface.v[-1] - y0) / cell)) + 1
    z = np.full(nx * ny, np.inf)
    k = int(np.ceil(tool_radius / cell)) + 1
    ci = np.round((c[:, 0] - x0) / cell).astype(np.int64)
    cj = np.round((c[:, 1] - y0) / cell).astype(np.int64)
    r2 = tool_radius * tool_radius
    for di in range(-k, k + 1):
        i = ci + di
        for dj in range(-k, k + 1):
            j = cj + dj
            d2 = (x0 + i * cell - c[:, 0]) ** 2 + (y0 + j * cell - c[:, 1]) ** 2
            ok = (d2 <= r2) & (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
            if ok.any():
                np.minimum.at(z, i[ok] * ny + j[ok], c[ok, 2] + tool_radius - np.sqrt(r2 - d2[ok]))
    z = z.reshape(nx, ny)
    if np.isinf(z).any():
        raise ValueError("the program does not cover the whole part; widen the raster")
    return ZMap(x0, y0, cell, z)


def measure(zmap: ZMap, nominal, normal, noise: float = 0.0, seed: int = 0, iterations: int = 6) -> np.ndarray:
    """Measured points: where p + t n meets the z-map (Newton on t), plus noise along n."""
    p = np.asarray(nominal, float)
    n = np.asarray(normal, float)
    t = np.zeros(len(p))
    for _ in range(iterations):
        q = p + t[:, None] * n
        g = zmap.height(q[:, 0], q[:, 1]) - q[:, 2]
        # d/dt of (height − z) ≈ −n_z for the small slopes between cells
        t = t + g / np.maximum(n[:, 2], 0.2)
    if noise > 0:
        t = t + np.random.default_rng(seed).normal(0.0, noise, len(t))
    return p + t[:, None] * n


def probe_points(surface: Surface, border: float = 5.0, spacing: float = 2.5):
    """A grid of nominal points and normals inside the part, leaving an unmeasured border strip."""
    xs = np.arange(surface.u[0] + border, surface.u[-1] - border + 1e-9, spacing)
    ys = np.arange(surface.v[0] + border, surface.v[-1] - border + 1e-9, spacing)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    x, y = X.ravel(), Y.ravel()
    return surface.point(x, y), surface.normal(x, y)
