//! supine-tests: host-side tests that span crates (end to end, fault injection, allocation counting, determinism,
//! external peers). The tests live in `tests/tests/*.rs`; this library holds what they share.
