"""The correction pipeline of an NC program: read piece by piece, sampled, the field evaluated
at the samples, the output emitted and written — natively in the engine's threads for a plain shift
or bilinear grid, piece by piece through Python for any other field — with the checks that refuse
before anything counts as written (unsupported constructs, points outside the field, the limit, a
non-finite field). :mod:`ncadapt.nc` holds the program object and calls this."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from . import constants
from ._nc import Corrector as _NativeCorrector
from ._nc import EngineError
from ._nc import correct_native as _nc_correct
from .errors import InputError, RefusedError

_AXES = "XYZABCUVW"
# bytes of program per piece of a correction or inspection (about 10,000 lines): a few hundred
# thousand sample points, a few MB at a time, whatever the program's length
_PIECE_BYTES = constants.PIECE_BYTES


@dataclass(frozen=True)
class Unsupported:
    """A construct the engine does not interpret: where it is and how many motion blocks it affects."""

    line: int
    col: int
    construct: str
    blocks: int


@dataclass(frozen=True)
class Correction:
    """What :meth:`Program.correct` did. Lengths in mm.

    ``points``, ``displacements`` (n, 3) and ``line`` (n,) give every corrected sample point, the
    displacement applied there and the 1-based line of its block (None after
    :meth:`Program.correct_to`, which does not keep them); ``n_points`` counts them.
    """

    lines_in: int
    lines_out: int
    blocks_changed: int
    lines_added: int
    arcs_linearised: int
    max_displacement: float
    mean_displacement: float
    n_points: int
    points: np.ndarray | None = field(repr=False)
    displacements: np.ndarray | None = field(repr=False)
    line: np.ndarray | None = field(repr=False)
    unsupported_kept: tuple[Unsupported, ...] = ()
    warnings: tuple[str, ...] = ()
    #: Splines (LinuxCNC's G5, G5.1) written as straight pieces (the field bends them).
    splines_linearised: int = 0
    #: Remarks on blocks kept but not corrected (G53 moves, G28/G30 returns): (line, message).
    notes: tuple[tuple[int, str], ...] = ()
    #: The program was run into a straight program first (``expand``; a Sinumerik or Marlin
    #: program always): ``lines_in`` its lines, ``blocks`` the straight program's, ``blocks_run``
    #: the blocks it ran (flow lines included), ``written`` how it was written (``as it is``,
    #: ``in place``, ``straight``), ``lines_rewritten`` the lines rewritten in place (or written
    #: straight), ``kept`` no block changed; None otherwise. ``lines_in``/``lines_out`` of the
    #: correction are then the program's and the output's, its other figures the straight
    #: program's.
    expanded: dict | None = None

    def as_dict(self) -> dict:
        """The figures as plain JSON-ready values (no arrays)."""
        d = {k: v for k, v in asdict(self).items() if k not in ("points", "displacements", "line")}
        d["unsupported_kept"] = [asdict(u) for u in self.unsupported_kept]
        d["warnings"] = list(self.warnings)
        d["notes"] = [{"line": ln, "message": m} for ln, m in self.notes]
        return d


def _engine_error(e: EngineError, path: str | None) -> InputError:
    kind, line, col, message = e.args
    return InputError(message, path, line, col)


def _engine(fn, name):
    try:
        return fn()
    except EngineError as e:
        raise _engine_error(e, name) from None


def _unsupported_error(name, uns) -> RefusedError:
    flow = any(u.construct.startswith(("O-word", "parameters or expressions", "subprogram M")) for u in uns)
    return RefusedError(
        f"{name}: {len(uns)} unsupported construct(s); nothing written "
        "(--keep-unsupported, keep_unsupported=True in Python, copies those blocks unchanged and corrects the "
        "rest"
        + (
            "; --expand, expand=True in Python, flattens parameters, O-word flow and M98 subprograms into "
            "straight G-code"
            if flow
            else ""
        )
        + ")",
        [asdict(u) for u in uns],
    )


def check_sampling(chord_tol, max_segment) -> None:
    """Refuse sampling options outside :data:`ncadapt.constants.CHORD_TOL_RANGE` and
    :data:`ncadapt.constants.MAX_SEGMENT_RANGE` (mm)."""
    lo, hi = constants.CHORD_TOL_RANGE
    if not lo <= chord_tol <= hi:
        raise ValueError(f"chord_tol must be within {lo:g}..{hi:g} mm, got {chord_tol}")
    lo, hi = constants.MAX_SEGMENT_RANGE
    if not lo <= max_segment <= hi:
        raise ValueError(f"max_segment must be within {lo:g}..{hi:g} mm, got {max_segment}")


def _piece_records(r: dict) -> dict:
    """A piece's records as arrays (see ``Program._records``), with ``start`` (m, 9): where each begins."""
    end = np.frombuffer(r["end"], dtype="<f8").reshape(-1, 9)
    origin = np.frombuffer(r["origin"], dtype="<f8")
    return {
        "line": np.frombuffer(r["line"], dtype="<u4").astype(np.int64) + 1,
        "motion": np.frombuffer(r["motion"], dtype=np.uint8),
        "flags": np.frombuffer(r["flags"], dtype=np.uint8),
        "named": np.frombuffer(r["named"], dtype="<u2"),
        "end": end,
        "start": np.vstack([origin[None, :], end[:-1]]),
    }


def _split_uvw(disp: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """A field that uses the axes may displace U, V and W too: (n, 9) displacements in the order
    XYZABCUVW, the rotary ones zero. Returns the X Y Z part and the U V W part (None when zero)."""
    if disp.shape == pts.shape:
        return disp, None
    if disp.shape != (len(pts), 9):
        raise ValueError(f"field returned shape {disp.shape}, expected {pts.shape} or {(len(pts), 9)}")
    if np.any(disp[:, 3:6] != 0):
        raise ValueError("a field displaces X Y Z U V W; its A, B and C columns must be zero")
    uvw = np.ascontiguousarray(disp[:, 6:9])
    return np.ascontiguousarray(disp[:, :3]), (uvw if np.any(uvw != 0) else None)


def _axes_at(pts: np.ndarray, rec: np.ndarray, r: dict) -> np.ndarray:
    """All nine axes (XYZABCUVW) at sampled points: XYZ as sampled, the others interpolated
    between the block's start and end by the point's fraction along it (as the sampler and the
    emitter do on split moves) — for fields that depend on a rotary axis (``uses_axes``)."""
    rec = rec.astype(np.int64)
    e = r["end"][rec]
    s = r["start"][rec]
    s = np.where(np.isfinite(s), s, e)
    a = np.linalg.norm(pts - s[:, :3], axis=1)
    b = np.linalg.norm(e[:, :3] - pts, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(a + b > 1e-12, a / (a + b), 1.0)
    out = s + t[:, None] * (e - s)
    out[:, :3] = pts
    return out


class _Approach:
    """Uncorrected rapids that end inside the part: a rapid (left as programmed) followed by a
    straight plunge (a G1 that descends from its end, X and Y unchanged) which, once corrected,
    ends at or above the rapid's end — the surface has moved up by more than the whole plunge.
    Followed across pieces (the engine's own pipeline makes the same check)."""

    #: A descent larger than rounding: a plunge, not a level move (mm).
    PLUNGE_MIN = 1e-6

    def __init__(self):
        self.pending: tuple[int, np.ndarray] | None = None  # (line, XYZ) of an uncorrected rapid, the last record
        self.found: tuple[int, float, int, float] | None = None

    def add(self, r: dict, recs_i: np.ndarray, pts: np.ndarray, disp: np.ndarray) -> None:
        n = len(r["line"])
        if not n:
            return
        last = np.full(n, -1, dtype=np.int64)  # each record's last sample (its end), -1 for none
        last[recs_i.astype(np.int64)] = np.arange(len(recs_i))
        m, end = r["motion"], r["end"][:, :3]
        rapid = (m == 0) & ((r["flags"] & 16) == 0) & (last < 0) & np.isfinite(end).all(axis=1)
        plunge = (m == 1) & (last >= 0)
        nan3 = np.full((1, 3), np.nan)
        p_rapid = np.concatenate([[self.pending is not None], rapid[:-1]])
        p_end = np.vstack([self.pending[1][None, :] if self.pending else nan3, end[:-1]])
        p_line = np.concatenate([[self.pending[0] if self.pending else 0], r["line"][:-1]])
        j = np.where(plunge, last, 0)
        cz = pts[j, 2] + disp[j, 2] if len(pts) else np.full(n, np.nan)
        with np.errstate(invalid="ignore"):
            hit = np.flatnonzero(
                plunge
                & p_rapid
                & (end[:, 0] == p_end[:, 0])
                & (end[:, 1] == p_end[:, 1])
                & (end[:, 2] < p_end[:, 2] - self.PLUNGE_MIN)
                & (cz >= p_end[:, 2])
            )
        if len(hit) and self.found is None:
            i = int(hit[0])
            self.found = (int(p_line[i]), float(p_end[i, 2]), int(r["line"][i]), float(cz[i]))
        self.pending = (int(r["line"][-1]), end[-1].copy()) if rapid[-1] else None

    def error(self, name) -> RefusedError | None:
        if self.found is None:
            return None
        rl, rz, cl, cz = self.found
        return RefusedError(
            f"{name}: the rapid at line {rl} ends at Z{rz:.4f} (mm), below where the plunge after it (line {cl}) "
            f"ends once corrected (Z{cz:.4f}): the field raises the surface there by more than the plunge "
            "descends, so the rapid would end inside the part; nothing written (--rapids corrects the rapids "
            "too, or give the approach more clearance)",
            [{"line": rl, "z": rz, "cut_line": cl, "corrected_z": cz}],
        )


class _Warnings:
    """Warnings gathered piece by piece: cutting moves left as written because the program does
    not say where they are, and uncorrected rapids below a clearance plane."""

    def __init__(self, field, clearance):
        self.unknown, self.first = 0, None
        self.clearance, self.bounds, self.low = clearance, getattr(field, "bounds", None), []

    def add(self, r: dict) -> None:
        # an axis unknown at the end (after G28, G30, G53, a canned cycle …), or at the start for
        # an arc and for an axis other than XYZ that the block moves (its pieces are interpolated)
        cutting = (r["motion"] >= 1) & (r["motion"] <= 3)
        arc = (r["motion"] == 2) | (r["motion"] == 3)
        named = ((r["named"][:, None] >> np.arange(9)) & 1).astype(bool)
        needs_end = named.copy()
        needs_end[:, :3] = True
        needs_start = named.copy()
        needs_start[:, :3] = arc[:, None]
        end_unknown = needs_end & ~np.isfinite(r["end"])
        start_unknown = needs_start & ~np.isfinite(r["start"])
        # a G1 that names no axis (`G01 F360`) goes nowhere, wherever the tool is
        still = (r["motion"] == 1) & (r["named"] == 0) & ((r["flags"] & 16) == 0)
        left = np.flatnonzero(cutting & ~still & ((r["flags"] & 8) == 0) & (end_unknown | start_unknown).any(axis=1))
        if len(left) and self.first is None:
            i = left[0]
            said = []
            for what, u in (("end", end_unknown[i]), ("start", start_unknown[i])):
                if u.any():
                    said.append(f"the {what} of {''.join(a for a, k in zip(_AXES, u) if k)} unknown")
            self.first = (int(r["line"][i]), " and ".join(said))
        self.unknown += len(left)
        if self.clearance is not None:
            # (the rapids of a canned cycle move with their hole)
            rapid = np.flatnonzero((r["motion"] == 0) & ((r["flags"] & 16) == 0))
            end = r["end"][rapid]
            low = end[:, 2] < self.clearance
            if self.bounds is not None:
                x0, x1, y0, y1 = self.bounds
                low &= (end[:, 0] >= x0) & (end[:, 0] <= x1) & (end[:, 1] >= y0) & (end[:, 1] <= y1)
            self.low += [(int(r["line"][rapid[i]]), float(end[i, 2])) for i in np.flatnonzero(low)]

    def messages(self) -> list[str]:
        out = []
        if self.unknown:
            line, axes = self.first
            out.append(
                f"{self.unknown} cutting move(s) not corrected because the position is unknown (first at line "
                f"{line}: {axes}: no earlier move sets it, or a move the engine does not trace left it unknown); "
                f"give every axis a G0/G1 at the start and after G28, G30, G53 or a canned cycle"
            )
        out += [
            f"line {ln}: rapid ends at Z{z:.4f}, below the clearance Z{self.clearance:g} inside the field's "
            f"area, and is not corrected"
            for ln, z in self.low
        ]
        return out


def _comp_check(run, field, r, disp, checks, name):
    """The refusal (line, why) of a piece with moves under cutter compensation, or None: the
    field evaluated at the tool centre around its corners must not vary by more than the chord
    tolerance, nor move X or Y (the engine's ``comp_check``)."""
    first = int(r["line"][np.flatnonzero(r["flags"] & 32)[0]])
    if getattr(field, "uses_axes", False):
        # the rotary and U V W axes of a compensated move are not interpolated at the tool centre
        return first, (
            "cutter or nose radius compensation, or a lathe's G90/G94 cycle, with a field that depends on the rotary "
            "or U, V, W axes: not treated"
        )
    cpts = np.frombuffer(checks, dtype="<f8").reshape(-1, 3)
    try:
        cdisp = np.ascontiguousarray(field(cpts), dtype=np.float64) if len(cpts) else np.zeros((0, 3))
    except _OutsideError:
        return first, (
            "a point the check needs (the tool centre around a compensated corner, the field within a lathe tool's "
            "nose radius, or along a lathe cycle's cuts) is outside the field's domain"
        )
    if cdisp.shape != cpts.shape or not np.isfinite(cdisp).all():
        raise RefusedError(f"{name}: the field is not finite at the tool around a compensated corner")
    return _engine(lambda: run.comp_check(disp, cdisp), name)


def _native_field(field) -> tuple | None:
    """The field as the engine evaluates it itself (``_nc.correct_native``): a :class:`Shift` or a
    bilinear :class:`GridField`, given with the numbers their ``_eval`` uses; None for any other
    field (subclasses included), which is evaluated in Python."""
    if type(field) is _fields.Shift:
        return ("shift", tuple(float(v) for v in field.d))
    if type(field) is _fields.GridField and field.method == "linear" and field.outside in _fields.OUTSIDE:
        return (
            "grid",
            [float(v) for v in field.xs],
            [float(v) for v in field.ys],
            field._steps[0],
            field._steps[1],
            np.ascontiguousarray(field.dz, dtype=np.float64).ravel().tolist(),
            field.outside,
            tuple(float(v) for v in field.bounds or ()),
        )
    return None


def _lathe_y(disp: np.ndarray, lines, chord_tol: float, name) -> None:
    """On a lathe the tool is at Y 0, where the field's y moves it along the turned surface, for
    which the machine has no axis: refused above the chord tolerance, else not applied (set to 0
    in ``disp``)."""
    if not len(disp):
        return
    y = np.abs(disp[:, 1])
    i = int(np.argmax(y))
    if y[i] > chord_tol:
        line = int(lines[i])
        raise RefusedError(
            f"{name}: line {line}: the field moves Y by {disp[i, 1]:.4f} mm there, and a lathe has no Y axis "
            f"(at Y 0 the field's y is along the turned surface): give the field's x (radial) and z, or a y "
            f"within --chord-tol ({chord_tol:g} mm); nothing written",
            [{"line": line, "displacement": disp[i].round(4).tolist()}],
        )
    disp[:, 1] = 0.0


def _grid_spec(field) -> tuple | None:
    """The native spec of a bilinear grid field (:func:`_native_field`), else None."""
    spec = _native_field(field)
    return spec if spec is not None and spec[0] == "grid" else None


def _correct_native(
    source,
    name,
    out_file,
    field,
    spec,
    *,
    chord_tol,
    max_segment,
    limit,
    rapids,
    keep_unsupported,
    clearance,
    say,
    gx,
    gy,
    expand_cycles=False,
    dialect="linuxcnc",
    read_ahead=None,
    tools=(),
) -> Correction | None:
    """The correction run by the engine alone (reading, field, figures, emitting and writing to
    ``out_file`` in threads without the GIL), for the fields of :func:`_native_field`. None when a
    check refuses the program: ``out_file`` is then emptied and the caller runs the Python
    evaluation, which reports the refusal as it always has."""
    shift_norm = None
    if spec[0] == "shift":
        # the displacement's length as the Python evaluation computes it for every point
        d = np.array([spec[1]])
        shift_norm = float(np.sqrt(np.einsum("ij,ij->i", d, d))[0])
    out_file.flush()
    start = out_file.tell()
    r = _engine(
        lambda: _nc_correct(
            source,
            out_file.fileno(),
            spec,
            float(chord_tol),
            float(max_segment),
            bool(rapids),
            gx,
            gy,
            _PIECE_BYTES,
            float(limit),
            bool(keep_unsupported),
            None if clearance is None else float(clearance),
            shift_norm,
            lambda a, b: say(f"correcting lines {a + 1:,}-{b:,}"),
            bool(expand_cycles),
            dialect,
            read_ahead,
            list(tools),
        ),
        name,
    )
    if r is None:
        out_file.seek(start)
        out_file.truncate()
        return None
    notes = _Warnings(field, clearance)
    notes.unknown, notes.first, notes.low = r["unknown"], r["first_unknown"], list(r["low"])
    uns = tuple(Unsupported(*u) for u in r["unsupported"])
    return _correction(r["stats"], r["max"], r["total"], r["n_points"], uns, keep_unsupported, notes, r["notes"])


def _correct(
    source,
    name,
    write,
    field,
    *,
    chord_tol=constants.CHORD_TOL,
    max_segment=constants.MAX_SEGMENT,
    limit=constants.LIMIT,
    rapids=False,
    keep_unsupported=False,
    clearance=None,
    progress=None,
    keep_points=True,
    out_file=None,
    expand_cycles=False,
    dialect="linuxcnc",
    read_ahead=None,
    tools=None,
) -> Correction:
    """Read, sample, evaluate the field and emit, piece by piece; ``write`` takes the output bytes.

    ``source`` is the program's bytes or its file's path. Every check runs over the whole program
    before the caller's output counts as written: a refusal raises after the last piece, and the
    callers discard what ``write`` received. With ``out_file`` (the open file ``write`` ends in,
    nothing written yet) a field the engine evaluates itself (:func:`_native_field`) is applied
    by the engine alone, writing to the file directly. ``dialect`` (``linuxcnc``, ``fanuc``,
    ``grbl``, ``marlin``) is the controller the program is written for. ``tools`` {tool number:
    diameter mm}: the tool table cutter radius compensation (G41/G42) takes its radius from.
    """
    tools = sorted((int(t), float(d)) for t, d in (tools or {}).items())
    say = progress or (lambda msg: None)
    check_sampling(chord_tol, max_segment)
    if not limit > 0:
        raise ValueError(f"limit must be > 0 mm, got {limit}")
    grid = getattr(field, "grid_lines", None)
    gx, gy = ([], []) if grid is None else (list(map(float, grid[0])), list(map(float, grid[1])))
    spec = _native_field(field) if out_file is not None and not keep_points else None
    lathe = dialect.endswith("-lathe")
    if spec is not None and lathe and spec[0] == "shift":
        dx, dy, dz = spec[1]
        if abs(dy) > chord_tol:
            raise RefusedError(
                f"{name}: the shift moves Y by {dy:g} mm, and a lathe has no Y axis: give DX and DZ, "
                f"or a DY within --chord-tol ({chord_tol:g} mm); nothing written"
            )
        spec = ("shift", (dx, 0.0, dz))
    if spec is None and read_ahead is not None:
        read_ahead.cancel()  # the Python evaluation reads the program itself
    if spec is not None:
        c = _correct_native(
            source,
            name,
            out_file,
            field,
            spec,
            chord_tol=chord_tol,
            max_segment=max_segment,
            limit=limit,
            rapids=rapids,
            keep_unsupported=keep_unsupported,
            clearance=clearance,
            say=say,
            gx=gx,
            gy=gy,
            expand_cycles=expand_cycles,
            dialect=dialect,
            read_ahead=read_ahead,
            tools=tools,
        )
        if c is not None:
            return c
    run = _engine(
        lambda: _NativeCorrector(
            source,
            float(chord_tol),
            float(max_segment),
            bool(rapids),
            True,
            gx,
            gy,
            _PIECE_BYTES,
            bool(expand_cycles),
            dialect,
            # sampled as the engine samples for itself: an arc a bilinear grid leaves flat at its end
            _grid_spec(field),
            tools,
        ),
        name,
    )
    kept: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    outside: list[dict] = []
    n_outside, domain = 0, ""
    worst: list[tuple[float, int, np.ndarray, np.ndarray]] = []  # the largest displacements seen
    n_pts, total, refused = 0, 0.0, False
    notes = _Warnings(field, clearance)
    approach = _Approach()
    comp_refusal = None  # (line, why): cutter compensation the correction cannot follow
    while (chunk := _engine(run.next, name)) is not None:
        first, end, xyz, rec, recs, checks = chunk
        say(f"correcting lines {first + 1:,}-{end:,}")
        r = _piece_records(recs)
        notes.add(r)
        if run.n_unsupported() and not keep_unsupported:
            # refused whatever the field does: read on for the whole list, without evaluating it
            refused = True
            run.discard()
            continue
        pts = np.frombuffer(xyz, dtype="<f8").reshape(-1, 3)
        recs_i = np.frombuffer(rec, dtype="<u4")
        lines = r["line"][recs_i]
        uvw = None
        try:
            if not len(pts):
                disp = np.zeros((0, 3))
            elif getattr(field, "uses_axes", False):
                disp = np.ascontiguousarray(field(pts, _axes_at(pts, recs_i, r)), dtype=np.float64)
                disp, uvw = _split_uvw(disp, pts)
            else:
                disp = np.ascontiguousarray(field(pts), dtype=np.float64)
        except _OutsideError as e:
            refused = True
            n_outside += len(e.indices)
            domain = e.domain
            outside += [
                {"line": int(lines[i]), "position": pts[i].round(4).tolist()}
                for i in e.indices[: max(0, 10 - len(outside))]
            ]
            run.discard()
            continue
        if disp.shape != pts.shape:
            raise ValueError(f"field returned shape {disp.shape}, expected {pts.shape}")
        if lathe:
            disp = np.array(disp)
            _lathe_y(disp, lines, chord_tol, name)
        if not np.isfinite(disp).all():
            bad = int(np.flatnonzero(~np.isfinite(disp).all(axis=1))[0])
            raise RefusedError(f"{name}: the field is not finite at line {lines[bad]} {pts[bad].round(4).tolist()}")
        if uvw is not None and not np.isfinite(uvw).all():
            bad = int(np.flatnonzero(~np.isfinite(uvw).all(axis=1))[0])
            raise RefusedError(f"{name}: the field is not finite at line {lines[bad]} {pts[bad].round(4).tolist()}")
        if comp_refusal is None and (r["flags"] & 32).any():
            comp_refusal = _comp_check(run, field, r, disp, checks, name)
            refused |= comp_refusal is not None
        approach.add(r, recs_i, pts, disp)
        refused |= approach.found is not None
        norms = np.sqrt(np.einsum("ij,ij->i", disp, disp) + (0.0 if uvw is None else np.einsum("ij,ij->i", uvw, uvw)))
        n_pts += len(norms)
        total += float(norms.sum())
        # the ten largest displacements seen (a piece whose largest is below the tenth adds none)
        if len(norms) and (len(worst) < 10 or float(norms.max()) > worst[-1][0]):
            top = np.argpartition(-norms, min(10, len(norms)) - 1)[:10]
            worst = sorted(
                worst + [(float(norms[i]), int(lines[i]), pts[i].copy(), disp[i].copy()) for i in top],
                key=lambda w: -w[0],
            )[:10]
            refused |= worst[0][0] > limit
        if keep_points:
            kept.append((pts.copy(), disp, lines))
        if refused:
            run.discard()  # the output is no longer wanted; the checks still see every piece
        else:
            write(_engine(lambda d=disp, u=uvw: run.emit(d, u), name))
    uns = tuple(Unsupported(*u) for u in run.unsupported())
    if uns and not keep_unsupported:
        raise _unsupported_error(name, uns)
    if n_outside:
        raise RefusedError(
            f"{name}: {n_outside:,} point(s) outside the field's domain {domain}; nothing written "
            f"(first at line {outside[0]['line']}); --outside clamp or extrapolate (outside= in Python) allows them",
            outside,
        )
    if comp_refusal is not None:
        line, why = comp_refusal
        raise RefusedError(f"{name}: line {line}: {why}; nothing written", [{"line": line}])
    worst_norm = worst[0][0] if worst else 0.0
    into_part = approach.error(name)
    if into_part is not None:
        raise into_part
    if worst_norm > limit:
        details = [
            {"line": ln, "position": p.round(4).tolist(), "displacement": d.round(4).tolist(), "magnitude": round(m, 4)}
            for m, ln, p, d in worst
        ]
        raise RefusedError(
            f"{name}: displacement {worst_norm:.4f} mm at line {details[0]['line']} exceeds the limit "
            f"{limit:g} mm; nothing written",
            details,
        )
    tail = _engine(run.finish, name)
    if not refused:
        write(tail)
    pts_all = disp_all = line_all = None
    if keep_points:
        pts_all = np.concatenate([k[0] for k in kept]) if kept else np.zeros((0, 3))
        disp_all = np.concatenate([k[1] for k in kept]) if kept else np.zeros((0, 3))
        line_all = np.concatenate([k[2] for k in kept]) if kept else np.zeros(0, dtype=np.int64)
    return _correction(
        run.stats(), worst_norm, total, n_pts, uns, keep_unsupported, notes, run.notes(), pts_all, disp_all, line_all
    )


def _correction(
    stats,
    max_norm,
    total,
    n_pts,
    uns,
    keep_unsupported,
    notes,
    engine_notes,
    points=None,
    displacements=None,
    line=None,
) -> Correction:
    """The :class:`Correction` of a run: its engine's figures and the warnings gathered."""
    warnings = notes.messages()
    if keep_unsupported and uns:
        warnings.insert(0, f"{len(uns)} unsupported construct(s) kept unchanged, their blocks not corrected")
    return Correction(
        lines_in=stats["lines_in"],
        lines_out=stats["lines_out"],
        blocks_changed=stats["blocks_changed"],
        lines_added=stats["lines_added"],
        arcs_linearised=stats["arcs_linearised"],
        splines_linearised=stats["splines_linearised"],
        max_displacement=max_norm,
        mean_displacement=total / n_pts if n_pts else 0.0,
        n_points=n_pts,
        points=points,
        displacements=displacements,
        line=line,
        unsupported_kept=uns if keep_unsupported else (),
        warnings=tuple(warnings),
        notes=tuple(engine_notes),
    )


class _BackgroundWriter:
    """Writes chunks to a file in a second thread, so the disk works while the next chunk is
    computed (file writes release the GIL). At most two chunks wait; errors surface on exit. The
    thread starts with the first chunk (a native correction writes the file itself)."""

    def __init__(self, f):
        self._f = f
        self._pool = None
        self._pending: list = []

    def write(self, data: bytes) -> None:
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor  # imported where needed: start-up time

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ncadapt-writer")
        if len(self._pending) >= 2:
            self._pending.pop(0).result()
        self._pending.append(self._pool.submit(self._f.write, data))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        try:
            for fut in self._pending:
                fut.result()
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=True)
        return False


# imported late: fields imports nothing from here, but keeps the outside error type
from . import fields as _fields  # noqa: E402
from .fields import OutsideError as _OutsideError  # noqa: E402
