//! Structs that a user writes as JSON objects only.
//!
//! serde's derived `Deserialize` for a struct also accepts its *sequence form*: the field values
//! in declaration order, so `[{"shape": "sphere", ...}, [0, 0, -9.81], ...]` was taken for a
//! grasp file. [`object_only!`](crate::object_only) replaces that impl by one that asks the
//! deserializer for a map (a JSON object) and refuses anything else with "invalid type: …,
//! expected `WHAT`". The struct keeps its `#[derive(Deserialize)]`, with
//! `#[serde(remote = "Self")]` so that the derived code becomes an inherent
//! `Type::deserialize` (and `Type::serialize`) that the new impl calls on the object's
//! entries: field paths, `deny_unknown_fields`, defaults and the `expecting` text all stay.

/// Implements `Deserialize` (and, with `serialize`, `Serialize`) for a struct that derives them
/// under `#[serde(remote = "Self")]`, accepting only a JSON object; `$what` names what was
/// expected in the error (user words, not the Rust type).
#[macro_export]
macro_rules! object_only {
    ($ty:ident, $what:expr) => {
        impl<'de> ::serde::Deserialize<'de> for $ty {
            fn deserialize<D: ::serde::Deserializer<'de>>(
                d: D,
            ) -> ::core::result::Result<Self, D::Error> {
                struct ObjectVisitor;
                impl<'de> ::serde::de::Visitor<'de> for ObjectVisitor {
                    type Value = $ty;
                    fn expecting(&self, f: &mut ::core::fmt::Formatter) -> ::core::fmt::Result {
                        f.write_str($what)
                    }
                    fn visit_map<A: ::serde::de::MapAccess<'de>>(
                        self,
                        map: A,
                    ) -> ::core::result::Result<$ty, A::Error> {
                        $ty::deserialize(::serde::de::value::MapAccessDeserializer::new(map))
                    }
                }
                d.deserialize_map(ObjectVisitor)
            }
        }
    };
    ($ty:ident, $what:expr, serialize) => {
        $crate::object_only!($ty, $what);
        impl ::serde::Serialize for $ty {
            fn serialize<S: ::serde::Serializer>(
                &self,
                s: S,
            ) -> ::core::result::Result<S::Ok, S::Error> {
                $ty::serialize(self, s)
            }
        }
    };
}
