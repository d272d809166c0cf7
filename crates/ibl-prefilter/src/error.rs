//! The error type of the prefilter bake, grouped by cause like the core's.

use ibl_core::error::{Classify, ErrorClass};

/// Everything the prefilter bake can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A parameter out of range or inconsistent with the input (invalid input).
    #[error("invalid parameter: {0}")]
    Param(String),
    /// Reading, decoding or writing failed, or the input is malformed or unsupported: the
    /// core error keeps its own class.
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        match self {
            Error::Param(_) => ErrorClass::InvalidInput,
            Error::Core(e) => e.class(),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
