//! The core error type, grouped by cause: invalid input, unsupported input, I/O.

use std::path::{Path, PathBuf};

/// Everything that can go wrong in the core library.
///
/// Variants are grouped by cause so binaries can map them to exit codes:
/// [`Error::InvalidInput`] and [`Error::NonFinite`] are bad data or parameters,
/// [`Error::Unsupported`] is valid data we do not handle, [`Error::Io`] is the file system.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The input is malformed, out of range or inconsistent.
    #[error("{}: {reason}", path_or_param(.path))]
    InvalidInput {
        /// The file, or `None` for a parameter.
        path: Option<PathBuf>,
        /// What is wrong.
        reason: String,
    },
    /// The input has NaN or infinite texels (use `--sanitize` to set them to 0).
    #[error("{}: {count} NaN/Inf texel values (use --sanitize to set them to 0)", .path.display())]
    NonFinite {
        /// The file read.
        path: PathBuf,
        /// Non-finite channel values found.
        count: usize,
    },
    /// The input is well-formed but uses something we do not implement.
    #[error("{}: unsupported: {what}", path_or_param(.path))]
    Unsupported {
        /// The file, or `None` for a parameter.
        path: Option<PathBuf>,
        /// What is not supported.
        what: String,
    },
    /// Decoding the input would need more memory than the run's budget allows, or an
    /// allocation failed: refused before (or instead of) aborting.
    #[error("{}: {reason}", path_or_param(.path))]
    Memory {
        /// The file being read, or `None`.
        path: Option<PathBuf>,
        /// What was needed and what the budget is.
        reason: String,
    },
    /// Reading or writing a file failed.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The path read or written.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

fn path_or_param(p: &Option<PathBuf>) -> String {
    match p {
        Some(p) => p.display().to_string(),
        None => "invalid parameter".to_string(),
    }
}

/// Exit-code class of an error, shared by all binaries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorClass {
    /// Bad data or parameters: exit code 2.
    InvalidInput,
    /// Valid input the tools do not handle, or more than the memory budget: exit code 3.
    Unsupported,
    /// A file-system failure: exit code 4.
    Io,
}

impl Error {
    /// Bad data in a named file.
    pub fn invalid(path: impl AsRef<Path>, reason: impl Into<String>) -> Self {
        Error::InvalidInput {
            path: Some(path.as_ref().to_path_buf()),
            reason: reason.into(),
        }
    }
    /// A parameter out of range (no file involved).
    pub fn param(reason: impl Into<String>) -> Self {
        Error::InvalidInput {
            path: None,
            reason: reason.into(),
        }
    }
    /// A valid but unsupported file.
    pub fn unsupported(path: impl AsRef<Path>, what: impl Into<String>) -> Self {
        Error::Unsupported {
            path: Some(path.as_ref().to_path_buf()),
            what: what.into(),
        }
    }
    /// An I/O failure on a path.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
    /// Which exit-code class this error belongs to.
    pub fn class(&self) -> ErrorClass {
        match self {
            Error::InvalidInput { .. } | Error::NonFinite { .. } => ErrorClass::InvalidInput,
            // Exit 3 with unsupported input: the data may be valid, this run cannot hold it.
            Error::Unsupported { .. } | Error::Memory { .. } => ErrorClass::Unsupported,
            Error::Io { .. } => ErrorClass::Io,
        }
    }
}

/// A result with the core [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Errors of any library of the workspace say which exit-code class they belong to, so
/// binaries can map them without knowing the library.
pub trait Classify: std::error::Error {
    /// The exit-code class of this error.
    fn class(&self) -> ErrorClass;
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        Error::class(self)
    }
}

/// An error and its causes on one line, "outer: cause: root cause", skipping a cause whose
/// text the line already holds (thiserror's `#[error(transparent)]` and "{0}" wrappers repeat
/// their source). What every binary prints and what batch reports record.
pub fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(c) = src {
        let t = c.to_string();
        if !s.contains(&t) {
            s.push_str(": ");
            s.push_str(&t);
        }
        src = c.source();
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chain_joins_causes_on_one_line_without_repeats() {
        #[derive(Debug)]
        struct E(&'static str, Option<Box<E>>);
        impl std::fmt::Display for E {
            fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str(self.0)
            }
        }
        impl std::error::Error for E {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                self.1.as_deref().map(|e| e as _)
            }
        }
        let root = E("disk full", None);
        let mid = E("writing a.exr", Some(Box::new(root)));
        // A transparent wrapper repeats its source's text: shown once.
        let top = E("writing a.exr", Some(Box::new(mid)));
        assert_eq!(chain(&top), "writing a.exr: disk full");
        assert!(!chain(&top).contains('\n'));
    }
}
