//! Errors of the runner: located diagnostics found before any work, and failures while running.

use ibl_core::error::{Classify, ErrorClass};
use std::fmt;
use std::path::{Path, PathBuf};

/// One problem found in a pipeline before any stage ran, located in its file where possible.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Diagnostic {
    /// The pipeline file.
    pub file: PathBuf,
    /// 1-based line and column of the offending text, when it has a place in the file.
    pub line: Option<usize>,
    /// 1-based column, when known.
    pub col: Option<usize>,
    /// What is wrong.
    pub message: String,
    /// The offending source line with a caret under the column.
    pub snippet: Option<String>,
}

impl Diagnostic {
    /// A problem with no place in the file (a missing input file, a cycle through several stages).
    pub(crate) fn global(file: &Path, message: impl Into<String>) -> Self {
        Diagnostic {
            file: file.to_path_buf(),
            line: None,
            col: None,
            message: message.into(),
            snippet: None,
        }
    }

    /// A problem at byte `offset` of `src`, the text of `file`.
    pub fn at(file: &Path, src: &str, offset: usize, message: impl Into<String>) -> Self {
        let (line, col) = line_col(src, offset);
        let text = src.lines().nth(line - 1).unwrap_or("");
        let caret_pad: String = text
            .chars()
            .take(col - 1)
            .map(|c| if c == '\t' { '\t' } else { ' ' })
            .collect();
        let gutter = format!("{line:>5} | ");
        let snippet = format!("{gutter}{text}\n{:>5} | {caret_pad}^", "");
        Diagnostic {
            file: file.to_path_buf(),
            line: Some(line),
            col: Some(col),
            message: message.into(),
            snippet: Some(snippet),
        }
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.line, self.col) {
            (Some(l), Some(c)) => write!(f, "{}:{l}:{c}: {}", self.file.display(), self.message)?,
            _ => write!(f, "{}: {}", self.file.display(), self.message)?,
        }
        if let Some(s) = &self.snippet {
            write!(f, "\n{s}")?;
        }
        Ok(())
    }
}

/// 1-based (line, column in characters) of byte `offset` in `src`.
pub(crate) fn line_col(src: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(src.len());
    let before = &src[..floor_char_boundary(src, offset)];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    (line, before[line_start..].chars().count() + 1)
}

/// Byte offset of 1-based (line, column in characters) in `src` (clamped to the text).
pub(crate) fn offset_of(src: &str, line: usize, col: usize) -> usize {
    let mut start = 0;
    for _ in 1..line.max(1) {
        match src[start..].find('\n') {
            Some(i) => start += i + 1,
            None => return src.len(),
        }
    }
    let rest = &src[start..];
    let line_len = rest.find('\n').unwrap_or(rest.len());
    start
        + rest[..line_len]
            .char_indices()
            .nth(col.saturating_sub(1))
            .map(|(i, _)| i)
            .unwrap_or(line_len)
}

fn floor_char_boundary(s: &str, mut i: usize) -> usize {
    while i > 0 && !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// Everything the runner can fail with, grouped by cause.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The pipeline is invalid: every problem found before any stage ran.
    #[error("{}", render(.0))]
    Invalid(Vec<Diagnostic>),
    /// An error of the core library (image decoding, atomic writes).
    #[error(transparent)]
    Core(#[from] ibl_core::Error),
    /// The runner's own file-system work (cache, manifest, staging) failed.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// Another `bake` holds the output folder.
    #[error("{}: {why}", .path.display())]
    Busy {
        /// The output folder's lock file.
        path: PathBuf,
        /// Who holds it.
        why: String,
    },
}

fn render(d: &[Diagnostic]) -> String {
    let mut s = d
        .iter()
        .map(|d| d.to_string())
        .collect::<Vec<_>>()
        .join("\n");
    if d.len() > 1 {
        s.push_str(&format!("\n{} problems found; nothing was run", d.len()));
    }
    s
}

impl Error {
    /// A file-system error of the runner at `path`.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }
    /// One diagnostic as an error.
    pub fn invalid(d: Diagnostic) -> Self {
        Error::Invalid(vec![d])
    }
}

impl Classify for Error {
    fn class(&self) -> ErrorClass {
        match self {
            Error::Invalid(_) => ErrorClass::InvalidInput,
            Error::Core(e) => e.class(),
            Error::Io { .. } | Error::Busy { .. } => ErrorClass::Io,
        }
    }
}

/// "outer: cause: root cause" on one line (`ibl_core::error::chain`).
pub use ibl_core::error::chain as error_chain;

/// The runner's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_col_and_offset_are_inverse() {
        let src = "ab\ncdé\n\nfg";
        for off in [0, 1, 3, 5, 7, 8, 9] {
            let (l, c) = line_col(src, off);
            assert_eq!(offset_of(src, l, c), off, "offset {off} -> {l}:{c}");
        }
        assert_eq!(line_col(src, 3), (2, 1));
        assert_eq!(line_col(src, 9), (4, 1));
    }

    #[test]
    fn diagnostic_shows_line_and_caret() {
        let src = "Pipeline(\n    stagez: [],\n)";
        let d = Diagnostic::at(Path::new("p.ron"), src, 14, "unknown field");
        let s = d.to_string();
        assert!(s.starts_with("p.ron:2:5: unknown field"), "{s}");
        assert!(s.contains("    2 |     stagez: [],\n      |     ^"), "{s}");
    }
}
