"""The freeform compensation report: deviation maps before and after, histograms, Moran's I, the
noise diagnostics of the random part."""

from __future__ import annotations

import numpy as np

from ..stats import p_text
from . import figure_png, page, pyplot, table


def _maps(xy, panels, title, names=("x", "y")):
    plt = pyplot()

    vmax = max(float(np.abs(v).max()) for _, v in panels) * 1000
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.6), squeeze=False)
    for ax, (name, v) in zip(axes[0], panels):
        sc = ax.scatter(xy[:, 0], xy[:, 1], c=np.asarray(v) * 1000, cmap="RdBu_r", vmin=-vmax, vmax=vmax, s=14)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel(f"{names[0]}, mm")
        ax.set_aspect("equal")
    axes[0][0].set_ylabel(f"{names[1]}, mm")
    fig.colorbar(sc, ax=axes[0].tolist(), label="deviation along the normal, µm", shrink=0.9)
    fig.suptitle(title, fontsize=11)
    return figure_png(fig)


def _hist(series):
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2))
    for name, v in series:
        ax.hist(np.asarray(v) * 1000, bins=40, alpha=0.6, label=name)
    ax.set_xlabel("deviation, µm")
    ax.set_ylabel("points")
    ax.legend()
    return figure_png(fig)


def _strip(extrapolation, xy, names):
    """The surface grid's nodes, the extrapolated ones in red, with the measured points."""
    plt = pyplot()
    e = extrapolation
    U, V = np.meshgrid(e.u, e.v, indexing="ij")
    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.scatter(U[~e.outside], V[~e.outside], s=2, c="0.75", label="surface grid, measured area")
    ax.scatter(U[e.outside], V[e.outside], s=2, c="tab:red", label="extrapolated nominal")
    ax.scatter(xy[:, 0], xy[:, 1], s=6, c="k", label="measured points")
    ax.set_xlabel(f"{names[0]}, mm")
    ax.set_ylabel(f"{names[1]}, mm")
    ax.set_aspect("equal")
    ax.legend(fontsize=8, loc="upper right")
    return figure_png(fig)


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
) -> str:
    """The report as HTML text. ``xy``: the points' (u, v), named ``names`` on the maps; ``after``:
    deviations of the re-machined part at the same points."""
    m = analysis.moran
    p_txt = m.p_said()
    w_txt = m.weights.describe() + ", row-standardised"
    v, o = analysis.verdict, analysis.offset
    o_txt = p_text(o.p_value, 2)
    verdict = (
        f"<p class='verdict {'yes' if v.systematic else 'no'}'>The deviations are "
        f"{'<b>systematic</b>' if v.systematic else '<b>not systematic</b>'} "
        f"(Moran's I = {m.I:.4f}, z = {m.z_randomization:.2f}, p {p_txt if p_txt[0] in '<≤' else '= ' + p_txt}; "
        f"mean offset {o.mean * 1000:+.2f} µm, t = {o.t:.2f}, p {o_txt if o_txt.startswith('<') else '= ' + o_txt}; "
        f"each test at α/2 = {v.alpha / 2:g})</p>"
    )
    sections = []
    if summary:
        cards = "".join(f"<div class='card'><div>{k}</div><div class='big'>{v}</div></div>" for k, v in summary.items())
        sections.append(("Result", f"<div class='cards'>{cards}</div>"))
    sections.append(
        (
            "Is the error systematic?",
            verdict
            + table(
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
                    ("mean offset, mm", o.mean),
                    ("offset t", o.t),
                    ("offset p (two-sided)", p_text(o.p_value, 4)),
                    ("weights", w_txt),
                    ("points", m.n),
                ],
                ["statistic", "value"],
            ),
        )
    )
    d = analysis.deviation
    sections.append(
        (
            "Deviations",
            table([(k, f"{v * 1000:.2f}") for k, v in d.items()], ["", "µm"])
            + _maps(
                xy,
                [("measured", deviation), ("systematic", decomposition.systematic), ("random", decomposition.random)],
                "Deviation along the outward normal (> 0: material left)",
                names,
            ),
        )
    )
    nz = decomposition.noise
    sections.append(
        (
            "Separating systematic from random error",
            table(
                [
                    ("filter", decomposition.method),
                    *((k, v) for k, v in decomposition.parameters.items()),
                    ("random part: std, mm", nz.std),
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
    if after is not None:
        sections.append(
            (
                "After compensation",
                _maps(
                    xy,
                    [("before", deviation), ("after", after)],
                    "Deviation of the first part and of the re-machined part",
                    names,
                )
                + _hist([("before", deviation), ("after", after)]),
            )
        )
    if extrapolation is not None:
        sections.append(
            (
                "Extrapolated nominal",
                (
                    f"<p class='verdict no'>The compensated surface reaches up to <b>{extrapolation.max_distance:.3g} mm</b> "
                    f"beyond the measured points, over <b>{100 * extrapolation.area_fraction:.0f} %</b> of its grid. In that "
                    "strip its nominal is extrapolated from the measured points, not measured, and so is the systematic "
                    "error: check it against the CAD model before machining there.</p>"
                )
                + _strip(extrapolation, xy, names),
            )
        )
    if files:
        sections.append(("Files", table([(k, v) for k, v in files.items()], ["", "file"])))
    return page(title, "ncadapt freeform compensation report", sections)
