"""The report's views of a compensated CAD part (``compensate --nominal``): the correction to be cut
on each face in its own (u, v) with the extrapolated strip, the largest deviations located by face,
(u, v) and x, y, z, and the interactive 3-D view of the part (deviations on the measured points,
the correction on the faces).

Lengths in mm (a face's (u, v) scaled to mm along it, :func:`ncadapt.processes.freeform.face_scale`);
deviations and corrections in µm on the plots and in the tables.
"""

from __future__ import annotations

import html
from dataclasses import dataclass

import numpy as np

from . import figure_png, pyplot, table

UM = 1000.0  # µm per mm
# the 3-D view: at most this many measured points (every k-th beyond it) and this many grid nodes a
# side of each face's correction (every k-th row and column, the last kept): the page stays a few MB
VIEW_POINTS = 40_000
VIEW_NODES = 120
# a triangle of the measured points (in the face's (u, v)) with a side longer than this many point
# spacings spans a gap (a concave edge of the measured area) and is not drawn
GAP_SPACINGS = 4.0


@dataclass(frozen=True)
class CadReport:
    """What the report needs of a CAD nominal: ``part`` the
    :class:`~ncadapt.processes.freeform.PartCompensation`; for each measured point (n of them)
    ``face`` (n,) int its face id, ``uv`` (n, 2) its (u, v) in the face's own parameters (mm, or rad
    for an angle) and ``points`` (n, 3) mm its point on the CAD face in the part's frame (the frame of
    the program; after ``--align`` the CAD model's); ``names`` {face id: the CAD file's name or None}."""

    part: object
    face: np.ndarray
    uv: np.ndarray
    points: np.ndarray
    names: dict

    def face_said(self, face_id: int) -> str:
        """``3`` or ``3 'top'``."""
        name = self.names.get(face_id)
        return str(face_id) + (f" {name!r}" if name is not None else "")


@dataclass(frozen=True)
class FaceCorrection:
    """The correction to be cut on one compensated face, over its whole (u, v) box.

    ``u``, ``v`` (nu,), (nv,): the grid's axes, the face's parameters; ``u_mm``, ``v_mm`` the same
    scaled to mm along the face; ``correction`` (nu, nv) mm: −dF along the outward normal (NaN at
    nodes outside the trimmed face); ``strip`` (nu, nv) bool: nodes on the face outside the measured
    points' hull, where dF is extrapolated (``border``: held or cubic); ``hull`` (k, 2) mm: the
    measured points' convex hull in (u_mm, v_mm), counter-clockwise; ``strip_fraction`` the strip's
    share of the face's nodes; ``strip_distance`` mm the farthest strip node from the hull (0 without
    a strip); ``inside`` and ``in_strip``: (min, max) of the correction there, mm (None when empty).
    A face of a face set (``in_set``) is extrapolated beyond the hull of the set's points, not its
    own: its outline is the edge of the grid nodes inside that hull (``measured``, (nu, nv) bool) and
    ``strip_distance`` the farthest strip node from the nearest of them."""

    face: int
    u: np.ndarray
    v: np.ndarray
    u_mm: np.ndarray
    v_mm: np.ndarray
    correction: np.ndarray
    strip: np.ndarray
    hull: np.ndarray
    strip_fraction: float
    strip_distance: float
    inside: tuple[float, float]
    in_strip: tuple[float, float] | None
    border: str
    in_set: bool = False
    measured: np.ndarray | None = None


def _distance_to_polygon(q, poly) -> np.ndarray:
    """(m,) distances of points ``q`` (m, 2) from the boundary of the closed polygon ``poly`` (k, 2)."""
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    out = np.full(len(q), np.inf)
    for start in range(0, len(q), 4096):  # (chunk, k) at a time
        p = q[start : start + 4096, None, :]
        t = np.clip(np.einsum("mkj,kj->mk", p - a, ab) / np.maximum(np.einsum("kj,kj->k", ab, ab), 1e-300), 0, 1)
        d = np.linalg.norm(p - (a + t[..., None] * ab), axis=2)
        out[start : start + 4096] = d.min(axis=1)
    return out


def face_corrections(part) -> list[FaceCorrection]:
    """The correction −dF of each compensated face of ``part`` (a
    :class:`~ncadapt.processes.freeform.PartCompensation`) over its grid, with its strip."""
    from scipy.spatial import ConvexHull

    out = []
    for f in part.faces:
        su, sv = f.scale
        c = np.where(f.in_face, -np.asarray(f.df_grid, float), np.nan)
        strip = np.asarray(f.border_strip, bool)
        inner = f.in_face & f.measured_region
        hull = f.coords[ConvexHull(f.coords).vertices]
        dist = 0.0
        in_set = getattr(f, "face_set", None) is not None
        if strip.any():
            U, V = np.meshgrid(f.u * su, f.v * sv, indexing="ij")
            q = np.column_stack([U[strip], V[strip]])
            if in_set:
                from scipy.spatial import cKDTree

                dist = float(cKDTree(np.column_stack([U[inner], V[inner]])).query(q)[0].max())
            else:
                dist = float(_distance_to_polygon(q, hull).max())
        out.append(
            FaceCorrection(
                f.face,
                np.asarray(f.u, float),
                np.asarray(f.v, float),
                f.u * su,
                f.v * sv,
                c,
                strip,
                hull,
                float(strip.sum() / f.in_face.sum()),
                dist,
                (float(c[inner].min()), float(c[inner].max())),
                (float(c[strip].min()), float(c[strip].max())) if strip.any() else None,
                f.border,
                in_set,
                inner,
            )
        )
    return out


# ------------------------------------------------------------------------------ the correction map
def _correction_panels(cad: CadReport, corrections, callouts):
    plt = pyplot()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from .freeform import _callout_marks

    vmax = max(max(float(np.nanmax(np.abs(fc.correction))) for fc in corrections) * UM, 1e-6)
    cols = min(len(corrections), 2)
    rows = -(-len(corrections) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.2 * cols, 4.8 * rows), squeeze=False)
    for ax in axes.ravel()[len(corrections) :]:
        ax.set_visible(False)
    pm = None
    for ax, f, fc in zip(axes.ravel(), cad.part.faces, corrections):  # type: ignore[attr-defined]
        U, V = np.meshgrid(fc.u_mm, fc.v_mm, indexing="ij")
        pm = ax.pcolormesh(U, V, fc.correction * UM, cmap="RdBu_r", vmin=-vmax, vmax=vmax, shading="nearest")
        handles = []
        if fc.strip.any():
            ax.contourf(U, V, fc.strip.astype(float), levels=[0.5, 1.5], colors="none", hatches=["////"])
            if fc.in_set:  # the set's hull, where it crosses the face
                ax.contour(U, V, fc.measured.astype(float), levels=[0.5], colors="k", linewidths=1.2)
            else:
                ax.plot(*np.vstack([fc.hull, fc.hull[:1]]).T, "k-", lw=1.2)
            handles.append(Patch(facecolor="none", edgecolor="k", hatch="////", label="dF extrapolated (not measured)"))
        ax.scatter(f.coords[:, 0], f.coords[:, 1], s=1.5, c="k", alpha=0.5)
        handles.append(Line2D([], [], marker="o", ls="", ms=3, color="k", alpha=0.5, label="measured points"))
        mine = [(k, j) for k, j in enumerate(callouts) if cad.face[j] == f.face]
        if mine:
            local = {int(p): i for i, p in enumerate(f.points)}
            at = np.array([local[int(j)] for _, j in mine])
            _callout_marks(ax, f.coords, at, [k + 1 for k, _ in mine])
        ax.legend(handles=handles, fontsize=7, loc="upper right", framealpha=0.9)
        ax.set_title(f"face {cad.face_said(f.face)}", fontsize=10)
        ax.set_xlabel("u, mm along the face")
        ax.set_ylabel("v, mm along the face")
        ax.set_aspect("equal")
    fig.colorbar(
        pm, ax=axes.ravel().tolist(), label="correction −dF along the outward normal, µm (< 0: cut deeper)", shrink=0.8
    )
    return figure_png(fig), vmax


def correction_section(cad: CadReport, callouts=()) -> str:
    """The report's section "The correction to be cut" for a CAD part: one map per face on one
    colour scale (µm), the strip hatched and the hull outlined, the numbered callouts (indices of
    points) marked on their face; the table of each face's grid, extent, strip and ranges."""
    corrections = face_corrections(cad.part)
    img, vmax = _correction_panels(cad, corrections, list(callouts))
    rows = []
    for fc in corrections:
        lo, hi = fc.hull.min(axis=0), fc.hull.max(axis=0)
        rows.append(
            (
                cad.face_said(fc.face),
                f"{len(fc.u)} × {len(fc.v)}",
                f"u {fc.u_mm[0]:.3f} … {fc.u_mm[-1]:.3f}, v {fc.v_mm[0]:.3f} … {fc.v_mm[-1]:.3f}",
                f"u {lo[0]:.3f} … {hi[0]:.3f}, v {lo[1]:.3f} … {hi[1]:.3f}",
                f"{fc.inside[0] * UM:+.1f} … {fc.inside[1] * UM:+.1f}",
                f"{100 * fc.strip_fraction:.1f}",
                f"{fc.strip_distance:.3f}",
                "—" if fc.in_strip is None else f"{fc.in_strip[0] * UM:+.1f} … {fc.in_strip[1] * UM:+.1f}",
                "held at the nearest measured node" if fc.border == "hold" else "cubic extrapolation",
            )
        )
    head = [
        "face",
        "grid, nodes",
        "face (u, v), mm along it",
        "measured hull (u, v), mm",
        "correction inside the hull, µm",
        "strip: share of the face, %",
        "strip: farthest from the hull, mm",
        "correction in the strip, µm",
        "dF in the strip",
    ]
    strip = any(fc.in_strip is not None for fc in corrections)
    note = (
        "<p class='verdict yes'>Check before cutting: in the hatched strip of a face (outside the outlined hull of "
        "its measured points) the correction is extrapolated, not measured.</p>"
        if strip
        else "<p>Every compensated face lies inside its measured points' hull: every correction is interpolated "
        "between measured points.</p>"
    )
    return (
        "<p>The displacement the compensated part and the corrected program apply: P_c = P − dF·n, shown as −dF "
        f"along the outward normal over each compensated face's whole (u, v), in mm along the face, on one colour "
        f"scale (±{vmax:.1f} µm); blank: outside the trimmed face. Numbered: the largest |deviations| measured.</p>"
        + note
        + f"<div id='correction'>{table(rows, head)}</div>"
        + img
    )


# ---------------------------------------------------------------------------------- the callouts
def callout_table(cad: CadReport, values, idx, div_id: str) -> str:
    """The numbered largest |deviations| ``idx`` (indices into ``values``, mm): face, its (u, v)
    parameters, the point's x, y, z (mm) and the deviation (µm)."""
    rows = []
    for k, j in enumerate(idx):
        p = cad.points[j]
        rows.append(
            (
                k + 1,
                cad.face_said(int(cad.face[j])),
                f"{cad.uv[j, 0]:.5g}",
                f"{cad.uv[j, 1]:.5g}",
                f"{p[0]:.3f}",
                f"{p[1]:.3f}",
                f"{p[2]:.3f}",
                f"{values[j] * UM:+.1f}",
            )
        )
    head = ["#", "face", "u (face parameter)", "v (face parameter)", "x, mm", "y, mm", "z, mm", "deviation, µm"]
    return f"<div id='{html.escape(div_id)}'>" + table(rows, head) + "</div>"


# ---------------------------------------------------------------------------------- the 3-D view
def _point_triangles(coords) -> np.ndarray:
    """Delaunay triangles of a face's points in its (u, v) mm, without those spanning a gap."""
    from scipy.spatial import Delaunay, cKDTree

    if len(coords) < 3:
        return np.zeros((0, 3), int)
    tri = Delaunay(coords).simplices
    d, _ = cKDTree(coords).query(coords, k=2)
    h = float(np.median(d[:, 1]))
    side = np.max(
        [np.linalg.norm(coords[tri[:, a]] - coords[tri[:, b]], axis=1) for a, b in ((0, 1), (1, 2), (2, 0))], 0
    )
    return tri[side <= GAP_SPACINGS * h]


def _grid_triangles(keep) -> np.ndarray:
    """Triangles of a (nu, nv) grid (nodes numbered row-major) whose three nodes are all kept."""
    nu, nv = keep.shape
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    b, c, d = a + nv, a + 1, a + nv + 1
    tri = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    k = keep.ravel()
    return tri[k[tri].all(axis=1)]


def _every(n, most) -> np.ndarray:
    return np.arange(n) if n <= most else np.unique(np.linspace(0, n - 1, most).round().astype(int))


def view_figure(cad: CadReport, series):
    """The plotly figure of :func:`part_view`: per face, a ``Mesh3d`` of its measured points at their
    x, y, z (``points``; triangulated in the face's (u, v)) coloured by the first of ``series``
    [(name, (n,) mm)] in µm, and a ``Mesh3d`` of its correction grid's nodes at their place on the
    nominal face (x, y, z, mm) coloured by −dF in µm; a menu switches the series and the correction
    (one colour scale for all the faces of a series)."""
    import plotly.graph_objects as go

    from .. import cad as cadmod

    part = cad.part
    n = len(cad.points)
    keep = _every(n, VIEW_POINTS)
    kept = np.zeros(n, bool)
    kept[keep] = True
    from .freeform import mesh, symmetric_range

    vals = [(name, np.asarray(v, float) * UM) for name, v in series]
    scale = symmetric_range

    hover = "x %{x:.3f} mm<br>y %{y:.3f} mm<br>z %{z:.3f} mm<br>%{intensity:.1f} µm<extra>face {f}</extra>"
    traces, point_idx = [], []
    for f in part.faces:  # type: ignore[attr-defined]
        sel = np.flatnonzero(kept[f.points])
        idx = f.points[sel]
        point_idx.append(idx)
        p = cad.points[idx]
        tri = _point_triangles(f.coords[sel])
        lo, hi = scale(vals[0][1])
        traces.append(
            mesh(
                p,
                tri,
                vals[0][1][idx],
                lo,
                hi,
                showscale=len(traces) == 0,
                colorbar={"title": {"text": "µm"}},
                name=f"face {f.face}, points",
                hovertemplate=hover.replace("{f}", str(f.face)),
            )
        )
    corr = []
    for f in part.faces:  # type: ignore[attr-defined]
        iu, iv = _every(len(f.u), VIEW_NODES), _every(len(f.v), VIEW_NODES)
        U, V = np.meshgrid(f.u[iu], f.v[iv], indexing="ij")
        inside = f.in_face[np.ix_(iu, iv)]
        k = inside.ravel()
        # the nodes on the trimmed face only, the grid's triangles renumbered among them
        number = np.cumsum(k) - 1
        tri = number[_grid_triangles(inside)]
        p = cadmod.face_evaluate(part.nominal_faces[f.face], U.ravel()[k], V.ravel()[k])[0]  # type: ignore[attr-defined]
        corr.append((p, tri, -f.df_grid[np.ix_(iu, iv)].ravel()[k] * UM))
    lo_c, hi_c = scale(np.concatenate([c for _, _, c in corr]))
    first_corr = len(traces)
    for f, (p, tri, c) in zip(part.faces, corr):  # type: ignore[attr-defined]
        traces.append(
            mesh(
                p,
                tri,
                c,
                lo_c,
                hi_c,
                showscale=len(traces) == first_corr,
                colorbar={"title": {"text": "−dF, µm"}},
                name=f"face {f.face}, correction",
                hovertemplate=hover.replace("{f}", str(f.face)),
                visible=False,
            )
        )
    fig = go.Figure(traces)
    nf = len(point_idx)
    buttons = []
    for name, w in vals:
        lo, hi = scale(w)
        buttons.append(
            {
                "label": name,
                "method": "restyle",
                "args": [
                    {
                        "visible": [True] * nf + [False] * nf,
                        "intensity": [w[i] for i in point_idx] + [c for _, _, c in corr],
                        "cmin": [lo] * nf + [lo_c] * nf,
                        "cmax": [hi] * nf + [hi_c] * nf,
                    }
                ],
            }
        )
    buttons.append(
        {"label": "correction −dF (to be cut)", "method": "restyle", "args": [{"visible": [False] * nf + [True] * nf}]}
    )
    pts = cad.points
    spans = np.maximum(np.ptp(pts, axis=0), 1e-9)
    ratio = spans / spans.max()
    fig.update_layout(
        height=650,
        margin={"l": 0, "r": 0, "t": 30, "b": 0},
        scene={
            "aspectmode": "manual",
            "aspectratio": dict(zip("xyz", np.maximum(ratio, 0.05))),
            "camera": {"eye": {"x": 1.3, "y": -1.5, "z": 1.2}},
            "xaxis": {"title": {"text": "x, mm"}},
            "yaxis": {"title": {"text": "y, mm"}},
            "zaxis": {"title": {"text": "z, mm"}},
        },
        updatemenus=[{"buttons": buttons, "x": 0, "y": 1.06, "xanchor": "left", "yanchor": "top"}],
    )
    return fig


def part_view(cad: CadReport, series, div_id: str = "surface3d") -> str:
    """The interactive 3-D view of a CAD part as HTML (plotly with its library embedded: no network);
    see :func:`view_figure`."""
    fig = view_figure(cad, series)
    n = len(cad.points)
    shown = "" if n <= VIEW_POINTS else f" ({VIEW_POINTS:,} of {n:,} points: every k-th)"
    return (
        "<p>The part in x, y, z (mm, true proportions). The deviation series (µm, along the outward normal) are drawn "
        f"on the measured points at their place on the CAD faces{shown}, triangulated face by face in its (u, v); "
        "'correction −dF' colours each compensated face's surface — its compensation grid's nodes at their place on "
        "the nominal face, not displaced — by −dF in µm (< 0: cut deeper), one scale for all the faces, the "
        "extrapolated strip included. Drag to turn, scroll to zoom, the menu switches.</p>"
        + fig.to_html(full_html=False, include_plotlyjs=True, div_id=div_id, config={"displaylogo": False})
    )
