"""Fuzz: generated RS274NGC programs, corrected, against LinuxCNC's ``rs274``.

The generator writes programs rs274 runs without error: a first block that sets every axis used
(rotary ones included), then G0/G1 moves (some with A/B/C words, some rotary only), G2/G3 arcs in
G17/G18/G19 with I/J/K (end point computed on the circle, printed to 7 decimals in mm, 8 in inch;
full circles, P turns) or R (negative R: the long way), helical arcs, arcs with a rotary word, G91
sections, G20 sections (straight-move values on a 0.0001 inch grid), modal motion, comments ``( )``
and ``;``, blank lines, N numbers, three number styles (``1.5``, ``1.500``, ``1.``/``.5``) and
compact blocks. A program rs274 refuses is a bug of the generator.

Properties:

1. a zero shift gives back the program's bytes;
2. under a shift and under a smooth field the corrected program runs in rs274 without error, the
   engine reads it as rs274 does, and rs274's motion of it passes through the engine's predicted
   corrected points (``points + displacements``) in order, as in ``test_rs274._corrected_matches``
   but with rs274's arcs traced as arcs;
3. rs274 against rs274, without the engine's predictions: every move end rs274 prints for the
   corrected program lies on rs274's path of the input displaced by the field within 5 µm (9 µm
   with G20 sections); the ends go forward along the input's moves, block by block, every input
   block's end is reached, and there A/B/C equal rs274's rotary position of the input at that
   block's end (inside a block they stay between its start and end). Rapids not corrected
   (``rapids=False``) keep their programmed target: each axis a rapid moves ends where the input's
   does, an axis it does not move may also stay where the corrected path left it. The program's
   first move, from a start the program does not give, may be left as written.

``make test`` runs 25 examples per test, ``make fuzz`` 2,000 (NCADAPT_FUZZ_EXAMPLES).
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument

from conftest import needs_rs274
from helpers import endpoints_agree, match_moves
from ncadapt import fields, nc
from ncadapt.constants import CHORD_TOL
from ncadapt.errors import RefusedError
from rs274 import Canon, Move, canonical, moves

EXAMPLES = int(os.environ.get("NCADAPT_FUZZ_EXAMPLES", "25"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))

#: property 3: how far a move end of the corrected program may be from the displaced input path, mm
TOL_PATH_MM = 0.005
TOL_PATH_INCH = 0.009
#: rotary positions: rs274 prints 4 decimals, the engine writes at least 4
TOL_ROTARY = 1e-4 + 1e-9
#: NCADAPT_FUZZ_STRICT_RAPIDS=1: an uncorrected rapid must end at the input's end in every axis,
#: also in the axes it does not move (the engine leaves those where the corrected cut left them)
STRICT_RAPIDS = os.environ.get("NCADAPT_FUZZ_STRICT_RAPIDS", "") not in ("", "0")

# ============================================================================= the generator
PLANES = {17: (0, 1, 2), 18: (2, 0, 1), 19: (1, 2, 0)}
CENTRE = "IJK"
COMMENTS = ("rough", "finish pass", "tool 1 d6", "check x=1 y=2", "op 20: contour", "")


@dataclass(frozen=True)
class Generated:
    text: str
    inch: bool  # has G20 sections
    rotary: str


class _Writer:
    """Writes one program, keeping the position as rs274 reads it back from the written numbers."""

    def __init__(self, draw):
        self.draw = draw
        self.has_inch = draw(st.booleans())
        self.rotary = "".join(sorted(draw(st.sets(st.sampled_from("ABC")))))
        self.style = draw(st.sampled_from(("plain", "fixed", "fanuc")))
        self.sep = draw(st.sampled_from((" ", " ", "")))
        self.numbered = draw(st.booleans())
        self.inch = self.has_inch and draw(st.booleans())
        self.inc = False
        self.plane = 17
        self.motion = None  # modal motion word as written ("G0" .. "G3")
        self.pos = [0.0, 0.0, 0.0]  # mm
        self.rot = {a: 0.0 for a in self.rotary}
        self.lines: list[str] = []
        self.n = 0

    def maybe(self, n: int) -> bool:
        """True once in n draws (shrinks to False: failing programs shrink to plain ones)."""
        return self.draw(st.integers(0, n - 1)) == n - 1

    # ------------------------------------------------------------------ numbers
    @property
    def unit(self) -> float:
        return 25.4 if self.inch else 1.0

    @property
    def tick(self) -> Decimal:
        """Grid of straight-move values in the current units: 0.0001 inch everywhere when the
        program has inch sections (2.54 µm in mm), else 1 µm."""
        if self.inch:
            return Decimal("0.0001")
        return Decimal("0.00254") if self.has_inch else Decimal("0.001")

    @property
    def grid_decimals(self) -> int:
        return 4 if self.inch else (5 if self.has_inch else 3)

    @property
    def arc_decimals(self) -> int:
        return 8 if self.inch else 7

    def fmt(self, v, dec: int) -> str:
        s = f"{v:.{dec}f}"
        if float(s) == 0:
            s = s.lstrip("-")
        if self.style == "fixed":
            return s
        s = s.rstrip("0")
        if self.style == "plain":
            s = s.rstrip(".")
            return "0" if s in ("", "-") else s
        # fanuc: "10." and ".5"
        if s.startswith("0.") and len(s) > 2:
            s = s[1:]
        elif s.startswith("-0.") and len(s) > 3:
            s = "-" + s[2:]
        return s

    def grid_ticks(self, v_mm: float) -> int:
        """The grid point nearest to a position, in ticks of the current units."""
        return int(round(v_mm / self.unit / float(self.tick)))

    def axis_word(self, k: int, value, dec: int, incremental: bool) -> str:
        """Write axis k's word (a value in current units, absolute or incremental) and follow it."""
        s = self.fmt(value, dec)
        v = float(s) * self.unit
        self.pos[k] = self.pos[k] + v if incremental else v
        return "XYZ"[k] + s

    def grid_word(self, k: int, delta_ticks: int) -> str:
        """Axis k moved by delta_ticks grid steps from the grid point nearest to it."""
        if self.inc:
            return self.axis_word(k, delta_ticks * self.tick, self.grid_decimals, True)
        return self.axis_word(k, (self.grid_ticks(self.pos[k]) + delta_ticks) * self.tick, self.grid_decimals, False)

    def rotary_words(self, force=False) -> list[str]:
        words = []
        for a in self.rotary:
            if not (force or self.maybe(4)):
                continue
            if self.inc and not force:
                d = self.draw(st.integers(-900, 900)) / 10
                self.rot[a] += d
                words.append(a + self.fmt(d, 1))
            else:
                v = self.draw(st.integers(-3600, 3600)) / 10
                self.rot[a] = v
                words.append(a + self.fmt(v, 1))
        return words

    def mm_ticks(self, lo_mm: float, hi_mm: float) -> tuple[int, int]:
        return int(lo_mm / self.unit / float(self.tick)), int(hi_mm / self.unit / float(self.tick))

    # ------------------------------------------------------------------ lines
    def emit(self, words: list[str], motion_line=True):
        d = self.draw
        if motion_line and self.maybe(6):
            words = words + [f"F{d(st.sampled_from(['100', '250', '500.', '20']))}"]
        if self.maybe(7):
            text = d(st.sampled_from(COMMENTS))
            at = d(st.integers(0, len(words)))  # before, between or after the words
            words = words[:at] + [f"({text})"] + words[at:]
        line = self.sep.join(words)
        if self.numbered and not self.maybe(4):
            self.n += 10
            line = f"N{self.n}{self.sep}{line}"
        if self.maybe(8):
            line += f"{d(st.sampled_from(['', ' ']))};{d(st.sampled_from(COMMENTS))}"
        self.lines.append(line)

    def modal_words(self) -> list[str]:
        """Sometimes switch distance mode or units, in the block or on their own line."""
        d = self.draw
        words = []
        if self.maybe(6):
            self.inc = not self.inc
            words.append("G91" if self.inc else "G90")
        if self.has_inch and self.maybe(6):
            self.inch = not self.inch
            words.append("G20" if self.inch else "G21")
        if words and d(st.booleans()):
            self.emit(words, motion_line=False)
            return []
        return words

    def motion_word(self, g: str, words: list[str], may_omit=True) -> list[str]:
        if may_omit and g == self.motion and words and self.maybe(3):
            return words
        self.motion = g
        return [g] + words

    def straight(self):
        d = self.draw
        pre = self.modal_words()
        g = d(st.sampled_from(["G0", "G1", "G1"]))
        lo, hi = self.mm_ticks(-30, 30)
        words = []
        for k in range(3):
            if d(st.integers(0, 2)) > 0:
                delta = d(st.integers(lo, hi)) if d(st.integers(0, 4)) else 0
                words.append(self.grid_word(k, delta))
        rot = self.rotary_words()
        # a line without axis words moves only if it names its motion
        self.emit(pre + self.motion_word(g, words + rot, may_omit=bool(words)))

    def arc(self):
        d = self.draw
        pre = self.modal_words()
        plane = d(st.sampled_from([17, 17, 18, 19]))
        if plane != self.plane:
            self.plane = plane
            if d(st.booleans()):
                self.emit([f"G{plane}"], motion_line=False)
            else:
                pre.append(f"G{plane}")
        a1, a2, an = PLANES[plane]
        g = d(st.sampled_from(["G2", "G3"]))
        sign = 1 if g == "G3" else -1
        form = d(st.sampled_from(["ijk", "ijk", "r"]))
        rlo, rhi = self.mm_ticks(0.5, 20)
        r_ticks = d(st.integers(rlo, rhi))
        phi0 = math.radians(d(st.integers(0, 3599)) / 10)
        start = (self.pos[a1], self.pos[a2])
        centre_words, full = [], False
        if form == "ijk":
            ci = -round(r_ticks * math.cos(phi0))
            cj = -round(r_ticks * math.sin(phi0))
            si, sj = self.fmt(ci * self.tick, self.grid_decimals), self.fmt(cj * self.tick, self.grid_decimals)
            centre_words = [CENTRE[a1] + si, CENTRE[a2] + sj]
            oi, oj = float(si) * self.unit, float(sj) * self.unit
            centre = (start[0] + oi, start[1] + oj)
            r = math.hypot(oi, oj)
            phi0 = math.atan2(-oj, -oi)
            full = self.maybe(6)
            sweep = 0.0 if full else math.radians(d(st.integers(30, 3570)) / 10)
            if self.maybe(8):
                centre_words.append("P2")
        else:
            rs = self.fmt(r_ticks * self.tick, self.grid_decimals)
            r = float(rs) * self.unit
            long_way = d(st.booleans())
            sweep = math.radians(d(st.integers(1860, 3540) if long_way else st.integers(60, 1740)) / 10)
            centre = (start[0] - r * math.cos(phi0), start[1] - r * math.sin(phi0))
            centre_words = [f"R{'-' if long_way else ''}{rs}"]
        phi1 = phi0 + sign * sweep
        end = (centre[0] + r * math.cos(phi1), centre[1] + r * math.sin(phi1))
        words = []
        if full:
            if self.inc and d(st.booleans()):  # zero increments name the plane's axes
                words += [
                    self.axis_word(a1, 0, self.grid_decimals, True),
                    self.axis_word(a2, 0, self.grid_decimals, True),
                ]
        else:
            for k, v in ((a1, end[0]), (a2, end[1])):
                value = (v - self.pos[k]) / self.unit if self.inc else v / self.unit
                words.append(self.axis_word(k, value, self.arc_decimals, self.inc))
            words.sort()
        if self.maybe(3):  # helix
            lo, hi = self.mm_ticks(-5, 5)
            words.append(self.grid_word(an, d(st.integers(lo, hi))))
        rot = self.rotary_words()
        self.emit(pre + self.motion_word(g, words + centre_words + rot, may_omit=bool(words)))

    def stray(self):
        """A line that does not move: blank, a comment, or modal words alone."""
        d = self.draw
        kind = d(st.sampled_from(["blank", "comment", "semicolon", "modal"]))
        if kind == "blank":
            self.lines.append(d(st.sampled_from(["", " "])))
        elif kind == "comment":
            self.lines.append(f"({d(st.sampled_from(COMMENTS))})")
        elif kind == "semicolon":
            self.lines.append(f";{d(st.sampled_from(COMMENTS))}")
        else:
            words = self.modal_words()
            if words:
                self.emit(words, motion_line=False)

    def build(self, max_blocks: int) -> Generated:
        d = self.draw
        head = [f"G{20 if self.inch else 21}", "G90", "G17"]
        if d(st.booleans()):
            head.append("F" + ("20" if self.inch else "500"))
        else:
            self.lines.append("F" + ("20" if self.inch else "500"))
        lo, hi = self.mm_ticks(-50, 50)
        words = [self.grid_word(k, d(st.integers(lo, hi))) for k in range(3)]
        self.motion = "G0"
        self.emit(head + ["G0"] + words + self.rotary_words(force=True), motion_line=False)
        for _ in range(d(st.integers(1, max_blocks))):
            what = d(st.sampled_from(["straight", "straight", "arc", "arc", "stray"]))
            getattr(self, what)()
        end = d(st.sampled_from(["M2", "M30", "same"]))
        if (
            end == "same"
            and self.lines
            and self.lines[-1].strip()
            and not self.lines[-1].lstrip().startswith(("(", ";"))
            and ";" not in self.lines[-1]
        ):
            self.lines[-1] += self.sep + "M2"
        else:
            self.lines.append(end if end != "same" else "M2")
        return Generated("\n".join(self.lines) + "\n", self.has_inch, self.rotary)


@st.composite
def programs(draw, max_blocks=12):
    return _Writer(draw).build(max_blocks)


def smooth_a(p):
    x, y = p[:, 0], p[:, 1]
    return np.column_stack([0 * x, 0 * x, 0.02 * np.sin(x / 7) * np.cos(y / 5)])


def smooth_b(p):
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    return np.column_stack(
        [
            0.003 * np.cos(y / 3),
            -0.002 * np.sin(x / 4) + 0.001 * np.cos(z / 2),
            0.02 * np.sin(x / 7) * np.cos(y / 5) + 0.0004 * x,
        ]
    )


SMOOTH = {"smooth_a": smooth_a, "smooth_b": smooth_b}
shifts = st.one_of(st.just((0.0, 0.0, 0.05)), st.tuples(*[st.integers(-50, 50).map(lambda v: v / 1000)] * 3))


# ============================================================================= rs274's motion as geometry
# ============================================================================= property 3
def _locate(P: np.ndarray, e: np.ndarray, s0: int, u0: float, tol: float):
    """First place at or after (segment s0, fraction u0) of polyline P within tol of e."""
    if len(P) == 1:
        return (0, 0.0) if np.linalg.norm(P[0] - e) <= tol else None
    A, B = P[s0:-1], P[s0 + 1 :]
    AB = B - A
    L2 = np.einsum("ij,ij->i", AB, AB)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(L2 > 0, np.einsum("ij,ij->i", e - A, AB) / L2, 0.0)
    lo = np.zeros(len(u))
    lo[0] = u0
    u = np.maximum(np.minimum(u, 1.0), lo)
    dist = np.linalg.norm(A + u[:, None] * AB - e, axis=1)
    ok = np.flatnonzero(dist <= tol)
    if not len(ok):
        return None
    return (s0 + int(ok[0]), float(u[ok[0]]))


def _distance(P: np.ndarray, e: np.ndarray) -> float:
    if len(P) == 1:
        return float(np.linalg.norm(P[0] - e))
    A, AB = P[:-1], P[1:] - P[:-1]
    L2 = np.einsum("ij,ij->i", AB, AB)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.clip(np.where(L2 > 0, np.einsum("ij,ij->i", e - A, AB) / L2, 0.0), 0, 1)
    return float(np.linalg.norm(A + u[:, None] * AB - e, axis=1).min())


def _kept_rapid_ends(inp: Move, m: Move, tol: float, res: float) -> bool:
    """An uncorrected rapid keeps its programmed target: every axis it moves ends where the
    input's does; an axis it does not move (to rs274's printed resolution `res`) may also stay
    where the corrected path left it."""
    at_target = np.abs(m.end[:3] - inp.end[:3]) <= tol
    if STRICT_RAPIDS:
        return bool(np.all(at_target))
    stays = (np.abs(inp.start[:3] - inp.end[:3]) <= res) & (np.abs(m.end[:3] - m.start[:3]) <= tol)
    return bool(np.all(at_target | stays))


def align(
    inp: list[Move], paths: list[np.ndarray], kept: list[bool], out: list[Move], tol: float, res: float, rotary: bool
):
    """Assign rs274's moves of the corrected program to the input's moves, in order: each output
    move end on its input move's displaced path at or after the previous one, the last output move
    of each input move at its displaced end (an uncorrected rapid: see ``_kept_rapid_ends``).
    Returns (assignment [(k, closes)], None) or (None, (output index, states then)) at the first
    move that fits nowhere."""
    N = len(inp)
    rot_end = [m.end[3:6] for m in inp]
    states = {(-1, True): (None, None)}  # (input move, its end reached) -> (place on its path, trail)
    for o, m in enumerate(out):
        e = m.end[:3]
        new = {}
        for (k, closed), (place, trail) in states.items():
            kk, (s0, u0) = (k + 1, (0, 0.0)) if closed else (k, place)
            if (
                kk >= N
                or (m.kind == "traverse") != (inp[kk].kind == "traverse")
                or (m.kind == "arc" and inp[kk].kind != "arc")
            ):
                continue
            rot_ok = not rotary or np.abs(m.end[3:6] - rot_end[kk]).max() <= TOL_ROTARY
            if kept[kk]:  # one move, not split
                if _kept_rapid_ends(inp[kk], m, tol, res) and rot_ok:
                    new[(kk, True)] = (None, (o, kk, True, trail))
                continue
            P = paths[kk]
            loc = _locate(P, e, s0, u0, tol)
            if loc is None:
                continue
            r0, r1 = inp[kk].start[3:6], inp[kk].end[3:6]
            inside = not rotary or bool(
                np.all(
                    (m.end[3:6] >= np.minimum(r0, r1) - TOL_ROTARY) & (m.end[3:6] <= np.maximum(r0, r1) + TOL_ROTARY)
                )
            )
            ends = np.linalg.norm(P[-1] - e) <= tol and rot_ok
            if inside and ((kk, False) not in new or loc < new[(kk, False)][0]):
                new[(kk, False)] = (loc, (o, kk, False, trail))
            if ends:
                new[(kk, True)] = (None, (o, kk, True, trail))
        if not new:
            return None, (o, states)
        states = new
    if (N - 1, True) not in states:
        return None, (len(out), states)
    trail, res = states[(N - 1, True)][1], []
    while trail is not None:
        o, k, closed, trail = trail
        res.append((k, closed))
    return res[::-1], None


def check_follows_input(inp_canon: Canon, out_canon: Canon, field, rapids: bool, tol: float, in_lines, out_lines):
    """Property 3 (see the module's docstring)."""
    inp, out = moves(inp_canon), moves(out_canon)
    paths, kept = [], []
    for k, m in enumerate(inp):
        P = m.dense()
        # the program's first move comes from where the program does not say: it may be left as
        # written (the engine does so when it names a rotary axis)
        first_kept = k == 0 and len(out) and np.linalg.norm(out[0].end[:3] - m.end[:3]) <= tol
        if (m.kind != "traverse" or rapids) and not first_kept:
            P = P + np.asarray(field(P), dtype=float)
        paths.append(P)
        kept.append(m.kind == "traverse" and not rapids)
    res = inp_canon.resolution_mm + 1e-9
    got, fail = align(inp, paths, kept, out, tol, res, rotary=True)
    if got is not None:
        return
    geo, geo_fail = align(inp, paths, kept, out, tol, res, rotary=False)
    if geo is not None:  # the path is right: name the first rotary position that is not
        for o, (k, closes) in enumerate(geo):
            ro, ri0, ri1 = out[o].end[3:6], inp[k].start[3:6], inp[k].end[3:6]
            if closes and np.abs(ro - ri1).max() > TOL_ROTARY:
                raise AssertionError(
                    f"output line {out_lines(o)} ends input line {in_lines(k)} with A B C {ro.tolist()}, "
                    f"rs274 runs the input to {ri1.tolist()} there"
                )
            if not closes and not np.all(
                (ro >= np.minimum(ri0, ri1) - TOL_ROTARY) & (ro <= np.maximum(ri0, ri1) + TOL_ROTARY)
            ):
                raise AssertionError(
                    f"output line {out_lines(o)} (a piece of input line {in_lines(k)}) has A B C {ro.tolist()}, "
                    f"outside the input's {ri0.tolist()} -> {ri1.tolist()}"
                )
        raise AssertionError("rotary positions differ (alignment ambiguous)")
    o, states = geo_fail
    if o == len(out):
        raise AssertionError(
            f"rs274's run of the corrected program stops before the end of input line "
            f"{in_lines(len(inp) - 1)}; states {sorted(states)}"
        )
    e = out[o].end[:3]
    near = []
    for kk in sorted({kk for k, _ in states for kk in (k, k + 1) if 0 <= kk < len(inp)}):
        near.append(f"input line {in_lines(kk)} ({inp[kk].kind}) {_distance(paths[kk], e) * 1000:.2f} µm")
    raise AssertionError(
        f"output line {out_lines(o)}: rs274's {out[o].kind} ends at {e.round(5).tolist()}, not on the displaced "
        f"input path where expected (tol {tol * 1000:g} µm): " + "; ".join(near)
    )


# ============================================================================= the checks
def _note(text: str) -> None:
    try:
        note(text)
    except InvalidArgument:  # called outside a test (to reproduce a failure by hand)
        pass


def _plunges_into_part(canon, field, tol: float) -> bool:
    """A rapid followed by a feed straight down from its end (X and Y unchanged) whose end, moved by
    the field, is at or above the rapid's end."""
    k = canon.kinds
    e = canon.ends[:, :3]
    for i in range(1, len(k)):
        if k[i - 1] == "traverse" and k[i] == "feed" and np.abs(e[i, :2] - e[i - 1, :2]).max() <= tol:
            dz = float(field(e[i][None, :])[0, 2])
            if e[i, 2] < e[i - 1, 2] and e[i, 2] + dz >= e[i - 1, 2] - tol:
                return True
    return False


def check_corrected(src: str, field, rapids: bool, has_inch: bool, tmp: Path) -> None:
    """Properties 2 and 3 for one program and field."""
    inp = tmp / "in.ngc"
    inp.write_text(src)
    in_canon = canonical(inp)
    assert in_canon.error is None, f"generator bug: rs274 refuses the program: {in_canon.error}"
    prog = nc.read(inp)
    assert not prog.unsupported, f"generator bug: {prog.unsupported}"
    endpoints_agree(prog.blocks, in_canon, "input")  # the engine reads the input as rs274 does
    try:
        out = prog.correct(field, rapids=rapids)
    except RefusedError as e:
        # refused only where rs274's own motion shows a rapid followed by a straight plunge that the
        # field raises past the rapid's end (to rs274's printed resolution)
        assert "would end inside the part" in str(e) and not rapids, str(e)
        assert _plunges_into_part(in_canon, field, TOL_PATH_INCH if has_inch else TOL_PATH_MM), str(e)
        return
    outp = out.write(tmp / "out.ngc")
    _note(f"corrected:\n{out.text}")
    out_canon = canonical(outp)
    # rs274 runs the output and reads it as the engine does
    assert out_canon.error is None, f"rs274 refuses the corrected program: {out_canon.error}"
    back = nc.read(outp)
    endpoints_agree(back.blocks, out_canon, "corrected")
    # property 3 (first: a wrong path is named as such, a wrong prediction by property 2)
    check_follows_input(
        in_canon,
        out_canon,
        field,
        rapids,
        TOL_PATH_INCH if has_inch else TOL_PATH_MM,
        lambda k: prog.blocks.line[k],
        lambda o: back.blocks.line[o],
    )
    c = out.correction
    predicted = c.points + c.displacements
    out_moves = moves(out_canon)
    res = out_canon.resolution_mm
    sel = [i for i, m in enumerate(out_moves) if rapids or m.kind != "traverse"]
    if sel and sel[0] == 0 and (not len(c.line) or c.line[0] != prog.blocks.line[0]):
        # the first move, from where the program does not say, is not corrected: it stays as written
        assert np.abs(out_moves[0].end[:3] - in_canon.ends[0, :3]).max() <= res + 1e-9, "first move moved, unpredicted"
        sel = sel[1:]
    # property 2: rs274's motion of the output passes through the engine's predicted points
    # (as _corrected_matches; a mixed program's inch sections are written to 5 inch decimals too)
    ours = 0.5e-5 * 25.4 if prog.units in ("inch", "mixed") else 0.5e-4
    tol = res + ours + 1e-6
    # an arc's centre is printed rounded too; an arc kept an arc is within the chord tolerance of
    # the displaced path at every point (as close as its chords would be)
    match_moves(
        predicted,
        [out_moves[i] for i in sel],
        tol,
        tol + 2 * res + CHORD_TOL,
        lambda i: f"output line {back.blocks.line[sel[i]]}",
    )


# ============================================================================= tests
@SETTINGS
@given(programs(), st.booleans())
def test_zero_shift_is_identity(g, rapids):
    note(g.text)
    prog = nc.parse(g.text)
    assert prog.correct(fields.Shift((0, 0, 0)), rapids=rapids).data == prog.data


@needs_rs274
@pytest.mark.rs274
@SETTINGS
@given(programs(), shifts, st.booleans())
def test_shift_follows_rs274(g, shift, rapids):
    note(g.text)
    with tempfile.TemporaryDirectory() as tmp:
        check_corrected(g.text, fields.Shift(shift), rapids, g.inch, Path(tmp))


@needs_rs274
@pytest.mark.rs274
@SETTINGS
@given(programs(), st.sampled_from(sorted(SMOOTH)), st.booleans())
def test_smooth_field_follows_rs274(g, name, rapids):
    note(g.text)
    with tempfile.TemporaryDirectory() as tmp:
        check_corrected(g.text, SMOOTH[name], rapids, g.inch, Path(tmp))


@needs_rs274
@pytest.mark.rs274
@SETTINGS
@given(programs())
def test_generated_programs_run_in_rs274(g):
    """The generator's own check: rs274 runs every program it writes."""
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "g.ngc"
        p.write_text(g.text)
        c = canonical(p)
        assert c.error is None, f"{c.error}\n{g.text}"
