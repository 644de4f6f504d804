//! CAN links: the wire module's CAN mapping (one group of 8-byte E2E-protected frames per message) carried as
//! SLCAN text lines over a serial port or as `struct can_frame`s on a SocketCAN socket, and rebuilt on receipt by
//! the wire module's [`CanReassembler`].
//!
//! Per message: one group encode (up to 9 frames, a 9-byte CRC-8 each) and one SLCAN line or 16-byte struct per
//! frame, into a pre-sized slot; per received frame: one line parse or struct unpack and one reassembler push.
//! Nothing allocates.

pub mod socketcan;
pub mod sys;

use supine_core::wire::Message;
use supine_core::wire::can::{CanBase, CanFrame, CanId, ExtendedId, StandardId};
use supine_core::wire::can_map::{self, MAX_GROUP_FRAMES};
use supine_core::wire::reassembly::{CanError, CanReassembler};
use supine_core::wire::slcan::{self, MAX_LINE, SlcanError, SlcanReader};

use crate::link::codec::{Codec, Decoded, Framing, RxError};
use crate::link::error::{LinkError, LinkErrorKind};

/// SLCAN bit-rate commands `S0`..`S8` (Lawicel; python-can's table), bit/s.
pub const SLCAN_BITRATES: [(u32, u8); 9] = [
    (10_000, b'0'),
    (20_000, b'1'),
    (50_000, b'2'),
    (100_000, b'3'),
    (125_000, b'4'),
    (250_000, b'5'),
    (500_000, b'6'),
    (750_000, b'7'),
    (1_000_000, b'8'),
];

impl From<CanError> for RxError {
    fn from(e: CanError) -> Self {
        match e {
            CanError::BadLength => RxError::Framing,
            CanError::BadCrc => RxError::Crc,
            CanError::Duplicate => RxError::Sequence,
            CanError::Invalid(d) => d.into(),
            _ => RxError::Decode,
        }
    }
}

/// Reassembly shared by both CAN codecs: pushes frames, turns the reassembler's results and its side effects
/// (groups abandoned incomplete, foreign frames) into [`Decoded`] values, one per call.
#[derive(Debug)]
struct CanRx {
    base: CanBase,
    reassembler: CanReassembler,
    incomplete_seen: u32,
    pending_incomplete: u32,
}

impl CanRx {
    fn new(base: CanBase) -> Self {
        CanRx {
            base,
            reassembler: CanReassembler::new(base),
            incomplete_seen: 0,
            pending_incomplete: 0,
        }
    }

    fn note_side_effects(&mut self) {
        let now = self.reassembler.stats().incomplete;
        self.pending_incomplete += now.wrapping_sub(self.incomplete_seen);
        self.incomplete_seen = now;
    }

    fn take_pending(&mut self) -> Option<Decoded> {
        if self.pending_incomplete > 0 {
            self.pending_incomplete -= 1;
            return Some(Decoded::Error(RxError::Reassembly));
        }
        None
    }

    fn push(&mut self, frame: &CanFrame) -> Decoded {
        let foreign_before = self.reassembler.stats().foreign;
        let result = self.reassembler.push(frame);
        self.note_side_effects();
        match result {
            Some(Ok(m)) => Decoded::Message(m),
            Some(Err(e)) => Decoded::Error(e.into()),
            None if self.reassembler.stats().foreign != foreign_before => Decoded::Foreign,
            None => Decoded::Unit,
        }
    }

    fn reset(&mut self) {
        self.reassembler.flush();
        self.note_side_effects();
    }

    fn encode_group(&self, msg: &Message) -> Result<can_map::CanGroup, LinkError> {
        can_map::encode_group(msg, self.base)
            .map_err(|_| LinkError::new(LinkErrorKind::Encode, "message does not fit its CAN signals"))
    }
}

/// The CAN mapping as SLCAN lines, for `slcan:` links.
#[derive(Debug)]
pub struct SlcanCodec {
    bitrate_code: u8,
    rx: CanRx,
    reader: SlcanReader,
}

impl SlcanCodec {
    /// A codec that opens the adapter at `bitrate` bit/s (one of [`SLCAN_BITRATES`]), at the default id base.
    pub fn new(bitrate: u32) -> Result<Self, LinkError> {
        Self::with_base(bitrate, CanBase::DEFAULT)
    }

    /// A codec at a chosen id base.
    pub fn with_base(bitrate: u32, base: CanBase) -> Result<Self, LinkError> {
        let code = SLCAN_BITRATES.iter().find(|(b, _)| *b == bitrate).map(|(_, c)| *c).ok_or_else(|| {
            LinkError::new(
                LinkErrorKind::InvalidSpec,
                format!(
                    "SLCAN bit rate {bitrate} is not one of 10k, 20k, 50k, 100k, 125k, 250k, 500k, 750k, 1M bit/s"
                ),
            )
        })?;
        Ok(SlcanCodec {
            bitrate_code: code,
            rx: CanRx::new(base),
            reader: SlcanReader::new(),
        })
    }
}

impl Codec for SlcanCodec {
    fn framing(&self) -> Framing {
        Framing::Slcan
    }

    fn max_encoded_len(&self) -> usize {
        MAX_GROUP_FRAMES * MAX_LINE
    }

    fn encode(&mut self, msg: &Message, out: &mut Vec<u8>) -> Result<(), LinkError> {
        let group = self.rx.encode_group(msg)?;
        let mut line = [0u8; MAX_LINE];
        for frame in group.iter() {
            let n = slcan::encode(frame, &mut line).ok_or(LinkError::new(
                LinkErrorKind::Encode,
                "CAN frame does not fit an SLCAN line",
            ))?;
            out.extend_from_slice(&line[..n]);
        }
        Ok(())
    }

    fn preamble(&mut self, out: &mut Vec<u8>) {
        // A bare CR flushes any half-typed command in the adapter; then close (in case it was open), set the bit
        // rate, open. The adapter's CR/BEL replies are ignored by the reader.
        out.extend_from_slice(b"\rC\rS");
        out.push(self.bitrate_code);
        out.extend_from_slice(b"\rO\r");
    }

    fn postamble(&mut self, out: &mut Vec<u8>) {
        out.extend_from_slice(b"C\r");
    }

    fn decode(&mut self, input: &[u8], _now_us: u64) -> (usize, Decoded) {
        if let Some(d) = self.rx.take_pending() {
            return (0, d);
        }
        for (i, &b) in input.iter().enumerate() {
            let Some(event) = self.reader.push(b) else {
                continue;
            };
            let out = match event {
                Ok(line) => self.rx.push(&line.frame),
                Err(SlcanError::NotAFrame(_)) => Decoded::Ignored,
                Err(SlcanError::DeviceError) => Decoded::Error(RxError::Adapter),
                Err(_) => Decoded::Error(RxError::Syntax),
            };
            return (i + 1, out);
        }
        (input.len(), Decoded::NeedMore)
    }

    fn reset_rx(&mut self) {
        self.reader = SlcanReader::new();
        self.rx.reset();
    }
}

/// The CAN mapping as `struct can_frame`s, for `can:` links.
#[derive(Debug)]
pub struct SocketCanCodec {
    rx: CanRx,
}

impl Default for SocketCanCodec {
    fn default() -> Self {
        Self::new()
    }
}

impl SocketCanCodec {
    /// A codec at the default id base.
    pub fn new() -> Self {
        Self::with_base(CanBase::DEFAULT)
    }

    /// A codec at a chosen id base.
    pub fn with_base(base: CanBase) -> Self {
        SocketCanCodec { rx: CanRx::new(base) }
    }
}

/// The wire module's frame as a `struct can_frame`.
pub fn frame_to_raw(frame: &CanFrame) -> Option<[u8; sys::CAN_MTU]> {
    let (id, extended) = match frame.id() {
        CanId::Standard(id) => (u32::from(id.as_raw()), false),
        CanId::Extended(id) => (id.as_raw(), true),
    };
    let mut raw = socketcan::pack_frame(id, extended, frame.data())?;
    if frame.is_remote() {
        let can_id = u32::from_ne_bytes([raw[0], raw[1], raw[2], raw[3]]) | sys::CAN_RTR_FLAG;
        raw[..4].copy_from_slice(&can_id.to_ne_bytes());
        raw[4] = frame.dlc();
    }
    Some(raw)
}

/// A `struct can_frame` as the wire module's frame; `None` for error frames and invalid lengths.
pub fn frame_from_raw(raw: &[u8; sys::CAN_MTU]) -> Option<CanFrame> {
    let socketcan::RawFrameKind::Data(f) = socketcan::unpack_frame(raw) else {
        return None;
    };
    let id = if f.extended {
        CanId::Extended(ExtendedId::new(f.id)?)
    } else {
        CanId::Standard(StandardId::new(u16::try_from(f.id).ok()?)?)
    };
    if f.remote {
        CanFrame::new_remote(id, f.len)
    } else {
        CanFrame::new(id, &f.data[..usize::from(f.len)])
    }
}

impl Codec for SocketCanCodec {
    fn framing(&self) -> Framing {
        Framing::SocketCan
    }

    fn max_encoded_len(&self) -> usize {
        MAX_GROUP_FRAMES * sys::CAN_MTU
    }

    fn encode(&mut self, msg: &Message, out: &mut Vec<u8>) -> Result<(), LinkError> {
        let group = self.rx.encode_group(msg)?;
        for frame in group.iter() {
            let raw = frame_to_raw(frame).ok_or(LinkError::new(
                LinkErrorKind::Encode,
                "CAN frame does not fit struct can_frame",
            ))?;
            out.extend_from_slice(&raw);
        }
        Ok(())
    }

    fn preamble(&mut self, _out: &mut Vec<u8>) {}

    fn postamble(&mut self, _out: &mut Vec<u8>) {}

    fn decode(&mut self, input: &[u8], _now_us: u64) -> (usize, Decoded) {
        if let Some(d) = self.rx.take_pending() {
            return (0, d);
        }
        let Some(raw) = input
            .get(..sys::CAN_MTU)
            .and_then(|b| <&[u8; sys::CAN_MTU]>::try_from(b).ok())
        else {
            return (
                input.len(),
                if input.is_empty() {
                    Decoded::NeedMore
                } else {
                    Decoded::Error(RxError::Framing)
                },
            );
        };
        let out = match frame_from_raw(raw) {
            Some(frame) => self.rx.push(&frame),
            None => Decoded::Error(RxError::Framing),
        };
        (sys::CAN_MTU, out)
    }

    fn reset_rx(&mut self) {
        self.rx.reset();
    }
}
