//! Enums named by a lower-case word in files, the API and the data base (shapes, contact
//! models, phases, grasp styles): one [`Named`] trait with the names, and
//! [`named_enum!`](crate::named_enum), which derives from them the parsing every edge uses —
//! `Deserialize`, `FromStr` (command-line flags, query strings, data base columns) and
//! `Display` — so that no code outside these impls compares a name by hand. An unknown name is
//! refused with [`UnknownName`], which says what was expected.

use std::fmt;

/// A word that names none of an enum's values.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownName {
    /// What the word should have named, in user words (`shape`, `contact model`, `phase`).
    pub what: &'static str,
    /// The word given.
    pub value: String,
    /// Every name accepted, in the enum's order.
    pub expected: Vec<&'static str>,
}

impl fmt::Display for UnknownName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown {} {:?}; expected one of {}",
            self.what,
            self.value,
            self.expected.join(", ")
        )
    }
}

impl std::error::Error for UnknownName {}

/// An enum whose values are named by words ([`named_enum!`](crate::named_enum) implements its
/// parsing and display from these).
pub trait Named: Sized + Copy + PartialEq + 'static {
    /// What a value is, in user words (`shape`, `contact model`, `phase`).
    const WHAT: &'static str;
    /// Every value, in the order errors list their names.
    const ALL: &'static [Self];

    /// The value's name, as in files, the API and the data base.
    fn name(self) -> &'static str;

    /// Every name, in [`ALL`](Self::ALL)'s order.
    fn names() -> Vec<&'static str> {
        Self::ALL.iter().map(|v| v.name()).collect()
    }

    /// The value named `s`; an error naming what was expected otherwise.
    fn from_name(s: &str) -> Result<Self, UnknownName> {
        Self::ALL
            .iter()
            .copied()
            .find(|v| v.name() == s)
            .ok_or_else(|| UnknownName {
                what: Self::WHAT,
                value: s.to_owned(),
                expected: Self::names(),
            })
    }
}

/// Implements `FromStr`, `Display` (honouring width and alignment: `{:<8}`) and
/// `Deserialize` (from a string; an unknown one is refused naming the accepted names) for a
/// type that implements [`Named`]. `Serialize` stays with the type (derived, so that the
/// OpenAPI derive reads the same names); a test of each type checks that both agree.
#[macro_export]
macro_rules! named_enum {
    ($ty:ty) => {
        impl ::core::str::FromStr for $ty {
            type Err = $crate::names::UnknownName;
            fn from_str(s: &str) -> ::core::result::Result<Self, Self::Err> {
                <$ty as $crate::names::Named>::from_name(s)
            }
        }

        impl ::core::fmt::Display for $ty {
            fn fmt(&self, f: &mut ::core::fmt::Formatter<'_>) -> ::core::fmt::Result {
                f.pad(<$ty as $crate::names::Named>::name(*self))
            }
        }

        impl<'de> ::serde::Deserialize<'de> for $ty {
            fn deserialize<D: ::serde::Deserializer<'de>>(
                d: D,
            ) -> ::core::result::Result<Self, D::Error> {
                struct NameVisitor;
                impl ::serde::de::Visitor<'_> for NameVisitor {
                    type Value = $ty;
                    fn expecting(&self, f: &mut ::core::fmt::Formatter) -> ::core::fmt::Result {
                        write!(
                            f,
                            "a {} name ({})",
                            <$ty as $crate::names::Named>::WHAT,
                            <$ty as $crate::names::Named>::names().join(", ")
                        )
                    }
                    fn visit_str<E: ::serde::de::Error>(
                        self,
                        v: &str,
                    ) -> ::core::result::Result<$ty, E> {
                        <$ty as $crate::names::Named>::from_name(v).map_err(E::custom)
                    }
                }
                d.deserialize_str(NameVisitor)
            }
        }
    };
}

/// Checks that `serde` writes every value of `T` as its [`Named::name`] and reads it back:
/// the derived `Serialize` and the names of [`Named`] agree. For the tests of each named enum.
#[cfg(test)]
pub(crate) fn assert_serde_agrees<T>()
where
    T: Named + serde::Serialize + serde::de::DeserializeOwned + fmt::Debug,
{
    for v in T::ALL {
        let json = serde_json::to_value(v).unwrap();
        assert_eq!(json, serde_json::Value::from(v.name()), "{v:?}");
        assert_eq!(serde_json::from_value::<T>(json).unwrap(), *v);
    }
}
