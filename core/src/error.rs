//! Small errors shared by several modules of core. Each is `Copy` and a few bytes, so per-frame code can return
//! them without cost; module-specific errors (decoding, model files, depth frames) live beside their code.

use core::fmt;

/// A value lies outside the range its type documents (a timestamp of 2^48 µs or more, an unknown enum value, a
/// confidence above 100).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RangeError;

impl fmt::Display for RangeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("value out of range")
    }
}

impl core::error::Error for RangeError {}

/// A caller buffer had the wrong length for the request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BufferLenError {
    /// Length required.
    pub expected: usize,
    /// Length given.
    pub found: usize,
}

impl fmt::Display for BufferLenError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "buffer holds {} points, {} required",
            self.found, self.expected
        )
    }
}

impl core::error::Error for BufferLenError {}
