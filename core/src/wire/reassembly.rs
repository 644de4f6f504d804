//! Rebuilds messages from CAN frame groups: one slot per message kind, frames placed by their index, a group
//! complete when every index has arrived with the same counter.
//!
//! Handles loss (a group missing frames is dropped and counted when a newer group replaces it or it expires),
//! reordering within a group (frames are placed by id, not arrival), duplicates (an identical repeat is counted
//! and ignored), bad CRCs and foreign frames. Allocation-free: 7 slots of 9 × 6 bytes. Cost per frame: one CRC-8
//! over 9 bytes and a 6-byte copy; a completed group adds one decode.
//!
//! Expiry needs no clock: a partial group is abandoned once [`EXPIRY_FRAMES`] frames have arrived since its last
//! frame, so that a group losing its tail can never be merged with the group sixteen counter values later.

use super::can::{self, CanBase, CanFrame, E2eError, E2ePacket};
use super::can_map::{self, MAX_GROUP_FRAMES, Signals};
use super::error::DecodeError;
use super::message::{Kind, Message};

/// Frames (of any id) after which an incomplete group is abandoned.
pub const EXPIRY_FRAMES: u32 = 32;

/// Counters of what a [`CanReassembler`] has seen. Each counter saturates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CanStats {
    /// Frames offered.
    pub frames: u32,
    /// Messages completed and decoded.
    pub messages: u32,
    /// Frames outside the supine id block (other nodes' traffic): not an error.
    pub foreign: u32,
    /// Supine ids with a length other than 8, or remote frames.
    pub bad_length: u32,
    /// Frames whose CRC-8 did not match.
    pub bad_crc: u32,
    /// Exact repeats of a frame already held.
    pub duplicates: u32,
    /// Groups abandoned with frames missing (replaced by a newer group, expired, or left at [`CanReassembler::flush`]).
    pub incomplete: u32,
    /// Complete groups whose fields were invalid (an out-of-range value, or a sequence number disagreeing with the
    /// counter).
    pub invalid: u32,
}

impl CanStats {
    /// All errors together (foreign frames are not errors).
    pub fn errors(&self) -> u32 {
        [
            self.bad_length,
            self.bad_crc,
            self.duplicates,
            self.incomplete,
            self.invalid,
        ]
        .iter()
        .fold(0u32, |a, &b| a.saturating_add(b))
    }
}

/// Why a frame did not (yet) produce a message, as reported by [`CanReassembler::push`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum CanError {
    /// Not 8 bytes or a remote frame.
    BadLength,
    /// CRC-8 mismatch.
    BadCrc,
    /// An exact repeat of a frame already held.
    Duplicate,
    /// A complete group did not decode.
    Invalid(DecodeError),
}

impl core::error::Error for CanError {}

impl core::fmt::Display for CanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            CanError::BadLength => f.write_str("CAN frame is not 8 data bytes"),
            CanError::BadCrc => f.write_str("CAN frame CRC-8 mismatch"),
            CanError::Duplicate => f.write_str("duplicate CAN frame"),
            CanError::Invalid(e) => write!(f, "CAN group does not decode: {e}"),
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Slot {
    counter: u8,
    /// Bit `i` set when frame `i` of the group is held.
    mask: u16,
    /// Frame count (of all ids) when this slot last took a frame.
    touched: u32,
    signals: [Signals; MAX_GROUP_FRAMES],
}

const EMPTY: Slot = Slot {
    counter: 0,
    mask: 0,
    touched: 0,
    signals: [[0; 6]; MAX_GROUP_FRAMES],
};

/// Reassembles supine messages from CAN frames at one base id.
#[derive(Debug, Clone)]
pub struct CanReassembler {
    base: CanBase,
    slots: [Slot; Kind::ALL.len()],
    stats: CanStats,
}

impl CanReassembler {
    /// A reassembler for the block at `base`.
    pub const fn new(base: CanBase) -> Self {
        CanReassembler {
            base,
            slots: [EMPTY; Kind::ALL.len()],
            stats: CanStats {
                frames: 0,
                messages: 0,
                foreign: 0,
                bad_length: 0,
                bad_crc: 0,
                duplicates: 0,
                incomplete: 0,
                invalid: 0,
            },
        }
    }

    /// What the reassembler has seen so far.
    pub const fn stats(&self) -> &CanStats {
        &self.stats
    }

    fn abandon(stats: &mut CanStats, slot: &mut Slot) {
        if slot.mask != 0 {
            stats.incomplete = stats.incomplete.saturating_add(1);
        }
        *slot = EMPTY;
    }

    /// Take one frame; a message when it completed a group, an error when the frame (or its group) was bad,
    /// `None` when it was foreign or the group is still incomplete.
    pub fn push(&mut self, frame: &CanFrame) -> Option<Result<Message, CanError>> {
        let stats = &mut self.stats;
        stats.frames = stats.frames.saturating_add(1);
        let now = stats.frames;
        let Some((kind, index)) = self.base.offset_of(frame.id()).and_then(can_map::locate) else {
            stats.foreign = stats.foreign.saturating_add(1);
            return None;
        };
        let packet = match E2ePacket::new_checked(frame.data()) {
            Ok(p) if !frame.is_remote() => p,
            _ => {
                stats.bad_length = stats.bad_length.saturating_add(1);
                return Some(Err(CanError::BadLength));
            }
        };
        if let Err(E2eError::BadCrc | E2eError::BadLength) =
            packet.check_crc(can::data_id(can_map::offset(kind, index)))
        {
            stats.bad_crc = stats.bad_crc.saturating_add(1);
            return Some(Err(CanError::BadCrc));
        }
        let counter = packet.counter();
        let signals = packet.signals();
        let bit = 1u16 << index;
        let slot = self.slots.get_mut(kind as usize)?;
        if slot.mask != 0 && now.wrapping_sub(slot.touched) > EXPIRY_FRAMES {
            Self::abandon(stats, slot);
        }
        if slot.mask != 0 && slot.counter != counter {
            Self::abandon(stats, slot);
        }
        if slot.mask & bit != 0 {
            if slot.signals.get(index) == Some(&signals) {
                stats.duplicates = stats.duplicates.saturating_add(1);
                return Some(Err(CanError::Duplicate));
            }
            // Same counter, different content: a later group reusing the counter. Start over with it.
            Self::abandon(stats, slot);
        }
        slot.counter = counter;
        slot.mask |= bit;
        slot.touched = now;
        if let Some(dst) = slot.signals.get_mut(index) {
            *dst = signals;
        }
        let full = (1u16 << can_map::group_len(kind)) - 1;
        if slot.mask != full {
            return None;
        }
        let result = can_map::from_signals(kind, &slot.signals).and_then(|m| {
            if (m.seq & 0x0F) as u8 == counter {
                Ok(m)
            } else {
                Err(DecodeError::InvalidValue)
            }
        });
        *slot = EMPTY;
        Some(match result {
            Ok(m) => {
                stats.messages = stats.messages.saturating_add(1);
                Ok(m)
            }
            Err(e) => {
                stats.invalid = stats.invalid.saturating_add(1);
                Err(CanError::Invalid(e))
            }
        })
    }

    /// Count every partial group as incomplete and forget it (at the end of a capture, or after a bus-off).
    pub fn flush(&mut self) {
        for slot in &mut self.slots {
            Self::abandon(&mut self.stats, slot);
        }
    }
}
