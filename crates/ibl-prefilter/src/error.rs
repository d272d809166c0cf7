//! The error type of the prefilter bake: the core's causes (invalid input, unsupported, I/O)
//! and no cause of its own; parameters out of range are the core's invalid input.

use ibl_core::error::{Classify, ErrorClass};

/// Everything the prefilter bake can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading, decoding or writing failed, the input is malformed or unsupported, or a
    /// parameter is out of range: the core error keeps its own class.
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
}

impl Error {
    /// A parameter out of range or inconsistent with the input (invalid input, exit code 2).
    pub fn param(why: impl Into<String>) -> Self {
        Error::Core(ibl_core::Error::param(why))
    }
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        match self {
            Error::Core(e) => e.class(),
        }
    }
}

/// A result with the prefilter [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
