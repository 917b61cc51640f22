//! Checking that a message is valid JSON without building anything.

/// `Ok` if `bytes` is one valid JSON value (surrounded by optional whitespace).
pub(crate) fn validate(bytes: &[u8]) -> Result<(), serde_json::Error> {
    serde_json::from_slice::<serde::de::IgnoredAny>(bytes).map(|_| ())
}
