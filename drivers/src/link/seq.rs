//! Receive-side sequence accounting: from the per-kind 16-bit sequence numbers of the messages that arrive, how
//! many were lost on the way (gaps), repeated or came out of order. O(1) per message, no allocation.

use supine_core::wire::{Kind, Message};

const KINDS: usize = Kind::ALL.len();

/// Counts received, lost (by sequence gaps) and duplicate/out-of-order messages, per kind.
///
/// A gap of more than half the sequence space (32768) is read as a repeat or reordering, not as loss. Losses at
/// the very end of a stream are invisible to the receiver; compare `received + lost` with what the sender
/// counted only up to the last message that arrived.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SequenceAccounting {
    last: [Option<u16>; KINDS],
    received: [u64; KINDS],
    lost: [u64; KINDS],
    out_of_order: [u64; KINDS],
}

impl SequenceAccounting {
    /// Nothing seen yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Account for one received message; returns how many of its kind were lost just before it.
    pub fn observe(&mut self, msg: &Message) -> u64 {
        let k = msg.kind() as usize;
        if k >= KINDS {
            return 0;
        }
        self.received[k] += 1;
        let Some(last) = self.last[k] else {
            self.last[k] = Some(msg.seq);
            return 0;
        };
        let step = msg.seq.wrapping_sub(last);
        if step == 0 || step > 0x8000 {
            self.out_of_order[k] += 1;
            return 0;
        }
        self.last[k] = Some(msg.seq);
        let lost = u64::from(step - 1);
        self.lost[k] += lost;
        lost
    }

    /// Messages received, all kinds.
    pub fn received(&self) -> u64 {
        self.received.iter().sum()
    }

    /// Messages lost (sequence gaps), all kinds.
    pub fn lost(&self) -> u64 {
        self.lost.iter().sum()
    }

    /// Repeated or out-of-order messages, all kinds.
    pub fn out_of_order(&self) -> u64 {
        self.out_of_order.iter().sum()
    }

    /// `(kind, received, lost)` for every kind seen.
    pub fn per_kind(&self) -> impl Iterator<Item = (Kind, u64, u64)> + '_ {
        Kind::ALL
            .iter()
            .enumerate()
            .filter(|(i, _)| self.received[*i] > 0)
            .map(|(i, &k)| (k, self.received[i], self.lost[i]))
    }
}
