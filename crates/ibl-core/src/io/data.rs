//! Structured outputs (coefficients, summaries, sidecars) as JSON or RON, chosen by the
//! file extension, written atomically.

use crate::error::{Error, Result};
use serde::Serialize;
use std::path::Path;

/// Serialises `value` as RON when `path` ends in `.ron`, otherwise as pretty JSON.
pub fn encode<T: Serialize>(path: &Path, value: &T) -> Result<Vec<u8>> {
    let text = if super::extension(path) == "ron" {
        ron::ser::to_string_pretty(value, ron::ser::PrettyConfig::default())
            .map_err(|e| Error::invalid(path, format!("RON encoding failed: {e}")))?
    } else {
        let mut out = Vec::new();
        let mut ser = serde_json::Serializer::with_formatter(&mut out, CompactLeaves::default());
        value
            .serialize(&mut ser)
            .map_err(|e| Error::invalid(path, format!("JSON encoding failed: {e}")))?;
        String::from_utf8(out).expect("serde_json writes UTF-8")
    };
    Ok((text + "\n").into_bytes())
}

/// Pretty JSON whose arrays nested inside arrays stay on one line, so coefficient lists read
/// as one `[r, g, b]` per line instead of one number per line.
#[derive(Default)]
struct CompactLeaves {
    pretty: serde_json::ser::PrettyFormatter<'static>,
    /// For each open container: is it an array?
    stack: Vec<bool>,
}

impl CompactLeaves {
    /// Inside an array that is itself inside an array: write compactly.
    fn compact(&self) -> bool {
        let n = self.stack.len();
        n >= 2 && self.stack[n - 1] && self.stack[n - 2]
    }
}

impl serde_json::ser::Formatter for CompactLeaves {
    fn begin_array<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.stack.push(true);
        if self.compact() {
            w.write_all(b"[")
        } else {
            self.pretty.begin_array(w)
        }
    }
    fn end_array<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        let compact = self.compact();
        self.stack.pop();
        if compact {
            w.write_all(b"]")
        } else {
            self.pretty.end_array(w)
        }
    }
    fn begin_array_value<W: ?Sized + std::io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> std::io::Result<()> {
        if self.compact() {
            if first {
                Ok(())
            } else {
                w.write_all(b", ")
            }
        } else {
            self.pretty.begin_array_value(w, first)
        }
    }
    fn end_array_value<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        if self.compact() {
            Ok(())
        } else {
            self.pretty.end_array_value(w)
        }
    }
    fn begin_object<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.stack.push(false);
        self.pretty.begin_object(w)
    }
    fn end_object<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.stack.pop();
        self.pretty.end_object(w)
    }
    fn begin_object_key<W: ?Sized + std::io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> std::io::Result<()> {
        self.pretty.begin_object_key(w, first)
    }
    fn begin_object_value<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.pretty.begin_object_value(w)
    }
    fn end_object_value<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        self.pretty.end_object_value(w)
    }
}

/// Encodes and writes atomically.
pub fn write<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    super::write_atomic(path, &encode(path, value)?)
}

/// Reads JSON or RON by extension.
pub fn read<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    if super::extension(path) == "ron" {
        ron::from_str(&text).map_err(|e| {
            Error::invalid(
                path,
                format!("{}:{}: {}", e.span.start.line, e.span.start.col, e.code),
            )
        })
    } else {
        serde_json::from_str(&text)
            .map_err(|e| Error::invalid(path, format!("{}:{}: {e}", e.line(), e.column())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Serialize, serde::Deserialize, PartialEq, Debug)]
    struct Coeffs {
        bands: usize,
        c: Vec<[f32; 3]>,
    }

    #[test]
    fn json_keeps_triples_on_one_line_and_round_trips() {
        let v = Coeffs {
            bands: 2,
            c: vec![[1.0, 2.5, -3.0], [0.0, 1e-7, 4.0]],
        };
        let text = String::from_utf8(encode(Path::new("a.json"), &v).unwrap()).unwrap();
        assert!(text.contains("[1.0, 2.5, -3.0]"), "{text}");
        assert_eq!(serde_json::from_str::<Coeffs>(&text).unwrap(), v);
        let ron_text = String::from_utf8(encode(Path::new("a.ron"), &v).unwrap()).unwrap();
        assert_eq!(ron::from_str::<Coeffs>(&ron_text).unwrap(), v);
    }
}
