//! supine-drivers: where supine meets hardware and files.
//!
//! Depth sources lend [`supine_core::depth::DepthFrame`]s; packet links carry `supine_core::wire` messages to and
//! from the arm controller. `unsafe` lives only in one `sys` module per FFI backend.
