//! Why bytes did not become a message, or a message did not become bytes. Errors are small `Copy` values so that
//! decoders can return and count them per frame without any cost beyond a byte or two.

use core::fmt;

/// Why a serial frame (or the payload of a reassembled CAN group) could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum DecodeError {
    /// Fewer bytes than the smallest frame (version, kind and CRC).
    TooShort,
    /// The checksum (CRC-32C on serial, CRC-8 on CAN) does not match the bytes.
    BadCrc,
    /// The version byte is one this decoder does not understand.
    BadVersion(u8),
    /// The kind byte names no message of this protocol version.
    UnknownKind(u8),
    /// The payload ended before every field of the message was read.
    Truncated,
    /// Bytes are left over after the last field of the message.
    TrailingBytes,
    /// A field holds a value outside its documented range (confidence above 100, a non-unit quaternion, an
    /// unknown enum value, a timestamp of 2^48 µs or more).
    InvalidValue,
    /// The payload is not valid postcard (an over-long varint, for example).
    Malformed,
    /// The COBS framing is broken: a block runs past the end of the frame.
    Cobs,
    /// More bytes arrived between two delimiters than the decoder's buffer holds.
    Oversized,
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DecodeError::TooShort => f.write_str("frame too short"),
            DecodeError::BadCrc => f.write_str("checksum mismatch"),
            DecodeError::BadVersion(v) => write!(f, "unsupported protocol version {v}"),
            DecodeError::UnknownKind(k) => write!(f, "unknown message kind {k}"),
            DecodeError::Truncated => f.write_str("payload ends before the last field"),
            DecodeError::TrailingBytes => f.write_str("bytes left after the last field"),
            DecodeError::InvalidValue => f.write_str("field value out of range"),
            DecodeError::Malformed => f.write_str("malformed payload encoding"),
            DecodeError::Cobs => f.write_str("broken COBS framing"),
            DecodeError::Oversized => f.write_str("frame longer than the decoder buffer"),
        }
    }
}

/// Why a message could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum EncodeError {
    /// The output buffer is smaller than the encoded message.
    BufferTooSmall,
    /// A value does not fit the narrower CAN signal (positions and distances are i16 mm on CAN).
    NotRepresentable,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::BufferTooSmall => f.write_str("output buffer too small"),
            EncodeError::NotRepresentable => f.write_str("value outside the range of its CAN signal"),
        }
    }
}

/// A raw value outside the range of a validated wire type (the crate-wide [`crate::error::RangeError`]).
pub use crate::error::RangeError;

impl core::error::Error for DecodeError {}
impl core::error::Error for EncodeError {}
