//! The decoders held to prost: property tests on generated and damaged messages, of the raw
//! topics (`decode.rs`, `shape.rs`, with the strategies of `strategies.rs`) and of the Foxglove
//! topics' checks (`check.rs`).

mod check;
mod decode;
mod shape;
mod strategies;
