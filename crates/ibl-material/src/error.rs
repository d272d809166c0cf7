//! The error type of the material library, grouped by cause like `ibl_core::Error`.

use ibl_core::error::{Classify, ErrorClass};
use std::path::PathBuf;

/// Everything that can go wrong in a material bake.
#[derive(Debug, thiserror::Error)]
pub enum MaterialError {
    /// Image I/O, bad input files, bad parameters (invalid input / unsupported / I/O by the
    /// wrapped error's own class).
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
    /// An expression given on the command line (or in a pipeline) does not parse.
    /// Invalid input.
    #[error("{flag}: {source}")]
    Expr {
        flag: &'static str,
        #[source]
        source: crate::expr::ExprError,
    },
    /// Some files of a batch failed; each failure was reported with its path.
    /// Takes the class of the first failure (in path order).
    #[error("batch {}: {failed} of {total} material(s) failed ({converted} converted, {skipped} skipped); first: {first}", .root.display())]
    BatchFailed {
        root: PathBuf,
        total: usize,
        converted: usize,
        skipped: usize,
        failed: usize,
        first: String,
        class: ErrorClass,
    },
}

impl MaterialError {
    pub fn class(&self) -> ErrorClass {
        match self {
            MaterialError::Core(e) => e.class(),
            MaterialError::Expr { .. } => ErrorClass::InvalidInput,
            MaterialError::BatchFailed { class, .. } => *class,
        }
    }
}

impl Classify for MaterialError {
    fn class(&self) -> ErrorClass {
        MaterialError::class(self)
    }
}

pub type Result<T, E = MaterialError> = std::result::Result<T, E>;
