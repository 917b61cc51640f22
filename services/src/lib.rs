//! ICMS services: recording, segmentation, store.
pub mod store;
