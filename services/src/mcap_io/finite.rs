//! A serde serializer that writes nothing and stops at the first NaN or infinity, reporting the
//! path of the field that holds it.
//!
//! `serde_json` silently writes `null` for non-finite floats, which a reader then fails to decode
//! (or worse, decodes as "absent"). The session writer runs this check before serialising.

use std::fmt;

use serde::ser::{self, Serialize};

/// The first non-finite float found in a value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NonFinite {
    /// Field path, e.g. `transforms[2].translation.x` (empty for a top-level float).
    pub path: String,
    /// The value (NaN or ±inf).
    pub value: f64,
}

/// Walks `value` and returns the first non-finite `f32`/`f64`, or `Err` with the message of a
/// `Serialize` implementation that failed.
pub(crate) fn find_non_finite<T: Serialize + ?Sized>(
    value: &T,
) -> Result<Option<NonFinite>, String> {
    let mut checker = Checker { path: Vec::new() };
    match value.serialize(&mut checker) {
        Ok(()) => Ok(None),
        Err(CheckError::NonFinite(found)) => Ok(Some(found)),
        Err(CheckError::Custom(msg)) => Err(msg),
    }
}

enum Segment {
    Field(&'static str),
    Key(String),
    Index(usize),
}

struct Checker {
    path: Vec<Segment>,
}

impl Checker {
    fn path_string(&self) -> String {
        let mut out = String::new();
        for seg in &self.path {
            match seg {
                Segment::Field(name) => {
                    if !out.is_empty() {
                        out.push('.');
                    }
                    out.push_str(name);
                }
                Segment::Key(key) => {
                    if !out.is_empty() {
                        out.push('.');
                    }
                    out.push_str(key);
                }
                Segment::Index(i) => {
                    out.push('[');
                    out.push_str(&i.to_string());
                    out.push(']');
                }
            }
        }
        out
    }

    fn check(&self, v: f64) -> Result<(), CheckError> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(CheckError::NonFinite(NonFinite {
                path: self.path_string(),
                value: v,
            }))
        }
    }

    fn nested<T: Serialize + ?Sized>(&mut self, seg: Segment, value: &T) -> Result<(), CheckError> {
        self.path.push(seg);
        let result = value.serialize(&mut *self);
        self.path.pop();
        result
    }
}

#[derive(Debug)]
enum CheckError {
    NonFinite(NonFinite),
    Custom(String),
}

impl fmt::Display for CheckError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CheckError::NonFinite(n) => write!(f, "non-finite {} at {}", n.value, n.path),
            CheckError::Custom(msg) => f.write_str(msg),
        }
    }
}

impl std::error::Error for CheckError {}

impl ser::Error for CheckError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        CheckError::Custom(msg.to_string())
    }
}

/// Compound serializer state: the checker plus the next element index, and whether a segment
/// (a variant name) was pushed on entry and must be popped on `end()`.
struct Compound<'a> {
    checker: &'a mut Checker,
    index: usize,
    pushed: bool,
    pending_key: Option<String>,
}

impl Compound<'_> {
    fn finish(self) -> Result<(), CheckError> {
        if self.pushed {
            self.checker.path.pop();
        }
        Ok(())
    }

    fn element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), CheckError> {
        let i = self.index;
        self.index += 1;
        self.checker.nested(Segment::Index(i), value)
    }
}

impl<'a> ser::Serializer for &'a mut Checker {
    type Ok = ();
    type Error = CheckError;
    type SerializeSeq = Compound<'a>;
    type SerializeTuple = Compound<'a>;
    type SerializeTupleStruct = Compound<'a>;
    type SerializeTupleVariant = Compound<'a>;
    type SerializeMap = Compound<'a>;
    type SerializeStruct = Compound<'a>;
    type SerializeStructVariant = Compound<'a>;

    fn serialize_bool(self, _: bool) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_i8(self, _: i8) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_i16(self, _: i16) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_i32(self, _: i32) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_i64(self, _: i64) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_i128(self, _: i128) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_u8(self, _: u8) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_u16(self, _: u16) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_u32(self, _: u32) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_u64(self, _: u64) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_u128(self, _: u128) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_f32(self, v: f32) -> Result<(), CheckError> {
        self.check(f64::from(v))
    }
    fn serialize_f64(self, v: f64) -> Result<(), CheckError> {
        self.check(v)
    }
    fn serialize_char(self, _: char) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_str(self, _: &str) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_none(self) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<(), CheckError> {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
    ) -> Result<(), CheckError> {
        Ok(())
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        value: &T,
    ) -> Result<(), CheckError> {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<(), CheckError> {
        self.nested(Segment::Field(variant), value)
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Compound<'a>, CheckError> {
        Ok(compound(self, None))
    }
    fn serialize_tuple(self, _: usize) -> Result<Compound<'a>, CheckError> {
        Ok(compound(self, None))
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Compound<'a>, CheckError> {
        Ok(compound(self, None))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Compound<'a>, CheckError> {
        Ok(compound(self, Some(variant)))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Compound<'a>, CheckError> {
        Ok(compound(self, None))
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Compound<'a>, CheckError> {
        Ok(compound(self, None))
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        _: usize,
    ) -> Result<Compound<'a>, CheckError> {
        Ok(compound(self, Some(variant)))
    }
}

fn compound<'a>(checker: &'a mut Checker, variant: Option<&'static str>) -> Compound<'a> {
    if let Some(v) = variant {
        checker.path.push(Segment::Field(v));
    }
    Compound {
        checker,
        index: 0,
        pushed: variant.is_some(),
        pending_key: None,
    }
}

/// The serde compound traits whose elements are positional (sequences and tuples): each element
/// is checked under its index, and `end` closes the compound. One body for the four traits.
macro_rules! positional_compound {
    ($($trait:ident :: $method:ident),+ $(,)?) => {$(
        impl ser::$trait for Compound<'_> {
            type Ok = ();
            type Error = CheckError;
            fn $method<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), CheckError> {
                self.element(value)
            }
            fn end(self) -> Result<(), CheckError> {
                self.finish()
            }
        }
    )+};
}

positional_compound!(
    SerializeSeq::serialize_element,
    SerializeTuple::serialize_element,
    SerializeTupleStruct::serialize_field,
    SerializeTupleVariant::serialize_field,
);

impl ser::SerializeMap for Compound<'_> {
    type Ok = ();
    type Error = CheckError;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, key: &T) -> Result<(), CheckError> {
        // Keys are named in the path; a float key is checked like any other float.
        key.serialize(&mut *self.checker)?;
        let name = serde_json::to_string(key).unwrap_or_else(|_| "?".to_owned());
        let name = name.trim_matches('"').to_owned();
        self.pending_key = Some(name);
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), CheckError> {
        let key = self.pending_key.take().unwrap_or_else(|| "?".to_owned());
        self.checker.nested(Segment::Key(key), value)
    }
    fn end(self) -> Result<(), CheckError> {
        self.finish()
    }
}

/// The serde compound traits whose fields are named (structs and struct variants): each field is
/// checked under its name. One body for the two traits.
macro_rules! named_compound {
    ($($trait:ident),+ $(,)?) => {$(
        impl ser::$trait for Compound<'_> {
            type Ok = ();
            type Error = CheckError;
            fn serialize_field<T: Serialize + ?Sized>(
                &mut self,
                key: &'static str,
                value: &T,
            ) -> Result<(), CheckError> {
                self.checker.nested(Segment::Field(key), value)
            }
            fn end(self) -> Result<(), CheckError> {
                self.finish()
            }
        }
    )+};
}

named_compound!(SerializeStruct, SerializeStructVariant);

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[derive(serde::Serialize)]
    struct V {
        x: f64,
        y: f32,
    }

    #[derive(serde::Serialize)]
    struct Outer {
        name: String,
        items: Vec<V>,
        extra: BTreeMap<String, f64>,
        opt: Option<f64>,
    }

    fn outer() -> Outer {
        Outer {
            name: "a".into(),
            items: vec![V { x: 1.0, y: 2.0 }, V { x: 3.0, y: 4.0 }],
            extra: BTreeMap::from([("k".to_owned(), 1.0)]),
            opt: Some(0.5),
        }
    }

    #[test]
    fn finite_values_pass() {
        assert_eq!(find_non_finite(&outer()), Ok(None));
    }

    #[test]
    fn nan_in_a_vector_element_is_found_with_its_path() {
        let mut o = outer();
        o.items[1].y = f32::NAN;
        let found = find_non_finite(&o).unwrap().unwrap();
        assert_eq!(found.path, "items[1].y");
        assert!(found.value.is_nan());
    }

    #[test]
    fn infinity_in_a_map_or_option_is_found() {
        let mut o = outer();
        o.extra.insert("force".into(), f64::INFINITY);
        assert_eq!(find_non_finite(&o).unwrap().unwrap().path, "extra.force");
        let mut o = outer();
        o.opt = Some(f64::NEG_INFINITY);
        assert_eq!(find_non_finite(&o).unwrap().unwrap().path, "opt");
    }
}
