//! `Params` → command-line arguments: the inverse of clap's parsing, derived from the same
//! struct, so a ninja edge runs exactly the bake the runner would run in-process.
//!
//! Fields are read through serde (a small serializer that keeps each field's value as text,
//! with the value's own `Display`, so an `f32` prints as the shortest text that parses back to
//! the same `f32`) and matched to clap's arguments by id (the field's name). Only fields that
//! differ from the default are emitted. The round trip `args → clap → Params` is tested for
//! every stage kind.

use serde::ser::{self, Impossible, Serialize};
use std::fmt::Display;

/// A field's value as the command line sees it.
#[derive(Clone, Debug, PartialEq)]
pub enum CliValue {
    /// A `bool` (a switch when the argument takes no value).
    Bool(bool),
    /// One value, as text.
    One(String),
    /// A list (`Vec<T>`): delimited or repeated, as the argument declares.
    List(Vec<String>),
    /// `None`: the flag is absent.
    Absent,
}

/// The struct's fields in declaration order with their values.
pub fn fields<P: Serialize>(p: &P) -> Result<Vec<(String, CliValue)>, String> {
    p.serialize(FieldsSer).map_err(|e| e.0)
}

/// Command-line arguments that make clap parse `P` back to `p`: `--flag=value` for every field
/// that differs from `P::default()`.
pub fn to_args<P>(p: &P) -> Result<Vec<String>, String>
where
    P: Serialize + Default + clap::Args,
{
    let cmd = P::augment_args(clap::Command::new("params"));
    let defaults: std::collections::HashMap<String, CliValue> =
        fields(&P::default())?.into_iter().collect();
    let mut args = Vec::new();
    for (name, value) in fields(p)? {
        if defaults.get(&name) == Some(&value) {
            continue;
        }
        let arg = cmd
            .get_arguments()
            .find(|a| a.get_id().as_str() == name)
            .ok_or_else(|| format!("parameter '{name}' has no command-line flag"))?;
        let flag = match (arg.get_long(), arg.get_short()) {
            (Some(l), _) => format!("--{l}"),
            (None, Some(s)) => format!("-{s}"),
            (None, None) => {
                return Err(format!("parameter '{name}' is positional; cannot emit it"))
            }
        };
        let takes_value = matches!(
            arg.get_action(),
            clap::ArgAction::Set | clap::ArgAction::Append
        );
        let text = |v: &str| enum_value(arg, v);
        match value {
            CliValue::Absent => {
                return Err(format!(
                    "parameter '{name}' is unset but its default is set; no flag can express that"
                ))
            }
            CliValue::Bool(b) if !takes_value => {
                let on = matches!(arg.get_action(), clap::ArgAction::SetTrue);
                if b != on {
                    return Err(format!(
                        "parameter '{name}' = {b} cannot be expressed by its switch"
                    ));
                }
                args.push(flag);
            }
            CliValue::Bool(b) => args.push(format!("{flag}={b}")),
            CliValue::One(v) => args.push(format!("{flag}={}", text(&v))),
            CliValue::List(vs) => match arg.get_value_delimiter() {
                Some(d) => args.push(format!(
                    "{flag}={}",
                    vs.iter()
                        .map(|v| text(v))
                        .collect::<Vec<_>>()
                        .join(&d.to_string())
                )),
                None => args.extend(vs.iter().map(|v| format!("{flag}={}", text(v)))),
            },
        }
    }
    Ok(args)
}

/// The spelling clap accepts for an enum value serde wrote as `v` (they may differ in case or
/// separators); `v` itself when the argument has no fixed set of values.
fn enum_value(arg: &clap::Arg, v: &str) -> String {
    let norm = |s: &str| {
        s.chars()
            .filter(|c| c.is_alphanumeric())
            .flat_map(|c| c.to_lowercase())
            .collect::<String>()
    };
    let pv = arg.get_possible_values();
    if pv.is_empty() || pv.iter().any(|p| p.get_name() == v) {
        return v.to_string();
    }
    pv.iter()
        .find(|p| norm(p.get_name()) == norm(v))
        .map(|p| p.get_name().to_string())
        .unwrap_or_else(|| v.to_string())
}

#[derive(Debug)]
/// A parameter value that has no command-line form.
pub struct SerError(String);
impl Display for SerError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for SerError {}
impl ser::Error for SerError {
    fn custom<T: Display>(msg: T) -> Self {
        SerError(msg.to_string())
    }
}

fn unsupported<T>(what: &str) -> Result<T, SerError> {
    Err(SerError(format!(
        "a {what} cannot be written as a command-line value"
    )))
}

/// Accepts only a struct and collects its fields.
struct FieldsSer;
struct FieldsCollector(Vec<(String, CliValue)>);

macro_rules! not_a_struct {
    ($($f:ident($($t:ty),*)),*) => {
        $(fn $f(self, $(_: $t),*) -> Result<Self::Ok, SerError> { unsupported("Params that is not a struct") })*
    };
}

impl ser::Serializer for FieldsSer {
    type Ok = Vec<(String, CliValue)>;
    type Error = SerError;
    type SerializeSeq = Impossible<Self::Ok, SerError>;
    type SerializeTuple = Impossible<Self::Ok, SerError>;
    type SerializeTupleStruct = Impossible<Self::Ok, SerError>;
    type SerializeTupleVariant = Impossible<Self::Ok, SerError>;
    type SerializeMap = Impossible<Self::Ok, SerError>;
    type SerializeStruct = FieldsCollector;
    type SerializeStructVariant = Impossible<Self::Ok, SerError>;

    fn serialize_struct(self, _: &'static str, len: usize) -> Result<FieldsCollector, SerError> {
        Ok(FieldsCollector(Vec::with_capacity(len)))
    }
    not_a_struct!(
        serialize_bool(bool),
        serialize_i8(i8),
        serialize_i16(i16),
        serialize_i32(i32),
        serialize_i64(i64),
        serialize_u8(u8),
        serialize_u16(u16),
        serialize_u32(u32),
        serialize_u64(u64),
        serialize_f32(f32),
        serialize_f64(f64),
        serialize_char(char),
        serialize_str(&str),
        serialize_bytes(&[u8]),
        serialize_none(),
        serialize_unit(),
        serialize_unit_struct(&'static str),
        serialize_unit_variant(&'static str, u32, &'static str)
    );
    fn serialize_some<T: ?Sized + Serialize>(self, _: &T) -> Result<Self::Ok, SerError> {
        unsupported("Params that is not a struct")
    }
    fn serialize_newtype_struct<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        v: &T,
    ) -> Result<Self::Ok, SerError> {
        v.serialize(self)
    }
    fn serialize_newtype_variant<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: &T,
    ) -> Result<Self::Ok, SerError> {
        unsupported("Params that is not a struct")
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Self::SerializeSeq, SerError> {
        unsupported("Params that is not a struct")
    }
    fn serialize_tuple(self, _: usize) -> Result<Self::SerializeTuple, SerError> {
        unsupported("Params that is not a struct")
    }
    fn serialize_tuple_struct(
        self,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeTupleStruct, SerError> {
        unsupported("Params that is not a struct")
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeTupleVariant, SerError> {
        unsupported("Params that is not a struct")
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self::SerializeMap, SerError> {
        unsupported("Params that is not a struct")
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeStructVariant, SerError> {
        unsupported("Params that is not a struct")
    }
}

impl ser::SerializeStruct for FieldsCollector {
    type Ok = Vec<(String, CliValue)>;
    type Error = SerError;
    fn serialize_field<T: ?Sized + Serialize>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), SerError> {
        let v = value
            .serialize(ValueSer)
            .map_err(|e| SerError(format!("parameter '{key}': {}", e.0)))?;
        self.0.push((key.to_string(), v));
        Ok(())
    }
    fn skip_field(&mut self, _: &'static str) -> Result<(), SerError> {
        Ok(())
    }
    fn end(self) -> Result<Self::Ok, SerError> {
        Ok(self.0)
    }
}

/// One field's value.
struct ValueSer;
struct ListCollector(Vec<String>);

impl ValueSer {
    fn one(v: impl Display) -> Result<CliValue, SerError> {
        Ok(CliValue::One(v.to_string()))
    }
}

/// Serializer methods whose value is one `Display`ed value.
macro_rules! as_one {
    ($($f:ident($t:ty)),*) => {
        $(fn $f(self, v: $t) -> Result<CliValue, SerError> { Self::one(v) })*
    };
}

impl ser::Serializer for ValueSer {
    type Ok = CliValue;
    type Error = SerError;
    type SerializeSeq = ListCollector;
    type SerializeTuple = ListCollector;
    type SerializeTupleStruct = ListCollector;
    type SerializeTupleVariant = Impossible<CliValue, SerError>;
    type SerializeMap = Impossible<CliValue, SerError>;
    type SerializeStruct = Impossible<CliValue, SerError>;
    type SerializeStructVariant = Impossible<CliValue, SerError>;

    fn serialize_bool(self, v: bool) -> Result<CliValue, SerError> {
        Ok(CliValue::Bool(v))
    }
    as_one!(
        serialize_i8(i8),
        serialize_i16(i16),
        serialize_i32(i32),
        serialize_i64(i64),
        serialize_u8(u8),
        serialize_u16(u16),
        serialize_u32(u32),
        serialize_u64(u64),
        serialize_f32(f32),
        serialize_f64(f64),
        serialize_char(char),
        serialize_str(&str)
    );
    fn serialize_bytes(self, _: &[u8]) -> Result<CliValue, SerError> {
        unsupported("byte string")
    }
    fn serialize_none(self) -> Result<CliValue, SerError> {
        Ok(CliValue::Absent)
    }
    fn serialize_some<T: ?Sized + Serialize>(self, v: &T) -> Result<CliValue, SerError> {
        v.serialize(self)
    }
    fn serialize_unit(self) -> Result<CliValue, SerError> {
        Ok(CliValue::Absent)
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<CliValue, SerError> {
        Ok(CliValue::Absent)
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
    ) -> Result<CliValue, SerError> {
        Self::one(variant)
    }
    fn serialize_newtype_struct<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        v: &T,
    ) -> Result<CliValue, SerError> {
        v.serialize(self)
    }
    fn serialize_newtype_variant<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: &T,
    ) -> Result<CliValue, SerError> {
        unsupported("enum variant with data")
    }
    fn serialize_seq(self, len: Option<usize>) -> Result<ListCollector, SerError> {
        Ok(ListCollector(Vec::with_capacity(len.unwrap_or(0))))
    }
    fn serialize_tuple(self, len: usize) -> Result<ListCollector, SerError> {
        Ok(ListCollector(Vec::with_capacity(len)))
    }
    fn serialize_tuple_struct(
        self,
        _: &'static str,
        len: usize,
    ) -> Result<ListCollector, SerError> {
        Ok(ListCollector(Vec::with_capacity(len)))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeTupleVariant, SerError> {
        unsupported("enum variant with data")
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self::SerializeMap, SerError> {
        unsupported("map")
    }
    fn serialize_struct(
        self,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeStruct, SerError> {
        unsupported("nested struct")
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeStructVariant, SerError> {
        unsupported("enum variant with data")
    }
}

impl ListCollector {
    fn push<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), SerError> {
        match v.serialize(ValueSer)? {
            CliValue::One(s) => self.0.push(s),
            CliValue::Bool(b) => self.0.push(b.to_string()),
            _ => return unsupported("list of lists or options"),
        }
        Ok(())
    }
}

/// The list-collecting traits: every element is pushed, the end is the list.
macro_rules! list_collector {
    ($($tr:ident::$f:ident),*) => {
        $(impl ser::$tr for ListCollector {
            type Ok = CliValue;
            type Error = SerError;
            fn $f<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), SerError> {
                self.push(v)
            }
            fn end(self) -> Result<CliValue, SerError> {
                Ok(CliValue::List(self.0))
            }
        })*
    };
}

list_collector!(
    SerializeSeq::serialize_element,
    SerializeTuple::serialize_element,
    SerializeTupleStruct::serialize_field
);

/// Parses `args` with clap into `P` (the other half of the round trip).
pub fn from_args<P: clap::Args + clap::FromArgMatches>(args: &[String]) -> Result<P, String> {
    // A flag the CLI requires (hv-lut --nu) is left out of the defaults' arguments: RON
    // validation, not clap, refuses a pipeline without it.
    let cmd = P::augment_args(clap::Command::new("params").no_binary_name(true))
        .mut_args(|a| a.required(false));
    let m = cmd.try_get_matches_from(args).map_err(|e| e.to_string())?;
    P::from_arg_matches(&m).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(
        Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
    )]
    #[serde(rename_all = "kebab-case")]
    enum Mode {
        FastPath,
        Exact,
    }

    #[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
    #[serde(deny_unknown_fields, default)]
    struct Demo {
        #[arg(long)]
        size: Option<usize>,
        #[arg(long, default_value_t = 0.5, allow_negative_numbers = true)]
        roughness: f32,
        #[arg(long)]
        half: bool,
        #[arg(long, value_enum, default_value_t = Mode::Exact)]
        mode: Mode,
        #[arg(long, value_delimiter = ',', default_values_t = vec![0.2f32, 1.0])]
        alphas: Vec<f32>,
        #[arg(long = "name-tag", default_value = "x")]
        name: String,
    }
    impl Default for Demo {
        fn default() -> Self {
            ibl_core::params::clap_defaults()
        }
    }

    #[test]
    fn defaults_emit_nothing() {
        assert_eq!(to_args(&Demo::default()).unwrap(), Vec::<String>::new());
    }

    #[test]
    fn every_field_round_trips_through_clap() {
        let p = Demo {
            size: Some(64),
            roughness: -0.1f32 + 0.0000001,
            half: true,
            mode: Mode::FastPath,
            alphas: vec![0.1, 0.466_7, 1e-7],
            name: "a b=c".into(),
        };
        let args = to_args(&p).unwrap();
        eprintln!("{args:?}");
        assert!(args.contains(&"--mode=fast-path".to_string()));
        assert!(args.contains(&"--half".to_string()));
        let back: Demo = from_args(&args).unwrap();
        assert_eq!(back, p);
    }
}
