//! Serial framing: `0x00 ‖ COBS(version ‖ kind ‖ postcard(seq, timestamp, body) ‖ CRC-32C LE) ‖ 0x00`.
//!
//! [`Frame`] is the Packet view of one decoded (un-COBSed) frame; [`Message::emit_plain`] / [`Message::parse`]
//! convert between it and the Repr, and [`Message::encode_serial`] / [`decode_plain`] add the COBS layer. A frame
//! is at most [`MAX_PLAIN_LEN`] bytes (112 for the largest message), so encoding needs no more than
//! [`MAX_WIRE_LEN`] bytes of caller stack; cost per frame is one CRC pass, one COBS pass and the postcard walk.
//!
//! CRC-32C rather than CRC-16: after garbage on the line every run of bytes between two zeros is a candidate
//! frame, and a 16-bit check would accept one random candidate in 65 536; CRC-32C (Hamming distance 6 at these
//! lengths) makes that one in 4·10^9 for two bytes more per frame. See SPEC.md.

use serde::{Deserialize, Serialize};

use super::VERSION;
use super::cobs;
use super::error::{DecodeError, EncodeError};
use super::message::{Body, Kind, Message};
use super::types::Timestamp;
use crate::crc::crc32c;

/// Byte offsets of the fixed fields of a decoded serial frame.
mod field {
    /// Protocol version.
    pub const VERSION: usize = 0;
    /// Message kind.
    pub const KIND: usize = 1;
    /// Start of the postcard payload.
    pub const PAYLOAD: usize = 2;
    /// Length of the trailing CRC-32C.
    pub const CRC_LEN: usize = 4;
}

/// The smallest possible decoded frame: version, kind and CRC with an empty payload.
pub const MIN_PLAIN_LEN: usize = field::PAYLOAD + field::CRC_LEN;
/// Upper bound on a decoded frame of this protocol version (the largest, salient points, needs 112 bytes).
pub const MAX_PLAIN_LEN: usize = 128;
/// Upper bound on a frame on the wire: COBS overhead and both delimiters included.
pub const MAX_WIRE_LEN: usize = MAX_PLAIN_LEN + cobs::max_overhead(MAX_PLAIN_LEN) + 2;

/// A decoded (un-COBSed) serial frame: version, kind, postcard payload and CRC.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Frame<T> {
    /// Wrap a buffer without any check; accessors then return defaults instead of panicking on short buffers.
    pub const fn new_unchecked(buffer: T) -> Frame<T> {
        Frame { buffer }
    }

    /// Wrap a buffer after [`Frame::check_len`] and [`Frame::check_crc`].
    pub fn new_checked(buffer: T) -> Result<Frame<T>, DecodeError> {
        let frame = Frame::new_unchecked(buffer);
        frame.check_len()?;
        frame.check_crc()?;
        Ok(frame)
    }

    /// Ensure that no accessor returns a default because the buffer is too short.
    pub fn check_len(&self) -> Result<(), DecodeError> {
        if self.buffer.as_ref().len() < MIN_PLAIN_LEN {
            Err(DecodeError::TooShort)
        } else {
            Ok(())
        }
    }

    /// Ensure the CRC-32C matches the bytes it covers.
    pub fn check_crc(&self) -> Result<(), DecodeError> {
        if self.crc() == crc32c(self.covered()) {
            Ok(())
        } else {
            Err(DecodeError::BadCrc)
        }
    }

    /// The protocol version byte (0 if the buffer is empty).
    pub fn version(&self) -> u8 {
        self.buffer.as_ref().get(field::VERSION).copied().unwrap_or(0)
    }

    /// The raw kind byte (0xFF if the buffer is too short).
    pub fn kind_raw(&self) -> u8 {
        self.buffer.as_ref().get(field::KIND).copied().unwrap_or(0xFF)
    }

    /// The postcard payload between the kind byte and the CRC (empty if the buffer is too short).
    pub fn payload(&self) -> &[u8] {
        let b = self.buffer.as_ref();
        let end = b.len().saturating_sub(field::CRC_LEN);
        b.get(field::PAYLOAD..end).unwrap_or(&[])
    }

    /// The CRC-32C stored in the frame (0 if the buffer is too short).
    pub fn crc(&self) -> u32 {
        let b = self.buffer.as_ref();
        let at = b.len().saturating_sub(field::CRC_LEN);
        match b.get(at..).and_then(|s| <[u8; 4]>::try_from(s).ok()) {
            Some(bytes) if b.len() >= MIN_PLAIN_LEN => u32::from_le_bytes(bytes),
            _ => 0,
        }
    }

    /// The bytes the CRC covers: everything before it.
    fn covered(&self) -> &[u8] {
        let b = self.buffer.as_ref();
        b.get(..b.len().saturating_sub(field::CRC_LEN)).unwrap_or(&[])
    }

    /// The whole frame.
    pub fn as_bytes(&self) -> &[u8] {
        self.buffer.as_ref()
    }
}

/// The envelope fields in the postcard payload, ahead of the body.
#[derive(Serialize, Deserialize)]
struct Header {
    seq: u16,
    timestamp: Timestamp,
}

fn de_error(e: postcard::Error) -> DecodeError {
    match e {
        postcard::Error::DeserializeUnexpectedEnd => DecodeError::Truncated,
        postcard::Error::SerdeDeCustom => DecodeError::InvalidValue,
        _ => DecodeError::Malformed,
    }
}

/// Deserialize one `T` from the front of `bytes`, returning the rest.
fn take<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> Result<(T, &[u8]), DecodeError> {
    postcard::take_from_bytes::<T>(bytes).map_err(de_error)
}

/// Serialize `value` at the front of `buf`, returning the bytes written.
fn put<T: Serialize>(value: &T, buf: &mut [u8]) -> Result<usize, EncodeError> {
    postcard::to_slice(value, buf)
        .map(|s| s.len())
        .map_err(|_| EncodeError::BufferTooSmall)
}

impl Message {
    /// Parse a CRC-checked frame into a message.
    pub fn parse<T: AsRef<[u8]>>(frame: &Frame<T>) -> Result<Message, DecodeError> {
        frame.check_len()?;
        if frame.version() != VERSION {
            return Err(DecodeError::BadVersion(frame.version()));
        }
        let kind = Kind::from_u8(frame.kind_raw()).ok_or(DecodeError::UnknownKind(frame.kind_raw()))?;
        let (header, rest) = take::<Header>(frame.payload())?;
        let (body, rest) = match kind {
            Kind::TorsoPose => take(rest).map(|(b, r)| (Body::TorsoPose(b), r))?,
            Kind::SalientPoints => take(rest).map(|(b, r)| (Body::SalientPoints(b), r))?,
            Kind::Probe => take(rest).map(|(b, r)| (Body::Probe(b), r))?,
            Kind::BodyShape => take(rest).map(|(b, r)| (Body::BodyShape(b), r))?,
            Kind::Health => take(rest).map(|(b, r)| (Body::Health(b), r))?,
            Kind::ArmState => take(rest).map(|(b, r)| (Body::ArmState(b), r))?,
            Kind::Command => take(rest).map(|(b, r)| (Body::Command(b), r))?,
        };
        if !rest.is_empty() {
            return Err(DecodeError::TrailingBytes);
        }
        Ok(Message {
            seq: header.seq,
            timestamp: header.timestamp,
            body,
        })
    }

    /// Write the decoded frame (version, kind, payload, CRC) into `buf`; the length written.
    pub fn emit_plain(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let head = buf.get_mut(..field::PAYLOAD).ok_or(EncodeError::BufferTooSmall)?;
        head.copy_from_slice(&[VERSION, self.kind() as u8]);
        let mut n = field::PAYLOAD;
        let header = Header {
            seq: self.seq,
            timestamp: self.timestamp,
        };
        n += put(&header, buf.get_mut(n..).ok_or(EncodeError::BufferTooSmall)?)?;
        let rest = buf.get_mut(n..).ok_or(EncodeError::BufferTooSmall)?;
        n += match &self.body {
            Body::TorsoPose(b) => put(b, rest)?,
            Body::SalientPoints(b) => put(b, rest)?,
            Body::Probe(b) => put(b, rest)?,
            Body::BodyShape(b) => put(b, rest)?,
            Body::Health(b) => put(b, rest)?,
            Body::ArmState(b) => put(b, rest)?,
            Body::Command(b) => put(b, rest)?,
        };
        let crc = crc32c(buf.get(..n).ok_or(EncodeError::BufferTooSmall)?);
        let tail = buf
            .get_mut(n..n + field::CRC_LEN)
            .ok_or(EncodeError::BufferTooSmall)?;
        tail.copy_from_slice(&crc.to_le_bytes());
        Ok(n + field::CRC_LEN)
    }

    /// Write the complete wire frame `0x00 ‖ COBS(frame) ‖ 0x00` into `out`; the length written.
    ///
    /// The leading delimiter costs one byte and means garbage or a cut-off frame before this one can never
    /// swallow it: the receiver always starts this frame afresh.
    pub fn encode_serial(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut plain = [0u8; MAX_PLAIN_LEN];
        let n = self.emit_plain(&mut plain)?;
        let plain = plain.get(..n).ok_or(EncodeError::BufferTooSmall)?;
        *out.first_mut().ok_or(EncodeError::BufferTooSmall)? = 0;
        let body = out.get_mut(1..).ok_or(EncodeError::BufferTooSmall)?;
        let m = cobs::encode(plain, body).ok_or(EncodeError::BufferTooSmall)?;
        *out.get_mut(1 + m).ok_or(EncodeError::BufferTooSmall)? = 0;
        Ok(m + 2)
    }
}

/// Decode one decoded (un-COBSed) frame: length, CRC, version, kind and payload checks, in that order.
pub fn decode_plain(bytes: &[u8]) -> Result<Message, DecodeError> {
    Message::parse(&Frame::new_checked(bytes)?)
}

/// Decode one COBS-encoded frame without delimiters, in place (the buffer is overwritten).
pub fn decode_cobs_in_place(buf: &mut [u8]) -> Result<Message, DecodeError> {
    let n = cobs::decode_in_place(buf).ok_or(DecodeError::Cobs)?;
    decode_plain(buf.get(..n).ok_or(DecodeError::Cobs)?)
}
