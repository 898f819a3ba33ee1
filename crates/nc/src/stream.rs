//! A program read from a file (or any reader) in pieces of whole lines, so that a correction or an
//! inspection holds one piece at a time whatever the program's length.
//!
//! Each piece is lexed and interpreted where the one before left off ([`Interpreter::run`]), so
//! its records, samples and emitted text are those of the whole program. The number style the
//! emitter writes in is the whole program's: [`scan_style`] reads it in a first pass.

use std::io::Read;

use crate::error::NcError;
use crate::interp::{Dialect, Interp, Interpreter};
use crate::lex::{lex_at, Lexed, NumberStyle};

/// Where a stream reads its program from.
pub type Reader = Box<dyn Read + Send + Sync>;

/// One piece of a program: its bytes (whole lines), their words and their records.
pub struct Piece {
    pub src: Vec<u8>,
    pub lexed: Lexed,
    pub interp: Interp,
    /// Line index (0-based, from the program's start) of the piece's first line.
    pub line_base: usize,
}

/// Reads whole lines from `reader`: at least `want` bytes unless the input ends first.
struct Lines {
    reader: Reader,
    carry: Vec<u8>,
    eof: bool,
}

impl Lines {
    fn next(&mut self, want: usize) -> Result<Option<Vec<u8>>, NcError> {
        let mut buf = std::mem::take(&mut self.carry);
        let from = want.max(1) - 1;
        let mut searched = 0usize;
        loop {
            // the piece ends at the first line end after `want` bytes
            let start = from.max(searched);
            if start < buf.len() {
                if let Some(k) = buf[start..].iter().position(|&c| c == b'\n') {
                    self.carry = buf.split_off(start + k + 1);
                    return Ok(Some(buf));
                }
            }
            searched = buf.len();
            if self.eof {
                return Ok(if buf.is_empty() { None } else { Some(buf) });
            }
            let at = buf.len();
            buf.resize(at + want.max(1 << 16), 0);
            let n = loop {
                match self.reader.read(&mut buf[at..]) {
                    Ok(n) => break n,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(e) => return Err(NcError::Usage(format!("cannot read the program: {e}"))),
                }
            };
            buf.truncate(at + n);
            self.eof = n == 0;
        }
    }
}

/// The number style and line ending of a whole program, read piece by piece.
pub fn scan_style(reader: Reader, piece_bytes: usize) -> Result<(NumberStyle, bool), NcError> {
    let mut lines = Lines {
        reader,
        carry: Vec::new(),
        eof: false,
    };
    let mut style = NumberStyle::default();
    let mut counts = [0usize; 4];
    let mut base = 0usize;
    while let Some(buf) = lines.next(piece_bytes)? {
        let lx = lex_at(&buf, base)?;
        base += lx.lines.len();
        style.merge(&lx.style);
        for (c, n) in counts.iter_mut().zip(lx.counts) {
            *c += n;
        }
    }
    style.spaced = counts[0] >= counts[1];
    Ok((style, counts[2] > counts[3]))
}

/// A program interpreted piece by piece.
pub struct Stream {
    lines: Lines,
    piece_bytes: usize,
    line_base: usize,
    style: NumberStyle,
    crlf: bool,
    /// The interpreter's state; its unsupported constructs, notes and summary cover every piece
    /// read so far.
    pub interp: Interpreter,
}

impl Stream {
    /// Read `reader` in pieces of about `piece_bytes`, writing numbers in `style` (from
    /// [`scan_style`]) with `crlf` line ends where lines are added.
    pub fn new(reader: Reader, piece_bytes: usize, style: NumberStyle, crlf: bool) -> Self {
        Stream {
            lines: Lines {
                reader,
                carry: Vec::new(),
                eof: false,
            },
            piece_bytes,
            line_base: 0,
            style,
            crlf,
            interp: Interpreter::new(),
        }
    }

    /// The stream of a program written for `dialect` (LinuxCNC's RS274NGC by default).
    pub fn with_dialect(mut self, dialect: Dialect) -> Self {
        self.interp = Interpreter::with_dialect(dialect);
        self
    }

    /// The tool table for cutter radius compensation ([`Interpreter::with_tools`]).
    pub fn with_tools(mut self, tools: std::sync::Arc<Vec<(u32, f64)>>) -> Self {
        self.interp = std::mem::take(&mut self.interp).with_tools(tools);
        self
    }

    /// Lines read so far.
    pub fn lines_read(&self) -> usize {
        self.line_base
    }

    /// The next piece, or None at the end of the input.
    pub fn next_piece(&mut self) -> Result<Option<Piece>, NcError> {
        let (style, crlf) = (self.style, self.crlf);
        self.next_piece_with(|_| (style, crlf))
    }

    /// The next piece, written in the style `style` gives from the piece's own lexing (which
    /// carries the piece's style and counts).
    pub fn next_piece_with(
        &mut self,
        style: impl FnOnce(&Lexed) -> (NumberStyle, bool),
    ) -> Result<Option<Piece>, NcError> {
        let Some(src) = self.lines.next(self.piece_bytes)? else {
            return Ok(None);
        };
        if self.line_base + src.len() >= u32::MAX as usize {
            return Err(NcError::Usage(
                "a program of more than 4 billion lines".into(),
            ));
        }
        let mut lexed = lex_at(&src, self.line_base)?;
        (lexed.style, lexed.crlf) = style(&lexed);
        let interp = self.interp.run(&lexed, self.line_base)?;
        let line_base = self.line_base;
        self.line_base += lexed.lines.len();
        Ok(Some(Piece {
            src,
            lexed,
            interp,
            line_base,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emit::{EmitState, Emitter};
    use crate::sample::{sample_range, SampleOpts, Samples};

    /// A program read in pieces of any size gives the whole program's records and output.
    #[test]
    fn pieces_give_the_whole_program() {
        let src = "%\nG21 G90 G0 X0 Y0 Z5\nG1 Z-1.000 F100\nG2 X10 Y0 I5 J0\nG91 G1 X2\nX2 Y3 (c)\r\nG3 X-4 Y0 I-2 J0\nG90 G0 Z5\nM30\ntrailing text !\n";
        let whole = crate::Program::parse(src.as_bytes().to_vec()).unwrap();
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
        let s = whole.sample(&o).unwrap();
        let (expect, _) = Emitter::new(&whole.src, &whole.lexed, &whole.interp)
            .run(&s, &field(&s))
            .unwrap();
        for piece_bytes in [1, 7, 30, 1 << 20] {
            let (style, crlf) = scan_style(
                Box::new(std::io::Cursor::new(src.as_bytes().to_vec())),
                piece_bytes,
            )
            .unwrap();
            assert_eq!((style, crlf), (whole.lexed.style, whole.lexed.crlf));
            let mut st = Stream::new(
                Box::new(std::io::Cursor::new(src.as_bytes().to_vec())),
                piece_bytes,
                style,
                crlf,
            );
            let (mut out, mut state, mut ends) = (Vec::new(), None::<EmitState>, Vec::new());
            while let Some(p) = st.next_piece().unwrap() {
                let mut s = Samples::default();
                sample_range(&p.interp, &o, 0..p.interp.records.len(), &mut s).unwrap();
                let em_state = state.take().unwrap_or_else(|| EmitState::new(&p.interp));
                let mut em = Emitter::resume(&p.src, &p.lexed, &p.interp, em_state);
                em.lines(0..p.lexed.lines.len(), &s, &field(&s), &mut out)
                    .unwrap();
                state = Some(em.into_state());
                ends.extend(
                    p.interp
                        .records
                        .iter()
                        .map(|r| (r.line, r.end[0].to_bits())),
                );
            }
            let whole_ends: Vec<_> = whole
                .interp
                .records
                .iter()
                .map(|r| (r.line, r.end[0].to_bits()))
                .collect();
            assert_eq!(ends, whole_ends, "pieces of {piece_bytes} bytes");
            assert_eq!(
                String::from_utf8(out).unwrap(),
                String::from_utf8(expect.clone()).unwrap(),
                "pieces of {piece_bytes} bytes"
            );
            assert_eq!(st.interp.summary.end_line, whole.interp.summary.end_line);
        }
    }
}
