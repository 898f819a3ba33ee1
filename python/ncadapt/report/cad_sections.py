"""Sections of a compensated CAD part: the part cut by a plane x, y or z = constant (in the CAD
model's frame, mm), and along each cut through a compensated face the measured deviation, the
systematic part dF and the compensation (P_c − P)·n — the CAD counterpart of the height-field
sections of :mod:`ncadapt.report.freeform`.

A cut is found on each compensated face as the zero line of g(u, v) = P(u, v)·e − c (e the
plane's axis, c its position) over the face's compensation grid (contourpy's marching squares),
its vertices then moved onto the plane by Newton steps in (u, v) (|g| ≤ :data:`ON_PLANE` mm) and
kept where they lie on the trimmed face, a piece that leaves the face ended on its trimming edge
(bisection). Positions along a cut are arc lengths in 3-D, mm.
"""

from __future__ import annotations

import html
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from . import figure_png, pyplot, table

UM = 1000.0  # µm per mm
AXES = ("x", "y", "z")
# the cut's vertices lie this close to the plane after the Newton steps, mm
ON_PLANE = 1e-7
NEWTON_STEPS = 8
# a face whose points all lie within this of the plane lies in it: it has no cut, mm
IN_PLANE = 1e-9


@dataclass(frozen=True)
class Cut:
    """One connected cut of a plane through one compensated face.

    ``uv`` (m, 2): the face's parameters along it; ``points`` (m, 3) mm: the nominal face's points
    (on the plane); ``position`` (m,) mm: arc length from the cut's first point; ``systematic``
    (m,) mm: dF (the face's bicubic spline through its grid, along the outward normal);
    ``compensated`` (m,) mm: (P_c − P)·n, the compensated face's offset from the nominal along its
    normal (−dF); ``extrapolated`` (m,) bool: outside the measured hull (dF carried by the border
    rule); ``measured``: indices of the measured points of this face within half their spacing of
    the plane and nearest this cut, ``measured_position`` (k,) mm their position along it."""

    face: int
    uv: np.ndarray
    points: np.ndarray
    position: np.ndarray
    systematic: np.ndarray
    compensated: np.ndarray
    extrapolated: np.ndarray
    measured: np.ndarray
    measured_position: np.ndarray


@dataclass(frozen=True)
class CadSection:
    """The plane ``axis`` = ``at`` (mm, CAD frame) through a compensated part: its ``cuts``, one
    per connected piece on a compensated face, ordered by face and along the plane."""

    axis: str
    at: float
    cuts: tuple[Cut, ...]

    def as_dict(self) -> dict:
        """The section's values for JSON, mm."""
        return {
            "axis": self.axis,
            "at": self.at,
            "cuts": [
                {
                    "face": c.face,
                    "position": c.position.tolist(),
                    "points": c.points.tolist(),
                    "systematic": c.systematic.tolist(),
                    "compensated": c.compensated.tolist(),
                    "extrapolated": c.extrapolated.tolist(),
                    "measured": c.measured.tolist(),
                    "measured_position": c.measured_position.tolist(),
                }
                for c in self.cuts
            ],
        }


def _plane_value(face, u, v, k, at):
    from .. import cad

    return cad.face_evaluate(face, u, v)[0][:, k] - at


def _onto_plane(face, uv, k, at, h):
    """Newton steps in (u, v) along the gradient of g = P·e − c (finite differences of step h)."""
    u, v = uv[:, 0].copy(), uv[:, 1].copy()
    for _ in range(NEWTON_STEPS):
        g = _plane_value(face, u, v, k, at)
        if np.all(np.abs(g) <= ON_PLANE):
            break
        gu = (_plane_value(face, u + h[0], v, k, at) - g) / h[0]
        gv = (_plane_value(face, u, v + h[1], k, at) - g) / h[1]
        d2 = gu * gu + gv * gv
        ok = d2 > 0
        step = np.where(ok, g / np.where(ok, d2, 1.0), 0.0)
        u, v = u - step * gu, v - step * gv
    return np.column_stack([u, v]), np.abs(_plane_value(face, u, v, k, at))


def _lines(f, g):
    """The zero lines of g (nu, nv) over the face's whole (u, v) box, as (m, 2) arrays of (u, v)."""
    import contourpy

    gen = contourpy.contour_generator(f.u, f.v, g.T, line_type=contourpy.LineType.Separate)  # z[j, i] at (u_i, v_j)
    return [np.asarray(line, float) for line in gen.lines(0.0) if len(line) >= 2]


def _edge(face, inside_uv, outside_uv, k, at, h):
    """The point of the segment inside → outside (face parameters) on the face's trimming edge
    (bisection, 40 halvings), moved onto the plane."""
    from .. import cad

    a, b = np.asarray(inside_uv, float), np.asarray(outside_uv, float)
    for _ in range(40):
        m = 0.5 * (a + b)
        if cad.face_inside(face, [m[0]], [m[1]], edges=True)[0]:
            a = m
        else:
            b = m
    return _onto_plane(face, a[None], k, at, h)[0][0]


def _runs(face, line, k, at, h):
    """The pieces of a zero line on the trimmed face, each ended on the trimming edge where it leaves it."""
    from .. import cad

    uv, off = _onto_plane(face, line, k, at, h)
    ok = (off <= 10 * ON_PLANE) & cad.face_inside(face, uv[:, 0], uv[:, 1], edges=True)
    out = []
    j = 0
    while j < len(uv):
        if not ok[j]:
            j += 1
            continue
        e = j
        while e + 1 < len(uv) and ok[e + 1]:
            e += 1
        piece = [uv[j : e + 1]]
        if j > 0:
            piece.insert(0, _edge(face, uv[j], uv[j - 1], k, at, h)[None])
        if e + 1 < len(uv):
            piece.append(_edge(face, uv[e], uv[e + 1], k, at, h)[None])
        run = np.concatenate(piece)
        keep = np.concatenate([[True], np.linalg.norm(np.diff(run, axis=0), axis=1) > 1e-12])
        if keep.sum() >= 2:
            out.append(run[keep])
        j = e + 1
    return out


def _along(points) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def _nearest_on(polyline, position, q):
    """For points q (k, 3): the distance to the polyline (m, 3) and the arc length of the nearest point."""
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    L2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
    t = np.clip(np.einsum("kij,ij->ki", q[:, None, :] - a[None], ab) / L2, 0.0, 1.0)
    near = a[None] + t[..., None] * ab[None]
    d = np.linalg.norm(q[:, None, :] - near, axis=2)
    j = np.argmin(d, axis=1)
    k = np.arange(len(q))
    return d[k, j], position[j] + t[k, j] * np.sqrt(L2[j])


def cad_section(pc, nominal_points, axis: str, at: float) -> CadSection:
    """The plane ``axis`` = ``at`` (``axis`` x, y or z of the CAD frame; ``at`` mm) through the
    compensated faces of ``pc`` (:class:`~ncadapt.processes.freeform.PartCompensation`);
    ``nominal_points`` (n, 3) mm: the measured points projected onto the faces (the measurements'
    ``nominal``). A plane that cuts no compensated face is refused (:class:`~ncadapt.InputError`).

    Examples
    --------
    >>> # sec = cad_section(pc, meas.nominal, "x", 40.0); sec.cuts[0].systematic  # dF along x = 40, mm
    """
    from scipy.interpolate import RegularGridInterpolator
    from scipy.spatial import cKDTree

    from .. import cad

    if axis not in AXES:
        raise InputError(
            f"--section {axis}={at:g}: with --nominal a section is a plane x=…, y=… or z=… (mm, CAD frame)"
        )
    k = AXES.index(axis)
    nominal_points = np.asarray(nominal_points, float)
    cuts, spans = [], []
    for f in pc.faces:
        face = pc.nominal_faces[f.face]
        U, V = np.meshgrid(f.u, f.v, indexing="ij")
        P = cad.face_evaluate(face, U, V)[0].reshape(len(f.u), len(f.v), 3)
        g = P[..., k] - at
        inside = g[f.in_face]
        spans.append((float(P[..., k][f.in_face].min()), float(P[..., k][f.in_face].max())))
        if not (g.min() < 0 < g.max()) or np.ptp(inside) <= IN_PLANE:
            continue
        h = (1e-6 * max(f.u[-1] - f.u[0], 1e-9), 1e-6 * max(f.v[-1] - f.v[0], 1e-9))
        xy = f.coords
        dnn, _ = cKDTree(xy).query(xy, k=2)
        half = 0.5 * float(np.median(dnn[:, 1]))
        pts_face = nominal_points[f.points]
        near = np.flatnonzero(np.abs(pts_face[:, k] - at) <= half)
        face_cuts = []
        for uv in (run for line in _lines(f, g) for run in _runs(face, line, k, at, h)):
            p, n, _ = cad.face_evaluate(face, uv[:, 0], uv[:, 1])
            # along the plane's first other axis where the cut moves along it, else its second
            o = [a for a in range(3) if a != k]
            lead = o[0] if abs(p[-1, o[0]] - p[0, o[0]]) > 1e-9 else o[1]
            if p[-1, lead] < p[0, lead]:
                uv, p, n = uv[::-1], p[::-1], n[::-1]
            dfv = f.df(uv[:, 0], uv[:, 1])
            pcp = f.compensated.point(uv[:, 0], uv[:, 1])
            reg = RegularGridInterpolator((f.u, f.v), f.measured_region.astype(float))(
                np.clip(uv, [f.u[0], f.v[0]], [f.u[-1], f.v[-1]])
            )
            face_cuts.append([f.face, uv, p, _along(p), dfv, np.einsum("ij,ij->i", pcp - p, n), reg < 1 - 1e-9])
        if not face_cuts:
            continue
        # each measured point near the plane goes to its nearest cut
        best = np.full(len(near), np.inf)
        where = np.full(len(near), -1)
        pos = np.zeros(len(near))
        for c_i, c in enumerate(face_cuts):
            if len(near):
                d, s = _nearest_on(c[2], c[3], pts_face[near])
                better = d < best
                best, where, pos = np.where(better, d, best), np.where(better, c_i, where), np.where(better, s, pos)
        for c_i, c in enumerate(face_cuts):
            mine = where == c_i
            j = np.argsort(pos[mine], kind="stable")
            cuts.append(Cut(*c, f.points[near[mine]][j], pos[mine][j]))
    if not cuts:
        lo = min(s[0] for s in spans)
        hi = max(s[1] for s in spans)
        raise InputError(
            f"--section {axis}={at:g}: the plane cuts none of the compensated faces ({axis} {lo:g} … {hi:g} mm)"
        )
    return CadSection(axis, float(at), tuple(cuts))


# ------------------------------------------------------------------------------------ drawing
def _plot(sec: CadSection, deviation):
    plt = pyplot()
    k = AXES.index(sec.axis)
    a, b = (i for i in range(3) if i != k)
    fig, (top, bot) = plt.subplots(2, 1, figsize=(8, 6.2), gridspec_kw={"height_ratios": [1, 1.4]})
    shift = 0.0
    gap = 0.04 * sum(float(c.position[-1]) for c in sec.cuts)
    for i, c in enumerate(sec.cuts):
        colour = f"C{i % 10}"
        top.plot(c.points[:, a], c.points[:, b], "-", color=colour, lw=1.6, label=f"face {c.face}")
        top.plot(*c.points[0, [a, b]], "o", color=colour, ms=4)
        x = c.position + shift
        if c.extrapolated.any():
            step = float(np.median(np.diff(x))) if len(x) > 1 else 0.0
            for j in np.flatnonzero(c.extrapolated):
                bot.axvspan(x[j] - step / 2, x[j] + step / 2, color="0.9", lw=0, zorder=0)
        bot.plot(c.measured_position + shift, np.asarray(deviation)[c.measured] * UM, "o", ms=4, color="0.35")
        bot.plot(x, c.systematic * UM, "-", color="tab:red", lw=1.6)
        bot.plot(x, c.compensated * UM, "-", color="tab:blue", lw=1.6)
        if i:
            bot.axvline(shift - gap / 2, color="k", lw=0.6, ls=":")
        bot.text(shift, 1.0, f" face {c.face}", transform=bot.get_xaxis_transform(), va="top", fontsize=8)
        shift += float(c.position[-1]) + gap
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel(f"{AXES[a]}, mm")
    top.set_ylabel(f"{AXES[b]}, mm")
    top.set_title(f"the cut {sec.axis} = {sec.at:g} mm (nominal; a dot marks where each cut starts)", fontsize=10)
    top.legend(fontsize=8)
    bot.axhline(0, color="k", lw=1.2)
    bot.plot([], [], "o", ms=4, color="0.35", label="measured")
    bot.plot([], [], "-", color="tab:red", lw=1.6, label="systematic dF")
    bot.plot([], [], "-", color="tab:blue", lw=1.6, label="compensated (P_c − P)·n")
    if any(c.extrapolated.any() for c in sec.cuts):
        bot.plot([], [], "s", color="0.9", label="extrapolated strip")
    bot.set_xlabel("mm along the cut (each face's cut from its start)")
    bot.set_ylabel("along the outward normal, µm")
    bot.legend(fontsize=8, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.2), frameon=False)
    fig.tight_layout()
    return figure_png(fig)


def block(sec: CadSection, deviation) -> str:
    """The report's section: the cut's shape, the profiles along it and their values (µm)."""
    key = f"{sec.axis}={sec.at:g}"
    k = AXES.index(sec.axis)
    a, b = (AXES[i] for i in range(3) if i != k)
    tables = []
    for c in sec.cuts:
        rows = [
            (f"{s:.3f}", f"{p[AXES.index(a)]:.4f}", f"{p[AXES.index(b)]:.4f}", f"{d * UM:+.2f}", f"{q * UM:+.2f}", e)
            for s, p, d, q, e in zip(c.position, c.points, c.systematic, c.compensated, c.extrapolated)
        ]
        meas = [(f"{s:.3f}", f"{np.asarray(deviation)[j] * UM:+.2f}") for s, j in zip(c.measured_position, c.measured)]
        tables.append(
            f"<h4>face {c.face}</h4>"
            + table(
                [(r[0], r[1], r[2], r[3], r[4], "yes" if r[5] else "") for r in rows],
                ["along the cut, mm", f"{a}, mm", f"{b}, mm", "systematic, µm", "compensated, µm", "extrapolated"],
            )
            + f"<div class='measured'>{table(meas, ['along the cut, mm', 'measured, µm'])}</div>"
        )
    return (
        f"<p>The plane {sec.axis} = {sec.at:g} mm (CAD frame) through the compensated faces: deviation along the "
        "outward normal against the arc length along each cut (µm; the nominal is the zero line). Measured: the "
        "points of the face within half their spacing of the plane.</p>"
        + _plot(sec, deviation)
        + f"<details id='section-{html.escape(key)}'><summary>values</summary>"
        + "".join(tables)
        + "</details>"
    )
