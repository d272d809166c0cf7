//! The error type of the material library: the core's causes (through `ibl_core::Error`) and
//! two of its own, an expression that does not parse (invalid input) and a batch with failures
//! (the class of its first failure).

use ibl_core::error::{Classify, ErrorClass};
use std::path::PathBuf;

/// Everything that can go wrong in a material bake.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Image I/O, bad input files, bad parameters (invalid input / unsupported / I/O by the
    /// wrapped error's own class).
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
    /// An expression given on the command line (or in a pipeline) does not parse.
    /// Invalid input.
    #[error("{flag}: {source}")]
    Expr {
        /// The flag (or RON key) holding the expression.
        flag: &'static str,
        /// Where and why it does not parse.
        #[source]
        source: crate::expr::ExprError,
    },
    /// Some files of a batch failed; each failure was reported with its path.
    /// Takes the class of the first failure (in path order).
    #[error("batch {}: {failed} of {total} material(s) failed ({converted} converted, {skipped} skipped); first: {first}", .root.display())]
    BatchFailed {
        /// The folder the batch walked.
        root: PathBuf,
        /// Materials seen.
        total: usize,
        /// Materials converted.
        converted: usize,
        /// Materials up to date.
        skipped: usize,
        /// Materials that failed.
        failed: usize,
        /// The first failure's one-line error.
        first: String,
        /// The first failure's exit-code class.
        class: ErrorClass,
    },
}

impl Error {
    /// Which exit-code class this error belongs to.
    pub fn class(&self) -> ErrorClass {
        match self {
            Error::Core(e) => e.class(),
            Error::Expr { .. } => ErrorClass::InvalidInput,
            Error::BatchFailed { class, .. } => *class,
        }
    }
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        Error::class(self)
    }
}

/// A result with the material [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
