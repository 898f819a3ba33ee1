"""The NC engine on a corpus of real programs: what it accepts, and whether its corrections are exact.

The corpus (``../shared/corpus/nc`` from the project's root, with ``manifest.tsv``) holds programs
written by other people and their tools. For each program:

1. read it; a refusal (an :class:`~ncadapt.errors.InputError`, or an unsupported construct the
   engine will not correct) is an outcome, but it must name its line;
2. a zero correction must give back the program byte for byte;
3. it is corrected by a shift of 0.05 mm in Z and by a gentle grid field (``dz`` of at most
   0.02 mm) over its feed extent;
4. when LinuxCNC's ``rs274`` runs the input, both corrected programs must run in it too, their rapids
   must end where the input's do in every axis they move (an axis a rapid does not move may stay
   where the corrected motion left it), and their cutting motion must be rs274's motion of the input displaced by
   the field (:func:`compare_motion`), within 5 µm (9 µm in inch programs, which rs274 prints to
   4 decimals of an inch).

``python tests/corpus.py`` prints the outcome per dialect and per program as markdown tables.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import re
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import ncgi  # noqa: E402
from ncadapt import dialects, fields, marlin, nc, sinumerik  # noqa: E402
from ncadapt.errors import InputError, RefusedError  # noqa: E402
from ncadapt.flatten import flatten  # noqa: E402
from rs274 import _PLANES, RS274, Canon, canonical  # noqa: E402

CORPUS = Path(__file__).resolve().parents[1].parent / "shared" / "corpus" / "nc"

#: The displacements the programs are corrected by: a shift in Z, and a grid field of this amplitude.
SHIFT = (0.0, 0.0, 0.05)
AMPLITUDE = 0.02
#: The motion mode a Sinumerik program that moves before stating one is read in: Siemens' setting
#: of $MC_GCODE_RESET_VALUES (the user states the machine's with --start-motion).
START_MOTION = "G1"
#: Agreement of the corrected motion with the displaced input: mm programs, inch (or mixed) programs.
TOL_MM, TOL_INCH = 0.005, 0.009
#: Longest corrected piece (mm): coarser than the default (1 mm) to keep the run short.
MAX_SEGMENT = 5.0
#: Densification of rs274's motion: longest piece (mm) and chord error of arcs (mm).
_STEP, _CHORD = 1.0, 0.0002


# ------------------------------------------------------------------------------------------ corpus
@dataclass(frozen=True)
class Entry:
    file: str
    dialect: str
    source: str
    lines: int
    #: the folder the file is in (the corpus's by default; a flattened copy's for --expand)
    root: Path | None = None
    #: where the file comes from: its repository and its path there
    repo: str = ""
    origin: str = ""

    @property
    def path(self) -> Path:
        return (self.root or CORPUS) / self.file


def manifest() -> list[Entry]:
    """The programs of the corpus (empty when it is absent)."""
    m = CORPUS / "manifest.tsv"
    if not m.is_file():
        return []
    with m.open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    return [
        Entry(r["file"], r["dialect"], r["source"], int(r["lines"]), repo=r["origin_repo"], origin=r["path"])
        for r in rows
    ]


def subprogram_folder(entry: Entry, work: Path) -> Path:
    """A folder holding the Sinumerik subprograms of ``entry``'s repository under the names they
    have there (the corpus prefixes its files' names): the machine's subprogram folder, as the
    repository's users fill it."""
    folder = work / "subprograms"
    folder.mkdir(parents=True, exist_ok=True)
    for e in manifest():
        if e.repo == entry.repo and e.origin.upper().endswith(".SPF"):
            (folder / Path(e.origin).name).write_bytes(e.path.read_bytes())
    return folder


# ------------------------------------------------------------------------------------------ rs274
#: Adjustments that let rs274 run programs written for other controls; each is keyed by the error
#: rs274 gives without it and is applied to the input and to the corrected programs alike.
def _append_end(data: bytes) -> bytes:
    return data + b"\nM2\n"


_K0 = re.compile(rb"\s?[Kk]\s*[+-]?(?:0+\.?0*|\.0+)(?![\d.])")


def _strip_k0(data: bytes) -> bytes:
    return _K0.sub(b"", data)


# Haas auxiliary M codes (chip auger, coolant spigot, air gun, through-spindle coolant): they move
# nothing, and LinuxCNC does not know them
_HAAS_M = re.compile(rb"\bM0*(?:31|33|34|35|83|84|88|89)\b", re.IGNORECASE)


def _strip_haas_m(data: bytes) -> bytes:
    return _HAAS_M.sub(b"", data)


# a P word (dwell) on G81, G73 or G83, which Fanuc/Haas controls ignore there and LinuxCNC refuses
_CYCLE_LINE = re.compile(rb"^.*\bG0*(?:81|73|83)(?![\d.]).*$", re.IGNORECASE | re.MULTILINE)
_P_WORD = re.compile(rb"\s?P\s*[+-]?(?:\d+\.?\d*|\.\d+)", re.IGNORECASE)


def _strip_cycle_p(data: bytes) -> bytes:
    return _CYCLE_LINE.sub(lambda m: _P_WORD.sub(b"", m.group(0)), data)


def _feed_first(data: bytes) -> bytes:
    """A feed rate before the program: one that gives none (a program that only states positions,
    or a Sinumerik machine's feed from its settings) moves the same, and rs274 refuses G1 at F0."""
    head = re.match(rb"(?:[ \t]*(?:%[^\n]*)?\r?\n)*", data)  # after the % line (and blank lines) it starts with
    at = head.end() if head else 0
    return data[:at] + b"F1000\n" + data[at:]


def _strip_bom(data: bytes) -> bytes:
    """Without the UTF-8 byte order mark an editor put first, which LinuxCNC reads as a character."""
    return data.removeprefix(b"\xef\xbb\xbf")


def _strip_u(data: bytes) -> bytes:
    """Without U words: a Marlin program's extruder, carried as U, which rs274 has no axis for."""
    return re.sub(rb"[ \t]*U[-+]?(?:\d+\.?\d*|\.\d+)", b"", data)


ADJUSTMENTS = {
    "File ended with no percent sign or program end": ("M2 appended", _append_end),
    "K word given for arc in xy plane": ("K0 words removed", _strip_k0),
    "Unknown m code used: M3": ("Haas auxiliary M codes removed", _strip_haas_m),
    "Unknown m code used: M8": ("Haas auxiliary M codes removed", _strip_haas_m),
    "P word with no G2 G3 G4 G10 G64": ("P words of G81/G73/G83 removed", _strip_cycle_p),
    "Bad character 'u' used": ("U words (a Marlin program's E) removed", _strip_u),
    "Cannot do g1 with zero feed rate": ("F1000 before the program", _feed_first),
    "Bad character '\\357' used": ("byte order mark removed", _strip_bom),
}


#: The diameter of every tool of :func:`tool_table`, inch (rs274 reads a table in inches
#: without an INI file). 0: the comparison here reads rs274's motion as the programmed points,
#: which cutter compensation moves by the radius; compensated motion with a radius is compared
#: in tests/test_cutter_comp.py (the corpus programs included).
TOOL_DIAMETER_INCH = 0.0
#: The tools of :func:`tool_table` (number: diameter mm).
TOOLS = {t: TOOL_DIAMETER_INCH * 25.4 for t in range(1, 100)}


def tool_table(folder: Path) -> Path:
    """A tool table with tools 1-99 (length 0, diameter :data:`TOOL_DIAMETER_INCH`), for programs
    that change tools or compensate the cutter radius."""
    p = folder / "tools.tbl"
    if not p.exists():
        p.write_text("".join(f"T{t} P{t} Z0 D{TOOL_DIAMETER_INCH} ;\n" for t in range(1, 100)))
    return p


def run_rs274(path: Path, tools: Path, timeout: float = 120) -> Canon:
    """``rs274 -t tools -g path``: its canonical motion in mm."""
    return canonical(path, timeout=timeout, tools=tools)


def rs274_input(path: Path, work: Path) -> tuple[Canon, list[str]]:
    """rs274's motion of a program, with the adjustments it needed (their names)."""
    tools = tool_table(work)
    data = path.read_bytes()
    used: list[str] = []
    while True:
        p = work / ("in" + path.suffix)
        p.write_bytes(adjust(data, used))
        canon = run_rs274(p, tools)
        new = [k for k in ADJUSTMENTS if canon.error and k in canon.error and k not in used]
        if canon.error is None or not new:
            return canon, used
        used += new


def adjust(data: bytes, used: list[str]) -> bytes:
    for k in used:
        data = ADJUSTMENTS[k][1](data)
    return data


# ------------------------------------------------------------------------------------------ geometry
def rebase(canon: Canon, base: np.ndarray) -> Canon:
    """``canon`` with every end (and arc centre) less ``base``: rs274's motion in the program's
    coordinates where its first move is, those the engine keeps positions (and a field) in, when
    the program sets offsets before it moves (``G10 L2 P0 X450`` first)."""
    arcs = [
        None if a is None else (a[0], a[1] - base[_PLANES[a[3]][0]], a[2] - base[_PLANES[a[3]][1]], a[3])
        for a in canon.arcs
    ]
    return dataclasses.replace(canon, ends=canon.ends - base[None, :], arcs=arcs)


def densify(canon: Canon, sel: np.ndarray, step: float = _STEP, chord: float = _CHORD):
    """Points along the moves ``sel`` (indices into ``canon``), each from its start (the previous
    move's end; rs274 starts at 0) to its end: straight moves in pieces of at most ``step``, arcs in
    pieces within ``chord`` of the arc (and at most ``step``). Returns the points (n, 3), the offset
    of each move's points (len(sel) + 1; every move has at least its start and end) and the arc
    length of every point from its move's start."""
    ends = canon.ends[:, :3]
    starts = np.vstack([np.zeros((1, 3)), ends[:-1]])
    sel = np.asarray(sel, dtype=np.int64)
    s, e = starts[sel], ends[sel]
    n = np.ones(len(sel), dtype=np.int64)
    is_arc = np.array([canon.kinds[k] == "arc" for k in sel], dtype=bool)
    # straight moves
    length = np.linalg.norm(e - s, axis=1)
    if np.isfinite(step):
        n = np.maximum(1, np.ceil(length / step).astype(np.int64))
    # arcs: angles in their plane; the radius and the normal coordinate change linearly with angle
    arc_info = {}
    for i in np.flatnonzero(is_arc):
        rot, c1, c2, plane = canon.arcs[sel[i]]
        a1, a2, an = _PLANES[plane]
        u0, v0 = s[i, a1] - c1, s[i, a2] - c2
        u1, v1 = e[i, a1] - c1, e[i, a2] - c2
        r0, r1 = math.hypot(u0, v0), math.hypot(u1, v1)
        t0, t1 = math.atan2(v0, u0), math.atan2(v1, u1)
        sweep = (t1 - t0) % (2 * math.pi) if rot > 0 else (t0 - t1) % (2 * math.pi)
        if math.hypot(u1 - u0, v1 - v0) <= 3 * canon.resolution_mm + 1e-9 and sweep < 1.0:
            sweep = 2 * math.pi  # it ends where it starts: a full circle
        sweep += 2 * math.pi * (abs(rot) - 1)
        sweep = sweep if rot > 0 else -sweep
        r = max(r0, r1, 1e-9)
        da = 2 * math.acos(max(-1.0, 1 - chord / r)) if chord < r else math.pi / 2
        arc_len = math.hypot(abs(sweep) * r, e[i, an] - s[i, an])
        n[i] = max(
            1, math.ceil(abs(sweep) / min(da, math.pi / 2)), math.ceil(arc_len / step) if np.isfinite(step) else 1
        )
        arc_info[i] = (a1, a2, an, c1, c2, r0, r1, t0, sweep)
    off = np.zeros(len(sel) + 1, dtype=np.int64)
    off[1:] = np.cumsum(n + 1)
    move = np.repeat(np.arange(len(sel)), n + 1)
    t = (np.arange(off[-1]) - off[move]) / n[move]
    pts = s[move] + t[:, None] * (e[move] - s[move])
    for i, (a1, a2, _an, c1, c2, r0, r1, t0, sweep) in arc_info.items():
        tt = t[off[i] : off[i + 1]]
        ang = t0 + tt * sweep
        rr = r0 + tt * (r1 - r0)
        q = pts[off[i] : off[i + 1]]
        q[:, a1] = c1 + rr * np.cos(ang)
        q[:, a2] = c2 + rr * np.sin(ang)
        q[0], q[-1] = s[i], e[i]  # exact ends, as rs274 printed them
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    arclen = cum - cum[off[move]]
    return pts, off, arclen


def _near(
    pts: np.ndarray,
    grp: np.ndarray,
    poly: np.ndarray,
    off: np.ndarray,
    arclen: np.ndarray,
    k: int = 4,
    chunk: int = 200_000,
):
    """Distance from every point to the polyline of its group (``poly[off[g]:off[g+1]]``), and the
    arc length along that polyline of the nearest place.

    The segments tried are those next to the ``k`` vertices of the group nearest to the point: on a
    polyline that follows a line or an arc, the segment nearest a point ends at one of them.
    """
    from scipy.spatial import cKDTree

    dmin = np.full(len(pts), np.inf)
    where = np.full(len(pts), np.nan)
    if not len(pts):
        return dmin, where
    pg = np.repeat(np.arange(len(off) - 1), np.diff(off))
    # a fourth coordinate keeps the groups far apart (the same value within a group, exactly)
    big = 1e7
    tree = cKDTree(np.column_stack([poly, pg * big]))
    kk = min(k, len(poly))
    for i0 in range(0, len(pts), chunk):
        sl = slice(i0, i0 + chunk)
        p, g = pts[sl], grp[sl]
        _, idx = tree.query(np.column_stack([p, g * big]), k=kk)
        idx = np.asarray(idx).reshape(len(p), kk)
        lo, hi = off[g][:, None], off[g + 1][:, None] - 1
        valid = pg[idx] == g[:, None]
        a = np.concatenate([np.clip(idx - 1, lo, hi), idx], axis=1)
        b = np.concatenate([idx, np.clip(idx + 1, lo, hi)], axis=1)
        valid = np.concatenate([valid, valid], axis=1)
        A, B = poly[a], poly[b]
        AB = B - A
        L2 = np.einsum("ijk,ijk->ij", AB, AB)
        dot = np.einsum("ijk,ijk->ij", p[:, None, :] - A, AB)
        t = np.clip(np.divide(dot, L2, out=np.zeros_like(dot), where=L2 > 0), 0.0, 1.0)
        d = np.linalg.norm(A + t[..., None] * AB - p[:, None, :], axis=2)
        d[~valid] = np.inf
        best = np.argmin(d, axis=1)
        r = np.arange(len(p))
        dmin[sl] = d[r, best]
        ab, tb = a[r, best], t[r, best]
        where[sl] = arclen[ab] + tb * np.sqrt(L2[r, best])
    return dmin, where


# ------------------------------------------------------------------------------------------ comparison
def compare_motion(
    inp: Canon,
    out: Canon,
    displaced: np.ndarray,
    field,
    tol: float,
    lines=None,
    max_piece: float | None = None,
    start_known: np.ndarray | None = None,
    cycle: np.ndarray | None = None,
) -> list[str]:
    """Compare rs274's motion of a corrected program (``out``) with its motion of the input
    (``inp``): the rapids must be the input's, and each cutting move ``k`` must follow the input's
    path, displaced by ``field`` where ``displaced[k]`` (the moves the engine can correct), as it
    is elsewhere.

    The corrected program may split a move into pieces and write arcs as straight pieces: the
    pieces replacing move ``k`` end where move ``k`` ends (displaced), every point of them is within
    ``tol`` of the displaced path of move ``k``, in order, and every point of that path is within
    ``tol`` of them. Rapids are not corrected, so where the motion passes from an uncorrected point
    to a corrected move (after a rapid, or after a move the engine leaves as written), the first
    piece connects the two: its end must be on the path, and the path is not required near it
    before its end. With ``max_piece`` (the correction's max_segment) that holds only for the first
    ``max_piece`` mm of the move: beyond, the path must be followed even if the first piece goes on
    (a straight move keeps one piece where it is straight) -- unless the engine does not know where
    the move starts (``start_known[k]`` False: a straight move is then corrected at its end only).

    ``cycle[k]`` marks the moves of canned cycles: a hole moves as a whole, so its rapids may end
    displaced by the field too (or where the input's end: the initial level of G98), and before
    such a rapid the output may make one more rapid along Z no longer than twice the largest
    displacement (LinuxCNC rapids down to a corrected R plane lower than the one it is at, at
    the hole, or up to one higher than the tool, where the tool is).

    ``lines`` (the source line of every input move) names the moves in the problems. Returns the
    problems found, each with how often it occurs and its first occurrence (empty: the motions agree).
    """

    def where(k):
        return f"line {lines[k]}" if lines is not None else f"move {k}"

    def xyz(v):
        return np.round(np.asarray(v, dtype=float)[:3], 4).tolist()

    n_in, n_out = len(inp.kinds), len(out.kinds)
    cut = np.array([k != "traverse" for k in inp.kinds], dtype=bool)
    cycle = np.zeros(n_in, dtype=bool) if cycle is None else np.asarray(cycle, dtype=bool)
    # a cycle's rapid moves with its hole: the field at its own end, or at the cutting move
    # before or after it (a rise to the R plane is made where the previous hole was)
    cyc_target = np.repeat(inp.ends[None, :, :3], 3, axis=0)
    slack = 0.0
    if cycle.any():
        idx = np.arange(n_in)
        cut_at = np.where(cut, idx, -1)
        before = np.maximum.accumulate(cut_at)
        after = np.minimum.accumulate(np.where(cut, idx, n_in)[::-1])[::-1]
        sel = np.flatnonzero(cycle)
        for c, src in enumerate((sel, before[sel], after[sel])):
            ok = (src >= 0) & (src < n_in)
            at = inp.ends[np.where(ok, src, sel), :3]
            cyc_target[c, sel] += np.asarray(field(at), dtype=float)
        slack = 2 * float(np.abs(cyc_target[:, sel] - inp.ends[sel, :3]).max()) + tol
    displaced = np.asarray(displaced, dtype=bool) & cut
    # where each cutting move must end
    target = inp.ends[:, :3].copy()
    if displaced.any():
        target[displaced] += np.asarray(field(inp.ends[displaced, :3]), dtype=float)
    ie6, oe6 = inp.ends, out.ends
    oe, okind, tgt = out.ends[:, :3].tolist(), out.kinds, target.tolist()
    istart = np.vstack([np.zeros((1, 3)), inp.ends[:-1, :3]])
    zero_len = (np.abs(inp.ends[:, :3] - istart).max(axis=1) == 0) & np.array(
        [k == "feed" for k in inp.kinds], dtype=bool
    )

    # 1. the sequence: rapids one for one, each cutting move a run of output moves ending at its target
    problems: list[str] = []
    rapids: list[tuple[int, int, int]] = []  # (input move, output move, the cutting move before it or -1)
    groups = np.full((n_in, 2), -1, dtype=np.int64)
    j = 0
    last_cut = -1  # the last cutting move since a rapid
    for k in range(n_in):
        if not cut[k]:
            # an extra rapid along Z before a cycle's rapid (to a lower corrected R plane)
            def ends_here(jj, k=k):
                e = oe6[jj, :3]
                return np.abs(e - ie6[k, :3]).max() <= tol or (np.abs(e - cyc_target[:, k]).max(axis=1) <= tol).any()

            def along_z(a, b):
                return (
                    max(abs(oe[a][0] - oe[b][0]), abs(oe[a][1] - oe[b][1])) <= tol and abs(oe[a][2] - oe[b][2]) <= slack
                )

            # down at the hole (j then j + 1), or up where the tool stands (j - 1 then j: LinuxCNC
            # rises to a corrected R plane higher than the tool first)
            if (
                cycle[k]
                and j + 1 < n_out
                and okind[j] == okind[j + 1] == "traverse"
                and (along_z(j, j + 1) or (j > 0 and along_z(j - 1, j)))
                # (j may end near this rapid's end too, at a hole moved alike: when the input
                # cuts next, the rapid is the one just before the cut)
                and (not ends_here(j) or (k + 1 < n_in and cut[k + 1]))
                and ends_here(j + 1)
            ):
                j += 1
            if j >= n_out or okind[j] != "traverse":
                got = "the end of the motion" if j >= n_out else f"a {okind[j]} move to {xyz(oe6[j])}"
                return [f"{where(k)}: the rapid to {xyz(ie6[k])} became {got}"]
            rapids.append((k, j, last_cut))
            j += 1
            last_cut = -1
            continue
        last_cut = k
        t = tgt[k]
        j0 = j
        while j < n_out and okind[j] != "traverse":
            p = oe[j]
            j += 1
            if abs(p[0] - t[0]) <= tol and abs(p[1] - t[1]) <= tol and abs(p[2] - t[2]) <= tol:
                # of the moves in a row that end this near, the nearest: a move may be split a few µm
                # before its end (at a grid line)
                best = math.dist(p, t)
                while j < n_out and okind[j] != "traverse":
                    q = oe[j]
                    if max(abs(q[0] - t[0]), abs(q[1] - t[1]), abs(q[2] - t[2])) > tol or math.dist(q, t) >= best:
                        break
                    best = math.dist(q, t)
                    j += 1
                break
        else:
            if zero_len[k]:  # a move that goes nowhere may be left out
                j = j0
                continue
            nxt = "a rapid" if j < n_out else "the end of the motion"
            what = "displaced " if displaced[k] else ""
            return [
                f"{where(k)}: the corrected motion reaches {nxt} without passing the {what}end "
                f"{xyz(target[k])} of this {inp.kinds[k]} move"
                + (f" (first output move after the previous: to {xyz(oe6[j0])})" if j0 < n_out else "")
            ]
        groups[k] = (j0, j)
    if j < n_out:
        return [
            f"the corrected motion has {n_out - j} move(s) more after the input's last, first a "
            f"{okind[j]} move to {xyz(oe6[j])}"
        ]
    # rapids end where they did: every axis they move; an axis a rapid does not move (to rs274's
    # printed resolution) may also stay where the corrected motion left it (the engine keeps the
    # axes a rapid names, and leaves the others where they are, as the machine does)
    if rapids:
        rk, rj, rc = np.array(rapids).T
        at_target = np.abs(oe6[rj] - ie6[rk]) <= tol
        # a canned cycle's rapid may end displaced with its hole
        moved = np.zeros_like(at_target)
        # (per axis: at the initial level of G98 a rapid moves in X and Y with the hole, not in Z)
        moved[:, :3] = (np.abs(oe6[rj, :3][None] - cyc_target[:, rk]) <= tol).any(axis=0)
        at_target |= moved & cycle[rk][:, None]
        istart6 = np.vstack([np.zeros((1, 6)), ie6[:-1]])[rk]
        ostart6 = np.vstack([np.zeros((1, 6)), oe6[:-1]])[rj]
        stays = (np.abs(ie6[rk] - istart6) <= inp.resolution_mm + 1e-9) & (np.abs(oe6[rj] - ostart6) <= tol)
        stays[:, 3:] = False  # rotary axes are never corrected
        bad = np.flatnonzero(~(at_target | stays).all(axis=1))
        if len(bad):
            k, jj, c = rk[bad[0]], rj[bad[0]], rc[bad[0]]
            why = ""
            if c >= 0 and displaced[c] and np.abs(oe6[jj, :3] - ie6[k, :3] - (target[c] - ie6[c, :3])).max() <= tol:
                why = f" (moved by the displacement of {where(c)}, the cutting move before it)"
            problems.append(
                f"{len(bad)} rapid(s) moved, first {where(k)}: the rapid to {xyz(ie6[k])} ends at {xyz(oe6[jj])}{why}"
            )
    # rotary axes end where they did
    gk = np.flatnonzero(groups[:, 1] > groups[:, 0])
    bad = np.flatnonzero(np.abs(oe6[groups[gk, 1] - 1, 3:] - ie6[gk, 3:]).max(axis=1) > 1e-3) if len(gk) else []
    if len(bad):
        k = gk[bad[0]]
        problems.append(
            f"{len(bad)} rotary end(s) changed, first {where(k)}: "
            f"{oe6[groups[k, 1] - 1, 3:].round(4).tolist()}, not {ie6[k, 3:].round(4).tolist()}"
        )

    # 2. the path of every cutting move: expected points (input densified, displaced) against the
    # output pieces (arcs densified)
    ks = np.flatnonzero(cut & (groups[:, 1] > groups[:, 0]))
    if not len(ks):
        return problems
    xp, xoff, xlen = densify(inp, ks)
    xmove = np.repeat(np.arange(len(ks)), np.diff(xoff))
    dmask = displaced[ks][xmove]
    if dmask.any():
        xp[dmask] += np.asarray(field(xp[dmask]), dtype=float)
    # the state before each move: a rapid (and the start) leaves the tool at an uncorrected point
    prev_state = np.zeros(n_in, dtype=bool)
    state = False
    for k in range(n_in):
        prev_state[k] = state
        state = bool(displaced[k]) if cut[k] else False
    transition = prev_state[ks] != displaced[ks]
    # the output pieces of each move, densified; the first point of every piece is the previous end
    j0s, j1s = groups[ks, 0], groups[ks, 1]
    osel = np.concatenate([np.arange(a, b) for a, b in zip(j0s, j1s)])
    op, ooff, _ = densify(out, osel, step=np.inf)
    opiece = np.repeat(np.arange(len(osel)), np.diff(ooff))
    omove = np.repeat(np.arange(len(ks)), j1s - j0s)[opiece]
    is_first = np.zeros(len(osel), dtype=bool)
    is_first[np.concatenate([[0], np.cumsum(j1s - j0s)[:-1]])] = True
    piece_start = np.zeros(len(op), dtype=bool)
    piece_start[ooff[:-1]] = True
    piece_end = np.zeros(len(op), dtype=bool)
    piece_end[ooff[1:] - 1] = True
    conn = transition[omove] & is_first[opiece]  # points of a connecting first piece

    def report(what, idx, moves, pts, dist):
        if len(idx):
            k = ks[moves[idx[0]]]
            problems.append(
                f"{len(idx)} point(s) {what}, first {where(k)} ({inp.kinds[k]}"
                f"{', displaced' if displaced[k] else ''}): {xyz(pts[idx[0]])}, "
                f"{dist[idx[0]] * 1000:.1f} µm off"
            )

    # (a) every output point on the expected path, in order (of a connecting piece: its end only)
    check = ~piece_start & (~conn | piece_end)
    pa, ga = op[check], omove[check]
    dmin, along = _near(pa, ga, xp, xoff, xlen)
    report("of the corrected motion off the input's path", np.flatnonzero(dmin > tol), ga, pa, dmin)
    # (the last point of a move is its end, which the sequence placed: a closed arc ends where it starts)
    inner = (ga[1:] == ga[:-1]) & (ga[1:] == np.append(ga[2:], -1))
    back = np.flatnonzero(inner & (along[1:] < along[:-1] - 2 * tol))
    back = back[[not _retraces(inp, ks[ga[b + 1]]) for b in back]] if len(back) else back
    if len(back):
        k = ks[ga[back[0] + 1]]
        problems.append(
            f"{len(back)} point(s) of the corrected motion go back along the path, first {where(k)} "
            f"({inp.kinds[k]}) at {xyz(pa[back[0] + 1])}"
        )
    # (b) every expected point near the output, but for the start of a move after an uncorrected point
    conn_end = np.flatnonzero(conn[check] & piece_end[check])
    free = np.zeros(len(ks))  # the length of each move, from its start, the output need not follow
    free[ga[conn_end]] = along[conn_end]
    if max_piece is not None and len(conn_end):
        m = ga[conn_end]
        known = np.ones(len(m), dtype=bool) if start_known is None else np.asarray(start_known, dtype=bool)[ks[m]]
        bounded = displaced[ks[m]] & known
        free[m[bounded]] = np.minimum(free[m[bounded]], 1.05 * max_piece)
    keep = ~piece_start | is_first[opiece]  # each move: from the start of its first piece
    pm = omove[keep]  # pieces of one move are contiguous: its kept points follow one another
    poly = op[keep]
    poff = np.searchsorted(pm, np.arange(len(ks) + 1))
    need = xlen > free[xmove] + tol
    dmin, _ = _near(xp[need], xmove[need], poly, poff, np.zeros(len(poly)))
    report("of the input's path the corrected motion misses", np.flatnonzero(dmin > tol), xmove[need], xp[need], dmin)
    return problems


def _retraces(canon: Canon, k: int) -> bool:
    """An arc of more than one turn with no motion along its normal passes its points twice."""
    a = canon.arcs[k]
    if a is None or abs(a[0]) <= 1:
        return False
    an = _PLANES[a[3]][2]
    prev = canon.ends[k - 1, an] if k else 0.0
    return abs(canon.ends[k, an] - prev) < 1e-9


def displaced_moves(prog: nc.Program, canon: Canon):
    """Which of rs274's moves the engine corrects, their lines and whether the engine knows where
    they start.

    The engine's blocks are rs274's moves one for one; a cutting block whose position the engine
    knows is corrected; the others are left as written (and the correction warns of them). Returns
    (displaced, lines, start_known, None), or (None, None, None, why) when the engine's reading is
    not rs274's.
    """
    b = prog.blocks
    n = len(canon.kinds)
    m = min(n, len(b))
    tol = np.full(6, canon.resolution_mm + 1e-9)
    tol[3:] = 5e-5 + 1e-9
    ours = b.end[:m, :6]
    known = np.isfinite(ours)
    bad = (known & (np.abs(np.where(known, ours, 0.0) - canon.ends[:m]) > tol)).any(axis=1)
    kinds = np.array(["traverse", "feed", "arc", "arc", "", "spline", "spline"])[b.motion[:m]]
    bad |= (kinds != "") & (kinds != np.array(canon.kinds[:m], dtype="<U8"))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        return (
            None,
            None,
            None,
            (
                f"line {b.line[k]}: the engine reads a {nc.MOTIONS[b.motion[k]]} move to "
                f"{np.round(ours[k, :3], 4).tolist()}, rs274 a {canon.kinds[k]} to "
                f"{canon.ends[k, :3].round(4).tolist()} (move {k})"
            ),
        )
    if len(b) != n:
        return None, None, None, f"the engine reads {len(b)} moves, rs274 {n}"
    # (every cutting move of a canned cycle moves with its hole)
    displaced = (b.supported | b.cycle) & (b.motion >= 1) & (b.motion <= 3)
    start_known = np.zeros(n, dtype=bool)
    start_known[1:] = np.isfinite(b.end[:-1, :3]).all(axis=1)
    return displaced, b.line, start_known, None


# ------------------------------------------------------------------------------------------ one program
def gentle_field(extent) -> fields.GridField:
    """An 11 x 11 grid of ``dz = 0.02 sin(x/L) cos(y/L)`` over the feed extent padded by a tenth (and
    1 mm), L a third of its width; points outside hold the border value."""
    if extent:
        (x0, x1), (y0, y1) = extent["x"], extent["y"]
    else:
        x0 = x1 = y0 = y1 = 0.0
    w = max(x1 - x0, y1 - y0)
    m = 0.1 * w + 1.0
    xs = np.linspace(x0 - m, x1 + m, 11)
    ys = np.linspace(y0 - m, y1 + m, 11)
    L = (w + 2 * m) / 3
    X, Y = np.meshgrid(xs, ys)
    return fields.GridField(xs, ys, AMPLITUDE * np.sin(X / L) * np.cos(Y / L), outside="clamp")


@dataclass
class Result:
    file: str
    dialect: str
    lines: int
    outcome: str = ""  # "accepted", "accepted (--expand)", "refused: line N: why", "error: ..."
    reason: str = ""  # the refusal without its numbers, for the summary
    refusal_line: int | None = None
    units: str = ""
    identity: bool | None = None
    identity_detail: str = ""
    motion: str = ""  # "matched", "mismatch", "no rs274", "rs274 rejects the input"
    motion_detail: str = ""
    uncorrected: int = 0  # cutting moves the engine leaves as written (position unknown)
    adjusted: list[str] = field(default_factory=list)  # what rs274 needed to run the programs
    seconds: float = 0.0

    @property
    def accepted(self) -> bool:
        return self.outcome.startswith("accepted")

    @property
    def refused(self) -> bool:
        return self.outcome.startswith("refused")


def _first_line(e: BaseException) -> str:
    return str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__


def _refusal_line(e: RefusedError) -> int | None:
    for d in e.details:
        if isinstance(d, dict) and d.get("line"):
            return int(d["line"])
    m = re.search(r"\bline (\d+)", e.message)
    return int(m.group(1)) if m else None


def _generic(msg: str) -> str:
    """A message without its numbers (those in words such as G41 stay)."""
    msg = re.sub(r"\s*\([-+]?\d*\.?\d+\)|(?<![\w.])[-+]?\d*\.?\d+(?![\w.])", "", msg)
    return re.sub(r"\s+", " ", msg).strip()


def _first_difference(a: bytes, b: bytes) -> str:
    la, lb = a.splitlines(), b.splitlines()
    for i, (x, y) in enumerate(zip(la, lb)):
        if x != y:
            return f"line {i + 1}: {x[:60]!r} became {y[:60]!r}"
    return f"{len(la)} lines became {len(lb)}" if len(la) != len(lb) else "line ends differ"


def run(entry: Entry, work: Path) -> Result:
    """Everything the corpus test checks, for one program (``work``: a folder for temporary files)."""
    t0 = time.perf_counter()
    r = Result(entry.file, entry.dialect, entry.lines)
    try:
        _run(entry, work, r)
    except Exception as e:  # noqa: BLE001 - an unexpected error is an outcome of the corpus run
        r.outcome = f"error: {type(e).__name__}: {_first_line(e)}"
        r.reason = f"{type(e).__name__}"
    r.seconds = time.perf_counter() - t0
    return r


def _run(entry: Entry, work: Path, r: Result) -> None:
    work.mkdir(parents=True, exist_ok=True)
    try:
        dialect = dialects.resolve(entry.path).engine  # as `ncadapt correct` does first (--dialect auto)
    except InputError as e:
        d = dialects.detect(entry.path.read_bytes()[: dialects.HEAD_BYTES], entry.file)
        r.outcome = f"refused: line {e.line}: {dialects.NAMES[d.name]} program ({d.text}), syntax not read"
        r.reason, r.refusal_line = f"{dialects.NAMES[d.name]} program, syntax not read", e.line
        return
    if dialect in ("sinumerik", "marlin") and entry.root is None:
        _run_translated(entry, work, r, dialect)
        return
    try:
        # the tool table rs274 is given, so cutter compensation is followed as rs274 follows it
        prog = nc.read(entry.path, dialect=dialect, tools=TOOLS)
        uns = prog.unsupported
    except InputError as e:
        r.outcome = f"refused: line {e.line}: {e.message}"
        r.reason, r.refusal_line = _generic(e.message), e.line
        return
    r.units = prog.units
    flow = ("O-word", "parameters or expressions", "subprogram M")
    if (
        uns
        and entry.root is None
        and dialect in ("linuxcnc", "linuxcnc-lathe", "fanuc")
        and any(u.construct.startswith(flow) for u in uns)
    ):
        # as `ncadapt correct --expand`: the flattened program is what is corrected and checked
        try:
            flat = flatten(entry.path.read_bytes(), entry.file, dialect.removesuffix("-lathe"))
        except InputError as e:
            r.outcome = f"refused: line {e.line}: {e.message} (--expand)"
            r.reason, r.refusal_line = _generic(e.message) + " (--expand)", e.line
            return
        folder = work / "flat"
        folder.mkdir(exist_ok=True)
        (folder / entry.file).write_bytes(flat.data)
        _run(dataclasses.replace(entry, root=folder), work, r)
        if r.outcome.startswith("accepted"):
            r.outcome = r.outcome.replace("accepted", "accepted (--expand)", 1)
            if r.motion == "matched":
                problems = _written_runs_as_flat(
                    entry, folder / entry.file, dialect, work, "--expand-cycles" in r.outcome
                )
                if problems:
                    r.motion, r.motion_detail = "mismatch", "written: " + "; ".join(problems)
        return
    if uns:
        u = uns[0]
        r.outcome = f"refused: line {u.line}: {u.construct}" + (f" (+{len(uns) - 1} more)" if len(uns) > 1 else "")
        r.reason, r.refusal_line = u.construct, u.line
        return
    try:
        zero = prog.correct(fields.Shift((0.0, 0.0, 0.0)))
        r.identity = zero.data == prog.data
        if not r.identity:
            r.identity_detail = _first_difference(prog.data, zero.data)
        grid = gentle_field(prog.inspect()["extents"]["feed"])
        expand_cycles = False
        try:
            outs = {
                "shift": prog.correct(fields.Shift(SHIFT), max_segment=MAX_SEGMENT),
                "grid": prog.correct(grid, max_segment=MAX_SEGMENT),
            }
        except InputError as e:
            if "use --expand-cycles" not in e.message:
                raise
            # as the user is told: the cycles written as the moves they make
            expand_cycles = True
            outs = {
                "shift": prog.correct(fields.Shift(SHIFT), max_segment=MAX_SEGMENT, expand_cycles=True),
                "grid": prog.correct(grid, max_segment=MAX_SEGMENT, expand_cycles=True),
            }
    except RefusedError as e:
        # (the message names the file and the line first, and ends saying nothing was written)
        why = re.sub(r"^.*?: line \d+: |; nothing written$", "", _first_line(e))
        r.refusal_line = _refusal_line(e)
        r.outcome = f"refused: line {r.refusal_line}: {why}" if r.refusal_line else f"refused: {why}"
        r.reason = _generic(why)
        return
    except InputError as e:  # a construct the correction cannot write faithfully, at its line
        r.outcome = f"refused: line {e.line}: {e.message}"
        r.reason, r.refusal_line = _generic(e.message), e.line
        return
    r.outcome = "accepted (--expand-cycles)" if expand_cycles else "accepted"
    fieldof = {"shift": fields.Shift(SHIFT), "grid": grid}
    if RS274 is None:
        r.motion = "no rs274"
        return
    canon_in, used = rs274_input(entry.path, work)
    r.adjusted = [ADJUSTMENTS[k][0] for k in used]
    if canon_in.error is not None:
        r.motion = "rs274 rejects the input"
        r.motion_detail = canon_in.error.replace("\n", " | ")
        return
    if canon_in.splines:
        r.motion = "not compared"
        r.motion_detail = "rs274 prints no point of a spline (NURBS_FEED); LinuxCNC's G5 and G5.1 are checked in tests/test_splines.py"
        return
    tol = TOL_MM if r.units == "mm" else TOL_INCH
    # (offsets the program sets before it moves are the frame of the engine's coordinates)
    base = np.asarray(canon_in.offsets[0], dtype=float) if canon_in.offsets else np.zeros(6)
    canon_in = rebase(canon_in, base)
    displaced, lines, start_known, why = displaced_moves(prog, canon_in)
    details = []
    if why is not None:
        details.append(f"reading: {why}")
    else:
        b = prog.blocks
        # (a G1 that names no axis goes nowhere: the correction does not warn of it)
        still = (b.motion == 1) & (prog._records()["named"] == 0) & ~b.cycle
        r.uncorrected = int((~displaced & ~still & (b.motion >= 1) & (b.motion <= 3)).sum())
        tools = tool_table(work)
        for name, out in outs.items():
            # the moves left as written are those the correction warns of
            said = re.findall(r"([\d,]+) cutting move\(s\) not corrected", " ".join(out.correction.warnings))
            warned = sum(int(n.replace(",", "")) for n in said)
            if warned != r.uncorrected:
                details.append(
                    f"{name}: {r.uncorrected} cutting move(s) left as written, the correction warns of {warned}"
                )
            p = out.write(work / (f"out-{name}" + entry.path.suffix))
            p.write_bytes(adjust(p.read_bytes(), used))
            canon_out = run_rs274(p, tools)
            if canon_out.error is not None:
                why = canon_out.error.replace("\n", " | ")
                details.append(f"{name}: rs274 rejects the corrected program: {why}")
                continue
            canon_out = rebase(canon_out, base)
            problems = compare_motion(
                canon_in, canon_out, displaced, fieldof[name], tol, lines, MAX_SEGMENT, start_known, prog.blocks.cycle
            )
            if problems:
                details.append(f"{name}: " + "; ".join(problems))
    r.motion = "mismatch" if details else "matched"
    r.motion_detail = " || ".join(details)


def _same_motion(a: Canon, b: Canon) -> bool:
    """rs274 runs both alike: the same moves, ending within a unit of its last printed digit
    (the flat program's numbers have six decimals, which rs274 rounds to four again)."""
    tol = 2 * max(a.resolution_mm, b.resolution_mm) + 1e-9
    return a.kinds == b.kinds and bool(np.all(np.abs(a.ends - b.ends) <= tol))


def _written_runs_as_flat(entry: Entry, flat: Path, dialect: str, work: Path, expand_cycles: bool) -> list[str]:
    """`ncadapt correct --expand` writes its correction in place (the program's own lines) or
    straight, which the harness's check of the flat program does not see: rs274 must run the
    program as the flat one, and what `correct_file` writes as the flat program corrected."""
    problems = []
    canon_src, used = rs274_input(entry.path, work)
    tools = tool_table(work)
    p = work / ("flat-in" + entry.path.suffix)
    p.write_bytes(adjust(flat.read_bytes(), used))
    if canon_src.error is not None or not _same_motion(canon_src, run_rs274(p, tools)):
        problems.append("rs274 does not run the flat program as the program")
    prog = nc.read(flat, dialect=dialect, tools=TOOLS)
    fields_of = {"shift": fields.Shift(SHIFT), "grid": gentle_field(prog.inspect()["extents"]["feed"])}
    for name, fld in fields_of.items():
        written = work / (f"written-{name}" + entry.path.suffix)
        opts = {"max_segment": MAX_SEGMENT, "expand_cycles": expand_cycles}
        nc.correct_file(entry.path, written, fld, expand=True, dialect=dialect, tools=TOOLS, **opts)
        flat_out = prog.correct(fld, **opts).write(work / (f"flat-{name}" + entry.path.suffix))
        for q in (written, flat_out):
            q.write_bytes(adjust(q.read_bytes(), used))
        a, b = run_rs274(written, tools), run_rs274(flat_out, tools)
        if a.error is not None or b.error is not None or not _same_motion(a, b):
            problems.append(f"{name}: what --expand writes does not run as the flat program corrected")
    return problems


def _run_translated(entry: Entry, work: Path, r: Result, dialect: str) -> None:
    """A Sinumerik or Marlin program as ``ncadapt correct`` treats it: translated into straight
    RS274NGC (a Sinumerik program run, checked against the oracle nc-gcode-interpreter running the
    source; a Marlin program's E carried as a U axis, which rs274 is not given), then corrected and
    compared with rs274 as any RS274NGC program; a zero correction must give the program back byte
    for byte."""
    data = entry.path.read_bytes()
    subs = [subprogram_folder(entry, work)] if dialect == "sinumerik" else []
    start = None  # the machine's start motion mode (Sinumerik), stated when the program needs it
    try:
        try:
            tr = sinumerik.translate(data, entry.file, subs) if subs else marlin.translate(data, entry.file)
        except InputError as e:
            if "--start-motion" not in e.message:
                raise
            # as the user is told: the machine's mode stated (Siemens' setting, G1)
            start = START_MOTION
            tr = sinumerik.translate(data, entry.file, subs, start)
    except InputError as e:
        r.outcome = f"refused: line {e.line}: {e.message}" + (f" (--start-motion {start})" if start else "")
        r.reason, r.refusal_line = _generic(e.message), e.line
        return
    folder = work / "straight"
    folder.mkdir(exist_ok=True)
    straight = Path(entry.file).stem + ".ngc"
    (folder / straight).write_bytes(tr.data)
    _run(dataclasses.replace(entry, file=straight, root=folder), work, r)
    if r.refusal_line is not None and 1 <= r.refusal_line <= len(tr.lines):
        k = r.refusal_line
        r.refusal_line = int(tr.lines[k - 1])
        r.outcome = r.outcome.replace(f"line {k}:", f"line {r.refusal_line}:", 1)
    if not r.accepted:
        return
    r.outcome = "accepted (run straight)" if dialect == "sinumerik" else "accepted (E as U)"
    if start:
        r.outcome += f" (--start-motion {start})"
    out = work / ("zero" + entry.path.suffix)
    zero = fields.Shift((0.0, 0.0, 0.0))
    nc.correct_file(entry.path, out, zero, dialect=dialect, subprograms=subs, start_motion=start)
    if out.read_bytes() != data:
        r.identity, r.identity_detail = False, _first_difference(data, out.read_bytes())
    if dialect != "sinumerik" or not ncgi.AVAILABLE or RS274 is None:
        return
    if tr.subprograms:
        note = (
            "nc-gcode-interpreter runs no subprograms: the call of "
            f"{', '.join(tr.subprograms)} is checked in tests/test_sinumerik.py against Siemens' rules"
        )
        r.motion_detail = f"{note} || {r.motion_detail}" if r.motion_detail else note
        return
    units = set(re.findall(rb"^G2[01] ", tr.data, re.M))
    if len(units) > 1:
        r.motion_detail = "nc-gcode-interpreter reports program units: a program in both units is not compared"
        return
    # the interpreter reports the program's numbers; rs274 reports mm
    try:
        want = ncgi.ends(data.decode("utf-8", "replace")) * (25.4 if units == {b"G20 "} else 1.0)
    except BaseException as e:  # noqa: BLE001 - the oracle's own failures (a parse error, a Rust panic)
        if isinstance(e, KeyboardInterrupt):
            raise
        why = str(e).splitlines()[0][:200] if str(e) else type(e).__name__
        r.motion_detail = f"nc-gcode-interpreter does not run the source ({why}): not compared"
        return
    canon, _ = rs274_input(folder / straight, work)
    if canon.error is not None:
        r.motion = "mismatch"
        r.motion_detail = "rs274 rejects the straight program: " + canon.error.replace("\n", " | ")
        return
    got = ncgi.distinct(canon.ends)
    if got.shape != want.shape or (want.size and np.abs(got - want).max() > ncgi.tolerance(want)):
        detail = "the straight program does not move as nc-gcode-interpreter runs the source"
        r.motion = "mismatch"
        r.motion_detail = f"{detail} || {r.motion_detail}" if r.motion_detail else detail


# ------------------------------------------------------------------------------------------ report
def _run_one(args) -> Result:
    entry, work = args
    return run(entry, Path(work))


def run_all(entries=None, workers: int = 2) -> list[Result]:
    from concurrent.futures import ProcessPoolExecutor

    entries = manifest() if entries is None else entries
    with tempfile.TemporaryDirectory(prefix="ncadapt-corpus-") as tmp:
        jobs = [(e, str(Path(tmp) / e.file)) for e in entries]
        # the longest first, so the two workers finish together
        order = sorted(range(len(jobs)), key=lambda i: -entries[i].lines)
        with ProcessPoolExecutor(workers) as pool:
            done = dict(zip(order, pool.map(_run_one, [jobs[i] for i in order])))
    return [done[i] for i in range(len(jobs))]


def tables(results: list[Result]) -> str:
    out = [
        "| dialect | programs | accepted | refused (top reasons) | identity | motion matched / compared |",
        "|---|---|---|---|---|---|",
    ]
    by: dict[str, list[Result]] = {}
    for r in results:
        by.setdefault(r.dialect, []).append(r)
    for d in sorted(by, key=lambda d: (-len(by[d]), d)):
        rs = by[d]
        acc = [r for r in rs if r.accepted]
        ref = [r for r in rs if r.refused]
        errs = [r for r in rs if r.outcome.startswith("error")]
        top = Counter(r.reason for r in ref).most_common(3)
        reasons = "; ".join(f"{why} ({n})" for why, n in top)
        refused = f"{len(ref)}" + (f": {reasons}" if reasons else "") + (f" — {len(errs)} error(s)" if errs else "")
        ident = sum(1 for r in acc if r.identity)
        compared = [r for r in acc if r.motion in ("matched", "mismatch")]
        matched = sum(1 for r in compared if r.motion == "matched")
        out.append(f"| {d} | {len(rs)} | {len(acc)} | {refused} | {ident}/{len(acc)} | {matched}/{len(compared)} |")
    tot = [r for r in results]
    acc = [r for r in tot if r.accepted]
    compared = [r for r in acc if r.motion in ("matched", "mismatch")]
    out.append(
        f"| **all** | {len(tot)} | {len(acc)} | {sum(r.refused for r in tot)} | "
        f"{sum(1 for r in acc if r.identity)}/{len(acc)} | "
        f"{sum(r.motion == 'matched' for r in compared)}/{len(compared)} |"
    )
    out += ["", "| program | dialect | lines | outcome | identity | motion | s |", "|---|---|---|---|---|---|---|"]
    for r in sorted(results, key=lambda r: (r.dialect, r.file)):
        ident = "" if r.identity is None else ("yes" if r.identity else f"no ({r.identity_detail})")
        notes = ([f"rs274: {', '.join(r.adjusted)}"] if r.adjusted else []) + (
            [f"{r.uncorrected} cutting move(s) left as written, position unknown"] if r.uncorrected else []
        )
        motion = r.motion + (f" ({'; '.join(notes)})" if notes else "")
        motion += f": {r.motion_detail}" if r.motion_detail else ""
        cell = lambda s: s.replace("|", "\\|").replace("\n", " ")  # noqa: E731
        out.append(
            f"| {r.file} | {r.dialect} | {r.lines} | {cell(r.outcome)} | {cell(ident)} | "
            f"{cell(motion)} | {r.seconds:.1f} |"
        )
    return "\n".join(out)


def main() -> int:
    if not CORPUS.is_dir():
        print(f"no corpus at {CORPUS}", file=sys.stderr)
        return 1
    t = time.perf_counter()
    results = run_all()
    print(tables(results))
    print(f"\n{len(results)} programs in {time.perf_counter() - t:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
