//! Criterion benchmarks of the DexiTac crates, one file per stage or
//! subsystem: `stages` (tactile pipeline), `camera_decode`, `loop_latency`
//! (the simulated closed loop), `recording` and `view`. Kept in their own
//! crate so that no other crate's tests build criterion (ARCHITECTURE.md).
//! Run with `cargo bench -p dexitac-benches --bench <name>`.
