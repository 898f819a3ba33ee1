//! Emitter: writes the corrected program, copying every unchanged block byte for byte.
//!
//! The emitter follows the position the machine will really have when it runs the output
//! (`epos`, from the numbers as written), so incremental programs stay exact and rounding never
//! accumulates. A changed block keeps its other words, their order and its comments; only the
//! numbers that change are rewritten, in the program's own number style.

use crate::error::NcError;
use crate::interp::{Interp, Motion, Record, AXES, MM_PER_INCH, NAXES, PLANE_AXES};
use crate::lex::{Lexed, NumberStyle, Word};
use crate::sample::{start_of, Samples};

/// Corrected pieces this close to a straight line (mm) are written as one move. Far below any
/// written digit, so merging never moves the path by a visible amount.
pub const MERGE_TOL_MM: f64 = 1e-6;

/// Counts for the summary.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EmitStats {
    pub lines_in: u64,
    pub lines_out: u64,
    pub blocks_changed: u64,
    pub lines_added: u64,
    pub arcs_linearised: u64,
}

/// Number formatting in a program's style.
#[derive(Clone, Copy, Debug)]
pub struct Format {
    pub style: NumberStyle,
    pub dec_mm: usize,
    pub dec_inch: usize,
}

impl Format {
    pub fn new(style: NumberStyle) -> Self {
        let d = style.max_decimals as usize;
        Format { style, dec_mm: d.max(4), dec_inch: d.max(5) }
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
        0.5 * 10f64.powi(-(self.decimals(inch) as i32))
    }

    /// Write `v` in the program's style and return the value the written text stands for.
    pub fn number(&self, v: f64, inch: bool, out: &mut Vec<u8>) -> f64 {
        const POW10: [u64; 10] = [1, 10, 100, 1_000, 10_000, 100_000, 1_000_000, 10_000_000, 100_000_000, 1_000_000_000];
        let dec = self.decimals(inch).min(9);
        let scale = POW10[dec];
        let scaled = v * scale as f64;
        if scaled.is_nan() || scaled.abs() >= 9.0e15 {
            // beyond any machine's travel; keep the text exact all the same
            let t = format!("{:.*}", dec, v);
            out.extend_from_slice(t.as_bytes());
            return t.parse().unwrap_or(v);
        }
        let m = scaled.round() as i64;
        let a = m.unsigned_abs();
        let (int, mut frac) = (a / scale, a % scale);
        if m < 0 {
            out.push(b'-');
        }
        let mut digits = dec;
        if !self.style.fixed {
            while digits > 0 && frac % 10 == 0 {
                frac /= 10;
                digits -= 1;
            }
        }
        if !(self.style.no_leading_zero && int == 0 && digits > 0) {
            write_uint(out, int);
        }
        out.push(b'.');
        if digits == 0 {
            if !self.style.bare_point {
                out.push(b'0');
            }
        } else {
            let start = out.len();
            write_uint(out, frac);
            let written = out.len() - start;
            if written < digits {
                // zero padding after the point: 0.0012 has frac 12 with 4 digits
                out.splice(start..start, std::iter::repeat_n(b'0', digits - written));
            }
        }
        m as f64 / scale as f64
    }
}

#[inline]
fn write_uint(out: &mut Vec<u8>, mut v: u64) {
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    out.extend_from_slice(&buf[i..]);
}

/// One edit of a line: replace bytes [start, end) by `text`.
struct Edit {
    start: u32,
    end: u32,
    text: Vec<u8>,
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
        (Motion::Other, _) => "",
    }
}

#[inline]
fn is_motion_g(w: &Word) -> bool {
    w.letter == b'G' && {
        let c = (w.value * 10.0).round() as i32;
        matches!(c, 0 | 10 | 20 | 30 | 800 | 730 | 740 | 760 | 810..=890 | 330 | 331 | 382..=385 | 50 | 51 | 52)
    }
}

#[inline]
fn is_stop_m(w: &Word) -> bool {
    w.letter == b'M' && matches!(w.value.round() as i32, 0 | 1 | 2 | 30 | 60)
}

fn axis_index(letter: u8) -> Option<usize> {
    AXES.iter().position(|&a| a == letter)
}

/// Emits a corrected program.
pub struct Emitter<'a> {
    src: &'a [u8],
    lx: &'a Lexed,
    it: &'a Interp,
    fmt: Format,
    eol: &'static [u8],
    epos: [f64; NAXES],
    /// Motion mode the output has in force where it differs from the program's.
    out_motion: Option<Motion>,
    pub stats: EmitStats,
    out: Vec<u8>,
    edits: Vec<Edit>,
    tail: Vec<Vec<u8>>,
}

impl<'a> Emitter<'a> {
    pub fn new(src: &'a [u8], lx: &'a Lexed, it: &'a Interp) -> Self {
        Emitter {
            src,
            lx,
            it,
            fmt: Format::new(lx.style),
            eol: if lx.crlf { b"\r\n" } else { b"\n" },
            epos: it.origin,
            out_motion: None,
            stats: EmitStats::default(),
            out: Vec::with_capacity(src.len() + src.len() / 8),
            edits: Vec::new(),
            tail: Vec::new(),
        }
    }

    /// Write the program with `disp` (n * 3 mm, one per sample) applied to the sampled blocks.
    pub fn run(mut self, samples: &Samples, disp: &[f64]) -> Result<(Vec<u8>, EmitStats), NcError> {
        if disp.len() != samples.xyz.len() {
            return Err(NcError::Usage(format!(
                "displacements have {} values, expected {} (3 per sample)",
                disp.len(),
                samples.xyz.len()
            )));
        }
        let nlines = self.lx.lines.len();
        self.stats.lines_in = nlines as u64;
        for li in 0..nlines {
            let line = &self.lx.lines[li];
            let ri = self.it.line_record[li];
            self.edits.clear();
            self.tail.clear();
            let words = self.lx.line_words(li);
            let explicit_motion = words.iter().any(is_motion_g);
            if ri != u32::MAX {
                let ri = ri as usize;
                let (first, count) = samples.range[ri];
                if count > 0 {
                    let f = first as usize;
                    let c = count as usize;
                    self.corrected(li, ri, &samples.xyz[3 * f..3 * (f + c)], &samples.t[f..f + c], &disp[3 * f..3 * (f + c)]);
                } else {
                    self.uncorrected(li, ri);
                }
            } else if explicit_motion {
                self.out_motion = None;
            }
            // copy the line with its edits, then any added lines
            let (ls, le, lee) = (line.start as usize, line.end as usize, line.eol_end as usize);
            if self.edits.is_empty() {
                self.out.extend_from_slice(&self.src[ls..lee]);
            } else {
                self.stats.blocks_changed += 1;
                self.edits.sort_by_key(|e| (e.start, e.end));
                let mut at = ls;
                for e in &self.edits {
                    let (s, t) = (e.start as usize, e.end as usize);
                    if s >= at {
                        self.out.extend_from_slice(&self.src[at..s]);
                        at = t;
                    }
                    self.out.extend_from_slice(&e.text);
                }
                self.out.extend_from_slice(&self.src[at..le]);
                if self.tail.is_empty() {
                    self.out.extend_from_slice(&self.src[le..lee]);
                }
            }
            if !self.tail.is_empty() {
                let own_eol: &[u8] = if lee > le { &self.src[le..lee] } else { self.eol };
                if self.edits.is_empty() {
                    // the line was copied with its ending; nothing to add between
                    if lee == le {
                        self.out.extend_from_slice(own_eol);
                    }
                } else {
                    self.out.extend_from_slice(own_eol);
                }
                let n = self.tail.len();
                for (k, t) in std::mem::take(&mut self.tail).into_iter().enumerate() {
                    self.out.extend_from_slice(&t);
                    if k + 1 < n || lee > le {
                        self.out.extend_from_slice(own_eol);
                    }
                }
                self.stats.lines_added += n as u64;
            }
        }
        self.stats.lines_out = self.stats.lines_in + self.stats.lines_added;
        Ok((self.out, self.stats))
    }

    fn unit(rec: &Record, k: usize) -> f64 {
        if rec.inch && !(3..6).contains(&k) {
            MM_PER_INCH
        } else {
            1.0
        }
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

    /// Insert the program's own motion word when the output's modal motion differs from it.
    fn restore_modal(&mut self, li: usize, rec: &Record, explicit: bool) {
        if explicit {
            self.out_motion = None;
            return;
        }
        if let Some(m) = self.out_motion {
            if m != rec.motion && rec.motion != Motion::Other {
                let mut text = motion_text(rec.motion, self.lx.style.padded_g).as_bytes().to_vec();
                text.extend_from_slice(if self.lx.style.spaced { b" " } else { b"" });
                let at = block_start(self.lx, li);
                self.edits.push(Edit { start: at, end: at, text });
            }
            self.out_motion = None;
        }
    }

    /// A block that is not corrected: kept, except that in G91 a supported move is re-aimed at
    /// its programmed target (the output position before it may differ from the program's).
    fn uncorrected(&mut self, li: usize, ri: usize) {
        let (it, lx) = (self.it, self.lx);
        let rec = &it.records[ri];
        let start = start_of(it, ri);
        let words = lx.line_words(li);
        let explicit = words.iter().any(is_motion_g);
        if rec.motion != Motion::Other {
            self.restore_modal(li, rec, explicit);
        } else if explicit {
            self.out_motion = None;
        }
        let rewrite = rec.supported && rec.incremental && rec.motion != Motion::Other;
        let mut written = [None; NAXES];
        if rewrite {
            for w in words {
                if let Some(k) = axis_index(w.letter) {
                    let u = Self::unit(rec, k);
                    let want = (rec.end[k] - self.epos[k]) / u;
                    if want.is_finite() && (want - w.value).abs() >= self.fmt.half(rec.inch) {
                        let mut text = Vec::new();
                        let v = self.fmt.number(want, rec.inch, &mut text);
                        self.edits.push(Edit { start: w.num_start, end: w.end, text });
                        written[k] = Some(v * u);
                    }
                }
            }
        }
        for k in 0..NAXES {
            let named = rec.named & (1 << k) != 0;
            self.epos[k] = match written[k] {
                Some(d) => self.epos[k] + d,
                None if named && !rec.incremental => rec.end[k],
                None => self.epos[k] + (rec.end[k] - start[k]),
            };
        }
    }

    /// Write a sampled block with its displacements.
    fn corrected(&mut self, li: usize, ri: usize, xyz: &[f64], ts: &[f64], disp: &[f64]) {
        let (it, lx) = (self.it, self.lx);
        let rec = &it.records[ri];
        let start = start_of(it, ri);
        let n = ts.len();
        let words = lx.line_words(li);
        let epos0 = self.epos;
        let explicit = words.iter().any(is_motion_g);
        let d0 = [disp[0], disp[1], disp[2]];
        let uniform = disp.chunks_exact(3).all(|d| (0..3).all(|k| (d[k] - d0[k]).abs() <= 1e-9));
        let half_mm = self.fmt.half(rec.inch) * if rec.inch { MM_PER_INCH } else { 1.0 };
        let target_at = |k: usize, t: f64| -> [f64; NAXES] {
            let mut p = [0.0; NAXES];
            for a in 0..NAXES {
                p[a] = if a < 3 {
                    xyz[3 * k + a] + disp[3 * k + a]
                } else if rec.named & (1 << a) != 0 {
                    if t == 1.0 { rec.end[a] } else { start[a] + t * (rec.end[a] - start[a]) }
                } else {
                    epos0[a]
                };
            }
            p
        };
        // the output starts this block where the corrected path expects it
        let on_path = (0..3).all(|a| (self.epos[a] - (start[a] + d0[a])).abs() < half_mm);
        let keep_arc = rec.motion.is_arc() && uniform && on_path;
        // a straight move whose corrected pieces all lie on one line is written as one move
        let only_xyz = rec.named & !0b111 == 0;
        let straight = !rec.motion.is_arc()
            && only_xyz
            && (n == 1 || {
                let e = target_at(n - 1, 1.0);
                (0..n - 1).all(|k| {
                    let p = target_at(k, ts[k]);
                    dist_to_segment(&p, &self.epos, &e) <= MERGE_TOL_MM
                })
            });
        if straight || keep_arc {
            self.restore_modal(li, rec, explicit);
            let target = target_at(n - 1, 1.0);
            self.set_axes(li, rec, &target);
            if keep_arc && rec.arc_absolute {
                self.shift_centre(li, rec, d0);
            }
            return;
        }
        // split or linearised: the original line carries the first piece
        let linearise = rec.motion.is_arc();
        if linearise {
            self.stats.arcs_linearised += 1;
            let g1 = motion_text(Motion::Feed, self.lx.style.padded_g).as_bytes().to_vec();
            if let Some(w) = words.iter().find(|w| is_motion_g(w)) {
                self.edits.push(Edit { start: w.start, end: w.end, text: g1 });
            } else {
                let mut text = g1;
                text.extend_from_slice(self.sep());
                let at = block_start(self.lx, li);
                self.edits.push(Edit { start: at, end: at, text });
            }
            for w in words.iter().filter(|w| matches!(w.letter, b'I' | b'J' | b'K' | b'R' | b'P')) {
                self.remove_word(li, w);
            }
            self.out_motion = Some(Motion::Feed);
        } else {
            self.restore_modal(li, rec, explicit);
        }
        // program stops move to the last piece
        let mut stops: Vec<u8> = Vec::new();
        for w in words.iter().filter(|w| is_stop_m(w)) {
            stops.extend_from_slice(self.sep());
            stops.extend_from_slice(&self.src[w.start as usize..w.end as usize]);
            self.remove_word(li, w);
        }
        let first = target_at(0, ts[0]);
        self.set_axes(li, rec, &first);
        let prefix: &[u8] = if self.lx.lines[li].block_delete { b"/" } else { b"" };
        // a uniform straight move that starts off the corrected path needs one piece to reach it
        let pieces: Vec<usize> = if !linearise && uniform && only_xyz { vec![n - 1] } else { (1..n).collect() };
        for &k in &pieces {
            let p = target_at(k, ts[k]);
            let mut text = prefix.to_vec();
            for a in 0..NAXES {
                if a >= 3 && rec.named & (1 << a) == 0 {
                    continue;
                }
                let u = Self::unit(rec, a);
                let want = if rec.incremental { (p[a] - self.epos[a]) / u } else { p[a] / u };
                let differs = if rec.incremental { want.abs() >= self.fmt.half(rec.inch) } else { (p[a] - self.epos[a]).abs() / u >= self.fmt.half(rec.inch) };
                if differs {
                    if text.len() > prefix.len() {
                        text.extend_from_slice(self.sep());
                    }
                    text.push(AXES[a]);
                    let v = self.fmt.number(want, rec.inch, &mut text);
                    self.epos[a] = if rec.incremental { self.epos[a] + v * u } else { v * u };
                }
            }
            if k + 1 == n && !stops.is_empty() {
                if text.len() == prefix.len() {
                    text.extend_from_slice(&stops[self.sep().len()..]);
                } else {
                    text.extend_from_slice(&stops);
                }
            }
            if text.len() > prefix.len() {
                self.tail.push(text);
            }
        }
    }

    /// Remove a word and the blanks before it.
    fn remove_word(&mut self, li: usize, w: &Word) {
        let line_start = self.lx.lines[li].start;
        let mut s = w.start;
        while s > line_start && matches!(self.src[s as usize - 1], b' ' | b'\t') {
            s -= 1;
        }
        self.edits.push(Edit { start: s, end: w.end, text: Vec::new() });
    }

    /// Aim the block's axis words at `target` (mm), rewriting only what changes and adding the
    /// axis words it lacks.
    fn set_axes(&mut self, li: usize, rec: &Record, target: &[f64; NAXES]) {
        let lx = self.lx;
        let words = lx.line_words(li);
        let half = self.fmt.half(rec.inch);
        let mut seen = [false; NAXES];
        for w in words {
            if let Some(a) = axis_index(w.letter) {
                seen[a] = true;
                let u = Self::unit(rec, a);
                let want = if rec.incremental { (target[a] - self.epos[a]) / u } else { target[a] / u };
                if (want - w.value).abs() < half {
                    self.epos[a] = if rec.incremental { self.epos[a] + w.value * u } else { w.value * u };
                } else {
                    let mut text = Vec::new();
                    let v = self.fmt.number(want, rec.inch, &mut text);
                    self.edits.push(Edit { start: w.num_start, end: w.end, text });
                    self.epos[a] = if rec.incremental { self.epos[a] + v * u } else { v * u };
                }
            }
        }
        let at = self.insert_point(li);
        let mut text = Vec::new();
        for a in 0..NAXES {
            if seen[a] || (a >= 3 && rec.named & (1 << a) == 0) {
                continue;
            }
            let u = Self::unit(rec, a);
            let delta = (target[a] - self.epos[a]) / u;
            if delta.abs() >= half {
                text.extend_from_slice(self.sep());
                text.push(AXES[a]);
                let want = if rec.incremental { delta } else { target[a] / u };
                let v = self.fmt.number(want, rec.inch, &mut text);
                self.epos[a] = if rec.incremental { self.epos[a] + v * u } else { v * u };
            }
        }
        if !text.is_empty() {
            if !self.lx.style.spaced || self.lx.line_words(li).is_empty() {
                // compact programs get no separator; a block that had no words gets none first
                if text.first() == Some(&b' ') && self.lx.line_words(li).is_empty() {
                    text.remove(0);
                }
            }
            self.edits.push(Edit { start: at, end: at, text });
        }
    }

    /// Shift an absolute (G90.1) arc centre by the block's uniform displacement.
    fn shift_centre(&mut self, li: usize, rec: &Record, d: [f64; 3]) {
        let [a1, a2, _] = PLANE_AXES[rec.plane as usize];
        let letter = |a: usize| [b'I', b'J', b'K'][a];
        let half = self.fmt.half(rec.inch);
        for (ci, a) in [(0usize, a1), (1usize, a2)] {
            let u = if rec.inch { MM_PER_INCH } else { 1.0 };
            let want = (rec.center[ci] + d[a]) / u;
            let lx = self.lx;
            if let Some(w) = lx.line_words(li).iter().find(|w| w.letter == letter(a)) {
                if (want - w.value).abs() >= half {
                    let mut text = Vec::new();
                    self.fmt.number(want, rec.inch, &mut text);
                    self.edits.push(Edit { start: w.num_start, end: w.end, text });
                }
            } else if want.abs() >= half {
                let at = self.insert_point(li);
                let mut text = self.sep().to_vec();
                text.push(letter(a));
                self.fmt.number(want, rec.inch, &mut text);
                self.edits.push(Edit { start: at, end: at, text });
            }
        }
    }
}

/// Distance from p to the segment a-b (XYZ).
fn dist_to_segment(p: &[f64; NAXES], a: &[f64; NAXES], b: &[f64; NAXES]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
    let l2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
    let t = if l2 > 0.0 { ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / l2).clamp(0.0, 1.0) } else { 0.0 };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
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
        let o = SampleOpts { chord_tol: 0.002, max_segment, include_rapids: false, only_supported: true, grid_x: vec![], grid_y: vec![] };
        let s = sample(&it, &o);
        let mut d = Vec::new();
        for p in s.xyz.chunks_exact(3) {
            d.extend_from_slice(&f(p[0], p[1], p[2]));
        }
        let (out, _) = Emitter::new(src.as_bytes(), &l, &it).run(&s, &d).unwrap();
        String::from_utf8(out).unwrap()
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
        assert_eq!(out, "G21 G90 G0 X0 Y0 Z5\nG1 Z-0.9000 F100 (cut)\nG2 X10.000 Y0.000 I5.000 J0.000\n");
    }

    #[test]
    fn incremental_stays_incremental() {
        let src = "G21 G90 G0 X0 Y0 Z0\nG91 G1 X2 F100\nX2\n";
        let out = correct(src, |x, _, _| [0.0, 0.0, 0.01 * x], 100.0);
        assert_eq!(out, "G21 G90 G0 X0 Y0 Z0\nG91 G1 X2 Z0.02 F100\nX2 Z0.02\n");
    }
}
