//! Rebuilds messages from CAN frame groups: one slot per message kind, frames placed by their index, a group
//! complete when every index has arrived with the same counter.
//!
//! Handles loss (a group missing frames is dropped and counted when a newer group replaces it or it expires),
//! reordering within a group (frames are placed by id, not arrival), duplicates (an identical repeat is counted
//! and ignored), bad CRCs and foreign frames. Allocation-free: 7 slots of 9 × 6 bytes. Cost per frame: one CRC-8
//! over 9 bytes and a 6-byte copy; a completed group adds one decode.
//!
//! Expiry needs no clock: a partial group is abandoned once [`EXPIRY_FRAMES`] frames of the supine id block have
//! arrived since its last frame, so that a group losing its tail can never be merged with the group sixteen counter
//! values later. Other nodes' traffic does not age groups (a busy bus would otherwise expire them early), and the
//! frame clock wraps rather than saturates, so expiry still works after 2^32 frames.

use super::can::{self, CanBase, CanFrame, E2eError, E2ePacket};
use super::can_map::{self, MAX_GROUP_FRAMES, Signals};
use super::error::DecodeError;
use super::message::{Kind, Message};

/// Frames of the supine id block after which an incomplete group is abandoned.
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
    /// Exact repeats of a frame already held (ignored; not errors).
    pub duplicates: u32,
    /// Groups abandoned with frames missing (replaced by a newer group, expired, or left at [`CanReassembler::flush`]).
    pub incomplete: u32,
    /// Complete groups whose fields were invalid (an out-of-range value, or a sequence number disagreeing with the
    /// counter).
    pub invalid: u32,
}

impl CanStats {
    /// All errors together (foreign frames and identical repeats are not errors).
    pub fn errors(&self) -> u32 {
        [self.bad_length, self.bad_crc, self.incomplete, self.invalid]
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
    /// The block's frame clock when this slot last took a frame.
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
    /// Frames of the own id block so far, wrapping: the clock groups expire by.
    clock: u32,
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
            clock: 0,
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
        let Some((kind, index)) = self.base.offset_of(frame.id()).and_then(can_map::locate) else {
            stats.foreign = stats.foreign.saturating_add(1);
            return None;
        };
        self.clock = self.clock.wrapping_add(1);
        let now = self.clock;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::can::{CanId, StandardId};
    use crate::wire::can_map::{CanGroup, encode_group};
    use crate::wire::sample;

    /// The sample message with the longest CAN group, and that group.
    fn longest_group() -> (Message, CanGroup) {
        sample::MESSAGES
            .iter()
            .map(|m| (*m, encode_group(m, CanBase::DEFAULT).unwrap()))
            .max_by_key(|(_, g)| g.len())
            .unwrap()
    }

    /// A one-frame group of another kind than `not`, as filler traffic of the own block.
    fn filler(not: Kind) -> CanGroup {
        sample::MESSAGES
            .iter()
            .filter(|m| m.kind() != not)
            .map(|m| encode_group(m, CanBase::DEFAULT).unwrap())
            .min_by_key(|g| g.len())
            .unwrap()
    }

    #[test]
    fn other_nodes_frames_do_not_age_a_group() {
        let (msg, group) = longest_group();
        assert!(group.len() >= 2);
        let mut r = CanReassembler::new(CanBase::DEFAULT);
        assert_eq!(r.push(&group[0]), None);
        let foreign = CanFrame::new(CanId::Standard(StandardId::new(0x7FF).unwrap()), &[0; 8]).unwrap();
        for _ in 0..(2 * EXPIRY_FRAMES) {
            assert_eq!(r.push(&foreign), None);
        }
        let mut out = None;
        for f in &group[1..] {
            out = r.push(f);
        }
        assert_eq!(out, Some(Ok(msg)));
        assert_eq!(r.stats().incomplete, 0);
        assert_eq!(r.stats().foreign, 2 * EXPIRY_FRAMES);
    }

    fn expires_after_own_block_traffic(mut r: CanReassembler) {
        let (msg, group) = longest_group();
        assert_eq!(r.push(&group[0]), None);
        let fill = filler(msg.kind());
        let mut pushed = 0;
        while pushed <= EXPIRY_FRAMES {
            for f in &fill {
                r.push(f);
                pushed += 1;
            }
        }
        // The rest of the group arrives too late: the old part expired, so no message is stitched together.
        for f in &group[1..] {
            assert_eq!(r.push(f), None);
        }
        assert_eq!(r.stats().incomplete, 1);
        r.flush();
        assert_eq!(r.stats().incomplete, 2);
    }

    #[test]
    fn a_group_expires_after_32_frames_of_its_own_block() {
        expires_after_own_block_traffic(CanReassembler::new(CanBase::DEFAULT));
    }

    #[test]
    fn expiry_survives_the_frame_counter_wrapping() {
        let mut r = CanReassembler::new(CanBase::DEFAULT);
        r.stats.frames = u32::MAX - 3;
        r.clock = u32::MAX - 3;
        expires_after_own_block_traffic(r);
    }

    #[test]
    fn identical_repeats_are_duplicates_not_errors() {
        let (_, group) = longest_group();
        let mut r = CanReassembler::new(CanBase::DEFAULT);
        r.push(&group[0]);
        assert_eq!(r.push(&group[0]), Some(Err(CanError::Duplicate)));
        assert_eq!(r.stats().duplicates, 1);
        assert_eq!(r.stats().errors(), 0);
    }
}
