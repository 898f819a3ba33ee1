//! Toolpath sampler: linear moves split to a maximum segment length, arcs (any plane, helical)
//! linearised by a chord tolerance, and every piece split again where it crosses a grid line.

use crate::error::NcError;
use crate::interp::{Interp, Motion, Record, LATHE_CUTS, NAXES, PLANE_AXES};
use std::f64::consts::PI;

/// Most pieces one block may be cut into. A block that would need more (a coordinate of 1e20, an
/// arc of a billion turns, a segment length of a nanometre) is refused at its line before any
/// memory is taken for it.
pub const MAX_PIECES_PER_BLOCK: f64 = 1_000_000.0;

/// Sampling options (lengths in mm).
#[derive(Clone, Debug)]
pub struct SampleOpts {
    pub chord_tol: f64,
    pub max_segment: f64,
    pub include_rapids: bool,
    /// Only blocks that can be corrected (else every traceable motion block).
    pub only_supported: bool,
    /// Sorted grid lines to split at (x then y); empty for none.
    pub grid_x: Vec<f64>,
    pub grid_y: Vec<f64>,
    /// The grid field the samples are for, when the engine evaluates it: a G17 arc over which it
    /// varies by no more than the chord tolerance is sampled at its end only (it stays an arc,
    /// and its chords are not needed).
    pub grid: Option<std::sync::Arc<crate::field::Grid>>,
}

/// Sample points: the end of every piece, in block order.
#[derive(Clone, Debug, Default)]
pub struct Samples {
    /// (n * 3) piece end points, mm.
    pub xyz: Vec<f64>,
    /// (n) position of the piece end along its block, 0 < t <= 1.
    pub t: Vec<f64>,
    /// (n) record index of each piece.
    pub rec: Vec<u32>,
    /// Index of the first record sampled: `range[k]` belongs to record `rec0 + k`.
    pub rec0: usize,
    /// For every record sampled: first sample index and count (count 0: not sampled).
    pub range: Vec<(u32, u32)>,
    /// Arcs sampled at their end only because the grid field varies over them by no more than
    /// the chord tolerance: (record index, that variation in mm), in record order.
    pub flat: Vec<(u32, f64)>,
    /// Where the field is evaluated for each sample (n * 3, mm) when a record of the range is
    /// under cutter radius compensation: the tool centre ([`crate::interp::Comp`]); empty when
    /// that is the sample itself.
    pub at: Vec<f64>,
    /// Tool-centre points around the corners of compensated contours (k * 3, mm), and the groups
    /// they form: (record index, first point, count). The field must vary over a group by no
    /// more than the chord tolerance ([`comp_check`]).
    pub checks: Vec<f64>,
    pub check_groups: Vec<(u32, u32, u32)>,
}

impl Samples {
    /// The points the field is evaluated at (n * 3, mm): the tool centres ([`Samples::at`]) when
    /// the range has compensated moves, else the samples.
    pub fn eval_points(&self) -> &[f64] {
        if self.at.is_empty() {
            &self.xyz
        } else {
            &self.at
        }
    }

    /// First sample index and count of record `ri`.
    #[inline]
    pub fn of(&self, ri: usize) -> (usize, usize) {
        let (f, c) = self.range[ri - self.rec0];
        (f as usize, c as usize)
    }
}

/// Start position of record `i`.
#[inline]
pub fn start_of(it: &Interp, i: usize) -> [f64; NAXES] {
    if i == 0 {
        it.origin
    } else {
        it.records[i - 1].end
    }
}

/// Arc geometry in its plane: start angle, signed sweep (rad), start and end radius.
pub fn arc_sweep(rec: &Record, start: &[f64; NAXES]) -> (f64, f64, f64, f64) {
    let [a1, a2, _] = PLANE_AXES[rec.plane as usize];
    let c = rec.center;
    let (sx, sy) = (start[a1] - c[0], start[a2] - c[1]);
    let (ex, ey) = (rec.end[a1] - c[0], rec.end[a2] - c[1]);
    let r0 = sx.hypot(sy);
    let r1 = ex.hypot(ey);
    let th0 = sy.atan2(sx);
    let th1 = ey.atan2(ex);
    let ccw = rec.motion == Motion::ArcCcw;
    let closed = (rec.end[a1] - start[a1]).hypot(rec.end[a2] - start[a2]) <= 1e-9 * r0.max(1.0);
    let mut d = th1 - th0;
    if closed {
        d = if ccw { 2.0 * PI } else { -2.0 * PI };
    } else if ccw {
        while d <= 0.0 {
            d += 2.0 * PI;
        }
    } else {
        while d >= 0.0 {
            d -= 2.0 * PI;
        }
    }
    let extra = (rec.turns.max(1) - 1) as f64 * 2.0 * PI;
    d += if ccw { extra } else { -extra };
    (th0, d, r0, r1)
}

/// Pieces of at most `max` for a length: a length a rounding error over a multiple of `max`
/// (3.0000000000000004 for 3) does not get an extra piece.
#[inline]
fn pieces_for(len: f64, max: f64) -> f64 {
    (len / max * (1.0 - 1e-12)).ceil()
}

/// Number of pieces for an arc.
pub fn arc_pieces(geom: (f64, f64, f64, f64), dn: f64, opts: &SampleOpts) -> f64 {
    arc_pieces_within(geom, dn, opts, opts.chord_tol)
}

/// [`arc_pieces`] with chords within `chord_tol` (mm).
fn arc_pieces_within(
    geom: (f64, f64, f64, f64),
    dn: f64,
    opts: &SampleOpts,
    chord_tol: f64,
) -> f64 {
    let (_, d, r0, r1) = geom;
    let r = r0.max(r1);
    let ad = d.abs();
    let mut n = (ad / (PI / 2.0)).ceil().max(1.0);
    if r > chord_tol {
        // the angle whose chord stays within the tolerance: 1 - cos(θ/2) = tol / r, written
        // with asin so that it keeps its precision for tolerances far below the radius
        let dth = 4.0 * (chord_tol / (2.0 * r)).sqrt().asin();
        if dth > 0.0 {
            n = n.max((ad / dth).ceil());
        }
    }
    let len = (ad * 0.5 * (r0 + r1)).hypot(dn);
    if opts.max_segment > 0.0 {
        n = n.max(pieces_for(len, opts.max_segment));
    }
    n
}

/// How much the grid field varies over a G17 arc's circle (the larger radius of a spiral), when
/// that is within the chord tolerance less a margin for the rounding of written numbers and the
/// block before the arc, in this run, is a corrected move (its end, where the output starts the
/// arc, is displaced by the field there). None otherwise.
fn flat_under(
    it: &Interp,
    i: usize,
    start: &[f64; NAXES],
    opts: &SampleOpts,
    s: &Samples,
) -> Option<f64> {
    let g = opts.grid.as_ref()?;
    let rec = &it.records[i];
    let k = i.checked_sub(s.rec0)?.checked_sub(1)?;
    let prev = &it.records[s.rec0 + k];
    if rec.plane != 0
        || prev.cycle != 0
        || prev.motion == Motion::Other
        || s.range.get(k).is_none_or(|&(_, c)| c == 0)
    {
        return None;
    }
    let c = rec.center;
    let r = (start[0] - c[0])
        .hypot(start[1] - c[1])
        .max((rec.end[0] - c[0]).hypot(rec.end[1] - c[1]));
    if !r.is_finite() {
        return None;
    }
    let (lo, hi) = g.range_over(c[0] - r, c[0] + r, c[1] - r, c[1] + r)?;
    (hi - lo <= opts.chord_tol - FLAT_MARGIN).then_some(hi - lo)
}

/// What [`flat_under`] leaves of the chord tolerance for the rounding of the numbers around the
/// arc: half a unit of the last written digit, at most 0.000005 inch (the emitter writes at least
/// 4 decimals in mm and 5 in inch).
pub const FLAT_MARGIN: f64 = 0.000_005 * crate::interp::MM_PER_INCH;

fn too_many(rec: &Record, n: f64) -> NcError {
    NcError::Interpret {
        line: rec.line as usize + 1,
        col: 1,
        message: format!(
            "this move would be cut into {n:.3e} pieces, more than the {MAX_PIECES_PER_BLOCK:.0} allowed for one block; check its coordinates, or raise the segment length or chord tolerance"
        ),
    }
}

fn traceable(rec: &Record) -> bool {
    rec.motion != Motion::Other
        && (0..3).all(|k| rec.end[k].is_finite())
        && rec.center.iter().all(|v| v.is_finite())
}

/// Sample the blocks of an interpreted program.
pub fn sample(it: &Interp, opts: &SampleOpts) -> Result<Samples, NcError> {
    let mut s = Samples::default();
    sample_range(it, opts, 0..it.records.len(), &mut s)?;
    Ok(s)
}

/// Sample records `recs` into `s`, replacing what it held (its buffers are reused).
pub fn sample_range(
    it: &Interp,
    opts: &SampleOpts,
    recs: std::ops::Range<usize>,
    s: &mut Samples,
) -> Result<(), NcError> {
    s.xyz.clear();
    s.t.clear();
    s.rec.clear();
    s.range.clear();
    s.flat.clear();
    s.at.clear();
    s.checks.clear();
    s.check_groups.clear();
    let any_comp = !it.comps.is_empty();
    s.rec0 = recs.start;
    let mut cuts: Vec<f64> = Vec::new();
    let (grid_x, grid_y) = (GridLines::new(&opts.grid_x), GridLines::new(&opts.grid_y));
    for i in recs {
        let rec = &it.records[i];
        let start = start_of(it, i);
        if (opts.only_supported && !rec.supported)
            || (rec.motion == Motion::Rapid && !opts.include_rapids)
            || !traceable(rec)
        {
            s.range.push((s.t.len() as u32, 0));
            continue;
        }
        let first = s.t.len();
        let mut prev = [start[0], start[1], start[2]];
        let mut prev_t = 0.0;
        let comp = (rec.comp != crate::interp::NO_COMP).then(|| &it.comps[rec.comp as usize]);
        // the tool centre's offset from the programmed point at `p`, `t` along the block
        let offset = |p: &[f64; 3], t: f64| -> [f64; 2] {
            match comp {
                None => [0.0; 2],
                // the arc that starts compensation: the tool at the same fraction of its own arc
                Some(crate::interp::Comp {
                    entry: Some((c, rho, a0, sweep)),
                    ..
                }) => {
                    let a = a0 + t * sweep;
                    [c[0] + rho * a.cos() - p[0], c[1] + rho * a.sin() - p[1]]
                }
                Some(c) if rec.motion.is_arc() => {
                    let (x, y) = (p[0] - rec.center[0], p[1] - rec.center[1]);
                    let l = x.hypot(y);
                    [c.radial * x / l, c.radial * y / l]
                }
                Some(c) => [
                    c.start[0] + t * (c.end[0] - c.start[0]),
                    c.start[1] + t * (c.end[1] - c.start[1]),
                ],
            }
        };
        let mut prev_o = offset(&prev, 0.0);
        let push = |s: &mut Samples,
                    p: [f64; 3],
                    t: f64,
                    prev: &mut [f64; 3],
                    prev_t: &mut f64,
                    prev_o: &mut [f64; 2],
                    cuts: &mut Vec<f64>| {
            let o = offset(&p, t);
            // (an arc under cutter compensation is not split at the grid lines: its chords would
            // be as short as the crossings make them, which the controller reads as corners)
            if (!opts.grid_x.is_empty() || !opts.grid_y.is_empty())
                && (comp.is_none() || !rec.motion.is_arc())
            {
                // where the tool centre crosses the grid lines
                cuts.clear();
                crossings(&grid_x, prev[0] + prev_o[0], p[0] + o[0], cuts);
                crossings(&grid_y, prev[1] + prev_o[1], p[1] + o[1], cuts);
                if cuts.len() > 1 {
                    cuts.sort_by(|a, b| a.partial_cmp(b).unwrap());
                }
                let mut last = -1.0;
                for &u in cuts.iter() {
                    if u - last < 1e-12 {
                        continue;
                    }
                    last = u;
                    s.xyz.extend_from_slice(&[
                        prev[0] + u * (p[0] - prev[0]),
                        prev[1] + u * (p[1] - prev[1]),
                        prev[2] + u * (p[2] - prev[2]),
                    ]);
                    s.t.push(*prev_t + u * (t - *prev_t));
                    s.rec.push(i as u32);
                    if any_comp {
                        let n = s.xyz.len();
                        s.at.extend_from_slice(&[
                            s.xyz[n - 3] + prev_o[0] + u * (o[0] - prev_o[0]),
                            s.xyz[n - 2] + prev_o[1] + u * (o[1] - prev_o[1]),
                            s.xyz[n - 1],
                        ]);
                    }
                }
            }
            s.xyz.extend_from_slice(&p);
            s.t.push(t);
            s.rec.push(i as u32);
            if any_comp {
                s.at.extend_from_slice(&[p[0] + o[0], p[1] + o[1], p[2]]);
            }
            *prev = p;
            *prev_t = t;
            *prev_o = o;
        };
        let end = [rec.end[0], rec.end[1], rec.end[2]];
        // (a G5 whose first control point is not known: its end alone)
        let spline = rec.motion.is_spline().then(|| it.spline(i)).flatten();
        let spline_unknown = rec.motion.is_spline()
            && spline.is_none_or(|sp| !sp.ctrl.iter().flatten().all(|v| v.is_finite()));
        let end_only = !prev.iter().all(|v| v.is_finite())
            || spline_unknown
            || rec.cycle == crate::interp::CYCLE_BOTTOM
            || rec.cycle == crate::interp::CYCLE_LATHE;
        // an arc over whose circle the field varies by no more than the chord tolerance, the block
        // before it corrected (so the output starts the arc where the field puts its start): it
        // stays an arc, moved along a helix to its end's displacement (the emitter keeps it)
        let flat = (!end_only && rec.motion.is_arc() && comp.is_none())
            .then(|| flat_under(it, i, &start, opts, s))
            .flatten();
        if end_only || flat.is_some() {
            // from an unknown start only the end is known; a hole of a canned cycle is moved
            // by the displacement at its bottom; a flat arc needs no chords
            s.xyz.extend_from_slice(&end);
            s.t.push(1.0);
            s.rec.push(i as u32);
            if any_comp {
                let o = offset(&end, 1.0);
                s.at.extend_from_slice(&[end[0] + o[0], end[1] + o[1], end[2]]);
            }
            if let Some(range) = flat {
                s.flat.push((i as u32, range));
            }
        } else if let Some(sp) = spline {
            // LinuxCNC's arcs of the curve, each cut in chords within the tolerance
            let mut cp = vec![
                [start[0], start[1], 1.0],
                [sp.ctrl[0][0], sp.ctrl[0][1], 1.0],
            ];
            if rec.motion == Motion::Spline {
                cp.push([sp.ctrl[1][0], sp.ctrl[1][1], 1.0]);
            }
            cp.push([rec.end[0], rec.end[1], 1.0]);
            let small = 1e-6
                * if rec.inch {
                    crate::interp::MM_PER_INCH
                } else {
                    1.0
                };
            let pieces = crate::spline::linuxcnc_pieces(&cp, cp.len(), small).map_err(|why| {
                NcError::Interpret {
                    line: rec.line as usize + 1,
                    col: 1,
                    message: why.into(),
                }
            })?;
            // the chords of each piece: (start, end, centre, start angle, sweep and radius of an
            // arc, length, count)
            let mut plan = Vec::with_capacity(pieces.len());
            let (mut from, mut total, mut count) = ([start[0], start[1]], 0.0, 0.0);
            for pc in &pieces {
                let (len, n, arc) = match pc.centre {
                    Some(c) => {
                        let r = (from[0] - c[0]).hypot(from[1] - c[1]);
                        let a0 = (from[1] - c[1]).atan2(from[0] - c[0]);
                        let a1 = (pc.end[1] - c[1]).atan2(pc.end[0] - c[0]);
                        let mut d = a1 - a0;
                        if pc.ccw {
                            while d <= 0.0 {
                                d += 2.0 * PI;
                            }
                        } else {
                            while d >= 0.0 {
                                d -= 2.0 * PI;
                            }
                        }
                        let n = arc_pieces_within((a0, d, r, r), 0.0, opts, opts.chord_tol);
                        (r * d.abs(), n, Some((c, a0, d, r)))
                    }
                    None => {
                        let len = (pc.end[0] - from[0]).hypot(pc.end[1] - from[1]);
                        let n = if opts.max_segment > 0.0 {
                            pieces_for(len, opts.max_segment).max(1.0)
                        } else {
                            1.0
                        };
                        (len, n, None)
                    }
                };
                plan.push((from, pc.end, arc, len, n));
                total += len;
                count += n;
                from = pc.end;
            }
            if !(count <= MAX_PIECES_PER_BLOCK) {
                return Err(too_many(rec, count));
            }
            let mut done = 0.0;
            let count = plan.len();
            for (q, (from, to, arc, len, n)) in plan.into_iter().enumerate() {
                let n = n as usize;
                for m in 1..=n {
                    let f = m as f64 / n as f64;
                    let last = q + 1 == count && m == n;
                    let xy = match arc {
                        _ if m == n => to,
                        Some((c, a0, d, r)) => {
                            let (sn, cs) = (a0 + f * d).sin_cos();
                            [c[0] + r * cs, c[1] + r * sn]
                        }
                        None => [
                            from[0] + f * (to[0] - from[0]),
                            from[1] + f * (to[1] - from[1]),
                        ],
                    };
                    let t = if last || total <= 0.0 {
                        1.0
                    } else {
                        ((done + f * len) / total).min(1.0)
                    };
                    let p = if last { end } else { [xy[0], xy[1], start[2]] };
                    push(s, p, t, &mut prev, &mut prev_t, &mut prev_o, &mut cuts);
                }
                done += len;
            }
        } else if rec.motion.is_arc() {
            let geom = arc_sweep(rec, &start);
            let an = PLANE_AXES[rec.plane as usize][2];
            // under cutter compensation the tool outside the arc runs the chords' offsets, whose
            // joints the controller neither rounds nor trims when they turn by under 0.05 rad: it
            // cuts chords of the offset circle, so their number is that circle's
            let out = comp.map_or(0.0, |c| c.radial.max(0.0));
            // (under radius compensation in G18/G19 half the tolerance goes to the chords, half
            // to the field's change within the radius: see comp_check)
            let tol = if rec.nose > 0.0 {
                opts.chord_tol / 2.0
            } else {
                opts.chord_tol
            };
            let mut n = arc_pieces_within(
                (geom.0, geom.1, geom.2 + out, geom.3 + out),
                rec.end[an] - start[an],
                opts,
                tol,
            );
            // the arc that starts compensation: the tool's own arc may be far longer
            if let Some(crate::interp::Comp {
                entry: Some((_, rho, a0, sweep)),
                ..
            }) = comp
            {
                n = n.max(arc_pieces_within(
                    (*a0, *sweep, *rho, *rho),
                    rec.end[an] - start[an],
                    opts,
                    tol,
                ));
            }
            if !(n <= MAX_PIECES_PER_BLOCK) {
                return Err(too_many(rec, n));
            }
            let n = n as usize;
            // the angle's cosine and sine turned by the piece's angle from one point to the
            // next, taken afresh from the library every ANCHOR points (the turns' rounding stays
            // within a few units of 1e-16 of the radius)
            const ANCHOR: usize = 8;
            let [a1, a2, an] = PLANE_AXES[rec.plane as usize];
            let (th0, d, r0, r1) = geom;
            let (sd, cd) = (d / n as f64).sin_cos();
            let (mut sn, mut cs) = (0.0, 1.0);
            for k in 1..=n {
                let t = k as f64 / n as f64;
                let p = if k == n {
                    end
                } else {
                    if (k - 1) % ANCHOR == 0 {
                        (sn, cs) = (th0 + t * d).sin_cos();
                    } else {
                        (sn, cs) = (sn * cd + cs * sd, cs * cd - sn * sd);
                    }
                    let r = r0 + t * (r1 - r0);
                    let mut p = [0.0; 3];
                    p[a1] = rec.center[0] + r * cs;
                    p[a2] = rec.center[1] + r * sn;
                    p[an] = start[an] + t * (rec.end[an] - start[an]);
                    p
                };
                push(s, p, t, &mut prev, &mut prev_t, &mut prev_o, &mut cuts);
            }
        } else {
            let len = ((end[0] - prev[0]).powi(2)
                + (end[1] - prev[1]).powi(2)
                + (end[2] - prev[2]).powi(2))
            .sqrt();
            let n = if opts.max_segment > 0.0 {
                pieces_for(len, opts.max_segment).max(1.0)
            } else {
                1.0
            };
            if !(n <= MAX_PIECES_PER_BLOCK) {
                return Err(too_many(rec, n));
            }
            let n = n as usize;
            let s0 = prev;
            for k in 1..=n {
                let t = k as f64 / n as f64;
                let p = if k == n {
                    end
                } else {
                    [
                        s0[0] + t * (end[0] - s0[0]),
                        s0[1] + t * (end[1] - s0[1]),
                        s0[2] + t * (end[2] - s0[2]),
                    ]
                };
                push(s, p, t, &mut prev, &mut prev_t, &mut prev_o, &mut cuts);
            }
        }
        s.range.push((first as u32, (s.t.len() - first) as u32));
        // a lathe's box cycle: the field along its two cuts, which meet at its corner (the
        // sample), from (corner X, start Z) and to (start X, corner Z)
        if rec.cycle == crate::interp::CYCLE_LATHE && s.t.len() > first {
            let k = it.boxes.partition_point(|b| b.line < rec.line);
            if let Some(b) = it
                .boxes
                .get(k)
                .filter(|b| b.line == rec.line && LATHE_CUTS.contains(&b.code))
            {
                // a grooving or threading cycle: the field over the rectangle it cuts in (from
                // its start to its end, widened by its margins), a grid of points at most
                // --max-segment apart, against the end's
                let c = [rec.end[0], rec.end[1], rec.end[2]];
                let g0 = s.checks.len() / 3;
                s.checks.extend_from_slice(&c);
                let lo = [
                    c[0].min(b.start[0]) - b.margin[0],
                    c[2].min(b.start[2]) - b.margin[1],
                ];
                let hi = [
                    c[0].max(b.start[0]) + b.margin[0],
                    c[2].max(b.start[2]) + b.margin[1],
                ];
                let n = [0, 1].map(|j| ((hi[j] - lo[j]) / opts.max_segment).ceil().max(1.0));
                if !((n[0] + 1.0) * (n[1] + 1.0) <= MAX_PIECES_PER_BLOCK) {
                    return Err(too_many(rec, (n[0] + 1.0) * (n[1] + 1.0)));
                }
                let n = n.map(|v| v as usize);
                for i in 0..=n[0] {
                    for j in 0..=n[1] {
                        s.checks.extend_from_slice(&[
                            lo[0] + (hi[0] - lo[0]) * i as f64 / n[0] as f64,
                            c[1],
                            lo[1] + (hi[1] - lo[1]) * j as f64 / n[1] as f64,
                        ]);
                    }
                }
                s.check_groups
                    .push((i as u32, g0 as u32, (s.checks.len() / 3 - g0) as u32));
            } else if let Some(b) = it.boxes.get(k).filter(|b| b.line == rec.line) {
                let c = [rec.end[0], 0.0, rec.end[2]];
                let g0 = s.checks.len() / 3;
                s.checks.extend_from_slice(&c);
                for far in [[c[0], 0.0, b.start[2]], [b.start[0], 0.0, c[2]]] {
                    let len = (far[0] - c[0]).hypot(far[2] - c[2]);
                    let n = (len / opts.max_segment).ceil().max(1.0) as usize;
                    for j in 1..=n {
                        let t = j as f64 / n as f64;
                        s.checks.extend_from_slice(&[
                            c[0] + t * (far[0] - c[0]),
                            0.0,
                            c[2] + t * (far[2] - c[2]),
                        ]);
                    }
                }
                s.check_groups
                    .push((i as u32, g0 as u32, (s.checks.len() / 3 - g0) as u32));
            }
        }
        // compensation in G18/G19 (a lathe's nose radius, a cutter's outside G17): the field at
        // the radius from each sample (the contact point the control offsets the tool from), in
        // eight directions of the compensation's plane
        if rec.nose > 0.0 {
            let r = rec.nose;
            let (u, v) = if rec.plane == 2 { (1, 2) } else { (0, 2) };
            for k in first..s.t.len() {
                let p = [s.xyz[3 * k], s.xyz[3 * k + 1], s.xyz[3 * k + 2]];
                s.check_groups
                    .push((i as u32, (s.checks.len() / 3) as u32, 9));
                s.checks.extend_from_slice(&p);
                for d in 0..8 {
                    let a = d as f64 * std::f64::consts::FRAC_PI_4;
                    let mut q = p;
                    q[u] += r * a.cos();
                    q[v] += r * a.sin();
                    s.checks.extend_from_slice(&q);
                }
            }
        }
        if let Some(c) = comp {
            if !c.corner.is_empty() && start[0].is_finite() && start[1].is_finite() {
                s.check_groups
                    .push((i as u32, (s.checks.len() / 3) as u32, c.corner.len() as u32));
                for o in &c.corner {
                    s.checks
                        .extend_from_slice(&[start[0] + o[0], start[1] + o[1], start[2]]);
                }
            }
        }
    }
    Ok(())
}

/// Sorted grid lines with a guess of where a value falls among them (exact for a uniform grid,
/// a starting point for any other).
struct GridLines<'a> {
    v: &'a [f64],
    first: f64,
    /// Lines per mm: (n - 1) / (last - first).
    per_mm: f64,
}

impl<'a> GridLines<'a> {
    fn new(v: &'a [f64]) -> Self {
        let n = v.len();
        let per_mm = if n >= 2 {
            (n - 1) as f64 / (v[n - 1] - v[0])
        } else {
            0.0
        };
        GridLines {
            v,
            first: if n > 0 { v[0] } else { 0.0 },
            per_mm: if per_mm.is_finite() { per_mm } else { 0.0 },
        }
    }

    /// `v.partition_point(|&g| g <= x)` (`OR_EQUAL`) or `v.partition_point(|&g| g < x)`: from
    /// the guess, walked to the exact place; a binary search when the guess is far off.
    #[inline(always)]
    fn partition<const OR_EQUAL: bool>(&self, x: f64) -> usize {
        let v = self.v;
        let n = v.len();
        let before = |g: f64| if OR_EQUAL { g <= x } else { g < x };
        let k = (x - self.first) * self.per_mm;
        let mut i = if k >= 0.0 {
            if k < n as f64 {
                // SAFETY: 0 <= k < n, so its whole part is a valid index; the line after it is
                // where x falls on a uniform grid
                (unsafe { k.to_int_unchecked::<u64>() as usize } + 1).min(n)
            } else {
                n
            }
        } else {
            0
        };
        let mut steps = 0;
        while i > 0 && !before(v[i - 1]) {
            i -= 1;
            steps += 1;
            if steps > 3 {
                return v.partition_point(|&g| before(g));
            }
        }
        while i < n && before(v[i]) {
            i += 1;
            steps += 1;
            if steps > 3 {
                return v.partition_point(|&g| before(g));
            }
        }
        i
    }
}

/// Fractions u in (0, 1) where the segment a→b crosses one of the sorted lines.
#[inline(always)]
fn crossings(lines: &GridLines, a: f64, b: f64, out: &mut Vec<f64>) {
    if lines.v.is_empty() || a == b {
        return;
    }
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    // most pieces lie within one cell: when the lines around the guessed cell hold both ends,
    // no line lies in (lo, hi) (the search below would find an empty range)
    let v = lines.v;
    let k = (lo - lines.first) * lines.per_mm;
    if k >= 0.0 && k < (v.len() - 1) as f64 {
        // SAFETY: 0 <= k < n - 1, so its whole part and the one after are valid indices
        let i = unsafe { k.to_int_unchecked::<i64>() } as usize;
        if v[i] <= lo && hi < v[i + 1] {
            return;
        }
    }
    crossings_found(lines, a, b, lo, hi, out);
}

/// [`crossings`] when the ends may lie in different cells.
#[inline(never)]
fn crossings_found(lines: &GridLines, a: f64, b: f64, lo: f64, hi: f64, out: &mut Vec<f64>) {
    let i0 = lines.partition::<true>(lo);
    let i1 = lines.partition::<false>(hi).max(i0);
    for &v in &lines.v[i0..i1] {
        let u = (v - a) / (b - a);
        if u > 1e-12 && u < 1.0 - 1e-12 {
            out.push(u);
        }
    }
}

/// Largest X or Y displacement (mm) a compensated move may get: the controller offsets the
/// moved contour along its own normal, which such a displacement turns (not followed).
pub const COMP_XY_TOL: f64 = 1e-9;

/// What refuses a compensated program once the field is known: the field displacing X or Y
/// under compensation, or varying around the tool at a corner by more than `budget` (mm; the
/// output keeps one displacement at a corner, where the controller turns the tool). `disp` holds
/// the displacements at the samples, `cdisp` at [`Samples::checks`]. (1-based line, message).
pub fn comp_check(
    it: &Interp,
    s: &Samples,
    disp: &[f64],
    cdisp: &[f64],
    budget: f64,
) -> Option<(u32, String)> {
    if it.comps.is_empty() && s.check_groups.is_empty() {
        return None;
    }
    for (k, &ri) in s.rec.iter().enumerate() {
        let rec = &it.records[ri as usize];
        if rec.comp != crate::interp::NO_COMP
            && (disp[3 * k].abs() > COMP_XY_TOL || disp[3 * k + 1].abs() > COMP_XY_TOL)
        {
            return Some((
                rec.line + 1,
                format!(
                    "the field moves X or Y ({:.4}, {:.4} mm) under cutter compensation: the controller offsets the moved contour along its own normal, which that turns; only a Z displacement is followed there",
                    disp[3 * k], disp[3 * k + 1]
                ),
            ));
        }
    }
    for &(ri, f, c) in &s.check_groups {
        let d = &cdisp[3 * f as usize..3 * (f + c) as usize];
        let mut worst = 0.0f64;
        for q in d.chunks_exact(3).skip(1) {
            let v = ((q[0] - d[0]).powi(2) + (q[1] - d[1]).powi(2) + (q[2] - d[2]).powi(2)).sqrt();
            worst = worst.max(v);
        }
        let rec = &it.records[ri as usize];
        if rec.cycle == crate::interp::CYCLE_LATHE {
            let k = it.boxes.partition_point(|b| b.line < rec.line);
            let cut = it
                .boxes
                .get(k)
                .filter(|b| b.line == rec.line && LATHE_CUTS.contains(&b.code));
            if let (Some(b), false) = (cut, worst <= budget) {
                let name = crate::interp::lathe_cut_name(b.code);
                return Some((
                    rec.line + 1,
                    format!(
                        "{name}: the field varies by {:.1} µm over the area it cuts in (from its start to its end), more than the chord tolerance {budget} mm, and the cycle is moved as one (its start and end by one displacement); raise --chord-tol to accept it",
                        worst * 1000.0
                    ),
                ));
            }
            if !(worst <= budget) {
                let um = worst * 1000.0;
                return Some((
                    rec.line + 1,
                    format!(
                        "a turning or facing cycle (G90, G94): the field varies by {um:.1} µm along its cuts, more than the chord tolerance {budget} mm, and the cycle block moves its corner by one displacement; write the cuts as moves (G0, G1) to have them corrected along their length, or raise --chord-tol"
                    ),
                ));
            }
            continue;
        }
        if rec.nose > 0.0 {
            // where the field is evaluated (the contact point, not the nose centre), and the
            // normal the control offsets the moved contour along, turned by the field's change:
            // each off by up to the change within the nose radius; where the move turns from the
            // one before, the point where the control meets the two offset paths by up to
            // 1/cos(turn/2) times that
            let corner = it
                .nose_corners
                .binary_search_by_key(&ri, |&(r, _, _)| r)
                .map_or(1.0, |k| it.nose_corners[k].1);
            // (an arc's chords take half the tolerance)
            let budget = if rec.motion.is_arc() {
                budget / 2.0
            } else {
                budget
            };
            if !(2.0 * worst * corner <= budget) {
                let um = 2.0 * worst * corner * 1000.0;
                let at_corner = if corner > 1.0 {
                    format!(
                        " (times {corner:.2} where it meets the move before, {:.0}° off its direction)",
                        2.0 * (1.0 / corner).acos().to_degrees()
                    )
                } else {
                    String::new()
                };
                return Some((
                    rec.line + 1,
                    format!(
                        "radius compensation in G18/G19 (a lathe's nose radius, or a cutter outside G17): the field changes by {:.1} µm within the radius ({:.4} mm), so the tool centre the control offsets from the corrected contour may be off by up to {um:.1} µm{at_corner}, more than the chord tolerance {budget} mm (raise --chord-tol to accept it)",
                        worst * 1000.0,
                        rec.nose
                    ),
                ));
            }
            continue;
        }
        if !(worst <= budget) {
            let r = it.comps[rec.comp as usize].radius;
            let um = worst * 1000.0;
            return Some((
                rec.line + 1,
                format!(
                    "cutter compensation corner: the field varies by {um:.1} µm around the tool (radius {r:.4} mm) where the controller turns it, more than the chord tolerance {budget} mm; the corrected program keeps one displacement there (raise --chord-tol to accept {um:.1} µm)"
                ),
            ));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interp::interpret;
    use crate::lex::lex;

    fn opts() -> SampleOpts {
        SampleOpts {
            chord_tol: 0.002,
            max_segment: 1.0,
            include_rapids: false,
            only_supported: true,
            grid_x: vec![],
            grid_y: vec![],
            grid: None,
        }
    }

    #[test]
    fn chord_tolerance_holds() {
        let src = b"G0 X10 Y0 Z0\nG3 X10 Y0 I-10 J0\n";
        let l = lex(src).unwrap();
        let it = interpret(&l).unwrap();
        let s = sample(&it, &opts()).unwrap();
        let n = s.t.len();
        // full circle of radius 10: pieces from the chord tolerance 0.002 and the 1 mm length
        let dth = 2.0 * (1.0f64 - 0.002 / 10.0).acos();
        let expect = ((2.0 * PI / dth).ceil()).max((2.0 * PI * 10.0f64).ceil()) as usize;
        assert_eq!(n, expect);
        for k in 0..n {
            let (x, y) = (s.xyz[3 * k], s.xyz[3 * k + 1]);
            assert!((x.hypot(y) - 10.0).abs() < 1e-9);
        }
    }

    #[test]
    fn grid_line_search_is_partition_point() {
        let uniform: Vec<f64> = (0..=100).map(|i| i as f64 * 0.1).collect();
        let irregular = vec![-3.0, -1.0, 0.0, 0.001, 0.5, 7.0, 7.0000001, 100.0];
        let mut seed = 0x2545F4914F6CDD1Du64;
        for v in [uniform, irregular, vec![1.0], vec![]] {
            let g = GridLines::new(&v);
            let mut xs: Vec<f64> = v
                .iter()
                .flat_map(|&x| [x, x - 1e-12, x + 1e-12, x.next_up(), x.next_down()])
                .collect();
            for _ in 0..10000 {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                xs.push((seed >> 11) as f64 / (1u64 << 53) as f64 * 130.0 - 15.0);
            }
            xs.extend([f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300]);
            for x in xs {
                assert_eq!(
                    g.partition::<true>(x),
                    v.partition_point(|&a| a <= x),
                    "{x} in {v:?}"
                );
                assert_eq!(
                    g.partition::<false>(x),
                    v.partition_point(|&a| a < x),
                    "{x} in {v:?}"
                );
            }
        }
    }

    #[test]
    fn crossings_are_every_line_strictly_inside() {
        let uniform: Vec<f64> = (0..=100).map(|i| i as f64).collect();
        let irregular = vec![-3.0, -1.0, 0.0, 0.001, 0.5, 7.0, 7.0000001, 100.0];
        let mut seed = 0x9E3779B97F4A7C15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for v in [uniform, irregular, vec![1.0]] {
            let g = GridLines::new(&v);
            for k in 0..20000 {
                let a = next() * 120.0 - 10.0;
                // short pieces (within a cell mostly), long ones, and ends on a line
                let b = match k % 4 {
                    0 => a + (next() - 0.5) * 0.5,
                    1 => a + (next() - 0.5) * 20.0,
                    2 => v[k % v.len()],
                    _ => a,
                };
                let a = if k % 8 == 3 { v[(k / 8) % v.len()] } else { a };
                let mut got = Vec::new();
                crossings(&g, a, b, &mut got);
                // every line, one by one
                let expect: Vec<f64> = v
                    .iter()
                    .filter(|&&l| a != b && l > a.min(b) && l < a.max(b))
                    .map(|&l| (l - a) / (b - a))
                    .filter(|&u| u > 1e-12 && u < 1.0 - 1e-12)
                    .collect();
                assert_eq!(got, expect, "{a} {b} in {v:?}");
            }
        }
    }

    #[test]
    fn grid_lines_split() {
        let src = b"G0 X0.5 Y0.5 Z0\nG1 X3.5 Y0.5\n";
        let l = lex(src).unwrap();
        let it = interpret(&l).unwrap();
        let mut o = opts();
        o.max_segment = 100.0;
        o.grid_x = vec![0.0, 1.0, 2.0, 3.0, 4.0];
        o.grid_y = vec![0.0, 1.0];
        let s = sample(&it, &o).unwrap();
        let xs: Vec<f64> = (0..s.t.len()).map(|k| s.xyz[3 * k]).collect();
        assert_eq!(xs, vec![1.0, 2.0, 3.0, 3.5]);
    }
}
