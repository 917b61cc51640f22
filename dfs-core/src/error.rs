//! The one error type of dfs-core.

use thiserror::Error;

/// Everything that can go wrong in dfs-core. Bad input is reported, never a panic.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DfsError {
    /// A joint angle or torque (or other input) is NaN or infinite.
    #[error("{what} is not finite (index {index}: {value:?})")]
    NotFinite {
        /// Which input (for example "joint angle").
        what: &'static str,
        /// Index of the offending element.
        index: usize,
        /// The value found.
        value: f64,
    },
    /// An input is finite but outside its allowed range. (Numbers in `Debug` form: 1e300, not
    /// three hundred digits.)
    #[error("{what} {index} = {value:?} is outside [{lower:?}, {upper:?}]")]
    OutOfRange {
        /// Which input (for example "joint angle").
        what: &'static str,
        /// Index of the offending element.
        index: usize,
        /// The value found.
        value: f64,
        /// Lower bound.
        lower: f64,
        /// Upper bound.
        upper: f64,
    },
    /// A vector has the wrong number of elements.
    #[error("{what} has {got} elements, expected {expected}")]
    WrongLength {
        /// Which input.
        what: &'static str,
        /// Number of elements given.
        got: usize,
        /// Number expected.
        expected: usize,
    },
    /// The simulation became unstable: the object's state would no longer be finite. The
    /// tick is refused and the object keeps its last finite state.
    #[error(
        "the simulation diverged: the object's {what} is no longer finite (the DFS steps the \
         object explicitly at its tick; a very light or thin object against the contact springs \
         is outside its stable range)"
    )]
    Diverged {
        /// What went non-finite (for example "pose").
        what: &'static str,
    },
    /// A result overflowed: a computed value is NaN or infinite although every input was
    /// finite and in range (the guard that keeps NaN out of every output).
    #[error("{what} is not a finite number: the computation overflowed")]
    Overflow {
        /// The output that overflowed (for example `contacts[2].feedback`).
        what: String,
    },
    /// The work was stopped before it finished (see [`crate::Stop`]).
    #[error(
        "the work was cancelled before it finished (its deadline passed, its request went \
         away, or the server is shutting down)"
    )]
    Cancelled,
    /// A model or parameter is invalid; the message names the field.
    #[error("invalid {field}: {reason}")]
    Invalid {
        /// The field (for example "object.mass").
        field: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl DfsError {
    /// Shorthand for [`DfsError::Invalid`].
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        DfsError::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

/// Result alias of dfs-core.
pub type Result<T> = std::result::Result<T, DfsError>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huge_values_are_printed_short() {
        let e = DfsError::OutOfRange {
            what: "joint angle",
            index: 3,
            value: 1e300,
            lower: -0.5,
            upper: 1.5,
        };
        assert_eq!(
            e.to_string(),
            "joint angle 3 = 1e300 is outside [-0.5, 1.5]"
        );
    }
}
