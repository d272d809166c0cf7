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

/// Reads JSON or RON by extension, as a `what` ("an SH-exp coefficient file"): a file that
/// parses but holds something else (another tool's sidecar) is refused as "not a `what`",
/// naming what it lacks, rather than with the bare "missing field" of the deserialiser.
pub fn read_as<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    read(path).map_err(|e| match e {
        Error::InvalidInput { reason, .. } if is_shape_error(&reason) => {
            Error::invalid(path, format!("not {what} ({reason})"))
        }
        e => e,
    })
}

/// A well-formed document of the wrong shape (as opposed to a syntax error).
fn is_shape_error(msg: &str) -> bool {
    [
        "missing field",
        "unknown field",
        "invalid type",
        "unknown variant",
    ]
    .iter()
    .any(|k| msg.contains(k))
}

/// Rewrites every number that is exactly an `f32` into the shortest decimal that reads back
/// as that `f32`: a parameter given as 0.2 prints as 0.2, not as 0.20000000298023224 (the
/// `f64` widening `serde_json::to_value` applies to `f32` fields). Deterministic and one-to-one
/// on `f32` values, so it may shape cache keys; integers are left as they are.
pub fn shortest_f32(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().expect("is_f64");
            let f = x as f32;
            if f as f64 == x && f.is_finite() {
                let short: f64 = f.to_string().parse().expect("f32 text parses as f64");
                if let Some(m) = serde_json::Number::from_f64(short) {
                    *n = m;
                }
            }
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(shortest_f32),
        serde_json::Value::Object(o) => o.values_mut().for_each(shortest_f32),
        _ => {}
    }
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

    #[test]
    fn f32_values_print_as_given() {
        #[derive(serde::Serialize)]
        struct P {
            a: f32,
            b: Vec<f32>,
            n: u32,
            d: f64,
        }
        let mut v = serde_json::to_value(P {
            a: 0.2,
            b: vec![0.1, 1.0e-7, 3.0],
            n: 7,
            d: 0.1,
        })
        .unwrap();
        shortest_f32(&mut v);
        assert_eq!(
            v.to_string(),
            r#"{"a":0.2,"b":[0.1,1e-7,3.0],"d":0.1,"n":7}"#
        );
        // Deterministic, and the values read back as the same f32.
        let mut again = v.clone();
        shortest_f32(&mut again);
        assert_eq!(again, v);
        assert_eq!(v["a"].as_f64().unwrap() as f32, 0.2f32);
    }

    #[test]
    fn a_document_of_another_shape_is_named_as_not_what_was_asked() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("hv.json");
        std::fs::write(&p, r#"{"table": "hv", "nu": 10}"#).unwrap();
        let e = read_as::<Coeffs>(&p, "a coefficient file").unwrap_err();
        assert!(e.to_string().contains("not a coefficient file"), "{e}");
        std::fs::write(&p, "{").unwrap();
        let e = read_as::<Coeffs>(&p, "a coefficient file").unwrap_err();
        assert!(!e.to_string().contains("not a"), "{e}");
    }

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
