//! Emitter: writes the corrected program, copying every unchanged block byte for byte.
//!
//! The emitter follows the position the machine will really have when it runs the output
//! (`epos`, from the numbers as written), so incremental programs stay exact and rounding never
//! accumulates. A changed block keeps its other words, their order and its comments; only the
//! numbers that change are rewritten, in the program's own number style.

use crate::error::NcError;
use crate::interp::{
    axis_index, axis_unit, cycle_steps, peck_clearance, polar_xy, CycleStep, Dialect, Hole, Interp,
    Motion, Record, Rotation, AXES, CYCLE_BOTTOM, LATHE_CUTS, MM_PER_INCH, NAXES, NO_ROT,
    PLANE_AXES,
};
use crate::lex::{round, Lexed, NumberStyle, Word};
use crate::sample::{start_of, Samples};

/// Counts for the summary.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EmitStats {
    pub lines_in: u64,
    pub lines_out: u64,
    pub blocks_changed: u64,
    pub lines_added: u64,
    pub arcs_linearised: u64,
    /// Splines (G5, G5.1) written as straight pieces.
    pub splines_linearised: u64,
}

/// Number formatting in a program's style.
#[derive(Clone, Copy, Debug)]
pub struct Format {
    pub style: NumberStyle,
    pub dec_mm: usize,
    pub dec_inch: usize,
    half_mm: f64,
    half_inch: f64,
}

impl Format {
    pub fn new(style: NumberStyle) -> Self {
        let d = style.max_decimals as usize;
        let (dec_mm, dec_inch) = (d.max(4), d.max(5));
        let half = |dec: usize| 0.5 * 10f64.powi(-(dec as i32));
        Format {
            style,
            dec_mm,
            dec_inch,
            half_mm: half(dec_mm),
            half_inch: half(dec_inch),
        }
    }

    #[inline]
    pub fn decimals(&self, inch: bool) -> usize {
        if inch {
            self.dec_inch
        } else {
            self.dec_mm
        }
    }

    /// Half of the last written digit, in program units.
    #[inline]
    pub fn half(&self, inch: bool) -> f64 {
        if inch {
            self.half_inch
        } else {
            self.half_mm
        }
    }

    /// [`Fmt::half`] in mm.
    pub fn half_in_mm(&self, inch: bool) -> f64 {
        self.half(inch) * if inch { MM_PER_INCH } else { 1.0 }
    }

    /// Write `v` in the program's style and return the value the written text stands for.
    #[inline]
    pub fn number(&self, v: f64, inch: bool, out: &mut Vec<u8>) -> f64 {
        match self.decimals(inch) {
            4 => self.number_dec::<4>(v, out),
            5 => self.number_dec::<5>(v, out),
            6 => self.number_dec::<6>(v, out),
            7 => self.number_dec::<7>(v, out),
            8 => self.number_dec::<8>(v, out),
            _ => self.number_dec::<9>(v, out),
        }
    }

    /// [`Format::number`] with `D` decimals: rounded half away from zero, the fraction's
    /// trailing zeros dropped unless the program writes them, the leading zero and a bare point
    /// as the program writes them. The text is written straight into `out`.
    #[inline(always)]
    fn number_dec<const D: usize>(&self, v: f64, out: &mut Vec<u8>) -> f64 {
        const POW10: [u64; 10] = [
            1,
            10,
            100,
            1_000,
            10_000,
            100_000,
            1_000_000,
            10_000_000,
            100_000_000,
            1_000_000_000,
        ];
        let scale = POW10[D];
        let scaled = v * scale as f64;
        if scaled.is_nan() || scaled.abs() >= 9.0e15 {
            // beyond any machine's travel; keep the text exact all the same
            let t = format!("{:.*}", D, v);
            out.extend_from_slice(t.as_bytes());
            return t.parse().unwrap_or(v);
        }
        // round half away from zero with one conversion (f64::round is a library call)
        // SAFETY: |scaled| < 9e15 (checked above) fits an i64
        let m = unsafe {
            if scaled >= 0.0 {
                (scaled + 0.5).to_int_unchecked::<i64>()
            } else {
                (scaled - 0.5).to_int_unchecked::<i64>()
            }
        };
        let a = m.unsigned_abs();
        let (q, r) = (a / scale, a % scale);
        // the text is put together in 32 bytes and copied at once: sign, whole digits (omitted
        // for ".5" when the program writes so), point, the fraction's D digits, of which those
        // up to the last non-zero one are kept unless the program writes trailing zeros (and "0"
        // after a bare point unless the program writes "5.")
        let mut b = [0u8; 32];
        let mut i = (m < 0) as usize;
        b[0] = b'-';
        // (with D >= 4, some fraction digit is written when the style is fixed or r > 0)
        if !(self.style.no_leading_zero && q == 0 && (self.style.fixed || r != 0)) {
            if q < 10 {
                b[i] = b'0' + q as u8;
                i += 1;
            } else if q < 100 {
                b[i] = DIGIT_PAIRS[2 * q as usize];
                b[i + 1] = DIGIT_PAIRS[2 * q as usize + 1];
                i += 2;
            } else {
                let mut nq = 3;
                while nq < 16 && q >= POW10_U64[nq] {
                    nq += 1;
                }
                let mut x = q;
                let mut j = i + nq;
                while j >= i + 2 {
                    let d = (x % 100) as usize;
                    x /= 100;
                    b[j - 2] = DIGIT_PAIRS[2 * d];
                    b[j - 1] = DIGIT_PAIRS[2 * d + 1];
                    j -= 2;
                }
                if j > i {
                    b[i] = b'0' + x as u8;
                }
                i += nq;
            }
        }
        b[i] = b'.';
        i += 1;
        // (at most 1 + 16 + 1 bytes so far: the D <= 9 digits below fit)
        let f = &mut b[i..i + D];
        let mut r = r as u32; // r < 10^D <= 10^9
        let mut k = D;
        while k >= 2 {
            let d = (r % 100) as usize;
            r /= 100;
            f[k - 2] = DIGIT_PAIRS[2 * d];
            f[k - 1] = DIGIT_PAIRS[2 * d + 1];
            k -= 2;
        }
        if k == 1 {
            f[0] = b'0' + r as u8;
        }
        let mut digits = D;
        if !self.style.fixed {
            while digits > 0 && f[digits - 1] == b'0' {
                digits -= 1;
            }
        }
        if digits > 0 {
            i += digits;
        } else if !self.style.bare_point {
            i += 1; // f[0] is '0'
        }
        out.reserve(b.len());
        let len = out.len();
        // SAFETY: `reserve` made room for the 32 bytes copied; the first `i` are the text
        unsafe {
            std::ptr::copy_nonoverlapping(b.as_ptr(), out.as_mut_ptr().add(len), b.len());
            out.set_len(len + i);
        }
        m as f64 / scale as f64
    }
}

const POW10_U64: [u64; 17] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
    1_000_000_000,
    10_000_000_000,
    100_000_000_000,
    1_000_000_000_000,
    10_000_000_000_000,
    100_000_000_000_000,
    1_000_000_000_000_000,
    10_000_000_000_000_000,
];

const DIGIT_PAIRS: &[u8; 200] = b"0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

/// One edit of a line: replace bytes [start, end) by the arena's bytes [t0, t1).
#[derive(Clone, Copy, Debug)]
struct Edit {
    start: u32,
    end: u32,
    t0: u32,
    t1: u32,
}

/// The F of a piece of a G93 (inverse-time) move whose F is `f`: the piece takes `share` of the
/// move's time, 1 / (f · share) minutes. Written to 7 significant digits (the time is kept to
/// 5e-7 of itself), without trailing zeros.
fn inverse_feed(f: f64, share: f64, line: u32) -> Result<String, NcError> {
    let v = f / share;
    if !(share > 0.0 && v.is_finite()) {
        return Err(NcError::Interpret {
            line: line as usize + 1,
            col: 1,
            message: format!(
                "inverse-time move (G93) cut into pieces: a piece with no share of the move's time (F{f} over {share}) cannot be written"
            ),
        });
    }
    let decimals = (6 - v.log10().floor() as i32).clamp(0, 12) as usize;
    let mut t = format!("{v:.decimals$}");
    if t.contains('.') {
        t.truncate(t.trim_end_matches('0').trim_end_matches('.').len());
    }
    Ok(t)
}

/// Millimetres (degrees) per unit of a word on axis k, in inches or not, a diameter X's halves.
fn unit_in(k: usize, inch: bool, diameter: bool) -> f64 {
    let u = axis_unit(k, if inch { MM_PER_INCH } else { 1.0 });
    if k == 0 && diameter {
        u / 2.0
    } else {
        u
    }
}

/// The error that refuses the correction at a block's line (the block of record `rec`).
fn refused_at(rec: &Record, message: impl Into<String>) -> NcError {
    NcError::Interpret {
        line: rec.line as usize + 1,
        col: 1,
        message: message.into(),
    }
}

fn motion_text(m: Motion, padded: bool) -> &'static str {
    match (m, padded) {
        (Motion::Rapid, false) => "G0",
        (Motion::Rapid, true) => "G00",
        (Motion::Feed, false) => "G1",
        (Motion::Feed, true) => "G01",
        (Motion::ArcCw, false) => "G2",
        (Motion::ArcCw, true) => "G02",
        (Motion::ArcCcw, false) => "G3",
        (Motion::ArcCcw, true) => "G03",
        (Motion::Spline, false) => "G5",
        (Motion::Spline, true) => "G05",
        (Motion::QSpline, false) => "G5.1",
        (Motion::QSpline, true) => "G05.1",
        (Motion::Other, _) => "",
    }
}

#[inline]
fn is_motion_g(w: &Word) -> bool {
    w.letter == b'G'
        && {
            let c = round(w.value * 10.0) as i32;
            matches!(c, 0 | 10 | 20 | 30 | 800 | 730 | 740 | 760 | 810..=890 | 330 | 331 | 382..=385 | 50 | 51 | 52)
        }
}

/// A canned cycle's code (G73, G74, G76, G81-G89): a motion code that keeps the cycle mode.
fn is_cycle_g(w: &Word) -> bool {
    w.letter == b'G' && matches!(round(w.value * 10.0) as i32, 730 | 740 | 760 | 810..=890)
}

/// LinuxCNC's polar distance `@` or angle `^`.
fn is_polar(w: &Word) -> bool {
    matches!(w.letter, b'@' | b'^')
}

/// G0, G1, G2 or G3: the motion codes of a Fanuc control's group 01, which its canned cycles
/// (group 09) and G80 leave as they are.
fn is_g01(w: &Word) -> bool {
    w.letter == b'G' && matches!(round(w.value * 10.0) as i32, 0 | 10 | 20 | 30)
}

#[inline]
fn is_stop_m(w: &Word) -> bool {
    w.letter == b'M' && matches!(round(w.value) as i32, 0 | 1 | 2 | 30 | 60)
}

/// What the emitter carries from one run of lines to the next: the position the output's
/// numbers give, the output's modal motion, the counts, and buffers reused from line to line.
#[derive(Clone, Debug)]
pub struct EmitState {
    epos: [f64; NAXES],
    /// Motion mode the output has in force where it differs from the program's.
    out_motion: Option<Motion>,
    pub stats: EmitStats,
    edits: Vec<Edit>,
    /// Replacement texts of the edits, one after the other.
    arena: Vec<u8>,
    /// Lines added after the current line, one after the other, and where each ends.
    tail: Vec<u8>,
    tail_ends: Vec<usize>,
    /// Write canned cycles as the G0/G1 moves they make (else they stay cycle blocks).
    pub expand_cycles: bool,
    /// Largest distance (mm) between a kept arc and the displaced path at the samples: an arc
    /// whose displacement is a shift in its plane and a helix along its normal within this stays
    /// an arc (the chord tolerance: its chords would be as far from the arc). 0 keeps only arcs
    /// moved as a whole.
    pub arc_tol: f64,
    /// The output's canned-cycle state: its initial level (mm) and its R and Z as last written
    /// (program units).
    cyc_level: f64,
    cyc_r: Option<f64>,
    cyc_z: Option<f64>,
    /// A block of the current cycle run was written as moves: the output's motion mode and
    /// sticky words are no longer the cycle's.
    cyc_expanded: bool,
    steps: Vec<CycleStep>,
    /// Under cutter compensation: the length (mm, in the plane) of the last piece the output
    /// has of the last move in the plane; a move after an inside corner needs it longer than the
    /// tool stops short there ([`crate::interp::Comp::trim`]).
    comp_piece: f64,
    /// Under radius compensation in G18/G19: the length (in the plane) of the last piece written.
    nose_piece: f64,
    /// The last move under radius compensation in G18/G19 was an arc written in chords.
    nose_chords: bool,
    /// Where the output stood at a Fanuc lathe's roughing cycle whose contour is being written.
    contour_from: Option<[f64; NAXES]>,
    /// The last move under cutter compensation (G17) was an arc written in chords.
    comp_chords: bool,
    /// The output's modal X and Z (mm) of a lathe's G90/G94 box cycle, as last written.
    out_box: [f64; 2],
    /// The output's spline register (a G5 without I and J starts by the last G5's -P -Q) holds
    /// the program's: no G5 since the start was written in pieces.
    spline_reg: bool,
}

impl EmitState {
    /// The state at the start of a program.
    pub fn new(it: &Interp) -> Self {
        EmitState {
            epos: it.origin,
            out_motion: None,
            stats: EmitStats::default(),
            edits: Vec::new(),
            arena: Vec::new(),
            tail: Vec::new(),
            tail_ends: Vec::new(),
            expand_cycles: false,
            comp_piece: f64::INFINITY,
            nose_piece: f64::INFINITY,
            nose_chords: false,
            contour_from: None,
            comp_chords: false,
            arc_tol: 0.0,
            cyc_level: f64::NAN,
            cyc_r: None,
            cyc_z: None,
            cyc_expanded: false,
            steps: Vec::new(),
            out_box: [f64::NAN; 2],
            spline_reg: true,
        }
    }
}

/// Under cutter compensation, the last piece of a straight move cut in pieces is kept this many
/// tool radii long: the tool stops short of an inside corner after it by r·tan(θ/2) for a turn
/// θ, so corners up to 2·atan(2) = 126.9° are reached; a sharper one after a cut move is refused.
pub const COMP_GUARD: f64 = 2.0;

/// Emits a corrected program.
pub struct Emitter<'a> {
    src: &'a [u8],
    lx: &'a Lexed,
    it: &'a Interp,
    fmt: Format,
    eol: &'static [u8],
    st: EmitState,
    /// The offsets of the program's coordinates in the block being written ([`Interp::frames`]):
    /// an absolute number `v` is the position `v·unit + off`.
    off: [f64; NAXES],
    /// Where the polar words of the block being written take the output, when they stay (for
    /// [`Emitter::set_axes`]).
    keep_polar: Option<[f64; 2]>,
}

impl<'a> Emitter<'a> {
    pub fn new(src: &'a [u8], lx: &'a Lexed, it: &'a Interp) -> Self {
        Self::resume(src, lx, it, EmitState::new(it))
    }

    /// Continue with the state a previous emitter left ([`Emitter::into_state`]).
    pub fn resume(src: &'a [u8], lx: &'a Lexed, it: &'a Interp, st: EmitState) -> Self {
        Emitter {
            src,
            lx,
            it,
            fmt: Format::new(lx.style),
            eol: if lx.crlf { b"\r\n" } else { b"\n" },
            st,
            off: [0.0; NAXES],
            keep_polar: None,
        }
    }

    pub fn into_state(self) -> EmitState {
        self.st
    }

    pub fn stats(&self) -> &EmitStats {
        &self.st.stats
    }

    /// Write the whole program with `disp` (n * 3 mm, one per sample) applied to the sampled blocks.
    pub fn run(mut self, samples: &Samples, disp: &[f64]) -> Result<(Vec<u8>, EmitStats), NcError> {
        let mut out = Vec::with_capacity(self.src.len() + self.src.len() / 8);
        self.lines(0..self.lx.lines.len(), samples, disp, &mut out)?;
        Ok((out, self.st.stats))
    }

    /// Write lines `range` to `out`. `samples` must hold every sampled record of those lines
    /// ([`crate::sample::sample_range`]) and `disp` one displacement per sample.
    pub fn lines(
        &mut self,
        range: std::ops::Range<usize>,
        samples: &Samples,
        disp: &[f64],
        out: &mut Vec<u8>,
    ) -> Result<(), NcError> {
        self.lines_uvw(range, samples, disp, &[], out)
    }

    /// [`Emitter::lines`] with a displacement of the U, V and W axes too: `uvw` holds three
    /// values per sample (U V W, mm), or nothing. A block whose U V W displacement is not zero is
    /// written piece by piece, each piece carrying its U V W (named in the block or not); the
    /// axes it displaces must be known at its start and end.
    pub fn lines_uvw(
        &mut self,
        range: std::ops::Range<usize>,
        samples: &Samples,
        disp: &[f64],
        uvw: &[f64],
        out: &mut Vec<u8>,
    ) -> Result<(), NcError> {
        if disp.len() != samples.xyz.len() || !(uvw.is_empty() || uvw.len() == disp.len()) {
            return Err(NcError::Usage(format!(
                "displacements have {} and {} values, expected {} (3 per sample)",
                disp.len(),
                uvw.len(),
                samples.xyz.len()
            )));
        }
        let nrec = samples.range.len();
        for li in range {
            let line = &self.lx.lines[li];
            let ri = self.it.line_record[li];
            self.st.edits.clear();
            self.st.arena.clear();
            self.st.tail.clear();
            self.st.tail_ends.clear();
            self.st.stats.lines_in += 1;
            let words = self.lx.line_words(li);
            // a motion code other than a cycle's, or G80, ends the cycle mode
            let leaves_cycle = words.iter().any(|w| is_motion_g(w) && !is_cycle_g(w));
            if self.st.cyc_expanded && !leaves_cycle && ri != u32::MAX {
                // a block that continues a cycle --expand-cycles wrote as moves, copied as written
                // (not traced: under an unsupported construct kept), would not drill in the output
                let rec = &self.it.records[ri as usize];
                if rec.motion == Motion::Other && rec.cycle == 0 && rec.named & 0b111 != 0 {
                    return Err(NcError::Interpret {
                        line: li + 1,
                        col: 1,
                        message: "a block with axis words in a canned cycle that --expand-cycles wrote as moves, kept as written (an unsupported construct is in force): the output is no longer in the cycle, so it would not drill; correct it without --expand-cycles".into(),
                    });
                }
            }
            if leaves_cycle {
                self.st.cyc_expanded = false; // (a cycle block sets it again when it is expanded)
            }
            if ri != u32::MAX {
                let ri = ri as usize;
                if ri < samples.rec0 || ri >= samples.rec0 + nrec {
                    return Err(NcError::Usage(format!(
                        "line {} has a block that was not sampled",
                        li + 1
                    )));
                }
                let (f, c) = samples.of(ri);
                self.off = self.it.frames[self.it.records[ri].frame as usize];
                // a Fanuc lathe's roughing cycle: the output goes back after its contour to where
                // it stood at the cycle's block (a record of the line, before its own move)
                let line_no = self.it.records[ri].line;
                let back = self.it.records[..=ri]
                    .iter()
                    .rev()
                    .take_while(|r| r.line == line_no)
                    .any(|r| r.cycle == crate::interp::CYCLE_CONTOUR_BACK);
                if back {
                    // (no cycle block seen: where the output is, is not known)
                    self.st.epos = self.st.contour_from.take().unwrap_or([f64::NAN; NAXES]);
                }
                let cycle = self.it.records[ri].cycle;
                if cycle == crate::interp::CYCLE_CONTOUR_START {
                    self.st.contour_from = Some(self.st.epos);
                }
                self.comp_inside_corner(ri)?;
                self.nose_exit(ri)?;
                let uvw = if uvw.is_empty() {
                    uvw
                } else {
                    &uvw[3 * f..3 * (f + c)]
                };
                if matches!(
                    cycle,
                    crate::interp::CYCLE_CONTOUR_START | crate::interp::CYCLE_CONTOUR_BACK
                ) {
                    // (copied; where the output is was set above)
                } else if self.it.records[ri].cycle == crate::interp::CYCLE_LATHE {
                    let line = self.it.records[ri].line;
                    let k = self.it.boxes.partition_point(|b| b.line < line);
                    match self.it.boxes.get(k) {
                        Some(&b) if b.line == line && LATHE_CUTS.contains(&b.code) => {
                            self.lathe_cut(li, ri, samples, disp, &b)?
                        }
                        _ => self.lathe_box(li, ri, samples, disp),
                    }
                } else if self.it.records[ri].cycle != 0 {
                    if uvw.iter().any(|&v| v != 0.0) {
                        return Err(NcError::Interpret {
                            line: li + 1,
                            col: 1,
                            message: "the field displaces U, V or W at a canned cycle's hole; a cycle's holes move in X, Y and Z only: write the holes as moves".into(),
                        });
                    }
                    // a cycle the engine treats has its holes' bottoms supported; one under an
                    // unsupported construct (kept with --keep-unsupported) is copied
                    let line_no = self.it.records[ri].line;
                    let copy = !self.it.records[samples.rec0..=ri]
                        .iter()
                        .rev()
                        .take_while(|r| r.line == line_no)
                        .any(|r| r.cycle == CYCLE_BOTTOM && r.supported);
                    self.cycle_block(li, ri, samples, disp, copy)?;
                } else if c > 0 {
                    self.corrected(
                        li,
                        ri,
                        &samples.xyz[3 * f..3 * (f + c)],
                        &samples.t[f..f + c],
                        &disp[3 * f..3 * (f + c)],
                        uvw,
                        samples
                            .flat
                            .binary_search_by_key(&(ri as u32), |&(r, _)| r)
                            .ok()
                            .map(|k| samples.flat[k].1),
                    )?;
                } else {
                    self.spline_register(ri, true)?;
                    self.uncorrected(li, ri);
                }
            } else if words.iter().any(|w| self.sets_motion(w)) {
                self.st.out_motion = None;
            } else if let Ok(k) = self
                .it
                .frame_lines
                .binary_search_by_key(&(li as u32), |&(l, ..)| l - self.it.line_base as u32)
            {
                let (_, frame, inch) = self.it.frame_lines[k];
                self.position_offset(li, frame, inch)?;
            }
            // copy the line with its edits, then any added lines
            let (ls, le, lee) = (
                line.start as usize,
                line.end as usize,
                line.eol_end as usize,
            );
            let src = self.src;
            let st = &mut self.st;
            let has_tail = !st.tail_ends.is_empty();
            if st.edits.is_empty() {
                out.extend_from_slice(&src[ls..lee]);
            } else {
                st.stats.blocks_changed += 1;
                st.edits.sort_by_key(|e| (e.start, e.end));
                let mut at = ls;
                for e in &st.edits {
                    let (s, t) = (e.start as usize, e.end as usize);
                    if s >= at {
                        out.extend_from_slice(&src[at..s]);
                        at = t;
                    }
                    out.extend_from_slice(&st.arena[e.t0 as usize..e.t1 as usize]);
                }
                out.extend_from_slice(&src[at..le]);
                if !has_tail {
                    out.extend_from_slice(&src[le..lee]);
                }
            }
            if has_tail {
                let own_eol: &[u8] = if lee > le { &src[le..lee] } else { self.eol };
                // a copied line came with its ending; an edited one, or a last line without one, needs it
                if !st.edits.is_empty() || lee == le {
                    out.extend_from_slice(own_eol);
                }
                let n = st.tail_ends.len();
                let mut from = 0;
                for (k, &to) in st.tail_ends.iter().enumerate() {
                    out.extend_from_slice(&st.tail[from..to]);
                    from = to;
                    if k + 1 < n || lee > le {
                        out.extend_from_slice(own_eol);
                    }
                }
                st.stats.lines_added += n as u64;
            }
            st.stats.lines_out = st.stats.lines_in + st.stats.lines_added;
        }
        Ok(())
    }

    /// Replace source bytes [start, end) by the number `v` in the program's style; the value written.
    fn edit_number(&mut self, start: u32, end: u32, v: f64, inch: bool) -> f64 {
        let t0 = self.st.arena.len() as u32;
        let w = self.fmt.number(v, inch, &mut self.st.arena);
        self.st.edits.push(Edit {
            start,
            end,
            t0,
            t1: self.st.arena.len() as u32,
        });
        w
    }

    /// Insert a motion word (and a separator) where the block's words begin.
    fn insert_motion(&mut self, li: usize, m: Motion) {
        let at = block_start(self.lx, li);
        let t0 = self.st.arena.len() as u32;
        self.st
            .arena
            .extend_from_slice(motion_text(m, self.lx.style.padded_g).as_bytes());
        self.st.arena.extend_from_slice(self.sep());
        self.st.edits.push(Edit {
            start: at,
            end: at,
            t0,
            t1: self.st.arena.len() as u32,
        });
    }

    /// Replace source bytes [start, end) by `text`.
    fn edit_bytes(&mut self, start: u32, end: u32, text: &[u8]) {
        let t0 = self.st.arena.len() as u32;
        self.st.arena.extend_from_slice(text);
        self.st.edits.push(Edit {
            start,
            end,
            t0,
            t1: self.st.arena.len() as u32,
        });
    }

    /// Millimetres (degrees) per unit of the block's words on axis k: a diameter X's are halves.
    fn unit(rec: &Record, k: usize) -> f64 {
        unit_in(k, rec.inch, rec.diameter)
    }

    /// The axis a word of block `rec` moves and whether its number is an increment: a Fanuc
    /// lathe's U and W are increments of X and Z.
    fn word_axis(&self, rec: &Record, letter: u8) -> Option<(usize, bool)> {
        if self.it.dialect == Dialect::FanucLathe {
            match letter {
                b'U' => return Some((0, true)),
                b'W' => return Some((2, true)),
                _ => {}
            }
        }
        axis_index(letter).map(|a| (a, rec.incremental))
    }

    /// Where new words go in the block: after its last axis word, or after its last word.
    fn insert_point(&self, li: usize) -> u32 {
        let line = &self.lx.lines[li];
        let words = self.lx.line_words(li);
        words
            .iter()
            .rev()
            .find(|w| axis_index(w.letter).is_some())
            .or(words.last())
            .map_or_else(|| block_start(self.lx, li).max(line.start), |w| w.end)
    }

    fn sep(&self) -> &'static [u8] {
        if self.lx.style.spaced {
            b" "
        } else {
            b""
        }
    }

    /// A word that sets the modal motion the next blocks move in: a motion code, or on a Fanuc
    /// control only G0 G1 G2 G3 (its canned cycles and G80 are a group of their own).
    fn sets_motion(&self, w: &Word) -> bool {
        if self.it.dialect.is_fanuc() {
            is_g01(w)
        } else {
            is_motion_g(w)
        }
    }

    /// Insert the program's own motion word when the output's modal motion differs from it.
    fn restore_modal(&mut self, li: usize, rec: &Record, explicit: bool) {
        if explicit {
            self.st.out_motion = None;
            return;
        }
        if let Some(m) = self.st.out_motion {
            if m != rec.motion && rec.motion != Motion::Other {
                self.insert_motion(li, rec.motion);
            }
            self.st.out_motion = None;
        }
    }

    /// A block that is not corrected: kept, except that in G91 a supported move is re-aimed at
    /// its programmed target (the output position before it may differ from the program's).
    fn uncorrected(&mut self, li: usize, ri: usize) {
        let it = self.it;
        let rec = &it.records[ri];
        let rot = self.rotation(rec);
        if let Some(r) = rot {
            // (as programmed: the block's numbers and where the output is, turned back)
            let mut rec = rec.clone();
            to_prog(&r, &mut rec.end);
            let mut start = start_of(it, ri);
            to_prog(&r, &mut start);
            to_prog(&r, &mut self.st.epos);
            self.uncorrected_from(li, &rec, start);
            from_prog(&r, &mut self.st.epos);
        } else {
            self.uncorrected_from(li, rec, start_of(it, ri));
        }
    }

    /// [`Emitter::uncorrected`] of the block of `rec`, which starts at `start`.
    fn uncorrected_from(&mut self, li: usize, rec: &Record, start: [f64; NAXES]) {
        let lx = self.lx;
        let words = lx.line_words(li);
        let explicit = words.iter().any(|w| self.sets_motion(w));
        if rec.motion != Motion::Other {
            self.restore_modal(li, rec, explicit);
        } else if explicit {
            self.st.out_motion = None;
        }
        // polar words (LinuxCNC's @ ^) that take the current point (G91, or one of them left
        // out) go elsewhere from where the output is: written as X and Y to the program's end
        if rec.motion != Motion::Other && words.iter().any(is_polar) {
            let half_mm = self.fmt.half_in_mm(rec.inch);
            let p = self.polar_end(li, rec);
            if (0..2).any(|a| (p[a] - rec.end[a]).abs() >= half_mm)
                && (0..2).all(|a| rec.end[a].is_finite() && self.st.epos[a].is_finite())
            {
                self.polar_to_xy(li);
                let mut target = self.st.epos;
                for (k, t) in target.iter_mut().enumerate() {
                    if rec.named & (1 << k) != 0 {
                        *t = rec.end[k];
                    }
                }
                self.set_axes_as_programmed(li, rec, &target, 0);
                return;
            }
        }
        // the axes the block's words move by increments (G91; a Fanuc lathe's U and W)
        let mut increments: u16 = 0;
        for w in words {
            if let Some((k, true)) = self.word_axis(rec, w.letter) {
                increments |= 1 << k;
            }
        }
        let rewrite = rec.supported && increments != 0 && rec.motion != Motion::Other;
        let mut written = [None; NAXES];
        if rewrite {
            for w in words {
                if let Some((k, true)) = self.word_axis(rec, w.letter) {
                    let u = Self::unit(rec, k);
                    let want = (rec.end[k] - self.st.epos[k]) / u;
                    if want.is_finite() && (want - w.value).abs() >= self.fmt.half(rec.inch) {
                        let v = self.edit_number(w.num_start, w.end, want, rec.inch);
                        written[k] = Some(v * u);
                    }
                }
            }
        }
        for k in 0..NAXES {
            let named = rec.named & (1 << k) != 0;
            self.st.epos[k] = match written[k] {
                Some(d) => self.st.epos[k] + d,
                None if named && increments & (1 << k) == 0 => rec.end[k],
                None => self.st.epos[k] + (rec.end[k] - start[k]),
            };
        }
    }

    /// Whether the output's X or Y (as the block's numbers read them) must change to reach
    /// `target`.
    fn xy_moves(&self, rec: &Record, target: &[f64; NAXES]) -> bool {
        let half = self.fmt.half(rec.inch);
        (0..2).any(|a| !((target[a] - self.st.epos[a]).abs() / Self::unit(rec, a) < half))
    }

    /// The coordinate rotation record `rec`'s X and Y are written under, if any.
    fn rotation(&self, rec: &Record) -> Option<Rotation> {
        (rec.rot != NO_ROT).then(|| self.it.rotations[rec.rot as usize])
    }

    /// The output's spline register after record `ri`, written as a G5 (`kept`) or in pieces: a
    /// G5 without I and J whose register the output no longer holds is refused (written as a G5
    /// it would start by another control point).
    fn spline_register(&mut self, ri: usize, kept: bool) -> Result<(), NcError> {
        let rec = &self.it.records[ri];
        if rec.motion != Motion::Spline {
            return Ok(());
        }
        if kept && !self.st.spline_reg && self.it.spline(ri).is_some_and(|s| s.continued) {
            return Err(refused_at(rec, "a G5 without I and J after a G5 written in straight pieces: kept as written, it would start by another control point (LinuxCNC's register holds the last G5's P and Q); write its I and J"));
        }
        self.st.spline_reg = kept;
        Ok(())
    }

    /// Under cutter compensation: a move after an inside corner needs the output's piece before
    /// the corner longer than the tool stops short there (else the controller finds the corner
    /// unreachable); the move's whole length (in the plane) stands as the last piece until
    /// [`Emitter::corrected`] cuts it.
    fn comp_inside_corner(&mut self, ri: usize) -> Result<(), NcError> {
        let rec = &self.it.records[ri];
        if rec.comp == crate::interp::NO_COMP {
            return Ok(());
        }
        let c = &self.it.comps[rec.comp as usize];
        // after an arc written in chords the controller is at the last chord's offset, and turns
        // from its direction: the move after G40, and an inside corner the arc's offset circle
        // makes, are not where the engine puts them
        if std::mem::take(&mut self.st.comp_chords) && (c.exit || c.arc_corner) {
            return Err(refused_at(
                rec,
                if c.exit {
                    "the move after G40 comes right after an arc under cutter compensation that the field does not move alike along it, written in chords: the controller starts it from its offset of the last chord, not of the arc; end compensation after a straight move, or raise --chord-tol to keep the arc an arc"
                } else {
                    "an inside corner under cutter compensation right after an arc that the field does not move alike along it, written in chords: the controller meets the last chord's offset, not the arc's offset circle; raise --chord-tol to keep the arc an arc"
                },
            ));
        }
        let start = start_of(self.it, ri);
        let len = if let Some((_, rho, _, sweep)) = c.entry {
            rho * sweep.abs() // (the tool's own arc, which starts compensation)
        } else if rec.motion.is_arc() {
            let (_, d, r0, r1) = crate::sample::arc_sweep(rec, &start);
            d.abs() * 0.5 * (r0 + r1)
        } else {
            (rec.end[0] - start[0]).hypot(rec.end[1] - start[1])
        };
        if !(len > 1e-9) {
            return Ok(()); // a move along Z: the tool stands
        }
        if c.trim > 0.0 && !(self.st.comp_piece > c.trim) {
            return Err(refused_at(rec, format!(
                    "an inside corner under cutter compensation: the tool stops {:.4} mm short of the corner, but the corrected program's piece before it is {:.4} mm long (the controller would find the corner unreachable); raise --chord-tol so the move before stays whole",
                    c.trim, self.st.comp_piece
                )));
        }
        self.st.comp_piece = len;
        Ok(())
    }

    /// The move after G40 that ends radius compensation in G18/G19 starts where the control's
    /// offset of the move before ends: after an arc written in chords, along the last chord's
    /// normal, not the arc's (by the radius times half a chord's angle): refused.
    fn nose_exit(&mut self, ri: usize) -> Result<(), NcError> {
        let rec = &self.it.records[ri];
        if rec.whole == crate::interp::WHOLE_NOSE && rec.nose == 0.0 {
            if std::mem::take(&mut self.st.nose_chords) {
                return Err(refused_at(rec, "the move that ends radius compensation in G18/G19 comes right after an arc the field does not move alike along it, written in chords: the control starts it from its offset of the last chord, not of the arc; end the compensation after a straight move, or raise --chord-tol to keep the arc an arc"));
            }
        } else if rec.nose > 0.0 && rec.motion != Motion::Other {
            self.st.nose_chords = false;
        }
        Ok(())
    }

    /// Write a sampled block with its displacements.
    fn corrected(
        &mut self,
        li: usize,
        ri: usize,
        xyz: &[f64],
        ts: &[f64],
        disp: &[f64],
        uvw: &[f64],
        flat: Option<f64>,
    ) -> Result<(), NcError> {
        let (it, lx) = (self.it, self.lx);
        let rec = &it.records[ri];
        let start = start_of(it, ri);
        let n = ts.len();
        // the U V W axes the field displaces in this block (bits of AXES)
        let mut moved: u16 = 0;
        for d in uvw.chunks_exact(3) {
            for (k, v) in d.iter().enumerate() {
                if *v != 0.0 {
                    moved |= 1 << (6 + k);
                }
            }
        }
        if let Some(a) = (6..NAXES)
            .find(|&a| moved & (1 << a) != 0 && !(start[a].is_finite() && rec.end[a].is_finite()))
        {
            return Err(refused_at(rec, format!(
                    "the field displaces {} here, but the program has not set {} before this block: set it (e.g. G0 {}0) before the first move",
                    AXES[a] as char, AXES[a] as char, AXES[a] as char
                )));
        }
        let words = lx.line_words(li);
        let epos0 = self.st.epos;
        // polar words: where they take the output from where it is
        let polar_end = words.iter().any(is_polar).then(|| self.polar_end(li, rec));
        let explicit = words.iter().any(|w| self.sets_motion(w));
        let d0 = [disp[0], disp[1], disp[2]];
        let uniform = disp
            .chunks_exact(3)
            .all(|d| (0..3).all(|k| (d[k] - d0[k]).abs() <= 1e-9));
        let half_mm = self.fmt.half_in_mm(rec.inch);
        let target_at = |k: usize, t: f64| -> [f64; NAXES] {
            // XYZ corrected, the axes the block names interpolated, the others where they are
            let mut p = epos0;
            for a in 0..3 {
                p[a] = xyz[3 * k + a] + disp[3 * k + a];
            }
            let mut named = (rec.named | moved) >> 3;
            while named != 0 {
                let a = 3 + named.trailing_zeros() as usize;
                p[a] = if t == 1.0 {
                    rec.end[a]
                } else {
                    start[a] + t * (rec.end[a] - start[a])
                };
                if moved & (1 << a) != 0 {
                    p[a] += uvw[3 * k + a - 6];
                }
                named &= named - 1;
            }
            p
        };
        // the output starts this block where the corrected path expects it
        let on_path = (0..3).all(|a| (self.st.epos[a] - (start[a] + d0[a])).abs() < half_mm);
        // an arc whose displacement is, within the chord tolerance, a shift in its plane and a
        // helix along its normal from where the output starts it: kept an arc, as close to the
        // displaced path at every sample as its chords would be
        let [a1, a2, an] = PLANE_AXES[rec.plane as usize];
        let ds = [
            epos0[0] - start[0],
            epos0[1] - start[1],
            epos0[2] - start[2],
        ];
        let de = [disp[3 * n - 3], disp[3 * n - 2], disp[3 * n - 1]];
        let helix = rec.motion.is_arc()
            && !uniform
            && self.st.arc_tol > 0.0
            && (de[a1] - ds[a1]).abs() < half_mm
            && (de[a2] - ds[a2]).abs() < half_mm
            && {
                let tol2 = self.st.arc_tol * self.st.arc_tol;
                disp.chunks_exact(3).zip(ts).all(|(d, &t)| {
                    let dn = ds[an] + t * (de[an] - ds[an]);
                    (d[a1] - ds[a1]).powi(2) + (d[a2] - ds[a2]).powi(2) + (d[an] - dn).powi(2)
                        <= tol2
                })
            };
        // an arc the sampler found flat under a grid field (sampled at its end only): the field
        // varies over it by `range` at most and the output starts it where the field puts its
        // start (the block before is corrected), so the helix to its end's displacement is
        // within `range` and the rounding of it everywhere; the start is checked to be so
        let flat_ok = flat.is_some_and(|range| {
            (de[a1] - ds[a1]).abs() < half_mm
                && (de[a2] - ds[a2]).abs() < half_mm
                && (de[an] - ds[an]).abs() <= range + 2.0 * half_mm
        });
        if flat.is_some() && !flat_ok {
            return Err(NcError::Usage(format!(
                "line {}: an arc sampled at its end only does not start where the field puts it",
                rec.line + 1
            )));
        }
        let keep_arc =
            rec.motion.is_arc() && moved == 0 && (uniform && on_path || helix || flat_ok);
        // a straight move whose corrected pieces all lie on one line, within half a unit of the
        // last written digit (the rounding every written number has), is written as one move; when
        // it also moves another axis (A B C U V W), which the machine interpolates with XYZ, each
        // piece must also be where that one move puts it at the piece's fraction
        let only_xyz = rec.named & !0b111 == 0;
        // (XYZ of `target_at`)
        let xyz_at = |k: usize| {
            [
                xyz[3 * k] + disp[3 * k],
                xyz[3 * k + 1] + disp[3 * k + 1],
                xyz[3 * k + 2] + disp[3 * k + 2],
            ]
        };
        // a spline moved as a whole and started where the field puts its start stays a spline
        // (its I J P Q are offsets): when the output holds the register it may read
        let keep_spline = rec.motion.is_spline()
            && moved == 0
            && uniform
            && on_path
            && (self.st.spline_reg || !self.it.spline(ri).is_some_and(|s| s.continued));
        let straight = !rec.motion.is_curve()
            && (n == 1
                || moved == 0 && {
                    let e = xyz_at(n - 1);
                    let a = [self.st.epos[0], self.st.epos[1], self.st.epos[2]];
                    (0..n - 1).all(|k| {
                        let p = xyz_at(k);
                        if only_xyz {
                            dist2_to_segment(&p, &a, &e) <= half_mm * half_mm
                        } else {
                            dist2_at_fraction(&p, &a, &e, ts[k]) <= half_mm * half_mm
                        }
                    })
                });
        // under cutter compensation the pieces of a move are corners for the controller: the
        // move after G41/G42 or G40 goes between the programmed and the offset point, so cut in
        // pieces its first (last) piece alone would; it is written whole, when the corrected path
        // along it is straight within the chord tolerance. Other straight moves keep their
        // pieces clear of the corners' ends ([`Emitter::comp_pieces`])
        let comp = (rec.comp != crate::interp::NO_COMP).then(|| &it.comps[rec.comp as usize]);
        let comp_whole = comp.is_some_and(|c| {
            !rec.motion.is_arc() && (c.start != c.end || c.kink > self.st.arc_tol)
        }) || (rec.whole != 0 && !rec.motion.is_arc());
        let whole_why = match rec.whole {
            crate::interp::WHOLE_CONTOUR => "the first and the last block of a roughing cycle's contour (numbered P and Q) must stay one move: the pieces after the last would not belong to the contour, and the first's would move the point the cycle roughs from",
            crate::interp::WHOLE_SYNC => "a spindle-synchronised move (G33) must stay one move: each block synchronises anew with the spindle, so its pieces would each start the thread again",
            _ => "the move that starts or ends radius compensation in G18/G19 must stay one move",
        };
        if comp.is_some_and(|c| c.entry.is_some()) && !keep_arc {
            return Err(refused_at(
                rec,
                "an arc that starts cutter compensation, which the field does not move alike along it (within the chord tolerance a helix): cut in chords, the controller would start compensation on the first of them, another path",
            ));
        }
        if rec.whole != 0 && rec.motion.is_arc() && !keep_arc {
            return Err(refused_at(rec, format!("{whole_why}, and this arc is not moved alike along it (it would be cut in chords)")));
        }
        // a synchronised move's thread is reckoned from where it starts: the output must stand at
        // its start moved by the field (the first sample's displacement, the move being straight
        // within the chord tolerance)
        if rec.whole == crate::interp::WHOLE_SYNC {
            let off = (0..3)
                .map(|a| (epos0[a] - (start[a] + d0[a])).powi(2))
                .sum::<f64>()
                .sqrt();
            if off.is_nan() {
                return Err(refused_at(rec, "a spindle-synchronised move (G33) from a position the program does not tell: its thread is reckoned from where it starts; give X, Y and Z before it"));
            }
            if !(off <= self.st.arc_tol) {
                return Err(refused_at(rec, format!(
                        "a spindle-synchronised move (G33) starts where the tool stands, {:.1} µm from where the field moves its start (more than the chord tolerance {} mm): its thread is reckoned from there; correct the move before it (--rapids for a rapid)",
                        off * 1000.0,
                        self.st.arc_tol
                    )));
            }
        }
        if comp_whole && !straight {
            let e = xyz_at(n - 1);
            let a = [self.st.epos[0], self.st.epos[1], self.st.epos[2]];
            let worst = (0..n - 1)
                .map(|k| dist2_to_segment(&xyz_at(k), &a, &e))
                .fold(0.0f64, f64::max)
                .sqrt();
            if !(worst <= self.st.arc_tol) || !only_xyz || moved != 0 {
                let why = if rec.whole != 0 {
                    whole_why
                } else {
                    "the move that starts or ends cutter compensation, or follows a turn under 0.05 rad (which the controller neither rounds nor trims), must stay one move"
                };
                let hint = if rec.whole != 0 {
                    "correct the move before it (--rapids for a rapid), or raise --chord-tol"
                } else {
                    "plunge with G1 before turning compensation on, correct the rapid before it (--rapids), or raise --chord-tol"
                };
                return Err(refused_at(rec, format!(
                        "{why}, but the corrected path along it is {:.1} µm off a straight line (more than the chord tolerance {} mm), or it moves another axis; {hint}",
                        worst * 1000.0,
                        self.st.arc_tol
                    )));
            }
        }
        // radius compensation in G18/G19: an arc the field bends is not cut into chords (the
        // control would offset its ends along the chords, and meet the moves beside it elsewhere);
        // at an inside corner the tool stops R·tan(turn/2) short of it on both moves, so the
        // pieces next to it must be longer; and the entry move must stay longer than the radius
        let [p1, p2, _] = PLANE_AXES[rec.plane as usize];
        let in_plane = |a: &[f64], b: &[f64]| (b[p1] - a[p1]).hypot(b[p2] - a[p2]);
        let trim = if rec.nose > 0.0 {
            self.it
                .nose_corners
                .binary_search_by_key(&(ri as u32), |&(r, _, _)| r)
                .map_or(0.0, |k| self.it.nose_corners[k].2)
        } else {
            0.0
        };
        if rec.nose > 0.0 {
            let chords = rec.motion.is_arc() && !keep_arc && !straight;
            let an = PLANE_AXES[rec.plane as usize][2];
            if chords && (rec.end[an] - start[an]).abs() > 1e-9 {
                return Err(refused_at(rec,
                    "a helical arc under radius compensation in G18/G19 that the field does not move alike along it: cut into chords, the control's corners between them would hold the helix's axis still",
                ));
            }
            self.st.nose_chords = chords;
            if trim > 0.0 && !(self.st.nose_piece > trim) {
                let before = if self.st.nose_piece.is_nan() {
                    "its length is not known (where the output stood was not)".to_string()
                } else {
                    format!("it is {:.4} mm long", self.st.nose_piece)
                };
                return Err(refused_at(rec, format!(
                    "an inside corner under radius compensation in G18/G19: the tool stops {trim:.4} mm short of it, but of the corrected program's piece before it {before} (the control would find the corner unreachable); raise --max-segment or --chord-tol so the move before stays whole"
                )));
            }
        }
        // before the first move giving X and Y after G68/G69, a corrected X or Y is written with
        // the other, absolute: not in G91
        let half = self.fmt.half(rec.inch);
        if rec.xy_both
            && rec.incremental
            && (0..n).any(|k| {
                // (the distance from where the output stands, which a rotation does not change)
                let e = target_at(k, ts[k]);
                (0..2).any(|a| !((e[a] - self.st.epos[a]).abs() / Self::unit(rec, a) < half * 0.5))
            })
        {
            return Err(refused_at(rec, "an incremental move before the first move giving X and Y after G68 or G69, which the field moves in X or Y: written, its X or Y would be read by the control's setting; give X and Y (absolute) on it"));
        }
        if straight || keep_arc || comp_whole || keep_spline {
            self.spline_register(ri, true)?;
            self.restore_modal(li, rec, explicit);
            let target = target_at(n - 1, 1.0);
            if rec.nose > 0.0 {
                let len = in_plane(&epos0, &target);
                if trim > 0.0 && !(len > trim) {
                    return Err(refused_at(rec, format!("an inside corner under radius compensation in G18/G19: the tool stops {trim:.4} mm short of it, but the corrected move after it is {len:.4} mm long (the control would find the corner unreachable)")));
                }
                if rec.whole == crate::interp::WHOLE_NOSE
                    && self.it.dialect.is_linuxcnc()
                    && !rec.motion.is_arc()
                    && !(len > rec.nose)
                {
                    return Err(refused_at(rec, format!("the move that starts cutter compensation, corrected, is {len:.4} mm long in its plane, not longer than the tool radius {:.4} mm (LinuxCNC refuses it)", rec.nose)));
                }
                self.st.nose_piece = len;
            }
            // polar words that reach the corrected end stay; others are written as X and Y
            if let Some(p) = polar_end {
                if (0..2).all(|a| (p[a] - target[a]).abs() < half_mm) {
                    self.keep_polar = Some(p);
                } else {
                    self.polar_to_xy(li);
                }
            }
            self.set_axes(li, rec, &target, moved);
            // an R-format arc names no centre: moved as a whole, its radius is the same
            if keep_arc && rec.arc_absolute && !words.iter().any(|w| w.letter == b'R') {
                self.shift_centre(li, rec, if helix { ds } else { d0 });
            }
            return Ok(());
        }
        // split or linearised: the original line carries the first piece
        if polar_end.is_some() {
            self.polar_to_xy(li);
        }
        let linearise = rec.motion.is_curve();
        self.spline_register(ri, false)?;
        if comp.is_some_and(|c| c.arc_corner) && linearise {
            // an inside corner before an arc written in chords: the controller meets the first
            // chord's offset, not the arc's offset circle
            return Err(refused_at(
                rec,
                "an inside corner under cutter compensation before an arc that the field does not move alike along it, written in chords: the controller meets the first chord's offset, not the arc's offset circle; raise --chord-tol to keep the arc an arc",
            ));
        }
        self.st.comp_chords = comp.is_some() && linearise;
        if linearise {
            if rec.motion.is_spline() {
                self.st.stats.splines_linearised += 1;
            } else {
                self.st.stats.arcs_linearised += 1;
            }
            let g1 = motion_text(Motion::Feed, self.lx.style.padded_g).as_bytes();
            if let Some(w) = words.iter().find(|w| is_motion_g(w)) {
                self.edit_bytes(w.start, w.end, g1);
            } else {
                self.insert_motion(li, Motion::Feed);
            }
            let spline = rec.motion.is_spline();
            // (the spline's P Q go: another code of the block that reads P, Q or R would lose
            // its own)
            if let Some(w) = words.iter().find(|w| spline && !spline_piece_keeps(w)) {
                return Err(refused_at(rec, format!(
                    "a spline written in pieces loses its I J P Q words, which {}{} in its block may also read (G4, G10, G64, M19, M50-M53, M61-M68, M98, a user M code): put that code on a line of its own",
                    w.letter as char, w.value
                )));
            }
            for w in words.iter().filter(|w| {
                matches!(w.letter, b'I' | b'J' | b'K' | b'R' | b'P') || spline && w.letter == b'Q'
            }) {
                self.remove_word(li, w);
            }
            self.st.out_motion = Some(Motion::Feed);
        } else {
            self.restore_modal(li, rec, explicit);
        }
        // a uniform straight move that starts off the corrected path needs one piece to reach it
        let keep: Vec<usize> = if let Some(c) = comp {
            self.comp_pieces(rec, c, &start, xyz, disp, n)?
        } else if !linearise && uniform && only_xyz && moved == 0 {
            vec![0, n - 1]
        } else {
            (0..n).collect()
        };
        let pieces = &keep[1..];
        // G93's F word, when the move's time is shared among its pieces
        let inverse_f = rec
            .inverse_time
            .then(|| words.iter().find(|w| w.letter == b'F'))
            .flatten()
            .map(|w| (w.num_start, w.end, w.value));
        // the length of each piece written, from where the output stands (on a lathe, in its
        // XZ plane: Y is 0)
        let lens: Vec<f64> = if rec.nose > 0.0 || inverse_f.is_some() {
            let mut prev = [epos0[0], epos0[1], epos0[2]];
            keep.iter()
                .map(|&k| {
                    let p = xyz_at(k);
                    let d = ((p[0] - prev[0]).powi(2)
                        + (p[1] - prev[1]).powi(2)
                        + (p[2] - prev[2]).powi(2))
                    .sqrt();
                    prev = p;
                    d
                })
                .collect()
        } else {
            Vec::new()
        };
        // a lathe's nose radius compensation: the control offsets each written piece along its
        // own normal, which the rounding of its numbers turns by up to 2√2·half/length, moving
        // the nose centre by the nose radius times that
        if rec.nose > 0.0 {
            let mut prev = [epos0[0], epos0[1], epos0[2]];
            let plens: Vec<f64> = keep
                .iter()
                .map(|&k| {
                    let p = xyz_at(k);
                    let d = in_plane(&prev, &p);
                    prev = p;
                    d
                })
                .collect();
            if let (Some(&first), true) = (plens.first(), trim > 0.0) {
                if !(first > trim) {
                    return Err(refused_at(rec, format!("an inside corner under radius compensation in G18/G19: the tool stops {trim:.4} mm short of it, but the corrected program's first piece after it is {first:.4} mm long (the control would find the corner unreachable); raise --max-segment or --chord-tol")));
                }
            }
            self.st.nose_piece = plens.last().copied().unwrap_or(f64::INFINITY);
            let shortest = rec.nose * 2.0 * std::f64::consts::SQRT_2 * half_mm / self.st.arc_tol;
            if let Some(&len) = lens.iter().find(|&&len| len < shortest) {
                return Err(refused_at(rec, format!(
                        "a piece {len:.4} mm long under radius compensation in G18/G19: the rounding of its numbers turns it enough to move the tool centre ({:.4} mm radius) by more than the chord tolerance {} mm (pieces under it must be at least {shortest:.4} mm); raise --max-segment or --chord-tol",
                        rec.nose, self.st.arc_tol
                    )));
            }
        }
        // program stops move to the last piece (they stay where they are when there is none)
        let mut stops: Vec<u8> = Vec::new();
        for w in words.iter().filter(|w| is_stop_m(w) && !pieces.is_empty()) {
            stops.extend_from_slice(self.sep());
            stops.extend_from_slice(&self.src[w.start as usize..w.end as usize]);
            self.remove_word(li, w);
        }
        // G93: the pieces share the move's time as they share the length of the corrected path
        // (the piece that joins it from where the output stands included), so every piece runs
        // at one speed and they take the move's time; a piece's F is the move's over its share.
        // A move along no X Y Z (rotary axes alone) shares it by fraction along the move. A
        // piece left out (it moves no written digit) passes its share on to the next
        let shares: Vec<f64> = if inverse_f.is_some() {
            let total: f64 = lens.iter().sum();
            if total > 1e-9 {
                lens.iter().map(|d| d / total).collect()
            } else {
                let mut t0 = 0.0;
                keep.iter()
                    .map(|&k| {
                        let s = ts[k] - t0;
                        t0 = ts[k];
                        s
                    })
                    .collect()
            }
        } else {
            Vec::new()
        };
        let first = target_at(keep[0], ts[keep[0]]);
        self.set_axes(li, rec, &first, moved);
        // (a first piece that goes nowhere keeps the move's F)
        if let Some((ns, ne, f)) = inverse_f.filter(|_| shares[0] > 0.0) {
            let text = inverse_feed(f, shares[0], rec.line)?;
            self.edit_bytes(ns, ne, text.as_bytes());
        }
        let mut pending = 0.0;
        let prefix: &[u8] = if self.lx.lines[li].block_delete {
            b"/"
        } else {
            b""
        };
        // XYZ and the other axes the block names, in the order of AXES
        let axes = 0b111 | rec.named | moved;
        // under a coordinate rotation the pieces' X and Y are written as programmed, turned back
        let rot = self.rotation(rec);
        if let Some(r) = rot {
            to_prog(&r, &mut self.st.epos);
        }
        for (i, &k) in pieces.iter().enumerate() {
            let t0 = self.st.tail.len();
            let body = t0 + prefix.len();
            self.st.tail.extend_from_slice(prefix);
            let piece_xy = rot.map_or([0.0; 2], |r| {
                r.to_prog([xyz[3 * k] + disp[3 * k], xyz[3 * k + 1] + disp[3 * k + 1]])
            });
            let both = rec.xy_both && {
                let mut t = target_at(k, ts[k]);
                if rot.is_some() {
                    t[0] = piece_xy[0];
                    t[1] = piece_xy[1];
                }
                self.xy_moves(rec, &t)
            };
            let mut bits = axes;
            while bits != 0 {
                let a = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                // (the axis of `target_at(k, ts[k])`; X and Y as programmed under a rotation)
                let pa = if a < 2 && rot.is_some() {
                    piece_xy[a]
                } else if a < 3 {
                    xyz[3 * k + a] + disp[3 * k + a]
                } else {
                    (if ts[k] == 1.0 {
                        rec.end[a]
                    } else {
                        start[a] + ts[k] * (rec.end[a] - start[a])
                    }) + if moved & (1 << a) != 0 {
                        uvw[3 * k + a - 6]
                    } else {
                        0.0
                    }
                };
                let u = Self::unit(rec, a);
                let want = if rec.incremental {
                    (pa - self.st.epos[a]) / u
                } else {
                    (pa - self.off[a]) / u
                };
                let differs = if rec.incremental {
                    want.abs() >= half
                } else {
                    (pa - self.st.epos[a]).abs() / u >= half
                };
                if differs || (both && a < 2) {
                    if self.st.tail.len() > body {
                        let sep = self.sep();
                        self.st.tail.extend_from_slice(sep);
                    }
                    self.st.tail.push(AXES[a]);
                    let v = self.fmt.number(want, rec.inch, &mut self.st.tail);
                    self.st.epos[a] = if rec.incremental {
                        self.st.epos[a] + v * u
                    } else {
                        v * u + self.off[a]
                    };
                }
            }
            if let Some((_, _, f)) = inverse_f {
                pending += shares[i + 1];
                if self.st.tail.len() > body {
                    let text = inverse_feed(f, pending, rec.line)?;
                    let sep = self.sep();
                    self.st.tail.extend_from_slice(sep);
                    self.st.tail.push(b'F');
                    self.st.tail.extend_from_slice(text.as_bytes());
                    pending = 0.0;
                }
            }
            if k + 1 == n && !stops.is_empty() {
                if self.st.tail.len() == body {
                    self.st.tail.extend_from_slice(&stops[self.sep().len()..]);
                } else {
                    self.st.tail.extend_from_slice(&stops);
                }
            }
            if self.st.tail.len() > body {
                self.st.tail_ends.push(self.st.tail.len());
            } else {
                self.st.tail.truncate(t0);
            }
        }
        if let Some(r) = rot {
            from_prog(&r, &mut self.st.epos);
        }
        Ok(())
    }

    /// The samples a compensated move cut in pieces is written at (ascending, the last the end),
    /// and the output's last piece of it kept in [`EmitState::comp_piece`]. The first piece must
    /// be longer than the tool stops short at an inside corner before the move; the last one is
    /// kept [`COMP_GUARD`] tool radii long for a corner after it (a sharper one is refused there,
    /// [`Emitter::comp_inside_corner`]). A straight move's samples closer to its ends are left out when
    /// the corrected path passes them within the chord tolerance, else the move is refused; an
    /// arc's chords cannot be left out.
    fn comp_pieces(
        &mut self,
        rec: &crate::interp::Record,
        c: &crate::interp::Comp,
        start: &[f64; NAXES],
        xyz: &[f64],
        disp: &[f64],
        n: usize,
    ) -> Result<Vec<usize>, NcError> {
        let along = |k: usize| (xyz[3 * k] - start[0]).hypot(xyz[3 * k + 1] - start[1]);
        let len = along(n - 1);
        let refuse = |message: String| NcError::Interpret {
            line: rec.line as usize + 1,
            col: 1,
            message,
        };
        // the written numbers are rounded (half a unit of the last digit, `half` mm): a piece of
        // length L turns by up to 2√2·half/L, which moves the offset end the controller starts
        // the next piece from by r times that: pieces shorter than `shortest` would move the
        // tool centre by more than the chord tolerance
        let half = self.fmt.half_in_mm(rec.inch);
        let shortest = c.radius * 2.0 * std::f64::consts::SQRT_2 * half / self.st.arc_tol;
        if rec.motion.is_arc() {
            // the chords' lengths (in the plane), from the arc's start
            let chords: Vec<f64> = (0..n)
                .map(|k| {
                    let (x0, y0) = if k == 0 {
                        (start[0], start[1])
                    } else {
                        (xyz[3 * k - 3], xyz[3 * k - 2])
                    };
                    (xyz[3 * k] - x0).hypot(xyz[3 * k + 1] - y0)
                })
                .collect();
            let chord = chords.iter().copied().fold(f64::INFINITY, f64::min);
            if chord < shortest {
                return Err(refused_at(rec, format!(
                    "an arc under cutter compensation cut in chords as short as {chord:.4} mm: the rounding of the written numbers turns such a chord enough to move the tool centre (radius {:.4} mm) by more than the chord tolerance; raise --chord-tol so the arc stays an arc or its chords are longer",
                    c.radius
                )));
            }
            let a = chords[0];
            if !(a > c.trim) {
                return Err(refused_at(rec, format!(
                    "an inside corner under cutter compensation before an arc cut in chords: the tool stops {:.4} mm short of the corner, longer than the first chord ({a:.4} mm); raise --chord-tol so the arc stays an arc",
                    c.trim
                )));
            }
            self.st.comp_piece = chords[n - 1];
            return Ok((0..n).collect());
        }
        let guard = (COMP_GUARD * c.radius).max(shortest).min(len);
        let mut keep: Vec<usize> = Vec::new();
        let mut last = 0.0;
        for k in 0..n - 1 {
            let at = along(k);
            if at > c.trim && at - last >= shortest && len - at >= guard {
                keep.push(k);
                last = at;
            }
        }
        keep.push(n - 1);
        // the samples left out must be on the corrected path the pieces take
        let at = |k: usize| {
            [
                xyz[3 * k] + disp[3 * k],
                xyz[3 * k + 1] + disp[3 * k + 1],
                xyz[3 * k + 2] + disp[3 * k + 2],
            ]
        };
        let mut from = [self.st.epos[0], self.st.epos[1], self.st.epos[2]];
        let mut worst = 0.0f64;
        let mut j = 0;
        for &k in &keep {
            let to = at(k);
            for m in j..k {
                worst = worst.max(dist2_to_segment(&at(m), &from, &to));
            }
            from = to;
            j = k + 1;
        }
        let worst = worst.sqrt();
        if !(worst <= self.st.arc_tol) {
            return Err(refuse(format!(
                "a move under cutter compensation: its pieces next to the corners must be longer than the tool stops short there ({:.4} mm at the start, {guard:.4} mm kept at the end), and the corrected path over them is {:.1} µm off a straight line (more than the chord tolerance {} mm); raise --chord-tol",
                c.trim,
                worst * 1000.0,
                self.st.arc_tol
            )));
        }
        let k = keep.len();
        self.st.comp_piece = len - if k > 1 { along(keep[k - 2]) } else { 0.0 };
        Ok(keep)
    }

    /// A canned-cycle block: each hole moved by the displacement at its bottom (X, Y by its x
    /// and y, Z and R by its z). Kept a cycle block, its X Y Z R words rewritten (and written
    /// where the output's sticky value differs), or written as the moves LinuxCNC makes of it
    /// (`expand_cycles`). With `copy` (a block under an unsupported construct, kept with
    /// `--keep-unsupported`) the block is copied: its words as written, and only the sticky X Y
    /// Z R it relies on written where the output's differ from the program's, so that it drills
    /// the holes it drills in the program; the position after it follows the copied block.
    fn cycle_block(
        &mut self,
        li: usize,
        last: usize,
        samples: &Samples,
        disp: &[f64],
        copy: bool,
    ) -> Result<(), NcError> {
        let it = self.it;
        let line_no = it.records[last].line;
        let mut first = last;
        while first > samples.rec0 && it.records[first - 1].line == line_no {
            first -= 1;
        }
        let k = it.cycles.partition_point(|c| c.line < line_no);
        let cy = match it.cycles.get(k) {
            Some(c) if c.line == line_no => c.clone(),
            _ => {
                return Err(NcError::Usage(format!(
                    "line {}: a canned cycle the interpreter did not keep",
                    line_no + 1
                )))
            }
        };
        let rec = &it.records[first];
        let (inch, incremental) = (rec.inch, rec.incremental);
        let u = if inch { MM_PER_INCH } else { 1.0 };
        let half = self.fmt.half(inch);
        if cy.sets_level {
            self.st.cyc_level = self.st.epos[2];
        }
        // worked out in the program's coordinates (the offsets of G92 & co. taken off)
        let off = self.off;
        let level = (self.st.cyc_level - off[2]) / u;
        let mut holes: Vec<Hole> = Vec::with_capacity(cy.repeats as usize);
        // where the program drills them, for a block whose polar words stay
        let mut at: Vec<[f64; 2]> = Vec::with_capacity(cy.repeats as usize);
        for ri in first..=last {
            let r = &it.records[ri];
            if r.cycle != CYCLE_BOTTOM {
                continue;
            }
            at.push([(r.end[0] - off[0]) / u, (r.end[1] - off[1]) / u]);
            let (f, c) = samples.of(ri);
            let d = if c > 0 {
                [disp[3 * f], disp[3 * f + 1], disp[3 * f + 2]]
            } else {
                [0.0; 3]
            };
            holes.push(Hole {
                x: (r.end[0] + d[0] - off[0]) / u,
                y: (r.end[1] + d[1] - off[1]) / u,
                r: (cy.r + d[2] - off[2]) / u,
                bottom: (r.end[2] + d[2] - off[2]) / u,
            });
        }
        let polar = self.lx.line_words(li).iter().any(is_polar);
        let cur = [
            (self.st.epos[0] - off[0]) / u,
            (self.st.epos[1] - off[1]) / u,
            (self.st.epos[2] - off[2]) / u,
        ];
        let name = |c: i32| format!("G{}", c / 10);
        let err = |msg: String| NcError::Interpret {
            line: line_no as usize + 1,
            col: 1,
            message: msg,
        };
        if holes.is_empty() {
            return Err(err("a canned cycle without holes".into()));
        }
        if copy && self.st.expand_cycles && !cy.sets_level && self.st.cyc_expanded {
            return Err(err(format!(
                "canned cycle {} is kept as written (an unsupported construct is in force) but continues a cycle whose earlier blocks --expand-cycles wrote as moves, so the output would not be in that cycle any more; correct it without --expand-cycles",
                name(cy.code)
            )));
        }
        // a G90 cycle block (holes placed by X Y, not by polar words) goes to its first hole
        // whatever X and Y the tool had before it: its X and Y are then written
        let xy_needed = copy || incremental || polar || self.st.expand_cycles;
        let holes_known = holes
            .iter()
            .all(|h| [h.x, h.y, h.r, h.bottom].iter().all(|v| v.is_finite()));
        if !(cur[2].is_finite()
            && (!xy_needed || cur[0].is_finite() && cur[1].is_finite())
            && level.is_finite()
            && holes_known)
        {
            if copy {
                // (the program's position is known here: a cycle from an unknown one is refused)
                for (k, e) in self.st.epos.iter_mut().enumerate().take(3) {
                    *e = it.records[last].end[k];
                }
                self.after_cycle_block();
                return Ok(());
            }
            return Err(err(format!(
                "canned cycle {}: the corrected program's position before it is unknown",
                name(cy.code)
            )));
        }
        if copy {
            self.st.cyc_expanded = false;
        } else if self.st.expand_cycles {
            if cy.retract_unknown {
                return Err(err(format!(
                    "canned cycle {}: neither G98 nor G99 is stated before it, and the control's mode decides how the tool retracts (Fanuc/Haas controls start in G98 at power-on, but a reset may keep the mode of the last program); --expand-cycles writes the retract moves, so state G98 or G99 before the cycle (without --expand-cycles the cycle blocks stay and the control decides)",
                    name(cy.code)
                )));
            }
            self.st.cyc_expanded = true;
            return self.expand_cycle(li, &cy, &holes, cur, level, inch, incremental);
        }
        // polar words (@ ^) stay, and say where the holes are, when the correction leaves every
        // hole where the program drills it in X and Y and moves them all alike in Z
        if polar && copy {
            return Err(err(format!(
                "canned cycle {} with polar words (@ ^) under an unsupported construct kept as written: where its holes land from the corrected position is not followed",
                name(cy.code)
            )));
        }
        if polar {
            let h0 = holes[0];
            // the polar words measure from where the output stands (G91, or a word left out):
            // from there they must still reach the holes where the correction wants them
            let words_polar = self.polar_words(li);
            let mut from = [cur[0], cur[1]];
            let drifts = at.iter().any(|p| {
                let start = if incremental { from } else { [cur[0], cur[1]] };
                from = polar_xy(start, words_polar, incremental);
                !((from[0] - p[0]).abs() < half && (from[1] - p[1]).abs() < half)
            });
            let sideways = drifts
                || holes
                    .iter()
                    .zip(&at)
                    .any(|(h, p)| (h.x - p[0]).abs() >= half || (h.y - p[1]).abs() >= half);
            let apart = holes
                .iter()
                .any(|h| (h.r - h0.r).abs() >= half || (h.bottom - h0.bottom).abs() >= half);
            if sideways || (incremental && apart) {
                return Err(err(format!(
                    "canned cycle {} with polar words (@ ^): the correction moves {}, which its polar words cannot say; use --expand-cycles",
                    name(cy.code),
                    if sideways { "a hole in X or Y (or the point its polar words measure from)" } else { "its holes by different amounts in Z" }
                )));
            }
        }
        // the numbers the block must have
        let h0 = holes[0];
        let (want, implied_xy) = if polar {
            // X and Y are the polar words' (never written beside them)
            let zr = if incremental {
                [h0.bottom - h0.r, h0.r - level]
            } else {
                [h0.bottom, h0.r]
            };
            ([at[0][0], at[0][1], zr[0], zr[1]], [at[0][0], at[0][1]])
        } else if copy {
            // the program's own numbers; in G91 X and Y are steps from wherever the tool is
            if incremental {
                ([0.0, 0.0, cy.z_word, cy.r_word], [0.0, 0.0])
            } else {
                ([h0.x, h0.y, cy.z_word, cy.r_word], [cur[0], cur[1]])
            }
        } else if incremental {
            let mut prev = [cur[0], cur[1]];
            let step = [h0.x - prev[0], h0.y - prev[1]];
            for h in &holes {
                let d = [h.x - prev[0], h.y - prev[1]];
                if (d[0] - step[0]).abs() >= half
                    || (d[1] - step[1]).abs() >= half
                    || (h.r - h0.r).abs() >= half
                    || (h.bottom - h0.bottom).abs() >= half
                {
                    return Err(err(format!(
                        "G91 canned cycle {} with L{}: the correction moves its holes by different amounts, which one cycle block cannot write; use --expand-cycles",
                        name(cy.code),
                        cy.repeats
                    )));
                }
                prev = [h.x, h.y];
            }
            (
                [step[0], step[1], h0.bottom - h0.r, h0.r - level],
                [0.0, 0.0],
            )
        } else {
            ([h0.x, h0.y, h0.bottom, h0.r], [cur[0], cur[1]])
        };
        let implied = [
            Some(implied_xy[0]),
            Some(implied_xy[1]),
            self.st.cyc_z,
            self.st.cyc_r,
        ];
        let mut written = [0.0; 4];
        let words = self.lx.line_words(li);
        for (i, letter) in [b'X', b'Y', b'Z', b'R'].into_iter().enumerate() {
            if polar && i < 2 {
                written[i] = want[i]; // the polar words' (checked above)
                continue;
            }
            written[i] = if let Some(w) = words.iter().find(|w| w.letter == letter) {
                if !copy && (want[i] - w.value).abs() >= half {
                    self.edit_number(w.num_start, w.end, want[i], inch)
                } else {
                    w.value
                }
            } else {
                match implied[i] {
                    Some(v) if (want[i] - v).abs() < half => v,
                    _ => {
                        let at = self.insert_point(li);
                        let t0 = self.st.arena.len() as u32;
                        let sep = self.sep();
                        self.st.arena.extend_from_slice(sep);
                        self.st.arena.push(letter);
                        let v = self.fmt.number(want[i], inch, &mut self.st.arena);
                        self.st.edits.push(Edit {
                            start: at,
                            end: at,
                            t0,
                            t1: self.st.arena.len() as u32,
                        });
                        v
                    }
                }
            };
        }
        self.st.cyc_z = Some(written[2]);
        self.st.cyc_r = Some(written[3]);
        // where the output's block leaves the machine, from the numbers as written
        let mut out_holes = Vec::with_capacity(holes.len());
        let (mut aa, mut bb) = (cur[0], cur[1]);
        for program_xy in at.iter().take(holes.len()) {
            let (r, cc) = if incremental {
                let r = written[3] + level;
                aa += written[0];
                bb += written[1];
                (r, r + written[2])
            } else {
                aa = written[0];
                bb = written[1];
                (written[3], written[2])
            };
            if polar {
                // the polar words drill where the program does
                [aa, bb] = *program_xy;
            }
            out_holes.push(Hole {
                x: aa,
                y: bb,
                r,
                bottom: cc,
            });
        }
        let mut steps = std::mem::take(&mut self.st.steps);
        steps.clear();
        let (end, choices) = cycle_steps(
            cy.code,
            cy.g98,
            cy.q,
            peck_clearance(inch),
            cur,
            level,
            &out_holes,
            None,
            &mut steps,
        );
        self.st.steps = steps;
        if !copy && approach_changes(&cy, choices, level, out_holes[0].r) {
            return Err(err(format!(
                "canned cycle {}: the correction moves the R plane past the tool's height, so LinuxCNC would travel to the hole at that height instead of the G98 retract level (or the other way round); use --expand-cycles (it writes the programmed approach)",
                name(cy.code)
            )));
        }
        for ((e, v), o) in self.st.epos.iter_mut().zip(end).zip(off) {
            *e = v * u + o;
        }
        self.after_cycle_block();
        Ok(())
    }

    /// A canned-cycle block written as the G0/G1 moves (and G4 dwells) LinuxCNC makes of the
    /// corrected holes; the block keeps its other words.
    #[allow(clippy::too_many_arguments)]
    fn expand_cycle(
        &mut self,
        li: usize,
        cy: &crate::interp::Cycle,
        holes: &[Hole],
        cur: [f64; 3],
        level: f64,
        inch: bool,
        incremental: bool,
    ) -> Result<(), NcError> {
        if matches!(cy.code, 740 | 840 | 860) {
            return Err(NcError::Interpret {
                line: cy.line as usize + 1,
                col: 1,
                message: format!(
                    "canned cycle G{} stops or reverses the spindle, which G0/G1 moves cannot write; correct it without --expand-cycles",
                    cy.code / 10
                ),
            });
        }
        let u = if inch { MM_PER_INCH } else { 1.0 };
        let half = self.fmt.half(inch);
        let words = self.lx.line_words(li);
        let mut stops: Vec<u8> = Vec::new();
        for w in words {
            let cycle_g = w.letter == b'G' && is_motion_g(w);
            if cycle_g
                || is_polar(w)
                || matches!(w.letter, b'X' | b'Y' | b'Z' | b'R' | b'Q' | b'P' | b'L')
            {
                self.remove_word(li, w);
            } else if is_stop_m(w) {
                stops.extend_from_slice(self.sep());
                stops.extend_from_slice(&self.src[w.start as usize..w.end as usize]);
                self.remove_word(li, w);
            }
        }
        let mut steps = std::mem::take(&mut self.st.steps);
        steps.clear();
        let (_, choices) = cycle_steps(
            cy.code,
            cy.g98,
            cy.q,
            peck_clearance(inch),
            cur,
            level,
            holes,
            None,
            &mut steps,
        );
        if approach_changes(cy, choices, level, holes[0].r) {
            // the programmed approach: at the retract level, or at the tool's height
            steps.clear();
            cycle_steps(
                cy.code,
                cy.g98,
                cy.q,
                peck_clearance(inch),
                cur,
                level,
                holes,
                Some((choices.0, cy.choices.1)),
                &mut steps,
            );
        }
        let prefix: &[u8] = if self.lx.lines[li].block_delete {
            b"/"
        } else {
            b""
        };
        let padded = self.lx.style.padded_g;
        for (k, s) in steps.iter().enumerate() {
            let t0 = self.st.tail.len();
            self.st.tail.extend_from_slice(prefix);
            match *s {
                CycleStep::Dwell => {
                    self.st
                        .tail
                        .extend_from_slice(if padded { b"G04" } else { b"G4" });
                    self.st.tail.extend_from_slice(self.sep());
                    self.st
                        .tail
                        .extend_from_slice(format!("P{}", cy.p).as_bytes());
                }
                CycleStep::Move(m, p, _) => {
                    self.st
                        .tail
                        .extend_from_slice(motion_text(m, padded).as_bytes());
                    let mut any = false;
                    for a in 0..3 {
                        let now = (self.st.epos[a] - self.off[a]) / u;
                        if (p[a] - now).abs() < half && (any || a < 2) {
                            continue;
                        }
                        let want = if incremental { p[a] - now } else { p[a] };
                        let sep = self.sep();
                        self.st.tail.extend_from_slice(sep);
                        self.st.tail.push(AXES[a]);
                        let v = self.fmt.number(want, inch, &mut self.st.tail);
                        self.st.epos[a] = if incremental {
                            self.st.epos[a] + v * u
                        } else {
                            v * u + self.off[a]
                        };
                        any = true;
                    }
                }
            }
            if k + 1 == steps.len() {
                self.st.tail.extend_from_slice(&stops);
            }
            let _ = t0;
            self.st.tail_ends.push(self.st.tail.len());
        }
        self.st.steps = steps;
        // the moves written set the output's modal motion; on a Fanuc control the program's
        // stays the group 01 motion before the cycle, which the next block may rely on
        self.st.out_motion = if self.it.dialect.is_fanuc() {
            self.st.steps.iter().rev().find_map(|s| match s {
                CycleStep::Move(m, ..) => Some(*m),
                _ => None,
            })
        } else {
            None
        };
        Ok(())
    }

    /// Remove a word and the blanks before it.
    fn remove_word(&mut self, li: usize, w: &Word) {
        let line_start = self.lx.lines[li].start;
        let mut s = w.start;
        while s > line_start && matches!(self.src[s as usize - 1], b' ' | b'\t') {
            s -= 1;
        }
        self.edit_bytes(s, w.end, b"");
    }

    /// A cycle block written as a cycle block sets the output's modal motion as the program's,
    /// except on a Fanuc control, whose cycles (group 09) leave the G0/G1/G2/G3 in force.
    fn after_cycle_block(&mut self) {
        if !self.it.dialect.is_fanuc() {
            self.st.out_motion = None;
        }
    }

    /// The polar words of line `li`: the distance `@` and the angle `^`, where written.
    fn polar_words(&self, li: usize) -> [Option<f64>; 2] {
        let mut polar = [None; 2];
        for w in self.lx.line_words(li) {
            match w.letter {
                b'@' => polar[0] = Some(w.value),
                b'^' => polar[1] = Some(w.value),
                _ => {}
            }
        }
        polar
    }

    /// Where the polar words of line `li` (block `rec`) take the output from where it is, as
    /// LinuxCNC reads them (X and Y, mm).
    fn polar_end(&self, li: usize, rec: &Record) -> [f64; 2] {
        let u = if rec.inch { MM_PER_INCH } else { 1.0 };
        let polar = self.polar_words(li);
        let cur = [
            (self.st.epos[0] - self.off[0]) / u,
            (self.st.epos[1] - self.off[1]) / u,
        ];
        let [x, y] = polar_xy(cur, polar, rec.incremental);
        [x * u + self.off[0], y * u + self.off[1]]
    }

    /// A Fanuc lathe's G90/G94 block ([`crate::interp::LatheBox`]; `ri` its last record, the
    /// return to its start, after its corner): its X and Z (or U and W, from where the output
    /// stands, the cycle's start) aimed at the corner moved by the field there (as the program
    /// has it where the corner is not corrected); X or Z the block leaves out (modal) written
    /// where the output's modal value is another. The output stays where it was: the cycle
    /// returns to its start.
    fn lathe_box(&mut self, li: usize, ri: usize, samples: &Samples, disp: &[f64]) {
        let rec = &self.it.records[ri - 1];
        let (f, c) = samples.of(ri - 1);
        let mut target = rec.end;
        if c > 0 {
            for a in [0, 2] {
                target[a] += disp[3 * f + a];
            }
        }
        let half = self.fmt.half(rec.inch);
        let mut seen = [false; 2];
        for w in self.lx.line_words(li) {
            let Some((a, incremental)) = self.word_axis(rec, w.letter) else {
                continue;
            };
            if a != 0 && a != 2 {
                continue;
            }
            seen[a / 2] = true;
            let u = Self::unit(rec, a);
            let from = if incremental {
                self.st.epos[a]
            } else {
                self.off[a]
            };
            let want = (target[a] - from) / u;
            let v = if (want - w.value).abs() < half {
                w.value
            } else {
                self.edit_number(w.num_start, w.end, want, rec.inch)
            };
            self.st.out_box[a / 2] = from + v * u;
        }
        let at = self.insert_point(li);
        let t0 = self.st.arena.len();
        for a in [0, 2] {
            let u = Self::unit(rec, a);
            if seen[a / 2] || (target[a] - self.st.out_box[a / 2]).abs() / u < half {
                continue;
            }
            let sep = self.sep();
            self.st.arena.extend_from_slice(sep);
            self.st.arena.push(AXES[a]);
            let v = self
                .fmt
                .number((target[a] - self.off[a]) / u, rec.inch, &mut self.st.arena);
            self.st.out_box[a / 2] = self.off[a] + v * u;
        }
        if self.st.arena.len() > t0 {
            self.st.edits.push(Edit {
                start: at,
                end: at,
                t0: t0 as u32,
                t1: self.st.arena.len() as u32,
            });
        }
    }

    /// A Fanuc lathe's grooving or threading cycle block ([`crate::interp::LatheBox`], one of
    /// [`LATHE_CUTS`]; `ri` its last record, the return to its start): moved as one by the field
    /// at its end. The output must stand at the start so moved (the thread's phase and the
    /// groove's place are reckoned from it): where it does not (the move there was a rapid, not
    /// corrected), a move there is written before the block, in the motion mode in force (G0 or
    /// G1). Its X and Z (or U and W, from there) are aimed at the end moved; an axis it leaves
    /// out is the start's. A block not treated is copied.
    fn lathe_cut(
        &mut self,
        li: usize,
        ri: usize,
        samples: &Samples,
        disp: &[f64],
        b: &crate::interp::LatheBox,
    ) -> Result<(), NcError> {
        let rec = &self.it.records[ri - 1];
        let linuxcnc = self.it.dialect.is_linuxcnc();
        let (f, c) = samples.of(ri - 1);
        if !rec.supported || c == 0 {
            // copied: a LinuxCNC G76 ends at the block's end, from where the output is
            if linuxcnc {
                for a in 0..3 {
                    let named = rec.named & (1 << a) != 0;
                    self.st.epos[a] = if named && !rec.incremental {
                        rec.end[a]
                    } else {
                        self.st.epos[a] + (rec.end[a] - b.start[a])
                    };
                }
            }
            return Ok(());
        }
        let lathe = self.it.dialect.lathe();
        let d = [
            disp[3 * f],
            if lathe { 0.0 } else { disp[3 * f + 1] },
            disp[3 * f + 2],
        ];
        let half = self.fmt.half(rec.inch);
        let start = [b.start[0] + d[0], b.start[1] + d[1], b.start[2] + d[2]];
        // the move to the moved start, in the state in force before the block
        let bf = b.before;
        let unit_before = |a: usize| unit_in(a, bf.inch, bf.diameter);
        let axes: &[usize] = if lathe { &[0, 2] } else { &[0, 1, 2] };
        let half_before = self.fmt.half(bf.inch);
        let away = axes
            .iter()
            .any(|&a| !((start[a] - self.st.epos[a]).abs() / unit_before(a) < half_before));
        if away {
            let Some(m) = bf
                .motion
                .filter(|_| axes.iter().all(|&a| self.st.epos[a].is_finite()))
            else {
                return Err(NcError::Interpret {
                    line: li + 1,
                    col: 1,
                    message: "a grooving or threading cycle starts where the tool stands, which the correction moves with the cycle; the move there is not corrected (a rapid) and no G0 or G1 is in force for a move to add before the block (or the position there is not known): write G0 or G1 before it".into(),
                });
            };
            // a line of its own before the block: its motion (the one in force) and the moved
            // start, absolute or from where the output is as the block before leaves the mode
            let at = self.lx.lines[li].start;
            let t0 = self.st.arena.len();
            if self.lx.lines[li].block_delete {
                self.st.arena.push(b'/');
            }
            self.st
                .arena
                .extend_from_slice(motion_text(m, self.lx.style.padded_g).as_bytes());
            for &a in axes {
                let sep = self.sep();
                self.st.arena.extend_from_slice(sep);
                self.st.arena.push(AXES[a]);
                let u = unit_before(a);
                let from = if bf.incremental {
                    self.st.epos[a]
                } else {
                    bf.off[a]
                };
                let v = self
                    .fmt
                    .number((start[a] - from) / u, bf.inch, &mut self.st.arena);
                self.st.epos[a] = from + v * u;
            }
            let eol = self.eol;
            self.st.arena.extend_from_slice(eol);
            self.st.edits.push(Edit {
                start: at,
                end: at,
                t0: t0 as u32,
                t1: self.st.arena.len() as u32,
            });
            self.st.stats.lines_added += 1;
        }
        let mut ends = [self.st.epos[0], self.st.epos[1], self.st.epos[2]];
        for w in self.lx.line_words(li) {
            let Some((a, incremental)) = self.word_axis(rec, w.letter) else {
                continue;
            };
            if a != 0 && a != 2 {
                continue;
            }
            let u = Self::unit(rec, a);
            let from = if incremental {
                self.st.epos[a]
            } else {
                self.off[a]
            };
            let want = (rec.end[a] + d[a] - from) / u;
            let v = if (want - w.value).abs() >= half {
                self.edit_number(w.num_start, w.end, want, rec.inch)
            } else {
                w.value
            };
            ends[a] = from + v * u;
        }
        if linuxcnc {
            // LinuxCNC's G76 ends at the block's end (moved; an axis it leaves out where it
            // started), not at its start
            self.st.epos[0] = ends[0];
            self.st.epos[2] = ends[2];
        }
        Ok(())
    }

    /// Remove the polar words of line `li`: the block's X and Y are then written as its other
    /// axis words are (where they differ from where the output is).
    fn polar_to_xy(&mut self, li: usize) {
        for w in self.lx.line_words(li).iter().filter(|w| is_polar(w)) {
            self.remove_word(li, w);
        }
    }

    /// Aim the block's axis words at `target` (mm), rewriting only what changes and adding the
    /// axis words it lacks; axes of `also` (bits of AXES) are written where they differ even when
    /// the block does not name them.
    fn set_axes(&mut self, li: usize, rec: &Record, target: &[f64; NAXES], also: u16) {
        // under a coordinate rotation X and Y are written as programmed: the target and the
        // output's position turned back, and the position turned again after
        let rot = self.rotation(rec);
        let mut turned = *target;
        if let Some(r) = rot {
            to_prog(&r, &mut turned);
            to_prog(&r, &mut self.st.epos);
        }
        self.set_axes_as_programmed(li, rec, &turned, also);
        if let Some(r) = rot {
            from_prog(&r, &mut self.st.epos);
        }
    }

    /// [`Emitter::set_axes`] with `target` and the output's position as the block's numbers
    /// read them.
    fn set_axes_as_programmed(
        &mut self,
        li: usize,
        rec: &Record,
        target: &[f64; NAXES],
        also: u16,
    ) {
        let lx = self.lx;
        let words = lx.line_words(li);
        let half = self.fmt.half(rec.inch);
        let mut seen = [false; NAXES];
        // polar words kept: they give X and Y
        if let Some(p) = self.keep_polar.take() {
            seen[0] = true;
            seen[1] = true;
            self.st.epos[0] = p[0];
            self.st.epos[1] = p[1];
        }
        for w in words {
            if let Some((a, incremental)) = self.word_axis(rec, w.letter) {
                seen[a] = true;
                let u = Self::unit(rec, a);
                let want = if incremental {
                    (target[a] - self.st.epos[a]) / u
                } else {
                    (target[a] - self.off[a]) / u
                };
                if (want - w.value).abs() < half {
                    self.st.epos[a] = if incremental {
                        self.st.epos[a] + w.value * u
                    } else {
                        w.value * u + self.off[a]
                    };
                } else {
                    let v = self.edit_number(w.num_start, w.end, want, rec.inch);
                    self.st.epos[a] = if incremental {
                        self.st.epos[a] + v * u
                    } else {
                        v * u + self.off[a]
                    };
                }
            }
        }
        let at = self.insert_point(li);
        let t0 = self.st.arena.len();
        let both = rec.xy_both && self.xy_moves(rec, target);
        for a in 0..NAXES {
            if seen[a] || (a >= 3 && (rec.named | also) & (1 << a) == 0) {
                continue;
            }
            let u = Self::unit(rec, a);
            let delta = (target[a] - self.st.epos[a]) / u;
            if delta.abs() >= half || (both && a < 2) {
                let sep = self.sep();
                self.st.arena.extend_from_slice(sep);
                self.st.arena.push(AXES[a]);
                let want = if rec.incremental {
                    delta
                } else {
                    (target[a] - self.off[a]) / u
                };
                let v = self.fmt.number(want, rec.inch, &mut self.st.arena);
                self.st.epos[a] = if rec.incremental {
                    self.st.epos[a] + v * u
                } else {
                    v * u + self.off[a]
                };
            }
        }
        if self.st.arena.len() > t0 {
            // a block that had no words gets no separator first
            let skip = (self.st.arena[t0] == b' ' && self.lx.line_words(li).is_empty()) as usize;
            self.st.edits.push(Edit {
                start: at,
                end: at,
                t0: (t0 + skip) as u32,
                t1: self.st.arena.len() as u32,
            });
        }
    }

    /// A G92 or G10 L20 line: the offsets it sets are the position of the tool less its words, and
    /// the corrected program has the tool elsewhere; its words are rewritten so that it sets the
    /// offsets of `frame`, those the program's later numbers are read in.
    fn position_offset(&mut self, li: usize, frame: u32, inch: bool) -> Result<(), NcError> {
        let off = self.it.frames[frame as usize];
        let half = self.fmt.half(inch);
        for w in self.lx.line_words(li) {
            let Some(a) = axis_index(w.letter) else {
                continue;
            };
            let u = axis_unit(a, if inch { MM_PER_INCH } else { 1.0 });
            if !off[a].is_finite() {
                continue;
            }
            let want = (self.st.epos[a] - off[a]) / u;
            if !want.is_finite() {
                return Err(NcError::Interpret {
                    line: li + 1,
                    col: (w.start - self.lx.lines[li].start) as usize + 1,
                    message: format!(
                        "the offset this sets depends on where the tool is, and the corrected program's {} is not known here",
                        AXES[a] as char
                    ),
                });
            }
            if (want - w.value).abs() >= half {
                self.edit_number(w.num_start, w.end, want, inch);
            }
        }
        Ok(())
    }

    /// Shift an absolute (G90.1) arc centre by the block's uniform displacement.
    fn shift_centre(&mut self, li: usize, rec: &Record, d: [f64; 3]) {
        let [a1, a2, _] = PLANE_AXES[rec.plane as usize];
        let letter = |a: usize| [b'I', b'J', b'K'][a];
        let half = self.fmt.half(rec.inch);
        for (ci, a) in [(0usize, a1), (1usize, a2)] {
            let u = if rec.inch { MM_PER_INCH } else { 1.0 };
            let want = (rec.center[ci] + d[a] - self.off[a]) / u;
            let lx = self.lx;
            if let Some(w) = lx.line_words(li).iter().find(|w| w.letter == letter(a)) {
                if (want - w.value).abs() >= half {
                    self.edit_number(w.num_start, w.end, want, rec.inch);
                }
            } else if want.abs() >= half {
                let at = self.insert_point(li);
                let t0 = self.st.arena.len() as u32;
                let sep = self.sep();
                self.st.arena.extend_from_slice(sep);
                self.st.arena.push(letter(a));
                self.fmt.number(want, rec.inch, &mut self.st.arena);
                self.st.edits.push(Edit {
                    start: at,
                    end: at,
                    t0,
                    t1: self.st.arena.len() as u32,
                });
            }
        }
    }
}

/// Whether LinuxCNC, given the corrected numbers, would reach the first hole of a G98 block at
/// another height than the program makes it: at the tool's height rather than at the retract
/// level above the R plane, or the other way round. (It decides by comparing the tool's height
/// with the R plane, which a correction may put the other way round when they were equal; in
/// G99, or when the retract level is the R plane, both ways travel at the R plane.)
fn approach_changes(cy: &crate::interp::Cycle, choices: (bool, bool), level: f64, r: f64) -> bool {
    cy.g98 && choices.1 != cy.choices.1 && !choices.0 && level > r
}

/// A word a spline block written in pieces keeps as it is: its own spline code and the modal
/// codes that read no P, Q or R (plane, distance, feed mode, units; spindle, coolant, stops).
fn spline_piece_keeps(w: &Word) -> bool {
    match w.letter {
        b'G' => matches!(
            round(w.value * 10.0) as i32,
            50 | 51 | 170 | 200 | 210 | 900 | 910 | 930 | 940 | 950
        ),
        b'M' => matches!(round(w.value) as i32, 0..=5 | 7..=9 | 30 | 48 | 49 | 60),
        _ => true,
    }
}

/// `p`'s X and Y turned back by rotation `r`: the programmed point there.
fn to_prog(r: &Rotation, p: &mut [f64; NAXES]) {
    let q = r.to_prog([p[0], p[1]]);
    (p[0], p[1]) = (q[0], q[1]);
}

/// `p`'s X and Y, programmed, where rotation `r` puts them.
fn from_prog(r: &Rotation, p: &mut [f64; NAXES]) {
    let q = r.to_frame([p[0], p[1]]);
    (p[0], p[1]) = (q[0], q[1]);
}

/// Squared distance from p to the segment a-b (XYZ).
#[inline]
fn dist2_to_segment(p: &[f64; 3], a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
    let l2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
    let t = if l2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// Squared distance from p to the point at fraction t of the segment a-b (XYZ).
#[inline]
fn dist2_at_fraction(p: &[f64; 3], a: &[f64; 3], b: &[f64; 3], t: f64) -> f64 {
    (0..3)
        .map(|k| (p[k] - (a[k] + t * (b[k] - a[k]))).powi(2))
        .sum::<f64>()
}

/// Where a block's words begin: after `/`, leading blanks and a leading N word.
fn block_start(lx: &Lexed, li: usize) -> u32 {
    let line = &lx.lines[li];
    let words = lx.line_words(li);
    match (words.first(), words.get(1)) {
        (Some(n), Some(next)) if n.letter == b'N' => next.start,
        (Some(n), None) if n.letter == b'N' => n.end,
        (Some(w), _) => w.start,
        (None, _) => line.start + line.block_delete as u32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interp::interpret;
    use crate::lex::lex;
    use crate::sample::{sample, SampleOpts};

    fn correct(src: &str, f: impl Fn(f64, f64, f64) -> [f64; 3], max_segment: f64) -> String {
        let l = lex(src.as_bytes()).unwrap();
        let it = interpret(&l).unwrap();
        let o = SampleOpts {
            chord_tol: 0.002,
            max_segment,
            include_rapids: false,
            only_supported: true,
            grid_x: vec![],
            grid_y: vec![],
            grid: None,
        };
        let s = sample(&it, &o).unwrap();
        let mut d = Vec::new();
        for p in s.xyz.chunks_exact(3) {
            d.extend_from_slice(&f(p[0], p[1], p[2]));
        }
        let (out, _) = Emitter::new(src.as_bytes(), &l, &it).run(&s, &d).unwrap();
        String::from_utf8(out).unwrap()
    }

    /// The formatting before `number_dec`, digit by digit, as a reference.
    fn reference_number(f: &Format, v: f64, inch: bool, out: &mut Vec<u8>) -> f64 {
        let this = f;
        const POW10: [u64; 10] = [
            1,
            10,
            100,
            1_000,
            10_000,
            100_000,
            1_000_000,
            10_000_000,
            100_000_000,
            1_000_000_000,
        ];
        let dec = this.decimals(inch).min(9);
        let scale = POW10[dec];
        let scaled = v * scale as f64;
        if scaled.is_nan() || scaled.abs() >= 9.0e15 {
            // beyond any machine's travel; keep the text exact all the same
            let t = format!("{:.*}", dec, v);
            out.extend_from_slice(t.as_bytes());
            return t.parse().unwrap_or(v);
        }
        // round half away from zero with one conversion (f64::round is a library call)
        let m = if scaled >= 0.0 {
            (scaled + 0.5) as i64
        } else {
            (scaled - 0.5) as i64
        };
        // the digits of |m| are written from the right into a buffer, two at a time, then copied
        // once: the last `dec` are the fraction
        let mut a = m.unsigned_abs();
        let mut buf = [0u8; 48];
        let end = buf.len();
        let mut i = end;
        let mut k = 0;
        while k + 2 <= dec {
            let d = (a % 100) as usize;
            a /= 100;
            i -= 2;
            buf[i..i + 2].copy_from_slice(&DIGIT_PAIRS[2 * d..2 * d + 2]);
            k += 2;
        }
        if k < dec {
            i -= 1;
            buf[i] = b'0' + (a % 10) as u8;
            a /= 10;
        }
        // the fraction without its trailing zeros, unless the program writes them
        let mut stop = end;
        if !this.style.fixed {
            while stop > i && buf[stop - 1] == b'0' {
                stop -= 1;
            }
        }
        let digits = stop - i;
        let frac_at = i;
        // the point (and "0" after it for a whole number, unless the program writes "5.")
        let mut head = [0u8; 24];
        let mut h = head.len();
        h -= 1;
        head[h] = b'.';
        if !(this.style.no_leading_zero && a == 0 && digits > 0) {
            loop {
                if a >= 10 {
                    let d = (a % 100) as usize;
                    a /= 100;
                    h -= 2;
                    head[h..h + 2].copy_from_slice(&DIGIT_PAIRS[2 * d..2 * d + 2]);
                    if a == 0 {
                        break;
                    }
                } else {
                    h -= 1;
                    head[h] = b'0' + a as u8;
                    break;
                }
            }
        }
        if m < 0 {
            h -= 1;
            head[h] = b'-';
        }
        out.extend_from_slice(&head[h..]);
        if digits > 0 {
            out.extend_from_slice(&buf[frac_at..stop]);
        } else if !this.style.bare_point {
            out.push(b'0');
        }
        m as f64 / scale as f64
    }

    #[test]
    fn numbers_are_the_rounded_values_in_every_style() {
        // against the standard library's formatting of the rounded value, trimmed by the style
        let mut seed = 0x2545F4914F6CDD1Du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for ((fixed, nlz, bare), max_decimals) in [
            (true, false, false),
            (false, false, false),
            (false, true, false),
            (false, false, true),
            (false, true, true),
        ]
        .into_iter()
        .flat_map(|s| [(s, 0u8), (s, 6), (s, 7), (s, 8)])
        {
            let style = NumberStyle {
                fixed,
                no_leading_zero: nlz,
                bare_point: bare,
                max_decimals,
                ..NumberStyle::default()
            };
            let f = Format::new(style);
            for k in 0..20000 {
                let mag = 10f64.powi((next() % 9) as i32 - 4);
                let v = ((next() >> 11) as f64 / (1u64 << 53) as f64 - 0.5)
                    * 2.0
                    * mag
                    * if k % 7 == 0 { 1e4 } else { 1.0 };
                for inch in [false, true] {
                    let dec = f.decimals(inch);
                    let mut out = Vec::new();
                    let got = f.number(v, inch, &mut out);
                    let scaled = v * 10f64.powi(dec as i32);
                    let m = if scaled >= 0.0 {
                        (scaled + 0.5).floor()
                    } else {
                        (scaled - 0.5).ceil()
                    };
                    let mut want = format!("{:.*}", dec, (m / 10f64.powi(dec as i32)).abs());
                    if !fixed {
                        want = want.trim_end_matches('0').to_string();
                        if want.ends_with('.') && !bare {
                            want.push('0');
                        }
                    }
                    if nlz && want.starts_with("0.") && want.len() > 2 && want != "0.0" {
                        want.remove(0);
                    }
                    if m < 0.0 {
                        want.insert(0, '-');
                    }
                    let mut reference = Vec::new();
                    let got_ref = reference_number(&f, v, inch, &mut reference);
                    assert_eq!(
                        String::from_utf8(out.clone()).unwrap(),
                        String::from_utf8(reference).unwrap(),
                        "{v} inch={inch} style={style:?}"
                    );
                    assert_eq!(got.to_bits(), got_ref.to_bits());
                    if max_decimals == 0 {
                        assert_eq!(
                            String::from_utf8(out).unwrap(),
                            want,
                            "{v} inch={inch} style={style:?}"
                        );
                        assert_eq!(got, m / 10f64.powi(dec as i32));
                    }
                }
            }
        }
    }

    #[test]
    fn number_styles() {
        let mut st = NumberStyle::default();
        let cases = |st: NumberStyle, v: f64| {
            let f = Format::new(st);
            let mut out = Vec::new();
            let val = f.number(v, false, &mut out);
            (String::from_utf8(out).unwrap(), val)
        };
        assert_eq!(cases(st, 1.23456), ("1.2346".into(), 1.2346));
        assert_eq!(cases(st, -0.00004), ("0.0".into(), 0.0));
        assert_eq!(cases(st, 10.0), ("10.0".into(), 10.0));
        assert_eq!(cases(st, -0.0012), ("-0.0012".into(), -0.0012));
        st.fixed = true;
        assert_eq!(cases(st, 10.0), ("10.0000".into(), 10.0));
        assert_eq!(cases(st, -0.05), ("-0.0500".into(), -0.05));
        st.fixed = false;
        st.no_leading_zero = true;
        st.bare_point = true;
        assert_eq!(cases(st, -0.5), ("-.5".into(), -0.5));
        assert_eq!(cases(st, 3.0), ("3.".into(), 3.0));
        assert_eq!(cases(st, 0.0), ("0.".into(), 0.0));
        st.max_decimals = 6;
        assert_eq!(cases(st, 0.1234567), (".123457".into(), 0.123457));
    }

    #[test]
    fn zero_field_identity() {
        let src = "%\r\nO1000 (part)\r\nN10 G21 G90 G0 X0 Y0 Z5\r\nN20 G1 Z-1. F100 ; plunge\r\nN30 G2 X10 Y0 I5 J0\r\nG3 X0 Y0 R5\r\n/ G1 X-.5\r\nM30\r\n%\r\n";
        assert_eq!(correct(src, |_, _, _| [0.0; 3], 1.0), src);
    }

    #[test]
    fn shift_keeps_arcs_and_style() {
        let src = "G21 G90 G0 X0 Y0 Z5\nG1 Z-1.000 F100 (cut)\nG2 X10.000 Y0.000 I5.000 J0.000\n";
        let out = correct(src, |_, _, _| [0.0, 0.0, 0.1], 1.0);
        assert_eq!(
            out,
            "G21 G90 G0 X0 Y0 Z5\nG1 Z-0.9000 F100 (cut)\nG2 X10.000 Y0.000 I5.000 J0.000\n"
        );
    }

    #[test]
    fn chunks_give_the_whole_output() {
        let src = "G21 G90 G0 X0 Y0 Z5\nG1 Z-1 F100\nG2 X10 Y0 I5 J0\nG91 G1 X2\nX2 Y3\n(c)\nG3 X-4 Y0 I-2 J0 M30\n";
        let l = lex(src.as_bytes()).unwrap();
        let it = interpret(&l).unwrap();
        let o = SampleOpts {
            chord_tol: 0.002,
            max_segment: 0.7,
            include_rapids: false,
            only_supported: true,
            grid_x: vec![],
            grid_y: vec![],
            grid: None,
        };
        let field = |s: &Samples| {
            s.xyz
                .chunks_exact(3)
                .flat_map(|p| [0.01 * p[1], 0.0, 0.02 * p[0]])
                .collect::<Vec<f64>>()
        };
        let s = sample(&it, &o).unwrap();
        let (whole, stats) = Emitter::new(src.as_bytes(), &l, &it)
            .run(&s, &field(&s))
            .unwrap();
        let prog = crate::Program::parse(src.as_bytes().to_vec()).unwrap();
        for step in 1..4 {
            let mut em = Emitter::new(src.as_bytes(), &l, &it);
            let (mut out, mut part) = (Vec::new(), Samples::default());
            for a in (0..l.lines.len()).step_by(step) {
                let b = (a + step).min(l.lines.len());
                crate::sample::sample_range(&it, &o, prog.records_of_lines(a..b), &mut part)
                    .unwrap();
                em.lines(a..b, &part, &field(&part), &mut out).unwrap();
            }
            assert_eq!(
                String::from_utf8(out).unwrap(),
                String::from_utf8(whole.clone()).unwrap(),
                "chunks of {step} lines"
            );
            assert_eq!(em.stats(), &stats);
        }
    }

    #[test]
    fn incremental_stays_incremental() {
        let src = "G21 G90 G0 X0 Y0 Z0\nG91 G1 X2 F100\nX2\n";
        let out = correct(src, |x, _, _| [0.0, 0.0, 0.01 * x], 100.0);
        assert_eq!(out, "G21 G90 G0 X0 Y0 Z0\nG91 G1 X2 Z0.02 F100\nX2 Z0.02\n");
    }
}
