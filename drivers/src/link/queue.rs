//! The bounded transmit queue between `Link::send` and the device: a ring of pre-allocated byte slots, one encoded
//! message per slot. When full, the newest message wins: the oldest message that has not started going out is
//! evicted and counted, but only once the new message has encoded: a message that fails to encode evicts nothing.
//! Nothing allocates after construction as long as encoders stay within the slot capacity (a full queue encodes into
//! a spare slot, swapped into the ring on success).

/// A ring of encoded messages waiting for the device.
#[derive(Debug)]
pub struct TxQueue {
    slots: Vec<Vec<u8>>,
    /// Where a message is encoded while the queue is full, so a failed encode leaves every queued message in place.
    spare: Vec<u8>,
    head: usize,
    len: usize,
    /// Bytes of the head slot already written.
    offset: usize,
    evicted: u64,
}

impl TxQueue {
    /// A queue of `capacity` messages (at least 2) of up to `slot_bytes` encoded bytes each.
    pub fn new(capacity: usize, slot_bytes: usize) -> Self {
        let capacity = capacity.max(2);
        TxQueue {
            slots: (0..capacity).map(|_| Vec::with_capacity(slot_bytes)).collect(),
            spare: Vec::with_capacity(slot_bytes),
            head: 0,
            len: 0,
            offset: 0,
            evicted: 0,
        }
    }

    /// Messages waiting (including one partly written).
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing waits.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Messages evicted because the queue was full.
    pub fn evicted(&self) -> u64 {
        self.evicted
    }

    /// Encode one message into the next free slot with `encode`; if the queue is full and the encode succeeded, the
    /// oldest unstarted message is evicted to make room. If `encode` fails the error is returned and the queue is as
    /// it was: nothing queued, nothing evicted.
    pub fn push_with<E>(&mut self, encode: impl FnOnce(&mut Vec<u8>) -> Result<(), E>) -> Result<(), E> {
        let cap = self.slots.len();
        if self.len < cap {
            let tail = (self.head + self.len) % cap;
            let slot = &mut self.slots[tail];
            slot.clear();
            encode(slot)?;
            self.len += 1;
            return Ok(());
        }
        self.spare.clear();
        encode(&mut self.spare)?;
        if self.offset == 0 {
            // Nothing in flight: drop the head.
            self.head = (self.head + 1) % cap;
            self.offset = 0;
        } else {
            // The head is partly written and must finish; drop the next one by moving the head's slot forward.
            let next = (self.head + 1) % cap;
            self.slots.swap(self.head, next);
            self.head = next;
        }
        self.len -= 1;
        self.evicted += 1;
        let tail = (self.head + self.len) % cap;
        std::mem::swap(&mut self.slots[tail], &mut self.spare);
        self.len += 1;
        Ok(())
    }

    /// The unwritten bytes of the oldest message, if any.
    pub fn front(&self) -> Option<&[u8]> {
        (self.len > 0).then(|| &self.slots[self.head][self.offset..])
    }

    /// Mark `n` bytes of the front message written; returns true if that completed the message.
    pub fn advance(&mut self, n: usize) -> bool {
        if self.len == 0 {
            return false;
        }
        self.offset += n;
        if self.offset >= self.slots[self.head].len() {
            self.head = (self.head + 1) % self.slots.len();
            self.len -= 1;
            self.offset = 0;
            true
        } else {
            false
        }
    }

    /// Restart the front message from its first byte (after a reconnect, the partial write went to a dead device
    /// or was cut off; the framing's preamble resynchronises the receiver).
    pub fn rewind_front(&mut self) {
        self.offset = 0;
    }

    /// Drop everything queued; returns how many messages were dropped.
    pub fn clear(&mut self) -> usize {
        let n = self.len;
        self.len = 0;
        self.offset = 0;
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push(q: &mut TxQueue, b: u8) {
        q.push_with::<()>(|s| {
            s.extend_from_slice(&[b, b, b]);
            Ok(())
        })
        .unwrap();
    }

    #[test]
    fn fifo_order_and_completion() {
        let mut q = TxQueue::new(4, 8);
        push(&mut q, 1);
        push(&mut q, 2);
        assert_eq!(q.front(), Some(&[1, 1, 1][..]));
        assert!(!q.advance(2));
        assert_eq!(q.front(), Some(&[1][..]));
        assert!(q.advance(1));
        assert_eq!(q.front(), Some(&[2, 2, 2][..]));
        assert!(q.advance(3));
        assert!(q.is_empty());
    }

    #[test]
    fn newest_wins_when_full() {
        let mut q = TxQueue::new(3, 8);
        for b in 1..=5 {
            push(&mut q, b);
        }
        assert_eq!(q.evicted(), 2);
        let mut seen = Vec::new();
        while let Some(f) = q.front() {
            seen.push(f[0]);
            let n = f.len();
            q.advance(n);
        }
        assert_eq!(seen, [3, 4, 5]);
    }

    #[test]
    fn a_message_in_flight_is_never_evicted() {
        let mut q = TxQueue::new(2, 8);
        push(&mut q, 1);
        push(&mut q, 2);
        q.advance(1); // 1 is in flight
        push(&mut q, 3); // evicts 2, not 1
        assert_eq!(q.evicted(), 1);
        assert_eq!(q.front(), Some(&[1, 1][..]));
        q.advance(2);
        assert_eq!(q.front(), Some(&[3, 3, 3][..]));
    }

    #[test]
    fn failed_encode_queues_nothing() {
        let mut q = TxQueue::new(2, 8);
        assert_eq!(q.push_with(|_| Err("too big")), Err("too big"));
        assert!(q.is_empty());
    }

    #[test]
    fn a_failed_encode_on_a_full_queue_evicts_nothing() {
        let mut q = TxQueue::new(2, 8);
        push(&mut q, 1);
        push(&mut q, 2);
        assert_eq!(q.push_with(|_| Err("too big")), Err("too big"));
        assert_eq!(q.evicted(), 0);
        assert_eq!(q.len(), 2);
        assert_eq!(q.front(), Some(&[1, 1, 1][..]));
        q.advance(3);
        assert_eq!(q.front(), Some(&[2, 2, 2][..]));
    }

    #[test]
    fn no_growth_after_construction() {
        let mut q = TxQueue::new(2, 8);
        let before: Vec<usize> = q.slots.iter().map(|s| s.capacity()).collect();
        for b in 0..50 {
            push(&mut q, b);
            q.advance(1);
        }
        let mut after: Vec<usize> = q.slots.iter().map(|s| s.capacity()).collect();
        after.sort();
        let mut before = before;
        before.sort();
        // Slots trade places with the spare but never grow.
        assert!(after.iter().all(|&c| c == before[0]), "{before:?} -> {after:?}");
    }
}
