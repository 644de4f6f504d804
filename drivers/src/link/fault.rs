//! [`FaultyLink`]: a link middleware, in the manner of smoltcp's `FaultInjector`, that drops messages,
//! damages their encoded bytes (a flipped byte in a serial frame, a changed data digit in an SLCAN line, a flipped
//! data byte in a `struct can_frame`), stalls the writer and reader, and disconnects the device underneath, all
//! from a seeded generator so that a failing run can be replayed.
//!
//! Per call: a few draws of a SplitMix64 generator and at most one in-place byte edit; no allocation.

use std::time::Duration;

use supine_core::wire::Message;

use super::codec::Framing;
use super::error::LinkError;
use super::port::LinkState;
use super::{Encoded, Link, LinkCounters, Tamper};
use supine_core::rng::SplitMix64;

/// What to inject, with probabilities in 0..=1.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinkFaultConfig {
    /// Generator seed.
    pub seed: u64,
    /// Probability that a sent message is dropped before it reaches the link.
    pub drop: f64,
    /// Probability that a sent message's encoded bytes are damaged (one frame of a CAN group).
    pub corrupt: f64,
    /// Probability per call (send, poll, receive) that a stall starts.
    pub stall: f64,
    /// How many calls a stall lasts: sends only queue, polls do nothing, receives return nothing.
    pub stall_calls: u32,
    /// Probability per send that the device is disconnected (it reconnects with back-off).
    pub disconnect: f64,
    /// Disconnect once, just before the send with this index (0-based), whatever `disconnect` says.
    pub disconnect_at: Option<u64>,
}

/// Faults injected so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultCounters {
    /// Messages dropped on purpose.
    pub dropped: u64,
    /// Messages whose bytes were damaged.
    pub corrupted: u64,
    /// Stalls started.
    pub stalls: u64,
    /// Calls swallowed by stalls.
    pub stalled_calls: u64,
    /// Disconnects forced.
    pub disconnects: u64,
}

/// A link wrapped with seeded faults; implements [`Link`] itself.
#[derive(Debug)]
pub struct FaultyLink<L> {
    inner: L,
    config: LinkFaultConfig,
    rng: SplitMix64,
    stall_left: u32,
    held: bool,
    sends: u64,
    active: bool,
    faults: FaultCounters,
}

impl<L: Link> FaultyLink<L> {
    /// Wrap `inner` with the faults of `config`.
    pub fn new(inner: L, config: LinkFaultConfig) -> Self {
        let rng = SplitMix64(config.seed);
        FaultyLink {
            inner,
            config,
            rng,
            stall_left: 0,
            held: false,
            sends: 0,
            active: true,
            faults: FaultCounters::default(),
        }
    }

    /// Turn injection on or off (e.g. off for the last message of a test so trailing losses are visible).
    pub fn set_active(&mut self, active: bool) {
        self.active = active;
        if !active {
            self.stall_left = 0;
        }
    }

    /// Start (`true`) or end a stall held by the caller, whatever the probabilities say: while held, every call is
    /// swallowed as in a drawn stall (a scripted "link stalled from frame A to frame B" in a soak test).
    pub fn hold_stall(&mut self, held: bool) {
        if held && !self.held {
            self.faults.stalls += 1;
        }
        self.held = held;
    }

    /// The wrapped link.
    pub fn inner(&self) -> &L {
        &self.inner
    }

    /// The wrapped link, mutably.
    pub fn inner_mut(&mut self) -> &mut L {
        &mut self.inner
    }

    /// The faults injected so far.
    pub fn faults(&self) -> FaultCounters {
        self.faults
    }

    /// True while a stall swallows this call.
    fn stalled(&mut self) -> bool {
        if !self.active {
            return false;
        }
        if self.held {
            self.faults.stalled_calls += 1;
            return true;
        }
        if self.stall_left == 0 && self.config.stall_calls > 0 && self.rng.chance(self.config.stall) {
            self.stall_left = self.config.stall_calls;
            self.faults.stalls += 1;
        }
        if self.stall_left > 0 {
            self.stall_left -= 1;
            self.faults.stalled_calls += 1;
            true
        } else {
            false
        }
    }
}

/// Damage one message's encoded bytes in place, the way the framing would be damaged on a real line.
/// Returns false when there was nothing to damage.
fn corrupt(rng: &mut SplitMix64, enc: &mut Encoded<'_>) -> bool {
    let bytes = &mut *enc.bytes;
    match enc.framing {
        Framing::Serial => {
            // `0x00 ‖ COBS ‖ 0x00`: flip bits of one byte between the delimiters.
            if bytes.len() <= 2 {
                return false;
            }
            let i = 1 + rng.below(bytes.len() - 2);
            bytes[i] ^= rng.nonzero_byte();
            true
        }
        Framing::SocketCan => {
            let units = bytes.len() / 16;
            if units == 0 {
                return false;
            }
            let u = rng.below(units) * 16;
            let len = usize::from(bytes[u + 4]).min(8);
            if len == 0 {
                return false;
            }
            let i = u + 8 + rng.below(len);
            bytes[i] ^= rng.nonzero_byte();
            true
        }
        Framing::Slcan => {
            // Change one data hex digit of one frame line into another hex digit: still a well-formed line, so
            // the damage must be caught by the frame's CRC-8, as a bit error on the bus would be.
            let lines = slcan_data_spans(bytes, None);
            if lines == 0 {
                return false;
            }
            let pick = rng.below(lines);
            let mut span = (0, 0);
            slcan_data_spans(bytes, Some((pick, &mut span)));
            let (start, len) = span;
            if len == 0 {
                return false;
            }
            let i = start + rng.below(len);
            const HEX: &[u8; 16] = b"0123456789ABCDEF";
            let Some(old) = HEX.iter().position(|&h| h == bytes[i].to_ascii_uppercase()) else {
                return false;
            };
            bytes[i] = HEX[(old + 1 + rng.below(15)) % 16];
            true
        }
    }
}

/// Count the SLCAN data-frame lines with data in `bytes`; with `want = Some((k, out))`, store the data digit
/// span `(start, len)` of the `k`-th such line in `out`.
fn slcan_data_spans(bytes: &[u8], mut want: Option<(usize, &mut (usize, usize))>) -> usize {
    let mut count = 0;
    let mut start = 0;
    while start < bytes.len() {
        let end = bytes[start..]
            .iter()
            .position(|&b| b == b'\r')
            .map_or(bytes.len(), |p| start + p);
        let line = &bytes[start..end];
        let id_len = match line.first() {
            Some(b't') => 3,
            Some(b'T') => 8,
            _ => 0,
        };
        if id_len > 0 {
            let dlc = line
                .get(1 + id_len)
                .and_then(|d| (*d as char).to_digit(10))
                .unwrap_or(0) as usize;
            let data_start = 2 + id_len;
            let data_len = (2 * dlc).min(line.len().saturating_sub(data_start));
            if data_len > 0 {
                if let Some((k, out)) = want.as_mut()
                    && *k == count
                {
                    **out = (start + data_start, data_len);
                }
                count += 1;
            }
        }
        start = end + 1;
    }
    count
}

impl<L: Link> Link for FaultyLink<L> {
    fn enqueue(&mut self, msg: &Message, tamper: Option<Tamper<'_>>) -> Result<(), LinkError> {
        let index = self.sends;
        self.sends += 1;
        if self.active {
            let scheduled = self.config.disconnect_at == Some(index);
            if scheduled || self.rng.chance(self.config.disconnect) {
                self.faults.disconnects += 1;
                self.inner.disconnect();
            }
            if self.rng.chance(self.config.drop) {
                self.faults.dropped += 1;
                return Ok(());
            }
        }
        let damage = self.active && self.rng.chance(self.config.corrupt);
        if !damage {
            return self.inner.enqueue(msg, tamper);
        }
        let rng = &mut self.rng;
        let mut damaged = false;
        let mut outer = tamper;
        let mut hook = |enc: &mut Encoded<'_>| {
            if let Some(t) = outer.as_mut() {
                t(enc);
            }
            damaged = corrupt(rng, enc);
        };
        let result = self.inner.enqueue(msg, Some(&mut hook));
        if damaged {
            self.faults.corrupted += 1;
        }
        result
    }

    fn send(&mut self, msg: &Message) -> Result<(), LinkError> {
        self.enqueue(msg, None)?;
        self.poll();
        Ok(())
    }

    fn poll(&mut self) {
        if !self.stalled() {
            self.inner.poll();
        }
    }

    fn receive(&mut self) -> Result<Option<Message>, LinkError> {
        if self.stalled() {
            return Ok(None);
        }
        self.inner.receive()
    }

    fn wait_readable(&mut self, timeout: Duration) {
        self.inner.wait_readable(timeout)
    }

    fn counters(&self) -> LinkCounters {
        LinkCounters {
            faults: self.faults,
            ..self.inner.counters()
        }
    }

    fn state(&self) -> LinkState {
        self.inner.state()
    }

    fn disconnect(&mut self) {
        self.inner.disconnect()
    }

    fn close(&mut self, timeout: Duration) -> Result<(), LinkError> {
        self.inner.close(timeout)
    }

    fn framing(&self) -> Framing {
        self.inner.framing()
    }

    fn describe(&self) -> &str {
        self.inner.describe()
    }

    fn last_io_error(&self) -> Option<String> {
        self.inner.last_io_error()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generator_is_seeded_and_spread() {
        let mut a = SplitMix64(7);
        let mut b = SplitMix64(7);
        assert_eq!(
            (0..5).map(|_| a.next_u64()).collect::<Vec<_>>(),
            (0..5).map(|_| b.next_u64()).collect::<Vec<_>>()
        );
        let hits = (0..10_000).filter(|_| a.chance(0.1)).count();
        assert!((800..1200).contains(&hits), "{hits}");
        assert!(!a.chance(0.0));
    }

    #[test]
    fn slcan_corruption_changes_exactly_one_data_digit() {
        let original = b"t1008AABBCCDDEEFF0011\rt1012A0\r".to_vec();
        let mut rng = SplitMix64(3);
        for _ in 0..50 {
            let mut bytes = original.clone();
            let mut enc = Encoded {
                framing: Framing::Slcan,
                bytes: &mut bytes,
            };
            assert!(corrupt(&mut rng, &mut enc));
            let diffs: Vec<usize> = (0..bytes.len()).filter(|&i| bytes[i] != original[i]).collect();
            assert_eq!(diffs.len(), 1);
            let i = diffs[0];
            assert!(
                (5..21).contains(&i) || (27..29).contains(&i),
                "changed a non-data byte at {i}"
            );
            assert!(bytes[i].is_ascii_hexdigit());
        }
    }

    #[test]
    fn serial_corruption_spares_the_delimiters() {
        let original = [0u8, 3, 1, 2, 2, 9, 0];
        let mut rng = SplitMix64(11);
        for _ in 0..50 {
            let mut bytes = original;
            assert!(corrupt(
                &mut rng,
                &mut Encoded {
                    framing: Framing::Serial,
                    bytes: &mut bytes
                }
            ));
            assert_eq!((bytes[0], bytes[6]), (0, 0));
            assert_ne!(bytes, original);
        }
    }

    #[test]
    fn socketcan_corruption_hits_data_bytes_only() {
        let mut frame = [0u8; 16];
        frame[4] = 8;
        let original = frame;
        let mut rng = SplitMix64(5);
        for _ in 0..50 {
            let mut bytes = original;
            assert!(corrupt(
                &mut rng,
                &mut Encoded {
                    framing: Framing::SocketCan,
                    bytes: &mut bytes
                }
            ));
            assert_eq!(bytes[..8], original[..8]);
            assert_ne!(bytes[8..], original[8..]);
        }
    }

    #[test]
    fn a_held_stall_queues_sends_until_released() {
        let dir = std::env::temp_dir().join(format!("supine-hold-stall-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("cap.bin");
        let inner = super::super::open_str(&format!("file:{}", path.display()), &Default::default()).unwrap();
        let mut link = FaultyLink::new(inner, LinkFaultConfig::default());
        let msg = supine_core::wire::sample::messages()[0];
        link.send(&msg).unwrap();
        let sent = link.counters().sent;
        assert_eq!(sent, 1);
        link.hold_stall(true);
        for _ in 0..(super::super::DEFAULT_QUEUE_CAPACITY + 8) {
            link.send(&msg).unwrap();
        }
        let c = link.counters();
        // Nothing moved; the full queue dropped its oldest messages (newest wins).
        assert_eq!(c.sent, sent);
        assert_eq!(c.dropped, 8);
        assert_eq!((c.faults.stalls, c.faults.stalled_calls > 0), (1, true));
        link.hold_stall(false);
        link.poll();
        assert!(link.counters().sent > sent);
        link.close(Duration::from_secs(1)).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
