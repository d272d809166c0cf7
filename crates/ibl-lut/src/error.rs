//! The error type of the LUT bakes, grouped by the core's causes: invalid parameters and
//! inputs, I/O (through the core error) and the one cause of their own, an output whose
//! extension names no format the bake writes (unsupported).

use ibl_core::error::{Classify, ErrorClass};
use std::path::PathBuf;

/// Everything the LUT bakes (DFG, Fresnel tail, AS size bias, half-vector LUT) can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An output path whose extension names no format this bake writes (unsupported).
    #[error("{}: unsupported output: {what}", .path.display())]
    UnsupportedOutput {
        /// The output path.
        path: PathBuf,
        /// What about it is not supported.
        what: String,
    },
    /// Bad parameters, image encoding, reading or writing: the core error keeps its class.
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
}

impl Error {
    /// An out-of-range or missing parameter (invalid input, exit code 2).
    pub fn param(why: impl Into<String>) -> Self {
        Error::Core(ibl_core::Error::param(why))
    }
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        match self {
            Error::UnsupportedOutput { .. } => ErrorClass::Unsupported,
            Error::Core(e) => e.class(),
        }
    }
}

/// A result with the LUT bakes' [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
