//! How a link turns messages into the bytes its port carries and back: the [`Codec`] trait, the receive-side
//! error classes a link counts, and the [`Framing`] tag that fault injection uses to damage bytes realistically.

use std::fmt;

use supine_core::wire::{DecodeError, Message};

use super::error::LinkError;

/// What the encoded bytes of one message look like on the port.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Framing {
    /// One serial frame: postcard + CRC-32C, COBS-encoded, ending in the `0x00` delimiter.
    Serial,
    /// SLCAN ASCII lines (`t…\r`/`T…\r`), one per CAN frame of the message.
    Slcan,
    /// 16-byte `struct can_frame`s, one per CAN frame of the message.
    SocketCan,
}

impl Framing {
    /// A short lower-case name for JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Framing::Serial => "serial",
            Framing::Slcan => "slcan",
            Framing::SocketCan => "socketcan",
        }
    }
}

/// Why received bytes did not become a message (counted per class, never fatal).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum RxError {
    /// Broken framing: COBS error, frame too short, or more bytes than the decoder holds before a delimiter.
    Framing,
    /// Checksum mismatch (CRC-32C of a serial frame, CRC-8 of a CAN frame).
    Crc,
    /// A protocol version this decoder does not know.
    Version,
    /// A payload that is not a valid message (unknown kind, truncated, trailing bytes, value out of range).
    Decode,
    /// The CAN end-to-end counter jumped or repeated inside a message group.
    Sequence,
    /// A CAN message group was abandoned incomplete (a frame of it was lost or damaged).
    Reassembly,
    /// An SLCAN line that does not parse.
    Syntax,
    /// The SLCAN adapter answered BEL: it rejected a command.
    Adapter,
}

impl RxError {
    /// Every class, for iteration in reports.
    pub const ALL: [RxError; 8] = [
        RxError::Framing,
        RxError::Crc,
        RxError::Version,
        RxError::Decode,
        RxError::Sequence,
        RxError::Reassembly,
        RxError::Syntax,
        RxError::Adapter,
    ];

    /// A short lower-case name for JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            RxError::Framing => "framing",
            RxError::Crc => "crc",
            RxError::Version => "version",
            RxError::Decode => "decode",
            RxError::Sequence => "sequence",
            RxError::Reassembly => "reassembly",
            RxError::Syntax => "syntax",
            RxError::Adapter => "adapter",
        }
    }
}

impl fmt::Display for RxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl From<DecodeError> for RxError {
    fn from(e: DecodeError) -> Self {
        match e {
            DecodeError::BadCrc => RxError::Crc,
            DecodeError::BadVersion(_) => RxError::Version,
            DecodeError::TooShort | DecodeError::Cobs | DecodeError::Oversized => RxError::Framing,
            _ => RxError::Decode,
        }
    }
}

/// Receive-side error counts, one per [`RxError`] class.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RxErrorCounts([u64; RxError::ALL.len()]);

impl RxErrorCounts {
    /// Count one error.
    pub fn add(&mut self, e: RxError) {
        self.0[e as usize] += 1;
    }

    /// The count of one class.
    pub fn get(&self, e: RxError) -> u64 {
        self.0[e as usize]
    }

    /// All classes together.
    pub fn total(&self) -> u64 {
        self.0.iter().sum()
    }

    /// `(name, count)` for every class.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        RxError::ALL.iter().map(|&e| (e.as_str(), self.get(e)))
    }
}

/// What one step of a decoder produced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decoded {
    /// All input was consumed and no unit (frame/line) completed yet.
    NeedMore,
    /// A unit completed that carries no message by itself (a CAN frame of an unfinished group).
    Unit,
    /// A unit completed a message.
    Message(Message),
    /// A unit was damaged or foreign.
    Error(RxError),
    /// A unit that means nothing to us and is no error (SLCAN acknowledgements and commands).
    Ignored,
    /// A CAN frame outside the supine id block (other nodes' traffic): counted, not an error.
    Foreign,
}

/// Turns messages into port bytes and port bytes into messages; one per link, owning the decoder state.
///
/// Implementations must not allocate after construction: `encode` writes into a slot whose capacity is
/// [`Codec::max_encoded_len`], and `decode` keeps fixed-size state.
pub trait Codec {
    /// The framing of the encoded bytes.
    fn framing(&self) -> Framing;
    /// The most bytes `encode` writes for one message.
    fn max_encoded_len(&self) -> usize;
    /// Append the encoding of `msg` to `out` (which is empty and has `max_encoded_len` capacity).
    fn encode(&mut self, msg: &Message, out: &mut Vec<u8>) -> Result<(), LinkError>;
    /// Bytes to write first after every (re)connect: a lone delimiter, an adapter open sequence.
    fn preamble(&mut self, out: &mut Vec<u8>);
    /// Bytes to write when closing (an adapter close command).
    fn postamble(&mut self, out: &mut Vec<u8>);
    /// Consume a prefix of `input` and say what it produced; `now_us` is a monotonic time for decoders that
    /// expire state by time. Called with empty input too, so a decoder can report results it held back (a group
    /// abandoned as a side effect of an earlier frame); it must return `NeedMore` only once `input` is consumed.
    fn decode(&mut self, input: &[u8], now_us: u64) -> (usize, Decoded);
    /// Forget partial input (after a reconnect).
    fn reset_rx(&mut self);
}
