//! Receive-side sequence accounting: from the per-kind 16-bit sequence numbers of the messages that arrive, how
//! many were lost on the way (gaps), repeated or came out of order. O(1) per message, no allocation.

use supine_core::wire::{Kind, Message};

const KINDS: usize = Kind::ALL.len();

/// Largest forward step between two backward-going messages for them to be read as a sender restart.
pub const RESTART_WINDOW: u16 = 16;

/// Counts received, lost (by sequence gaps) and duplicate/out-of-order messages, per kind.
///
/// A gap of more than half the sequence space (32768) is read as a repeat or reordering, not as loss. A sender
/// that restarts begins again from a low sequence number: two messages in a row that go back and then continue
/// from each other (a step of 1 to [`RESTART_WINDOW`]) are read as a restart, and counting starts again from them
/// (counted in [`SequenceAccounting::restarts`]; the first of them is then not out of order). Losses at the very
/// end of a stream are invisible to the receiver; compare `received + lost` with what the sender counted only up
/// to the last message that arrived.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SequenceAccounting {
    last: [Option<u16>; KINDS],
    received: [u64; KINDS],
    lost: [u64; KINDS],
    out_of_order: [u64; KINDS],
    /// The last message that went backwards: a restart if the next one continues from it.
    behind: [Option<u16>; KINDS],
    restarts: [u64; KINDS],
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
            if let Some(behind) = self.behind[k]
                && (1..=RESTART_WINDOW).contains(&msg.seq.wrapping_sub(behind))
            {
                // The sender restarted at `behind`: count from there; that message was not out of order after all.
                self.restarts[k] += 1;
                self.out_of_order[k] = self.out_of_order[k].saturating_sub(1);
                self.behind[k] = None;
                self.last[k] = Some(msg.seq);
                let lost = u64::from(msg.seq.wrapping_sub(behind) - 1);
                self.lost[k] += lost;
                return lost;
            }
            self.behind[k] = (step != 0).then_some(msg.seq);
            self.out_of_order[k] += 1;
            return 0;
        }
        self.behind[k] = None;
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

    /// Sender restarts detected (sequence numbers that went back and continued from there), all kinds.
    pub fn restarts(&self) -> u64 {
        self.restarts.iter().sum()
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

#[cfg(test)]
mod tests {
    use super::*;
    use supine_core::wire::sample;

    fn health(seq: u16) -> Message {
        let mut m = sample::messages()
            .into_iter()
            .find(|m| m.kind() == Kind::Health)
            .unwrap();
        m.seq = seq;
        m
    }

    #[test]
    fn gaps_repeats_and_reordering() {
        let mut a = SequenceAccounting::new();
        for s in [10, 11, 14, 14, 12] {
            a.observe(&health(s));
        }
        assert_eq!(
            (a.received(), a.lost(), a.out_of_order(), a.restarts()),
            (5, 2, 2, 0)
        );
    }

    #[test]
    fn a_sender_restart_rebaselines() {
        let mut a = SequenceAccounting::new();
        for s in 1000..1010 {
            a.observe(&health(s));
        }
        // The tracker restarts and counts from 0 again: after the restart everything is in order.
        for s in 0..20 {
            a.observe(&health(s));
        }
        assert_eq!(a.restarts(), 1);
        assert_eq!(a.out_of_order(), 0);
        assert_eq!(a.lost(), 0);
        assert_eq!(a.received(), 30);
        // Later gaps are still counted from the new baseline.
        a.observe(&health(25));
        assert_eq!(a.lost(), 5);
    }

    #[test]
    fn a_single_stale_message_is_not_a_restart() {
        let mut a = SequenceAccounting::new();
        for s in [100, 101, 102, 50, 103, 104] {
            a.observe(&health(s));
        }
        assert_eq!((a.restarts(), a.out_of_order(), a.lost()), (0, 1, 0));
    }
}
