//! The engine's one error type.

use std::fmt;

/// An error with the 1-based line and column where the input was wrong.
#[derive(Clone, Debug, PartialEq)]
pub enum NcError {
    /// The text could not be split into words.
    Parse {
        line: usize,
        col: usize,
        message: String,
    },
    /// The words could not be interpreted (an arc that does not close, a missing word).
    Interpret {
        line: usize,
        col: usize,
        message: String,
    },
    /// A caller passed arrays or options that do not fit the program.
    Usage(String),
}

impl fmt::Display for NcError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NcError::Parse { line, col, message } | NcError::Interpret { line, col, message } => {
                write!(f, "{line}:{col}: {message}")
            }
            NcError::Usage(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for NcError {}
