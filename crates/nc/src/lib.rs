//! ncadapt's NC engine: an exact-text G-code lexer, a modal interpreter, a toolpath sampler and
//! an emitter that changes only what a correction changes.
//!
//! The crate is plain Rust; the Python bindings live in the `ncadapt-nc-py` crate.

// `!(x > 0.0)` is meant: it is true for NaN too, which is how the engine refuses a NaN option
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// the interpreter's block handlers take the modal state piece by piece
#![allow(clippy::too_many_arguments)]

pub mod emit;
pub mod error;
pub mod field;
pub mod interp;
pub mod lex;
pub mod pipeline;
pub mod sample;
pub mod spline;
pub mod stream;

pub use error::NcError;

/// A program read into memory: its bytes, words and interpretation.
pub struct Program {
    pub src: Vec<u8>,
    pub lexed: lex::Lexed,
    pub interp: interp::Interp,
}

impl Program {
    /// Lex and interpret `src` (LinuxCNC's RS274NGC).
    pub fn parse(src: Vec<u8>) -> Result<Self, NcError> {
        Self::parse_as(src, interp::Dialect::LinuxCnc)
    }

    /// Lex and interpret `src`, a program written for `dialect`.
    pub fn parse_as(src: Vec<u8>, dialect: interp::Dialect) -> Result<Self, NcError> {
        Self::parse_with(src, dialect, Default::default())
    }

    /// Lex and interpret `src`, a program written for `dialect`, with the tool table `tools`
    /// (tool number, diameter mm) for cutter radius compensation.
    pub fn parse_with(
        src: Vec<u8>,
        dialect: interp::Dialect,
        tools: std::sync::Arc<Vec<(u32, f64)>>,
    ) -> Result<Self, NcError> {
        let lexed = lex::lex(&src)?;
        let interp = interp::Interpreter::with_dialect(dialect)
            .with_tools(tools)
            .run_all(&lexed)?;
        Ok(Program { src, lexed, interp })
    }

    /// Sample the program's blocks.
    pub fn sample(&self, opts: &sample::SampleOpts) -> Result<sample::Samples, NcError> {
        sample::sample(&self.interp, opts)
    }

    /// The records of lines `lines` (records are in line order).
    pub fn records_of_lines(&self, lines: std::ops::Range<usize>) -> std::ops::Range<usize> {
        let r = &self.interp.records;
        let a = r.partition_point(|x| (x.line as usize) < lines.start);
        let b = a + r[a..].partition_point(|x| (x.line as usize) < lines.end);
        a..b
    }
}
