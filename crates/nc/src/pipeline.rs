//! A whole correction with a native field, in four threads: one reads, lexes and interprets
//! the program piece by piece, one samples each piece and evaluates the field there (with the
//! figures: points, sum and largest displacement, warnings), one emits, one writes. At most a few
//! pieces are held at a time, so memory does not grow with the program.
//!
//! The number style every piece is written in is the whole program's. It is taken from the
//! first piece and checked against the whole program's at the end: when they differ (a program
//! whose later part writes more decimals, say), the correction is run again with the program's
//! style. The output is therefore the one [`crate::stream::scan_style`] and a second pass give.
//!
//! The run stops with [`Outcome::Refused`] as soon as a check would refuse the program (an
//! unsupported construct, a point outside the field, a displacement over the limit, a value that
//! is not finite): the caller then runs the evaluation that reports it.

use std::io::Write;
use std::sync::mpsc::{channel, sync_channel, Receiver, Sender, SyncSender};

use crate::emit::{EmitState, EmitStats, Emitter};
use crate::error::NcError;
use crate::field::{numpy_sum, Field};
use crate::interp::{Interp, Note, Summary, Unsupported, AXES, NAXES};
use crate::lex::NumberStyle;
use crate::sample::{sample_range, SampleOpts, Samples};
use crate::stream::{Piece, Reader, Stream};

/// Options of a native correction.
#[derive(Clone, Debug)]
pub struct Options {
    pub sample: SampleOpts,
    pub piece_bytes: usize,
    /// Largest displacement allowed, mm.
    pub limit: f64,
    pub keep_unsupported: bool,
    /// Report uncorrected rapids that end below this Z inside the field's bounds.
    pub clearance: Option<f64>,
    /// The displacement's length for a shift, as the caller computes it (None: sqrt(dz * dz)
    /// per point, a grid's displacement being (0, 0, dz)).
    pub shift_norm: Option<f64>,
    /// Write canned cycles as G0/G1 moves.
    pub expand_cycles: bool,
    /// The controller the program is written for.
    pub dialect: crate::interp::Dialect,
    /// The tool table for cutter radius compensation: (tool number, diameter mm).
    pub tools: std::sync::Arc<Vec<(u32, f64)>>,
}

/// Figures of a finished correction.
#[derive(Clone, Debug, Default)]
pub struct Report {
    pub stats: EmitStats,
    pub n_points: u64,
    /// Sum of the displacements' lengths, piece by piece as numpy sums them.
    pub total: f64,
    pub max: f64,
    /// Cutting moves left as written because a position is unknown, and the first of them
    /// (1-based line, what is unknown).
    pub unknown: u64,
    pub first_unknown: Option<(u32, String)>,
    /// Uncorrected rapids below the clearance inside the bounds: (1-based line, Z).
    pub low: Vec<(u32, f64)>,
    pub unsupported: Vec<Unsupported>,
    pub notes: Vec<Note>,
    pub summary: Summary,
    pub lines_read: usize,
}

/// How a run ended.
#[derive(Debug)]
pub enum Outcome {
    Done(Box<Report>),
    /// A check refuses the program; nothing useful was written.
    Refused,
    /// The progress callback asked to stop (a signal, say).
    Stopped,
}

/// A piece sampled and evaluated, for the emitting thread.
struct Job {
    piece: Piece,
    samples: Samples,
    disp: Vec<f64>,
}

/// The warnings of `ncadapt.nc._Warnings.add` for one piece's records.
fn warnings(it: &Interp, clearance: Option<f64>, bounds: Option<[f64; 4]>, r: &mut Report) {
    let mut prev = it.origin;
    for rec in &it.records {
        let start = prev;
        prev = rec.end;
        let m = rec.motion as u8;
        let cutting = (1..=3).contains(&m);
        // a G1 that names no axis (`G01 F360`) goes nowhere, wherever the tool is
        let still = m == 1 && rec.named == 0 && rec.cycle == 0;
        if cutting && !still && !rec.supported {
            let arc = m == 2 || m == 3;
            let mut end_unknown = [false; NAXES];
            let mut start_unknown = [false; NAXES];
            for a in 0..NAXES {
                let named = rec.named & (1 << a) != 0;
                end_unknown[a] = (a < 3 || named) && !rec.end[a].is_finite();
                start_unknown[a] = (if a < 3 { arc } else { named }) && !start[a].is_finite();
            }
            if end_unknown.iter().chain(&start_unknown).any(|&u| u) {
                if r.first_unknown.is_none() {
                    let mut said = Vec::new();
                    for (what, u) in [("end", &end_unknown), ("start", &start_unknown)] {
                        if u.iter().any(|&k| k) {
                            let axes: String = (0..NAXES)
                                .filter(|&a| u[a])
                                .map(|a| AXES[a] as char)
                                .collect();
                            said.push(format!("the {what} of {axes} unknown"));
                        }
                    }
                    r.first_unknown = Some((rec.line + 1, said.join(" and ")));
                }
                r.unknown += 1;
            }
        }
        if let Some(c) = clearance {
            if m == 0 && rec.cycle == 0 {
                let e = rec.end;
                let mut low = e[2] < c;
                if let Some([x0, x1, y0, y1]) = bounds {
                    low &= e[0] >= x0 && e[0] <= x1 && e[1] >= y0 && e[1] <= y1;
                }
                if low {
                    r.low.push((rec.line + 1, e[2]));
                }
            }
        }
    }
}

/// Uncorrected rapids followed by a straight plunge (a cut that descends from their end with X
/// and Y unchanged), followed across pieces: when the corrected plunge ends at or above the
/// rapid's end, the rapid ends inside the part (the check of `ncadapt.correction._Approach`,
/// which reports it).
#[derive(Default)]
struct Approach {
    /// Where (mm) an uncorrected rapid ended, when it is the last record seen.
    pending: Option<[f64; 3]>,
}

/// A descent larger than rounding: a plunge, not a level move.
const PLUNGE_MIN_MM: f64 = 1e-6;

impl Approach {
    fn runs_into_part(&mut self, it: &Interp, samples: &Samples, disp: &[f64]) -> bool {
        for (k, rec) in it.records.iter().enumerate() {
            let (f, c) = samples.of(k);
            let m = rec.motion as u8;
            if m == 1 && c > 0 {
                if let Some(r) = self.pending {
                    let j = f + c - 1;
                    let cz = samples.xyz[3 * j + 2] + disp[3 * j + 2];
                    let e = rec.end;
                    if e[0] == r[0] && e[1] == r[1] && e[2] < r[2] - PLUNGE_MIN_MM && cz >= r[2] {
                        return true;
                    }
                }
            }
            let r = [rec.end[0], rec.end[1], rec.end[2]];
            self.pending = (m == 0 && rec.cycle == 0 && c == 0 && r.iter().all(|v| v.is_finite()))
                .then_some(r);
        }
        false
    }
}

/// What the reading thread ends with: the style the pieces were written in, the program's own,
/// and the interpreter's reports.
struct ReadEnd {
    assumed: (NumberStyle, bool),
    whole: (NumberStyle, bool),
    interp: crate::interp::Interpreter,
    lines_read: usize,
}

/// Read, lex and interpret pieces into `tx`. With `style` None the first piece's style is
/// assumed for every piece; the program's own is returned to be checked.
fn read_pieces(
    reader: Reader,
    piece_bytes: usize,
    style: Option<(NumberStyle, bool)>,
    dialect: crate::interp::Dialect,
    tools: std::sync::Arc<Vec<(u32, f64)>>,
    tx: std::sync::mpsc::SyncSender<Result<Piece, NcError>>,
) -> Option<ReadEnd> {
    let mut stream = Stream::new(
        reader,
        piece_bytes,
        style.map_or(NumberStyle::default(), |s| s.0),
        style.is_some_and(|s| s.1),
    )
    .with_dialect(dialect)
    .with_tools(tools);
    let mut assumed = style;
    let mut whole = NumberStyle::default();
    let mut counts = [0usize; 4];
    loop {
        let r = stream.next_piece_with(|lx| {
            whole.merge(&lx.style);
            for (c, n) in counts.iter_mut().zip(lx.counts) {
                *c += n;
            }
            if assumed.is_none() {
                let mut s = lx.style;
                s.spaced = lx.counts[0] >= lx.counts[1];
                assumed = Some((s, lx.counts[2] > lx.counts[3]));
            }
            assumed.unwrap()
        });
        match r {
            Ok(Some(p)) => {
                if tx.send(Ok(p)).is_err() {
                    return None;
                }
            }
            Ok(None) => break,
            Err(e) => {
                let _ = tx.send(Err(e));
                return None;
            }
        }
    }
    whole.spaced = counts[0] >= counts[1];
    let whole = (whole, counts[2] > counts[3]);
    Some(ReadEnd {
        assumed: assumed.unwrap_or(whole),
        whole,
        lines_read: stream.lines_read(),
        interp: stream.interp,
    })
}

/// Emit jobs from `rx`, handing the output to the writing thread on `write` (and taking its
/// buffers back from `written`); the sample buffers go back on `back`.
fn emit_pieces(
    rx: Receiver<Job>,
    back: Sender<(Samples, Vec<f64>)>,
    write: SyncSender<Vec<u8>>,
    written: Receiver<Vec<u8>>,
    expand_cycles: bool,
    arc_tol: f64,
) -> Result<EmitStats, NcError> {
    let mut state: Option<EmitState> = None;
    let mut made = 0;
    for job in rx {
        let p = &job.piece;
        // at most three output buffers: one filled here, two with the writer
        let mut buf = match written.try_recv() {
            Ok(b) => b,
            Err(_) if made < 3 => {
                made += 1;
                Vec::with_capacity(p.src.len() * 6)
            }
            Err(_) => match written.recv() {
                Ok(b) => b,
                Err(_) => break,
            },
        };
        buf.clear();
        let st = state.take().unwrap_or_else(|| {
            let mut s = EmitState::new(&p.interp);
            s.expand_cycles = expand_cycles;
            s.arc_tol = arc_tol;
            s
        });
        let mut em = Emitter::resume(&p.src, &p.lexed, &p.interp, st);
        em.lines(0..p.lexed.lines.len(), &job.samples, &job.disp, &mut buf)?;
        state = Some(em.into_state());
        if write.send(buf).is_err() {
            break;
        }
        let _ = back.send((job.samples, job.disp));
    }
    Ok(state.map(|s| s.stats).unwrap_or_default())
}

/// Write the buffers from `rx` to `out`, handing each back on `back`.
fn write_pieces(
    rx: Receiver<Vec<u8>>,
    back: Sender<Vec<u8>>,
    out: &std::fs::File,
) -> Result<(), NcError> {
    let mut w = out;
    for buf in rx {
        w.write_all(&buf)
            .map_err(|e| NcError::Usage(format!("cannot write the output: {e}")))?;
        let _ = back.send(buf);
    }
    Ok(())
}

/// The reading thread of a first pass started ahead of the correction, while the caller is still
/// preparing (Python imports numpy and reads the field meanwhile, on a core that would idle):
/// it reads, lexes and interprets up to `ahead` pieces before it waits. Given to
/// [`correct_ahead`] with the same piece size and dialect; dropped, its thread stops at its next
/// piece.
pub struct ReadAhead {
    rx: Receiver<Result<Piece, NcError>>,
    handle: std::thread::JoinHandle<Option<ReadEnd>>,
    piece_bytes: usize,
    dialect: crate::interp::Dialect,
}

impl ReadAhead {
    pub fn start(
        reader: Reader,
        piece_bytes: usize,
        dialect: crate::interp::Dialect,
        ahead: usize,
    ) -> Self {
        let (tx, rx) = sync_channel::<Result<Piece, NcError>>(ahead.max(2));
        let handle = std::thread::spawn(move || {
            read_pieces(reader, piece_bytes, None, dialect, Default::default(), tx)
        });
        ReadAhead {
            rx,
            handle,
            piece_bytes,
            dialect,
        }
    }
}

/// One pass. `Ok(Err(style))`: the program's style differs from the one assumed; run again
/// with it. With `ahead` (a first pass) the pieces come from its thread.
fn pass(
    open: &dyn Fn() -> Result<Reader, NcError>,
    field: &Field,
    opts: &Options,
    style: Option<(NumberStyle, bool)>,
    out: &std::fs::File,
    progress: &mut dyn FnMut(usize, usize) -> bool,
    ahead: Option<ReadAhead>,
) -> Result<Result<Outcome, (NumberStyle, bool)>, NcError> {
    let reader = match ahead {
        Some(_) => None,
        None => Some(open()?),
    };
    let bounds = field.bounds();
    // the sampler knows a grid field: an arc it leaves flat stays an arc, sampled at its end
    let mut sample_opts = opts.sample.clone();
    if let Field::Grid(g) = field {
        sample_opts.grid = Some(std::sync::Arc::new(g.clone()));
    }
    std::thread::scope(|scope| {
        let (job_tx, job_rx) = sync_channel::<Job>(2);
        let (back_tx, back_rx) = channel::<(Samples, Vec<f64>)>();
        let piece_bytes = opts.piece_bytes;
        let (write_tx, write_rx) = sync_channel::<Vec<u8>>(2);
        let (written_tx, written_rx) = channel::<Vec<u8>>();
        let dialect = opts.dialect;
        let tools = opts.tools.clone();
        let (piece_rx, reading): (_, Box<dyn FnOnce() -> Option<ReadEnd>>) = match (ahead, reader) {
            (Some(a), _) => (
                a.rx,
                Box::new(move || a.handle.join().expect("the reading thread panicked")),
            ),
            (None, Some(reader)) => {
                let (piece_tx, piece_rx) = sync_channel::<Result<Piece, NcError>>(2);
                let h = scope.spawn(move || {
                    read_pieces(reader, piece_bytes, style, dialect, tools, piece_tx)
                });
                (
                    piece_rx,
                    Box::new(move || h.join().expect("the reading thread panicked")),
                )
            }
            (None, None) => unreachable!(),
        };
        let (expand, arc_tol) = (opts.expand_cycles, opts.sample.chord_tol);
        let emitting = scope
            .spawn(move || emit_pieces(job_rx, back_tx, write_tx, written_rx, expand, arc_tol));
        let writing = scope.spawn(move || write_pieces(write_rx, written_tx, out));
        let mut report = Report::default();
        let mut norms: Vec<f64> = Vec::new();
        let mut approach = Approach::default();
        let mut refused = false;
        let mut failed: Option<NcError> = None;
        let mut made = 0;
        let mut stopped = false;
        for r in piece_rx.iter() {
            let piece = match r {
                Ok(p) => p,
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            };
            // at most four sets of buffers: one here, two queued, one being emitted
            let (mut samples, mut disp) = match back_rx.try_recv() {
                Ok(b) => b,
                Err(_) if made < 4 => {
                    made += 1;
                    Default::default()
                }
                Err(_) => back_rx.recv().unwrap_or_default(),
            };
            if let Err(e) = sample_range(
                &piece.interp,
                &sample_opts,
                0..piece.interp.records.len(),
                &mut samples,
            ) {
                failed = Some(e);
                break;
            }
            warnings(&piece.interp, opts.clearance, bounds, &mut report);
            if (!opts.keep_unsupported && !piece.interp.unsupported.is_empty())
                || !field.eval(samples.eval_points(), &mut disp)
            {
                refused = true;
                break;
            }
            // cutter compensation: the field around the corners, and no X/Y displacement
            // (refused here; the caller's second reading says why)
            if !piece.interp.comps.is_empty() || !samples.check_groups.is_empty() {
                let mut cdisp = Vec::new();
                if !field.eval(&samples.checks, &mut cdisp)
                    || crate::sample::comp_check(
                        &piece.interp,
                        &samples,
                        &disp,
                        &cdisp,
                        sample_opts.chord_tol,
                    )
                    .is_some()
                {
                    refused = true;
                    break;
                }
            }
            norms.clear();
            match opts.shift_norm {
                Some(n) => norms.resize(samples.rec.len(), n),
                None => norms.extend(
                    disp.chunks_exact(3)
                        .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()),
                ),
            }
            report.n_points += norms.len() as u64;
            report.total += numpy_sum(&norms);
            let top = norms.iter().fold(0.0f64, |m, &v| if v > m { v } else { m });
            if top > report.max {
                report.max = top;
            }
            if approach.runs_into_part(&piece.interp, &samples, &disp)
                || report.max > opts.limit
                || !report.max.is_finite()
            {
                refused = true;
                break;
            }
            let (a, b) = (piece.line_base, piece.line_base + piece.lexed.lines.len());
            if job_tx
                .send(Job {
                    piece,
                    samples,
                    disp,
                })
                .is_err()
            {
                break;
            }
            if !progress(a, b) {
                stopped = true;
                break;
            }
        }
        drop(piece_rx);
        drop(job_tx);
        let read_end = reading();
        let emitted = emitting.join().expect("the emitting thread panicked");
        let wrote = writing.join().expect("the writing thread panicked");
        if let Some(e) = failed {
            return Err(e);
        }
        if stopped {
            return Ok(Ok(Outcome::Stopped));
        }
        if refused {
            return Ok(Ok(Outcome::Refused));
        }
        let stats = emitted?;
        wrote?;
        let Some(end) = read_end else {
            return Err(NcError::Usage("the reading thread stopped".into()));
        };
        if !opts.keep_unsupported && !end.interp.unsupported.is_empty() {
            return Ok(Ok(Outcome::Refused));
        }
        if end.whole != end.assumed {
            return Ok(Err(end.whole));
        }
        report.stats = stats;
        report.unsupported = end.interp.unsupported;
        report.notes = end.interp.notes;
        report.summary = end.interp.summary;
        report.lines_read = end.lines_read;
        Ok(Ok(Outcome::Done(Box::new(report))))
    })
}

/// Correct the program `open` reads with `field`, writing the output to `out` (from its start;
/// it is truncated first when a second pass is needed). `progress(first, end)` is called with
/// the 0-based line range of each piece handed to the emitter; when it returns false the run
/// stops ([`Outcome::Stopped`]).
pub fn correct(
    open: &dyn Fn() -> Result<Reader, NcError>,
    field: &Field,
    opts: &Options,
    out: &std::fs::File,
    progress: &mut dyn FnMut(usize, usize) -> bool,
) -> Result<Outcome, NcError> {
    correct_ahead(open, field, opts, out, progress, None)
}

/// [`correct`] whose first pass takes its pieces from `ahead`, started on the same program (it
/// is used only when its piece size and dialect are the options').
pub fn correct_ahead(
    open: &dyn Fn() -> Result<Reader, NcError>,
    field: &Field,
    opts: &Options,
    out: &std::fs::File,
    progress: &mut dyn FnMut(usize, usize) -> bool,
    ahead: Option<ReadAhead>,
) -> Result<Outcome, NcError> {
    field.check().map_err(NcError::Usage)?;
    // (a read-ahead reads without a tool table)
    let ahead = ahead.filter(|a| {
        a.piece_bytes == opts.piece_bytes && a.dialect == opts.dialect && opts.tools.is_empty()
    });
    match pass(open, field, opts, None, out, progress, ahead)? {
        Ok(o) => Ok(o),
        Err(style) => {
            // (a stop asked for during the first pass has ended it already)
            use std::io::Seek;
            let mut f = out;
            f.set_len(0)
                .and_then(|_| f.seek(std::io::SeekFrom::Start(0)))
                .map_err(|e| NcError::Usage(format!("cannot write the output: {e}")))?;
            match pass(open, field, opts, Some(style), out, progress, None)? {
                Ok(o) => Ok(o),
                Err(_) => Err(NcError::Usage(
                    "the program's number style changed between two readings".into(),
                )),
            }
        }
    }
}
