//! ncadapt's NC engine: an exact-text G-code lexer, a modal interpreter, a toolpath sampler and
//! an emitter that changes only what a correction changes.
//!
//! The crate is plain Rust; the Python bindings live in the `ncadapt-nc-py` crate.

pub mod emit;
pub mod error;
pub mod interp;
pub mod lex;
pub mod sample;

pub use error::NcError;

/// A program read into memory: its bytes, words and interpretation.
pub struct Program {
    pub src: Vec<u8>,
    pub lexed: lex::Lexed,
    pub interp: interp::Interp,
}

impl Program {
    /// Lex and interpret `src`.
    pub fn parse(src: Vec<u8>) -> Result<Self, NcError> {
        let lexed = lex::lex(&src)?;
        let interp = interp::interpret(&lexed)?;
        Ok(Program { src, lexed, interp })
    }

    /// Sample the program's blocks.
    pub fn sample(&self, opts: &sample::SampleOpts) -> sample::Samples {
        sample::sample(&self.interp, opts)
    }

    /// Write the program with one displacement (mm) per sample of `samples`.
    pub fn emit(&self, samples: &sample::Samples, disp: &[f64]) -> Result<(Vec<u8>, emit::EmitStats), NcError> {
        emit::Emitter::new(&self.src, &self.lexed, &self.interp).run(samples, disp)
    }
}
