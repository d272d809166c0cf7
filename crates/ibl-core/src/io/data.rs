//! Structured outputs (coefficients, summaries, sidecars) as JSON or RON, chosen by the
//! file extension, written atomically.

use crate::error::{Error, Result};
use serde::Serialize;
use std::path::Path;

/// Serialises `value` as RON when `path` ends in `.ron`, otherwise as pretty JSON.
pub fn encode<T: Serialize>(path: &Path, value: &T) -> Result<Vec<u8>> {
    let text = if super::extension(path) == "ron" {
        ron::ser::to_string_pretty(value, ron::ser::PrettyConfig::default()).map_err(|e| Error::invalid(path, format!("RON encoding failed: {e}")))?
    } else {
        serde_json::to_string_pretty(value).map_err(|e| Error::invalid(path, format!("JSON encoding failed: {e}")))?
    };
    Ok((text + "\n").into_bytes())
}

/// Encodes and writes atomically.
pub fn write<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    super::write_atomic(path, &encode(path, value)?)
}

/// Reads JSON or RON by extension.
pub fn read<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    if super::extension(path) == "ron" {
        ron::from_str(&text).map_err(|e| Error::invalid(path, format!("{}:{}: {}", e.span.start.line, e.span.start.col, e.code)))
    } else {
        serde_json::from_str(&text).map_err(|e| Error::invalid(path, format!("{}:{}: {e}", e.line(), e.column())))
    }
}
