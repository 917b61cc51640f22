//! ICMS services: recording, segmentation, store.
