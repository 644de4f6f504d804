//! Classic CAN 2.0 frames and the end-to-end protection every supine CAN frame carries.
//!
//! - [`StandardId`], [`ExtendedId`], [`CanId`]: validated identifiers (as in embedded-can).
//! - [`CanFrame`]: an owned classic frame (≤ 8 data bytes, or a remote frame), used by SLCAN and candump too.
//! - [`CanBase`]: the configurable base id of the supine id block (`base ..= base + 0x6F`).
//! - [`E2ePacket`]: the Packet view of one supine frame's 8 bytes: byte 0 a CRC-8/SAE-J1850 over the 16-bit
//!   data id and bytes 1..8 (as AUTOSAR E2E profile 1), byte 1 bits 0..3 a 4-bit rolling counter, bytes 2..8 the
//!   signals. Checking or filling a frame is one 9-byte CRC; nothing allocates.

use super::VERSION;
use crate::crc::crc8_sae_j1850;

/// An 11-bit standard CAN identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct StandardId(u16);

impl StandardId {
    /// The largest standard id.
    pub const MAX: u16 = 0x7FF;

    /// The id `raw`; `None` above 0x7FF.
    pub const fn new(raw: u16) -> Option<Self> {
        if raw <= Self::MAX {
            Some(StandardId(raw))
        } else {
            None
        }
    }

    /// The raw 11-bit value.
    pub const fn as_raw(self) -> u16 {
        self.0
    }
}

/// A 29-bit extended CAN identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ExtendedId(u32);

impl ExtendedId {
    /// The largest extended id.
    pub const MAX: u32 = 0x1FFF_FFFF;

    /// The id `raw`; `None` above 0x1FFF_FFFF.
    pub const fn new(raw: u32) -> Option<Self> {
        if raw <= Self::MAX {
            Some(ExtendedId(raw))
        } else {
            None
        }
    }

    /// The raw 29-bit value.
    pub const fn as_raw(self) -> u32 {
        self.0
    }
}

/// A standard or extended CAN identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CanId {
    /// 11-bit id.
    Standard(StandardId),
    /// 29-bit id.
    Extended(ExtendedId),
}

impl CanId {
    /// The raw numeric id (without any extended-frame flag).
    pub const fn raw(self) -> u32 {
        match self {
            CanId::Standard(id) => id.as_raw() as u32,
            CanId::Extended(id) => id.as_raw(),
        }
    }
}

/// A classic CAN frame: id, data length 0..=8 and data, or a remote frame with a DLC and no data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: CanId,
    remote: bool,
    len: u8,
    /// Bytes beyond `len` are always zero, so derived equality compares only the payload.
    data: [u8; 8],
}

impl CanFrame {
    /// A data frame; `None` if `data` is longer than 8 bytes.
    pub fn new(id: CanId, data: &[u8]) -> Option<CanFrame> {
        let mut buf = [0u8; 8];
        buf.get_mut(..data.len())?.copy_from_slice(data);
        Some(CanFrame {
            id,
            remote: false,
            len: data.len() as u8,
            data: buf,
        })
    }

    /// A remote (RTR) frame asking for `dlc` bytes; `None` if `dlc` is above 8.
    pub fn new_remote(id: CanId, dlc: u8) -> Option<CanFrame> {
        if dlc > 8 {
            return None;
        }
        Some(CanFrame {
            id,
            remote: true,
            len: dlc,
            data: [0; 8],
        })
    }

    /// The identifier.
    pub const fn id(&self) -> CanId {
        self.id
    }

    /// True for a remote (RTR) frame.
    pub const fn is_remote(&self) -> bool {
        self.remote
    }

    /// The data length code, 0..=8.
    pub const fn dlc(&self) -> u8 {
        self.len
    }

    /// The data bytes (empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            self.data.get(..usize::from(self.len)).unwrap_or(&self.data)
        }
    }
}

/// The base id of the supine block: frames use `base + 0x10 * kind + index`, 0x70 ids in all.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanBase(u16);

impl CanBase {
    /// Ids the block spans from the base.
    pub const SPAN: u16 = 0x70;
    /// The default base, 0x100 (ids 0x100..=0x16F), the one `supine.dbc` describes.
    pub const DEFAULT: CanBase = CanBase(0x100);

    /// A base whose whole block fits the 11-bit id space; `None` otherwise.
    pub const fn new(raw: u16) -> Option<CanBase> {
        if raw <= StandardId::MAX + 1 - Self::SPAN {
            Some(CanBase(raw))
        } else {
            None
        }
    }

    /// The raw base id.
    pub const fn as_raw(self) -> u16 {
        self.0
    }

    /// The offset of `id` inside this block, if it is inside.
    pub fn offset_of(self, id: CanId) -> Option<u8> {
        match id {
            CanId::Standard(s) => {
                let off = s.as_raw().checked_sub(self.0)?;
                if off < Self::SPAN { Some(off as u8) } else { None }
            }
            CanId::Extended(_) => None,
        }
    }

    /// The id at `offset` inside the block; `None` past its end.
    pub fn id_at(self, offset: u8) -> Option<StandardId> {
        if u16::from(offset) < Self::SPAN {
            StandardId::new(self.0 + u16::from(offset))
        } else {
            None
        }
    }
}

impl Default for CanBase {
    fn default() -> Self {
        CanBase::DEFAULT
    }
}

/// The E2E data id of the frame at `offset` in the block: the protocol version in the high byte, so frames of
/// another version fail the CRC instead of being misread, and independent of the base, so moving the block does
/// not change any CRC.
pub const fn data_id(offset: u8) -> u16 {
    ((VERSION as u16) << 8) | offset as u16
}

/// Byte offsets inside a supine CAN frame.
pub mod field {
    /// CRC-8/SAE-J1850 over data id (low byte first) and bytes 1..8.
    pub const CRC: usize = 0;
    /// Rolling counter, low nibble (the high nibble is reserved, 0).
    pub const COUNTER: usize = 1;
    /// First signal byte.
    pub const SIGNALS: usize = 2;
    /// Frame length: always 8.
    pub const LEN: usize = 8;
    /// Signal bytes per frame.
    pub const SIGNAL_LEN: usize = LEN - SIGNALS;
}

/// Why a CAN frame was not accepted as a supine frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum E2eError {
    /// Not 8 data bytes, or a remote frame.
    BadLength,
    /// The CRC-8 does not match the data id and bytes.
    BadCrc,
}

impl core::error::Error for E2eError {}

impl core::fmt::Display for E2eError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            E2eError::BadLength => f.write_str("CAN frame is not 8 data bytes"),
            E2eError::BadCrc => f.write_str("CAN frame CRC-8 mismatch"),
        }
    }
}

/// The Packet view of one supine CAN frame's data bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct E2ePacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> E2ePacket<T> {
    /// Wrap without checks; accessors return 0 for bytes the buffer lacks.
    pub const fn new_unchecked(buffer: T) -> Self {
        E2ePacket { buffer }
    }

    /// Wrap after checking the length is exactly 8.
    pub fn new_checked(buffer: T) -> Result<Self, E2eError> {
        let p = E2ePacket::new_unchecked(buffer);
        if p.buffer.as_ref().len() == field::LEN {
            Ok(p)
        } else {
            Err(E2eError::BadLength)
        }
    }

    fn byte(&self, i: usize) -> u8 {
        self.buffer.as_ref().get(i).copied().unwrap_or(0)
    }

    /// The stored CRC-8.
    pub fn crc(&self) -> u8 {
        self.byte(field::CRC)
    }

    /// The 4-bit rolling counter.
    pub fn counter(&self) -> u8 {
        self.byte(field::COUNTER) & 0x0F
    }

    /// The CRC-8 the frame should carry for `data_id`.
    pub fn compute_crc(&self, data_id: u16) -> u8 {
        let b = self.buffer.as_ref();
        let [lo, hi] = data_id.to_le_bytes();
        let mut bytes = [lo, hi, 0, 0, 0, 0, 0, 0, 0];
        for (dst, src) in bytes.iter_mut().skip(2).zip(b.iter().skip(1)) {
            *dst = *src;
        }
        crc8_sae_j1850(&bytes)
    }

    /// Ensure the CRC matches for `data_id`.
    pub fn check_crc(&self, data_id: u16) -> Result<(), E2eError> {
        if self.crc() == self.compute_crc(data_id) {
            Ok(())
        } else {
            Err(E2eError::BadCrc)
        }
    }

    /// The six signal bytes (zeros where the buffer is short).
    pub fn signals(&self) -> [u8; field::SIGNAL_LEN] {
        let mut out = [0u8; field::SIGNAL_LEN];
        for (dst, src) in out
            .iter_mut()
            .zip(self.buffer.as_ref().iter().skip(field::SIGNALS))
        {
            *dst = *src;
        }
        out
    }
}

/// Build the 8 data bytes of a supine frame: counter, signals, and the CRC over them for `data_id`.
pub fn seal(data_id: u16, counter: u8, signals: &[u8; field::SIGNAL_LEN]) -> [u8; field::LEN] {
    let mut b = [0u8; field::LEN];
    b[field::COUNTER] = counter & 0x0F;
    b[field::SIGNALS..].copy_from_slice(signals);
    b[field::CRC] = E2ePacket::new_unchecked(&b[..]).compute_crc(data_id);
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_validated() {
        assert!(StandardId::new(0x7FF).is_some());
        assert!(StandardId::new(0x800).is_none());
        assert!(ExtendedId::new(0x1FFF_FFFF).is_some());
        assert!(ExtendedId::new(0x2000_0000).is_none());
        assert_eq!(CanBase::new(0x790).map(CanBase::as_raw), Some(0x790));
        assert!(CanBase::new(0x791).is_none());
    }

    #[test]
    fn frames_are_validated() {
        let id = CanId::Standard(StandardId::new(0x123).unwrap());
        assert!(CanFrame::new(id, &[0; 9]).is_none());
        let f = CanFrame::new(id, &[1, 2]).unwrap();
        assert_eq!((f.dlc(), f.data()), (2, &[1u8, 2][..]));
        assert!(CanFrame::new_remote(id, 9).is_none());
        assert_eq!(CanFrame::new_remote(id, 4).unwrap().data(), &[] as &[u8]);
    }

    #[test]
    fn block_offsets() {
        let base = CanBase::DEFAULT;
        let id = |raw| CanId::Standard(StandardId::new(raw).unwrap());
        assert_eq!(base.offset_of(id(0x100)), Some(0));
        assert_eq!(base.offset_of(id(0x16F)), Some(0x6F));
        assert_eq!(base.offset_of(id(0x170)), None);
        assert_eq!(base.offset_of(id(0x0FF)), None);
        assert_eq!(
            base.offset_of(CanId::Extended(ExtendedId::new(0x100).unwrap())),
            None
        );
        assert_eq!(base.id_at(0x70), None);
    }

    #[test]
    fn seal_and_check() {
        let b = seal(data_id(0x21), 0x1A, &[1, 2, 3, 4, 5, 6]);
        assert_eq!(b[1], 0x0A);
        let p = E2ePacket::new_checked(&b[..]).unwrap();
        assert_eq!(p.counter(), 0x0A);
        assert_eq!(p.check_crc(data_id(0x21)), Ok(()));
        // The data id is in the CRC: the same bytes under another frame's id fail.
        assert_eq!(p.check_crc(data_id(0x22)), Err(E2eError::BadCrc));
        // Independent check: CRC-8/SAE-J1850 over [0x21, 0x01, 0x0A, 1, 2, 3, 4, 5, 6].
        assert_eq!(b[0], crc8_sae_j1850(&[0x21, 0x01, 0x0A, 1, 2, 3, 4, 5, 6]));
        assert_eq!(E2ePacket::new_checked(&b[..7]), Err(E2eError::BadLength));
    }
}
