//! The error type of the LUT bakes, grouped by cause (invalid parameters / unsupported
//! outputs / I/O through the core error).

use ibl_core::error::{Classify, ErrorClass};
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A parameter out of range or missing.
    #[error("invalid parameter: {0}")]
    Param(String),
    /// An output path whose extension names no format this bake writes.
    #[error("{}: unsupported output: {what}", .path.display())]
    UnsupportedOutput { path: PathBuf, what: String },
    /// Image encoding, reading or writing failed.
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
}

impl Error {
    pub fn param(why: impl Into<String>) -> Self {
        Error::Param(why.into())
    }
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        match self {
            Error::Param(_) => ErrorClass::InvalidInput,
            Error::UnsupportedOutput { .. } => ErrorClass::Unsupported,
            Error::Core(e) => e.class(),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
