"""The freeform compensation report, made for review before cutting: the correction map with its
extrapolated strip, deviation maps before / systematic / random / after (each on its own colour
scale), tolerance bands with the share of points in and out, numbered callouts at the largest
deviations, sections along chosen lines, an interactive 3-D view (plotly, its library embedded),
histograms on one binning, Moran's I and the noise diagnostics of the random part.

Lengths in the plane are in mm; every deviation, correction and histogram is in µm.
"""

from __future__ import annotations

import html
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..stats import p_text
from . import figure_png, page, pyplot, table

UM = 1000.0  # µm per mm
# numbered callouts on a map: the largest |deviation| points
CALLOUTS = 5
# the 3-D view draws at most this many points (every k-th beyond it): the page stays a few MB
VIEW_POINTS = 40_000
# tolerance bands: green inside ±T, then ±T…2T, 2T…3T, beyond 3T on each side (profile tolerance
# reports' graded bands); colours from ColorBrewer's RdYlBu and the green of its BuGn
BAND_COLOURS = ("#08306b", "#2171b5", "#9ecae1", "#2ca25f", "#fdd49e", "#f46d43", "#a50026")


# --------------------------------------------------------------------------------------- figures
def tolerance_shares(values, tolerance: float) -> dict:
    """The share of ``values`` (mm) inside the profile tolerance ±``tolerance`` (mm; |e| ≤ T), above
    +T and below −T, as fractions of the points: ``{"inside", "above", "below", "points"}``."""
    e = np.asarray(values, float).ravel()
    t = float(tolerance)
    if not (t > 0 and np.isfinite(t)):
        raise ValueError(f"tolerance must be a positive number of mm, got {tolerance!r}")
    return {
        "points": len(e),
        "inside": float(np.mean(np.abs(e) <= t)),
        "above": float(np.mean(e > t)),
        "below": float(np.mean(e < -t)),
    }


def largest(values, k: int = CALLOUTS) -> np.ndarray:
    """Indices of the ``k`` largest |values|, largest first (ties in input order)."""
    v = np.abs(np.asarray(values, float).ravel())
    return np.argsort(-v, kind="stable")[: min(k, len(v))]


def histogram_edges(series) -> np.ndarray:
    """One set of bin edges (µm) for every series of deviations (mm): a width of 1, 2, 2.5 or 5 ×
    10^k µm giving about 40 bins over the range of all of them, edges on multiples of the width."""
    v = np.concatenate([np.asarray(s, float).ravel() for s in series]) * UM
    lo, hi = float(v.min()), float(v.max())
    span = max(hi - lo, 1e-3)
    raw = span / 40
    k = np.floor(np.log10(raw))
    width = min((m * 10**k for m in (1, 2, 2.5, 5, 10) if m * 10**k >= raw), default=10 ** (k + 1))
    first = np.floor(lo / width) * width
    n = int(np.ceil((hi - first) / width)) or 1
    edges = first + width * np.arange(n + 1)
    if edges[-1] < hi:  # rounding at the top
        edges = np.append(edges, edges[-1] + width)
    return edges


@dataclass(frozen=True)
class Section:
    """A section of the compensated part along a line of its (u, v): ``axis`` = ``at`` (mm),
    sampled at the surface grid's nodes along the other parameter.

    Profiles, each of shape (m,) over ``position`` (mm along the line): ``nominal`` the height w
    of the nominal surface (mm); ``systematic`` dF linearly interpolated on the surface grid (mm,
    along the outward normal; extrapolated in the border strip); ``compensated`` (P_c − P)·n, the
    compensated surface's offset from the nominal along its normal (mm; −dF at the grid's nodes);
    ``extrapolated`` (m,) bool, samples in the border strip. ``measured``: the indices of the
    measured points within half their spacing of the line, ``measured_position`` their position
    along it (mm)."""

    axis: str
    at: float
    along: str
    position: np.ndarray
    nominal: np.ndarray
    systematic: np.ndarray
    compensated: np.ndarray
    extrapolated: np.ndarray
    measured: np.ndarray
    measured_position: np.ndarray


def section(compensation, xy, axis: str, at: float, names=("x", "y")) -> Section:
    """The section ``axis`` = ``at`` (``axis`` one of ``names``, the frame's (u, v) names, or "u",
    "v") of a :class:`~ncadapt.processes.freeform.Compensation`; ``xy`` (n, 2) the measured points'
    (u, v), mm. A line outside the surface grid is refused (:class:`~ncadapt.InputError`)."""
    from scipy.interpolate import RegularGridInterpolator
    from scipy.spatial import cKDTree

    keys = {names[0]: 0, names[1]: 1, "u": 0, "v": 1}
    if axis not in keys:
        raise InputError(
            f"--section {axis}={at:g}: the part's plane is ({names[0]}, {names[1]}); give {names[0]}=… or {names[1]}=…"
        )
    i = keys[axis]
    s = compensation.surface
    axes = (s.u, s.v)
    lo, hi = float(axes[i][0]), float(axes[i][-1])
    if not lo - 1e-9 <= at <= hi + 1e-9:
        raise InputError(f"--section {axis}={at:g}: outside the compensated surface, {names[i]} {lo:g} … {hi:g} mm")
    at = min(max(at, lo), hi)
    pos = np.asarray(axes[1 - i], float)
    u, v = (np.full_like(pos, at), pos) if i == 0 else (pos, np.full_like(pos, at))
    p, pc, n = s.point(u, v), compensation.compensated.point(u, v), s.normal(u, v)
    q = np.column_stack([u, v])
    sysv = RegularGridInterpolator((s.u, s.v), compensation.df_grid)(q)
    inside = RegularGridInterpolator((s.u, s.v), compensation.measured_region.astype(float))(q) > 1 - 1e-9
    uv = np.asarray(xy, float)
    d, _ = cKDTree(uv).query(uv, k=2)
    half = 0.5 * float(np.median(d[:, 1]))
    near = np.flatnonzero(np.abs(uv[:, i] - at) <= half)
    near = near[np.argsort(uv[near, 1 - i], kind="stable")]
    return Section(
        axis,
        float(at),
        names[1 - i],
        pos,
        compensation.frame.w(p),
        sysv,
        np.einsum("ij,ij->i", pc - p, n),
        ~inside,
        near,
        uv[near, 1 - i],
    )


# ---------------------------------------------------------------------------------------- plots
def _callout_marks(ax, xy, idx, labels=None):
    """Circle the points ``idx`` of ``xy`` and number them 1, 2, … (or ``labels``)."""
    ax.scatter(xy[idx, 0], xy[idx, 1], s=70, facecolors="none", edgecolors="k", linewidths=1.2)
    # neighbouring callouts are common (the largest deviations sit together): labels go round
    offsets = ((7, 7), (7, -15), (-15, 7), (-15, -15), (0, 14), (0, -20))
    for k, j in enumerate(idx):
        ax.annotate(
            str(k + 1 if labels is None else labels[k]),
            (xy[j, 0], xy[j, 1]),
            xytext=offsets[k % len(offsets)],
            textcoords="offset points",
            fontsize=9,
            fontweight="bold",
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "k", "lw": 0.6},
        )


def _maps(xy, panels, names, callouts):
    """One map per series, each on its own symmetric colour scale with its colour bar in µm."""
    plt = pyplot()
    cols = 2 if len(panels) == 4 else len(panels)
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.2 * rows), squeeze=False)
    for ax, (name, v) in zip(axes.ravel(), panels):
        w = np.asarray(v, float) * UM
        vmax = max(float(np.abs(w).max()), 1e-6)
        sc = ax.scatter(xy[:, 0], xy[:, 1], c=w, cmap="RdBu_r", vmin=-vmax, vmax=vmax, s=12)
        if name in callouts:
            _callout_marks(ax, xy, callouts[name])
        ax.set_title(f"{name} (±{vmax:.1f} µm)", fontsize=10)
        ax.set_xlabel(f"{names[0]}, mm")
        ax.set_aspect("equal")
        ax.set_ylabel(f"{names[1]}, mm")
        fig.colorbar(sc, ax=ax, label="µm", shrink=0.8, pad=0.02)
    return figure_png(fig)


def _tolerance_maps(xy, panels, names, tolerance, callouts):
    plt = pyplot()
    from matplotlib.colors import BoundaryNorm, ListedColormap

    t = tolerance * UM
    bounds = [-3 * t, -2 * t, -t, t, 2 * t, 3 * t]
    cmap = ListedColormap(BAND_COLOURS[1:-1]).with_extremes(under=BAND_COLOURS[0], over=BAND_COLOURS[-1])
    norm = BoundaryNorm(bounds, cmap.N)
    fig, axes = plt.subplots(1, len(panels), figsize=(5.0 * len(panels), 4.0), squeeze=False)
    for ax, (name, v) in zip(axes[0], panels):
        sc = ax.scatter(xy[:, 0], xy[:, 1], c=np.asarray(v, float) * UM, cmap=cmap, norm=norm, s=14)
        if name in callouts:
            _callout_marks(ax, xy, callouts[name])
        ax.set_title(name, fontsize=10)
        ax.set_xlabel(f"{names[0]}, mm")
        ax.set_aspect("equal")
        cb = fig.colorbar(sc, ax=ax, extend="both", shrink=0.8, pad=0.02, label="µm")
        cb.set_ticks(bounds)
        cb.set_ticklabels([f"{b:+.4g}" for b in bounds])
    axes[0][0].set_ylabel(f"{names[1]}, mm")
    return figure_png(fig)


def _hist(series, edges):
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.4))
    for name, v in series:
        ax.hist(np.asarray(v, float) * UM, bins=edges, histtype="step", linewidth=1.6, label=name)
    ax.set_xlabel("deviation along the outward normal, µm")
    ax.set_ylabel("points")
    ax.legend(fontsize=8)
    return figure_png(fig)


def _correction_map(compensation, xy, names, extrapolation):
    plt = pyplot()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    s = compensation.surface
    U, V = np.meshgrid(s.u, s.v, indexing="ij")
    c = -compensation.df_grid * UM
    vmax = max(float(np.abs(c).max()), 1e-6)
    fig, ax = plt.subplots(figsize=(7.5, 5.2))
    pm = ax.pcolormesh(U, V, c, cmap="RdBu_r", vmin=-vmax, vmax=vmax, shading="nearest")
    fig.colorbar(pm, ax=ax, label="correction −dF along the outward normal, µm (< 0: cut deeper)")
    strip = ~compensation.measured_region
    handles = []
    if strip.any():
        ax.contourf(U, V, strip.astype(float), levels=[0.5, 1.5], colors="none", hatches=["////"])
        ax.contour(U, V, compensation.measured_region.astype(float), levels=[0.5], colors="k", linewidths=1.2)
        handles.append(Patch(facecolor="none", edgecolor="k", hatch="////", label="dF extrapolated (not measured)"))
    if extrapolation is not None and extrapolation.outside.any():
        ax.contourf(U, V, extrapolation.outside.astype(float), levels=[0.5, 1.5], colors="none", hatches=["xx"])
        handles.append(Patch(facecolor="none", edgecolor="k", hatch="xx", label="nominal extrapolated"))
    ax.scatter(xy[:, 0], xy[:, 1], s=1.5, c="k", alpha=0.5)
    handles.append(Line2D([], [], marker="o", ls="", ms=3, color="k", alpha=0.5, label="measured points"))
    ax.legend(handles=handles, fontsize=8, loc="upper right", framealpha=0.9)
    ax.set_xlabel(f"{names[0]}, mm")
    ax.set_ylabel(f"{names[1]}, mm")
    ax.set_aspect("equal")
    ax.set_title(f"correction over the compensated surface (±{vmax:.1f} µm)", fontsize=10)
    return figure_png(fig)


def _section_plot(sec: Section, deviation):
    plt = pyplot()
    fig, (top, bot) = plt.subplots(2, 1, figsize=(8, 5), sharex=True, gridspec_kw={"height_ratios": [1, 2]})
    top.plot(sec.position, sec.nominal, "k-", lw=1.2, label="nominal")
    top.set_ylabel("w, mm")
    top.legend(fontsize=8)
    bot.axhline(0, color="k", lw=1.2, label="nominal")
    bot.plot(sec.measured_position, np.asarray(deviation)[sec.measured] * UM, "o", ms=4, color="0.35", label="measured")
    bot.plot(sec.position, sec.systematic * UM, "-", color="tab:red", lw=1.6, label="systematic dF")
    bot.plot(sec.position, sec.compensated * UM, "-", color="tab:blue", lw=1.6, label="compensated (P_c − P)·n")
    if sec.extrapolated.any():
        x = sec.position
        step = float(np.median(np.diff(x))) if len(x) > 1 else 0.0
        for k in np.flatnonzero(sec.extrapolated):
            bot.axvspan(x[k] - step / 2, x[k] + step / 2, color="0.9", lw=0, zorder=0)
        bot.plot([], [], "s", color="0.9", label="extrapolated strip")
    bot.set_xlabel(f"{sec.along}, mm (along {sec.axis} = {sec.at:g} mm)")
    bot.set_ylabel("along the outward normal, µm")
    bot.legend(fontsize=8, ncol=5, loc="upper center", bbox_to_anchor=(0.5, -0.22), frameon=False)
    return figure_png(fig)


def symmetric_range(w) -> tuple[float, float]:
    """A colour range centred on zero that holds every finite value of ``w`` (µm)."""
    m = max(float(np.nanmax(np.abs(w))) if np.size(w) else 0.0, 1e-6)
    return -m, m


def mesh(p, tri, values, lo: float, hi: float, **kw):
    """A plotly ``Mesh3d`` of points ``p`` (n, 3) and triangles ``tri`` (m, 3) coloured by ``values``
    on the red-blue scale from ``lo`` to ``hi``; ``kw`` passes on (name, colorbar, hovertemplate …)."""
    import plotly.graph_objects as go

    return go.Mesh3d(
        x=p[:, 0],
        y=p[:, 1],
        z=p[:, 2],
        i=tri[:, 0],
        j=tri[:, 1],
        k=tri[:, 2],
        intensity=values,
        colorscale="RdBu_r",
        cmin=lo,
        cmax=hi,
        **kw,
    )


def surface_view(points, series, div_id: str = "surface3d") -> str:
    """An interactive 3-D view (plotly, its library embedded: no network) of deviations on the
    surface: the measured points' nominal positions ``points`` (n, 3) mm, triangulated over their
    first two frame coordinates, coloured by one of ``series`` [(name, values (n,) mm)], chosen in a
    menu, each on its own symmetric scale in µm. More than :data:`VIEW_POINTS` points: every k-th."""
    import plotly.graph_objects as go
    from scipy.spatial import Delaunay

    pts = np.asarray(points, float)
    keep = np.arange(len(pts))
    if len(pts) > VIEW_POINTS:
        keep = np.unique(np.linspace(0, len(pts) - 1, VIEW_POINTS).round().astype(int))
    p = pts[keep]
    c = p - p.mean(axis=0)
    plane = np.linalg.svd(c, full_matrices=False)[2][:2]  # the points' best plane: a height field over it
    tri = Delaunay(c @ plane.T).simplices
    vals = [(name, np.asarray(v, float)[keep] * UM) for name, v in series]
    scale = symmetric_range
    lo, hi = scale(vals[0][1])
    # the box in the data's proportions; the thinnest axis of a flat part (its height) drawn a
    # quarter of the widest, said in the caption; a plane stays flat
    spans = np.ptp(p, axis=0)
    ratio = spans / max(float(spans.max()), 1e-9)
    thin = int(np.argmin(ratio))
    tall = 0.25 / ratio[thin] if 1e-6 < ratio[thin] < 0.25 else 1.0
    ratio[thin] = max(ratio[thin] * tall, 0.02)
    fig = go.Figure(
        mesh(
            p,
            tri,
            vals[0][1],
            lo,
            hi,
            colorbar={"title": {"text": "µm"}},
            hovertemplate="x %{x:.3f} mm<br>y %{y:.3f} mm<br>z %{z:.3f} mm<br>%{intensity:.1f} µm<extra></extra>",
            flatshading=False,
        )
    )
    buttons = [
        {
            "label": name,
            "method": "restyle",
            "args": [{"intensity": [w], "cmin": [scale(w)[0]], "cmax": [scale(w)[1]]}],
        }
        for name, w in vals
    ]
    fig.update_layout(
        height=600,
        margin={"l": 0, "r": 0, "t": 30, "b": 0},
        scene={
            "aspectmode": "manual",
            "aspectratio": dict(zip("xyz", ratio)),
            "camera": {"eye": {"x": 1.1, "y": -1.6, "z": 1.5}},
            "xaxis": {"title": {"text": "x, mm"}},
            "yaxis": {"title": {"text": "y, mm"}},
            "zaxis": {"title": {"text": "z, mm"}},
        },
        updatemenus=[{"buttons": buttons, "x": 0, "y": 1.06, "xanchor": "left", "yanchor": "top"}],
    )
    shown = "" if len(keep) == len(pts) else f" ({len(keep):,} of {len(pts):,} points: every k-th)"
    shown += "" if tall == 1 else f"; {'xyz'[thin]} drawn ×{tall:.3g}"
    return (
        f"<p>Deviation along the outward normal on the nominal surface, µm{shown}; drag to turn, scroll to "
        "zoom, the menu switches the series (each on its own colour scale).</p>"
        + fig.to_html(full_html=False, include_plotlyjs=True, div_id=div_id, config={"displaylogo": False})
    )


# ---------------------------------------------------------------------------------------- tables
def _um(v, digits=1) -> str:
    return f"{v * UM:+.{digits}f}"


def _stats_table(series) -> str:
    rows = []
    for label, f in (
        ("mean", np.mean),
        ("std", lambda w: np.std(w, ddof=1) if len(w) > 1 else 0.0),
        ("min", np.min),
        ("max", np.max),
        ("rms", lambda w: np.sqrt(np.mean(w * w))),
        ("max |·|", lambda w: np.max(np.abs(w))),
    ):
        rows.append((f"{label}, µm", *(f"{f(np.asarray(v, float)) * UM:.2f}" for _, v in series)))
    return table(rows, ["", *(name for name, _ in series)])


def _callout_table(xy, values, idx, names, div_id) -> str:
    rows = [(k + 1, f"{xy[j, 0]:.3f}", f"{xy[j, 1]:.3f}", _um(values[j], 1)) for k, j in enumerate(idx)]
    return f"<div id='{div_id}'>" + table(rows, ["#", f"{names[0]}, mm", f"{names[1]}, mm", "deviation, µm"]) + "</div>"


def _param_rows(decomposition):
    unit = {"sigma_c": ("σ_c, mm", 1.0), "sigma_s": ("σ_s, µm", UM), "noise_estimate": ("noise estimate, µm", UM)}
    for k, v in decomposition.parameters.items():
        if k in unit and isinstance(v, (int, float)) and not isinstance(v, bool):
            label, f = unit[k]
            yield label, f"{v * f:.4g}"
        else:
            yield k, v


# ---------------------------------------------------------------------------------------- report
def render(
    *,
    title,
    analysis,
    decomposition,
    xy,
    deviation,
    after=None,
    summary=None,
    files=None,
    names=("x", "y"),
    extrapolation=None,
    compensation=None,
    points=None,
    tolerance=None,
    sections=(),
    callouts: int = CALLOUTS,
    faces=None,
    predicted=None,
    cad=None,
) -> str:
    """The report as HTML text.

    ``xy`` (n, 2): the points' (u, v), mm, named ``names`` on the maps; ``deviation`` (n,) the
    measured deviations, mm; ``after`` (n,): deviations of the re-machined part at the same points;
    ``compensation``: the :class:`~ncadapt.processes.freeform.Compensation` (the correction map);
    ``points`` (n, 3): the nominal points in machine coordinates, mm (the 3-D view; default ``xy``
    at height 0); ``tolerance``: the profile tolerance ±T, mm (banded maps and the share of points
    inside); ``sections``: :class:`Section` s or :class:`~ncadapt.report.cad_sections.CadSection` s;
    ``callouts``: how many of the largest |deviations| are numbered on the maps and listed;
    ``faces``: [(face id, indices of its points)] of a CAD nominal (the tolerance table by face);
    ``predicted`` (n,): the deviations predicted after the correction, mm (default: ``deviation``
    minus the compensation's gain × the systematic part); ``cad``: a
    :class:`~ncadapt.report.cad_maps.CadReport` of a CAD nominal (the correction map face by face,
    the callouts located by face, (u, v) and x, y, z, the 3-D view on the part).
    """
    xy = np.asarray(xy, float)[:, :2]
    deviation = np.asarray(deviation, float)
    sysv, rnd = np.asarray(decomposition.systematic, float), np.asarray(decomposition.random, float)
    after = None if after is None else np.asarray(after, float)
    series = [("measured", deviation), ("systematic", sysv), ("random", rnd)]
    if after is not None:
        series.append(("after", after))
    marked = {"measured": largest(deviation, callouts)}
    if after is not None:
        marked["after"] = largest(after, callouts)
    parts = []
    if summary:
        cards = "".join(
            f"<div class='card'><div>{html.escape(str(k))}</div><div class='big'>{html.escape(str(v))}</div></div>"
            for k, v in summary.items()
        )
        parts.append(("Result", f"<div class='cards'>{cards}</div>"))
    if cad is not None:
        from . import cad_maps

        parts.append(("The correction to be cut", cad_maps.correction_section(cad, marked["measured"])))

        def callout_table(values, idx, div_id):
            return cad_maps.callout_table(cad, values, idx, div_id)
    else:

        def callout_table(values, idx, div_id):
            return _callout_table(xy, values, idx, names, div_id)

    if compensation is not None:
        parts.append(("The correction to be cut", _correction_section(compensation, xy, names, extrapolation)))
    if tolerance is not None:
        # what the program moves: this round's gain on the systematic part (1 in a first round)
        if predicted is None:
            predicted = deviation - sysv * (getattr(compensation, "gain", 1.0) if compensation is not None else 1.0)
        parts.append(
            ("Tolerance", _tolerance_section(xy, deviation, predicted, after, tolerance, names, marked, faces))
        )
    parts.append(
        (
            "Deviations",
            "<p>Deviation along the outward normal (&gt; 0: material left), each map on its own colour scale; "
            f"the {len(marked['measured'])} largest |deviations| are numbered.</p>"
            + _stats_table(series)
            + _maps(xy, series, names, marked)
            + "<h3>Largest deviations, measured</h3>"
            + callout_table(deviation, marked["measured"], "callouts-measured")
            + (
                "<h3>Largest deviations, after</h3>" + callout_table(after, marked["after"], "callouts-after")
                if after is not None
                else ""
            ),
        )
    )
    for sec in sections:
        if isinstance(sec, Section):
            parts.append((f"Section {sec.axis} = {sec.at:g} mm", _section_block(sec, deviation)))
        else:
            from . import cad_sections

            parts.append((f"Section {sec.axis} = {sec.at:g} mm", cad_sections.block(sec, deviation)))
    if cad is not None:
        from . import cad_maps

        parts.append(("3-D view", cad_maps.part_view(cad, series)))
    else:
        view_points = np.column_stack([xy, np.zeros(len(xy))]) if points is None else np.asarray(points, float)
        parts.append(("3-D view", surface_view(view_points, series)))
    edges = histogram_edges([v for _, v in series])
    parts.append(
        (
            "Histograms",
            f"<p>Every series on the same bins: {edges[1] - edges[0]:g} µm wide, from {edges[0]:g} µm to "
            f"{edges[-1]:g} µm.</p>" + _hist(series, edges),
        )
    )
    parts.append(("Is the error systematic?", _gate_section(analysis)))
    nz = decomposition.noise
    parts.append(
        (
            "Separating systematic from random error",
            table(
                [
                    ("filter", decomposition.method),
                    *_param_rows(decomposition),
                    ("random part: std, µm", f"{nz.std * UM:.2f}"),
                    ("Pearson χ² normality p", p_text(nz.pearson_p, 4)),
                    ("lag-1 autocorrelation r", nz.lag1_r),
                    ("Student t test p (one-sided)", p_text(nz.student_p, 4)),
                    ("Moran's I of the random part: z", nz.moran_z),
                    ("... p (one-sided)", p_text(nz.moran_p, 4)),
                    ("no systematic error left", "yes" if nz.passed else "no"),
                ],
                ["", "value"],
            ),
        )
    )
    if extrapolation is not None:
        parts.append(
            (
                "Extrapolated nominal",
                f"<p class='verdict no'>The compensated surface reaches up to <b>{extrapolation.max_distance:.3g} mm</b> "
                f"beyond the measured points, over <b>{100 * extrapolation.area_fraction:.0f} %</b> of its grid. In that "
                "strip its nominal is extrapolated from the measured points, not measured, and so is the systematic "
                "error: check it against the CAD model before machining there (hatched × on the correction map).</p>",
            )
        )
    if files:
        parts.append(("Files", table([(k, v) for k, v in files.items()], ["", "file"])))
    return page(title, "ncadapt freeform compensation report", parts)


def correction_figures(compensation) -> dict:
    """What the correction map's table states: the correction −dF (mm) inside the measured area and
    in the extrapolated strip (min, max), the strip's share of the grid's nodes and its farthest
    node from a measured one (mm)."""
    from scipy.spatial import cKDTree

    s = compensation.surface
    U, V = np.meshgrid(s.u, s.v, indexing="ij")
    c = -np.asarray(compensation.df_grid, float)
    inside = np.asarray(compensation.measured_region, bool)
    out = {"nodes": int(c.size), "inside_min": float(c[inside].min()), "inside_max": float(c[inside].max())}
    if (~inside).any():
        q = np.column_stack([U.ravel(), V.ravel()])
        d, _ = cKDTree(q[inside.ravel()]).query(q[~inside.ravel()])
        out |= {
            "strip_fraction": float((~inside).mean()),
            "strip_distance": float(d.max()),
            "strip_min": float(c[~inside].min()),
            "strip_max": float(c[~inside].max()),
        }
    return out


def _correction_section(compensation, xy, names, extrapolation) -> str:
    f = correction_figures(compensation)
    s = compensation.surface
    rows = [
        ("surface grid", f"{len(s.u)} × {len(s.v)} nodes"),
        ("extent", f"{names[0]} {s.u[0]:g} … {s.u[-1]:g} mm, {names[1]} {s.v[0]:g} … {s.v[-1]:g} mm"),
        ("correction inside the measured area, µm", f"{_um(f['inside_min'])} … {_um(f['inside_max'])}"),
    ]
    if "strip_fraction" in f:
        rows += [
            ("extrapolated strip: share of the grid, %", f"{100 * f['strip_fraction']:.1f}"),
            ("extrapolated strip: farthest from a measured node, mm", f"{f['strip_distance']:.3f}"),
            ("correction in the extrapolated strip, µm", f"{_um(f['strip_min'])} … {_um(f['strip_max'])}"),
        ]
    note = (
        "<p class='verdict yes'>Check before cutting: in the hatched strip the correction is extrapolated from "
        "the measured area, not measured.</p>"
        if "strip_fraction" in f
        else "<p>The compensated surface lies inside the measured area: every correction is interpolated between "
        "measured points.</p>"
    )
    return (
        "<p>The displacement the compensated surface and the corrected program apply: P_c = P − dF·n, shown as "
        "−dF along the outward normal over the whole compensated surface.</p>"
        + note
        + f"<div id='correction'>{table(rows, ['', 'value'])}</div>"
        + _correction_map(compensation, xy, names, extrapolation)
    )


def _tolerance_section(xy, deviation, predicted, after, tolerance, names, marked, faces=None) -> str:
    panels = [("measured", deviation)]
    if after is not None:
        panels.append(("after", after))
    else:
        panels.append(("predicted after (measured − systematic)", predicted))
    groups = (
        [("", slice(None))]
        if not faces
        else [("all faces, ", slice(None))] + [(f"face {fid}, ", idx) for fid, idx in faces]
    )
    rows = []
    for label, idx in groups:
        for name, v in panels:
            w = np.asarray(v, float)[idx]
            s = tolerance_shares(w, tolerance)
            rows.append(
                (
                    label + name,
                    s["points"],
                    f"{100 * s['inside']:.1f}",
                    f"{100 * (1 - s['inside']):.1f}",
                    f"{100 * s['above']:.1f}",
                    f"{100 * s['below']:.1f}",
                    f"{np.abs(w).max() * UM:.1f}",
                )
            )
    t = tolerance * UM
    head = ["", "points", "in tolerance, %", "out, %", f"above +{t:g} µm, %", f"below −{t:g} µm, %", "max |·|, µm"]
    return (
        f"<p>Profile tolerance ±{t:g} µm: green inside, graded bands of {t:g} µm outside (blue below, red "
        "above).</p>"
        + f"<div id='tolerance'>{table(rows, head)}</div>"
        + _tolerance_maps(xy, panels, names, tolerance, marked)
    )


def _section_block(sec: Section, deviation) -> str:
    rows = [
        (
            f"{x:.3f}",
            f"{w:.4f}",
            f"{s * UM:+.2f}",
            f"{c * UM:+.2f}",
            "yes" if e else "",
        )
        for x, w, s, c, e in zip(sec.position, sec.nominal, sec.systematic, sec.compensated, sec.extrapolated)
    ]
    meas = [(f"{x:.3f}", f"{np.asarray(deviation)[j] * UM:+.2f}") for x, j in zip(sec.measured_position, sec.measured)]
    key = f"{sec.axis}={sec.at:g}"
    return (
        f"<p>Along {sec.along} at {sec.axis} = {sec.at:g} mm, plotted as deviation along the outward normal against "
        "position (µm; the nominal is the zero line), the nominal height above it (mm). Measured: the points within "
        "half their spacing of the line.</p>"
        + _section_plot(sec, deviation)
        + f"<details id='section-{html.escape(key)}'><summary>values</summary>"
        + table(rows, [f"{sec.along}, mm", "nominal w, mm", "systematic, µm", "compensated, µm", "extrapolated"])
        + f"<div class='measured'>{table(meas, [f'{sec.along}, mm', 'measured, µm'])}</div></details>"
    )


def _gate_section(analysis) -> str:
    m = analysis.moran
    p_txt = m.p_said()
    w_txt = m.weights.describe() + ", row-standardised"
    v, o = analysis.verdict, analysis.offset
    o_txt = p_text(o.p_value, 2)
    verdict = (
        f"<p class='verdict {'yes' if v.systematic else 'no'}'>The deviations are "
        f"{'<b>systematic</b>' if v.systematic else '<b>not systematic</b>'} "
        f"(Moran's I = {m.I:.4f}, z = {m.z_randomization:.2f}, p {p_txt if p_txt[0] in '<≤' else '= ' + p_txt}; "
        f"mean offset {o.mean * UM:+.2f} µm, t = {o.t:.2f}, p {o_txt if o_txt.startswith('<') else '= ' + o_txt}; "
        f"each test at α/2 = {v.alpha / 2:g})</p>"
    )
    return verdict + table(
        [
            ("Moran's I", m.I),
            ("E[I]", m.expected),
            ("Var[I], normality", m.variance_normality),
            ("Var[I], randomisation", m.variance_randomization),
            ("z, normality", m.z_normality),
            ("z, randomisation", m.z_randomization),
            (
                "p (one-sided, " + (f"{m.permutations} permutations)" if m.permutations else "randomisation)"),
                m.p_said(),
            ),
            ("p (one-sided, normal approximation)", p_text(m.p_randomization, 4)),
            ("mean offset, µm", f"{o.mean * UM:+.2f}"),
            ("offset t", o.t),
            ("offset p (two-sided)", p_text(o.p_value, 4)),
            ("weights", w_txt),
            ("points", m.n),
        ],
        ["statistic", "value"],
    )
