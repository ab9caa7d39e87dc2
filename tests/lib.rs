//! End-to-end tests for DexiTac live in `tests/tests/`; this crate has no library code.
