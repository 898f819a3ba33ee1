//! Exact-text lexer: splits a program into lines and words without losing a byte.
//!
//! Every line keeps its byte range in the source (content and line ending separately), every word
//! keeps the byte range of its letter and of its number, so an emitter can copy a block byte for
//! byte or replace exactly one number in it.

use crate::error::NcError;

/// A letter word such as `X-.5`, `G1.` or `N010`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Word {
    /// Upper-case letter.
    pub letter: u8,
    /// Digits after the decimal point (-1 when the number has no point).
    pub decimals: i8,
    /// Byte offset of the letter in the source.
    pub start: u32,
    /// Byte offset of the first byte of the number (sign included).
    pub num_start: u32,
    /// Byte offset one past the last byte of the number.
    pub end: u32,
    /// The number's value as written.
    pub value: f64,
}

/// Something in a line that the interpreter cannot follow and the emitter must keep as it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Opaque {
    /// `#` parameters or `[ ]` expressions.
    Expression,
    /// `O` words with a keyword (`sub`, `call`, `if`, `while`, ...) or a named `o<...>`.
    OWordFlow,
    /// A grbl system command that moves the machine: homing `$H`, a jog `$J=...`.
    GrblMove,
    /// A grbl system command that changes the machine's settings: `$100=250`, `$RST=#`, `$N0=...`.
    GrblSetting,
    /// Any other grbl system command (`$X`, `$$`, `$#`, `$G`, `$C`, `$SLP`, ...): it moves nothing.
    GrblOther,
}

/// The kind of the grbl system command `rest` (the line after its `$`).
fn grbl_kind(rest: &[u8]) -> Opaque {
    let up = rest.to_ascii_uppercase();
    if up.starts_with(b"H") || up.starts_with(b"J=") {
        Opaque::GrblMove
    } else if up.contains(&b'=') {
        Opaque::GrblSetting
    } else {
        Opaque::GrblOther
    }
}

/// One line of the source.
#[derive(Clone, Debug, Default)]
pub struct Line {
    /// Byte offset of the first byte of the line.
    pub start: u32,
    /// Byte offset one past the content (the line ending excluded).
    pub end: u32,
    /// Byte offset one past the line ending (equal to `end` on a last line without one).
    pub eol_end: u32,
    /// Index of the first word of the line in [`Lexed::words`].
    pub first_word: u32,
    /// Number of words.
    pub n_words: u32,
    /// Starts with `/` (block delete).
    pub block_delete: bool,
    /// A `%` line.
    pub percent: bool,
    /// Has at least one comment.
    pub comment: bool,
    /// Byte offset where the first comment starts (or `end`).
    pub comment_start: u32,
    /// The rest of the line from some point on could not be lexed into words.
    pub opaque: Option<(Opaque, u32)>,
    /// The line could not be read: index into [`Lexed::errors`]. The interpreter reports it when
    /// the program reaches the line (text after M2/M30 or a closing `%` is never read, as in
    /// LinuxCNC).
    pub error: Option<u32>,
}

/// Number style of a program, read from its axis words.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NumberStyle {
    /// Largest number of decimals written in an axis or arc word.
    pub max_decimals: u8,
    /// Some number keeps trailing zeros (`1.500`): pad to a fixed number of decimals.
    pub fixed: bool,
    /// Some number is written without a leading zero (`.5`, `-.25`).
    pub no_leading_zero: bool,
    /// Some number is written with a bare trailing point (`10.`).
    pub bare_point: bool,
    /// Words are separated by spaces.
    pub spaced: bool,
    /// Motion words are written with a leading zero (`G01`).
    pub padded_g: bool,
}

/// A lexed program.
#[derive(Clone, Debug, Default)]
pub struct Lexed {
    pub lines: Vec<Line>,
    pub words: Vec<Word>,
    pub style: NumberStyle,
    /// The most common line ending: `\r\n` when most lines end so.
    pub crlf: bool,
    /// Lines that could not be read: the error of each (see [`Line::error`]).
    pub errors: Vec<NcError>,
    /// What the style's `spaced` and `crlf` were decided from: words written after a blank,
    /// words written right after the word before, CRLF and LF line ends (to merge the style of a
    /// program read in pieces).
    pub counts: [usize; 4],
}

impl NumberStyle {
    /// The style of two pieces of one program (decimals the larger; a form used in either is used).
    pub fn merge(&mut self, o: &NumberStyle) {
        self.max_decimals = self.max_decimals.max(o.max_decimals);
        self.fixed |= o.fixed;
        self.no_leading_zero |= o.no_leading_zero;
        self.bare_point |= o.bare_point;
        self.padded_g |= o.padded_g;
    }
}

impl Lexed {
    /// The words of line `i`.
    #[inline]
    pub fn line_words(&self, i: usize) -> &[Word] {
        let l = &self.lines[i];
        &self.words[l.first_word as usize..(l.first_word + l.n_words) as usize]
    }
}

const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

const O_KEYWORDS: [&[u8]; 15] = [
    b"sub",
    b"endsub",
    b"call",
    b"do",
    b"while",
    b"endwhile",
    b"if",
    b"elseif",
    b"else",
    b"endif",
    b"repeat",
    b"endrepeat",
    b"return",
    b"break",
    b"continue",
];

/// Parse a number at `i`: optional sign, digits with at most one point, at least one digit.
/// Returns (value, decimals, end, leading_zero_missing, trailing_zero, bare_point).
#[inline]
fn number(s: &[u8], mut i: usize) -> Option<(f64, i8, usize, bool, bool, bool)> {
    let mut neg = false;
    if i < s.len() && (s[i] == b'-' || s[i] == b'+') {
        neg = s[i] == b'-';
        i += 1;
    }
    // the digits, all of them accumulated (exact while there are at most 19)
    let mut mant: u64 = 0;
    let int_start = i;
    while i < s.len() && s[i].is_ascii_digit() {
        mant = mant.wrapping_mul(10).wrapping_add((s[i] - b'0') as u64);
        i += 1;
    }
    let int_digits = i - int_start;
    let mut frac_digits = 0usize;
    let mut point = false;
    let mut last_frac = b'1';
    if i < s.len() && s[i] == b'.' {
        point = true;
        i += 1;
        let frac_start = i;
        while i < s.len() && s[i].is_ascii_digit() {
            mant = mant.wrapping_mul(10).wrapping_add((s[i] - b'0') as u64);
            i += 1;
        }
        frac_digits = i - frac_start;
        if frac_digits > 0 {
            last_frac = s[i - 1];
        }
    }
    if int_digits + frac_digits == 0 {
        return None;
    }
    // exact digits below 2^53 over an exact power of ten: one correctly rounded division
    let value = if int_digits + frac_digits <= 19 && mant < (1u64 << 53) {
        mant as f64 / POW10[frac_digits]
    } else {
        // rare: very long numbers; let the standard library round them
        let txt = std::str::from_utf8(&s[..i]).ok()?;
        let start = txt
            .rfind(|c: char| !(c.is_ascii_digit() || c == '.'))
            .map_or(0, |p| p + 1);
        txt[start..].parse::<f64>().ok()?
    };
    let value = if neg { -value } else { value };
    let decimals = if point {
        frac_digits.min(127) as i8
    } else {
        -1
    };
    Some((
        value,
        decimals,
        i,
        point && int_digits == 0,
        frac_digits >= 1 && last_frac == b'0',
        point && frac_digits == 0,
    ))
}

/// `x.round()` (half away from zero) without the library call: the same value for every x.
#[inline]
pub fn round(x: f64) -> f64 {
    if x.abs() < 4.0e15 {
        // the whole part is exact, and so is the difference
        // SAFETY: |x| < 4e15 fits an i64
        let t = unsafe { x.to_int_unchecked::<i64>() } as f64;
        let d = x - t;
        if d >= 0.5 {
            t + 1.0
        } else if d <= -0.5 {
            t - 1.0
        } else {
            t
        }
    } else {
        x.round()
    }
}

fn err(line: usize, col: usize, msg: impl Into<String>) -> NcError {
    NcError::Parse {
        line: line + 1,
        col: col + 1,
        message: msg.into(),
    }
}

/// Lex a whole program.
pub fn lex(src: &[u8]) -> Result<Lexed, NcError> {
    lex_at(src, 0)
}

/// Lex the lines of `src`, which begin at line `line_base` (0-based) of their program: errors
/// count lines from the program's start.
pub fn lex_at(src: &[u8], line_base: usize) -> Result<Lexed, NcError> {
    if src.len() >= u32::MAX as usize {
        return Err(err(0, 0, "program larger than 4 GiB"));
    }
    let est = src.len() / 24 + 1;
    let mut out = Lexed {
        lines: Vec::with_capacity(est),
        words: Vec::with_capacity(est * 4),
        ..Default::default()
    };
    let mut style = NumberStyle::default();
    let mut n_crlf = 0usize;
    let mut n_lf = 0usize;
    let mut n_spaced = 0usize;
    let mut n_compact = 0usize;
    let mut pos = 0usize;
    let mut lineno = line_base;
    while pos < src.len() {
        let nl = memchr(b'\n', &src[pos..]).map(|k| pos + k);
        let (end, eol_end) = match nl {
            Some(k) => {
                if k > pos && src[k - 1] == b'\r' {
                    n_crlf += 1;
                    (k - 1, k + 1)
                } else {
                    n_lf += 1;
                    (k, k + 1)
                }
            }
            None => (src.len(), src.len()),
        };
        let mut line = Line {
            start: pos as u32,
            end: end as u32,
            eol_end: eol_end as u32,
            first_word: out.words.len() as u32,
            comment_start: end as u32,
            ..Default::default()
        };
        let s = &src[..end];
        // a UTF-8 byte order mark (an editor's, before the program's first byte) is no word: kept
        // as it is in the output, with the line
        let mut i = if lineno == 0 && pos == 0 && s.starts_with(b"\xEF\xBB\xBF") {
            3
        } else {
            pos
        };
        let mut first = true;
        let mut prev_word_end: Option<usize> = None;
        let mut bad: Option<NcError> = None;
        while i < end {
            let c = s[i];
            match c {
                b'\r'
                    if s[i + 1..end]
                        .iter()
                        .any(|&c| !matches!(c, b' ' | b'\t' | b'\r' | 0x0c)) =>
                {
                    // LinuxCNC reads a lone CR as a blank, so CR-only line ends make one block of
                    // the whole file: refused rather than guessed
                    bad = Some(err(lineno, i - pos, "carriage return inside a line (CR-only line ends?); LinuxCNC does not end a block there: convert the line ends to LF or CRLF"));
                    break;
                }
                b' ' | b'\t' | b'\r' | 0x0c => {
                    i += 1;
                    continue;
                }
                b'/' if first => {
                    line.block_delete = true;
                    i += 1;
                }
                b'%' if first => {
                    line.percent = true;
                    // anything after % on the line is ignored by controls
                    if line.comment_start == end as u32 {
                        line.comment_start = i as u32;
                    }
                    i = end;
                }
                b'(' => match memchr(b')', &s[i..end]) {
                    Some(k) => {
                        if !line.comment {
                            line.comment_start = i as u32;
                        }
                        line.comment = true;
                        i += k + 1;
                    }
                    None => {
                        bad = Some(err(
                            lineno,
                            i - pos,
                            "comment '(' is not closed on this line",
                        ));
                        break;
                    }
                },
                b';' => {
                    if !line.comment {
                        line.comment_start = i as u32;
                    }
                    line.comment = true;
                    i = end;
                }
                b'#' | b'[' => {
                    line.opaque = Some((Opaque::Expression, i as u32));
                    i = end;
                }
                b'$' if first => {
                    // a grbl system command: the whole line, kept as written
                    line.opaque = Some((grbl_kind(&s[i + 1..end]), i as u32));
                    i = end;
                }
                // (`@` and `^`: LinuxCNC's polar distance and angle)
                b'a'..=b'z' | b'A'..=b'Z' | b'$' | b'@' | b'^' => {
                    let letter = c.to_ascii_uppercase();
                    let wstart = i;
                    let mut j = i + 1;
                    while j < end && (s[j] == b' ' || s[j] == b'\t') {
                        j += 1;
                    }
                    // an expression, possibly behind a unary sign: X[...], X#1, Z-[...]
                    let mut e = j;
                    if e < end && (s[e] == b'-' || s[e] == b'+') {
                        e += 1;
                        while e < end && (s[e] == b' ' || s[e] == b'\t') {
                            e += 1;
                        }
                    }
                    if e < end && (s[e] == b'#' || s[e] == b'[') {
                        line.opaque = Some((Opaque::Expression, wstart as u32));
                        i = end;
                        continue;
                    }
                    if letter == b'O' && j < end && s[j] == b'<' {
                        line.opaque = Some((Opaque::OWordFlow, wstart as u32));
                        i = end;
                        continue;
                    }
                    match number(s, j) {
                        Some((_, _, k, ..))
                            if k + 1 < end
                                && matches!(s[k], b'e' | b'E')
                                && (s[k + 1].is_ascii_digit()
                                    || (matches!(s[k + 1], b'+' | b'-')
                                        && k + 2 < end
                                        && s[k + 2].is_ascii_digit())) =>
                        {
                            bad = Some(err(lineno, k - pos, "a number with an exponent (such as 1e3) is not an RS274NGC number; write it out in full"));
                            break;
                        }
                        Some((value, decimals, k, no_lead, trailing, bare)) => {
                            if letter == b'O' {
                                // a keyword after the number makes it control flow
                                let mut m = k;
                                while m < end && (s[m] == b' ' || s[m] == b'\t') {
                                    m += 1;
                                }
                                let mut e = m;
                                while e < end && s[e].is_ascii_alphabetic() {
                                    e += 1;
                                }
                                let kw = s[m..e].to_ascii_lowercase();
                                if e > m && O_KEYWORDS.contains(&kw.as_slice()) {
                                    line.opaque = Some((Opaque::OWordFlow, wstart as u32));
                                    i = end;
                                    continue;
                                }
                            }
                            if matches!(
                                letter,
                                b'X' | b'Y' | b'Z' | b'I' | b'J' | b'K' | b'R' | b'U' | b'V' | b'W'
                            ) {
                                if decimals > 0 {
                                    style.max_decimals =
                                        style.max_decimals.max(decimals.min(8) as u8);
                                }
                                style.fixed |= trailing;
                                style.no_leading_zero |= no_lead;
                                style.bare_point |= bare;
                            }
                            if letter == b'G' && decimals < 0 && k - j == 2 && s[j] == b'0' {
                                style.padded_g = true;
                            }
                            if let Some(pe) = prev_word_end {
                                if pe == wstart {
                                    n_compact += 1;
                                } else {
                                    n_spaced += 1;
                                }
                            }
                            out.words.push(Word {
                                letter,
                                decimals,
                                start: wstart as u32,
                                num_start: j as u32,
                                end: k as u32,
                                value,
                            });
                            line.n_words += 1;
                            prev_word_end = Some(k);
                            i = k;
                        }
                        None => {
                            bad = Some(err(
                                lineno,
                                j - pos,
                                format!("expected a number after '{}'", letter as char),
                            ));
                            break;
                        }
                    }
                }
                _ => {
                    let shown = if c.is_ascii_graphic() {
                        format!("'{}'", c as char)
                    } else {
                        format!("byte 0x{c:02x}")
                    };
                    bad = Some(err(lineno, i - pos, format!("unexpected {shown}; expected a word such as G1 or X10.5, a comment or a line end")));
                    break;
                }
            }
            first = false;
        }
        if let Some(e) = bad {
            line.error = Some(out.errors.len() as u32);
            out.errors.push(e);
        }
        out.lines.push(line);
        pos = eol_end;
        lineno += 1;
    }
    style.spaced = n_spaced >= n_compact;
    out.style = style;
    out.crlf = n_crlf > n_lf;
    out.counts = [n_spaced, n_compact, n_crlf, n_lf];
    Ok(out)
}

/// The first `b` in `s`, eight bytes at a time.
#[inline]
fn memchr(b: u8, s: &[u8]) -> Option<usize> {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    let pat = LO * b as u64;
    let mut chunks = s.chunks_exact(8);
    let mut at = 0;
    for c in &mut chunks {
        let w = u64::from_le_bytes(c.try_into().unwrap()) ^ pat;
        // a high bit in each byte of w that is zero; a borrow can only mark bytes after a zero
        // one, so the lowest mark is the first match
        let z = w.wrapping_sub(LO) & !w & HI;
        if z != 0 {
            return Some(at + (z.trailing_zeros() / 8) as usize);
        }
        at += 8;
    }
    chunks
        .remainder()
        .iter()
        .position(|&c| c == b)
        .map(|k| at + k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_and_forms() {
        let l = lex(b"N010 G1. X-.5 y+2 (c) ; rest\r\n%\n/G0 Z1").unwrap();
        assert_eq!(l.lines.len(), 3);
        let w = l.line_words(0);
        assert_eq!(w.len(), 4);
        assert_eq!(w[0].letter, b'N');
        assert_eq!(w[0].value, 10.0);
        assert_eq!(w[1].value, 1.0);
        assert_eq!(w[1].decimals, 0);
        assert_eq!(w[2].value, -0.5);
        assert_eq!(w[3].letter, b'Y');
        assert!(l.lines[0].comment);
        assert_eq!(l.lines[0].eol_end - l.lines[0].end, 2);
        assert!(l.lines[1].percent);
        assert!(l.lines[2].block_delete);
        assert_eq!(l.lines[2].eol_end, l.lines[2].end);
        assert!(l.style.no_leading_zero);
    }

    #[test]
    fn errors_have_positions() {
        let first_error = |src: &[u8]| {
            let l = lex(src).unwrap();
            let i = l.lines.iter().find_map(|x| x.error).expect("an error");
            match &l.errors[i as usize] {
                NcError::Parse { line, col, .. } => (*line, *col),
                other => panic!("{other:?}"),
            }
        };
        assert_eq!(first_error(b"G1 X1\nG1 X\n"), (2, 5));
        assert_eq!(first_error(b"G1 (open\n"), (1, 4));
        assert_eq!(first_error(b"G1 X1e3\n"), (1, 6));
        assert_eq!(first_error(b"G0 X0\rG1 X1\r"), (1, 6));
        // a CR before the line end is a blank, as in LinuxCNC
        assert!(lex(b"G0 X0\r\r\nG1 X1 \r\n").unwrap().errors.is_empty());
    }

    #[test]
    fn memchr_finds_the_first() {
        let mut seed = 0x2545F4914F6CDD1Du64;
        for _ in 0..20_000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let n = (seed % 40) as usize;
            let s: Vec<u8> = (0..n)
                .map(|k| {
                    // the bytes sought and their near misses (one bit or one unit away)
                    let b = [b'\n', b')', b'a', 0x8a, 0x0b, 0x09, 0xa9, 0x28, 0xff];
                    b[((seed >> (k % 60)) % 9) as usize]
                })
                .collect();
            assert_eq!(
                memchr(b'\n', &s),
                s.iter().position(|&c| c == b'\n'),
                "{s:?}"
            );
            assert_eq!(memchr(b')', &s), s.iter().position(|&c| c == b')'), "{s:?}");
        }
    }

    #[test]
    fn round_is_the_library_round() {
        let mut seed = 0x9E3779B97F4A7C15u64;
        for k in 0..200_000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let x = match k % 4 {
                0 => f64::from_bits(seed),
                1 => (seed >> 11) as f64 / (1u64 << 53) as f64 * 2000.0 - 1000.0,
                2 => ((seed % 20001) as f64 - 10000.0) / 10.0 + 0.05,
                _ => ((seed % 2001) as f64 - 1000.0) * 0.5,
            };
            let (a, b) = (round(x), x.round());
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()) || (a == 0.0 && b == 0.0),
                "{x}: {a} {b}"
            );
        }
        for x in [
            0.49999999999999994,
            -0.49999999999999994,
            0.5,
            -0.5,
            2.5,
            -2.5,
            4503599627370495.5,
            1e300,
            -0.0,
        ] {
            assert_eq!(round(x) as i64, x.round() as i64, "{x}");
        }
    }

    #[test]
    fn numbers_are_exact() {
        for (t, v) in [
            ("0.1", 0.1),
            ("123.456", 123.456),
            ("-0.0001", -0.0001),
            (".5", 0.5),
            ("7.", 7.0),
        ] {
            let l = lex(format!("X{t}").as_bytes()).unwrap();
            assert_eq!(l.words[0].value, v, "{t}");
        }
    }

    #[test]
    fn numbers_are_the_standard_librarys() {
        // long and short digit strings, leading zeros, points anywhere: the value is the
        // correctly rounded one std's parser gives
        let mut seed = 0x2545F4914F6CDD1Du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..100_000 {
            let n = 1 + (next() % 25) as usize;
            let mut t: String = (0..n)
                .map(|k| {
                    let r = next();
                    if k == 0 && r % 3 == 0 {
                        '0'
                    } else {
                        (b'0' + (r % 10) as u8) as char
                    }
                })
                .collect();
            let at = (next() % (n as u64 + 2)) as usize;
            if at <= n {
                t.insert(at, '.');
            }
            let sign = ["", "-", "+"][(next() % 3) as usize];
            let l = lex(format!("X{sign}{t}").as_bytes()).unwrap();
            let want: f64 = format!("{sign}{t}").parse().unwrap();
            assert_eq!(l.words[0].value.to_bits(), want.to_bits(), "{sign}{t}");
            let dot = t.find('.');
            let dec = dot.map_or(-1, |p| (t.len() - p - 1) as i8);
            assert_eq!(l.words[0].decimals, dec, "{t}");
        }
    }

    #[test]
    fn opaque_constructs() {
        let l = lex(b"#1=2\nG1 X[#1+1]\no100 sub\nO1234\n").unwrap();
        assert_eq!(l.lines[0].opaque.unwrap().0, Opaque::Expression);
        assert_eq!(l.lines[1].opaque.unwrap().0, Opaque::Expression);
        assert_eq!(l.lines[2].opaque.unwrap().0, Opaque::OWordFlow);
        assert!(l.lines[3].opaque.is_none());
    }

    #[test]
    fn grbl_system_commands() {
        let l = lex(b"$H
$J=G91 X1 F10
$100=250
$RST=#
$X
$$
  $hx
G0 X$1
")
        .unwrap();
        let kinds: Vec<_> = l.lines[..7].iter().map(|x| x.opaque.unwrap().0).collect();
        use Opaque::*;
        assert_eq!(
            kinds,
            [
                GrblMove,
                GrblMove,
                GrblSetting,
                GrblSetting,
                GrblOther,
                GrblOther,
                GrblMove
            ]
        );
        // a '$' that does not start the line is an error, as before
        assert!(l.lines[7].error.is_some());
    }
}
