//! End-to-end test support for ICMS (tests live in `tests/tests/`).
