//! supine-tests: host-side tests that span crates (end to end, fault injection, allocation counting, determinism,
//! external peers). The tests live in `tests/tests/*.rs`; this library is their kit:
//! - [`alloc_count`]: the counting global allocator every "allocates nothing per frame" test installs;
//! - [`fixtures`]: fixture model files (core's, written with `model_file::write`) and the committed recording.

pub mod alloc_count;
pub mod fixtures;
