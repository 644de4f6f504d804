//! The arm controller's side of the serial link: decode the byte stream, keep the newest valid torso pose and
//! probe report, and judge them against the arm's "now" (stale, from the future, corrupt link). This is the
//! logic `examples/arm_consumer.rs` runs; it is no_std and allocation-free so it can be lifted onto the arm MCU.
//!
//! Staleness uses the capture timestamp, not the arrival time: a pose that queued in a buffer is as old as the
//! depth frame it came from. `now` must be on the tracker's capture clock (a shared PTP-disciplined clock, or the
//! arm's clock corrected by an offset estimate); a pose far in the future means the clocks disagree and is not
//! usable either. Newer means a later capture timestamp: replays and reordered frames never replace a newer pose.
//! One exception: a tracker that restarts begins a new sequence on a clock that may have gone back. Two messages
//! of a kind in a row that are both older than the held one, with sequence numbers more than [`RESTART_WINDOW`]
//! behind it, but continue from each other (sequence number 1 to [`RESTART_WINDOW`] ahead, later capture time)
//! are read as a restart and the second replaces the held data
//! (counted in [`ArmConsumer::restarts`]); a single stale or replayed message still never does. A pose is only
//! usable while the newest health message is itself recent ([`Limits::max_health_age_us`]).
//! Cost: one serial-decoder pass per byte plus a comparison per message.

use super::message::{Body, Message, ProbeReport, TorsoPose};
use super::stream::{DEFAULT_CAPACITY, SerialDecoder, SerialStats};
use super::types::{Timestamp, TrackerState};

/// A value with the envelope of the message that carried it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamped<T> {
    /// Sequence number of the message.
    pub seq: u16,
    /// Capture timestamp of the message.
    pub timestamp: Timestamp,
    /// The value.
    pub value: T,
}

/// How old data may be before the arm must stop trusting it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Oldest acceptable capture time relative to now, µs (e.g. 100 000: three frames at 30 Hz).
    pub max_age_us: u64,
    /// How far in the future a capture time may lie (clock jitter), µs.
    pub max_future_us: u64,
    /// Oldest acceptable health message, µs (e.g. 600 000: three health periods of 200 ms). A tracker whose health
    /// has gone quiet may have stopped judging its own output; its poses are then not usable.
    pub max_health_age_us: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_age_us: 100_000,
            max_future_us: 5_000,
            max_health_age_us: 600_000,
        }
    }
}

/// Largest sequence step between two older-than-held messages for them to be read as a tracker restart.
pub const RESTART_WINDOW: u16 = 16;

/// The verdict on held data at a given now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Freshness<T> {
    /// Nothing valid received yet.
    Missing,
    /// Within the age limit: usable. `age_us` may be slightly negative (within `max_future_us`).
    Fresh {
        /// The data.
        data: Stamped<T>,
        /// now - capture time, µs.
        age_us: i64,
    },
    /// Older than the limit: do not act on it.
    Stale {
        /// The data.
        data: Stamped<T>,
        /// now - capture time, µs.
        age_us: i64,
    },
    /// Captured later than now by more than the tolerance: the clocks disagree; do not act on it.
    FromFuture {
        /// The data.
        data: Stamped<T>,
        /// capture time - now, µs.
        ahead_us: i64,
    },
}

impl<T: Copy> Freshness<T> {
    /// The data, if fresh.
    pub fn fresh(&self) -> Option<T> {
        match self {
            Freshness::Fresh { data, .. } => Some(data.value),
            _ => None,
        }
    }
}

fn judge<T: Copy>(held: Option<Stamped<T>>, now: Timestamp, limits: Limits) -> Freshness<T> {
    let Some(data) = held else {
        return Freshness::Missing;
    };
    let age_us = now.since(data.timestamp);
    if age_us < 0 && age_us.unsigned_abs() > limits.max_future_us {
        Freshness::FromFuture {
            data,
            ahead_us: -age_us,
        }
    } else if age_us > 0 && age_us.unsigned_abs() > limits.max_age_us {
        Freshness::Stale { data, age_us }
    } else {
        Freshness::Fresh { data, age_us }
    }
}

/// The newest value of one kind, and the last older message seen since (a restart candidate).
#[derive(Debug, Clone, Copy)]
struct Held<T> {
    newest: Option<Stamped<T>>,
    behind: Option<(u16, Timestamp)>,
}

impl<T> Held<T> {
    const EMPTY: Self = Held {
        newest: None,
        behind: None,
    };

    /// Keep `new` if it was captured later than the held value, or if it continues an older sequence that began
    /// with the previous message (a tracker restart); returns `(taken, restart)`.
    fn offer(&mut self, new: Stamped<T>) -> (bool, bool) {
        let Some(h) = &self.newest else {
            self.newest = Some(new);
            return (true, false);
        };
        if new.timestamp > h.timestamp {
            self.newest = Some(new);
            self.behind = None;
            return (true, false);
        }
        // Only a message clearly from an earlier sequence (older capture time and a sequence number far behind the
        // held one) can start a restart; a repeat or a slightly late frame never does.
        let far_behind = h.seq.wrapping_sub(new.seq) > RESTART_WINDOW;
        if new.timestamp == h.timestamp || !far_behind {
            self.behind = None;
            return (false, false);
        }
        let restart = self.behind.is_some_and(|(seq, ts)| {
            (1..=RESTART_WINDOW).contains(&new.seq.wrapping_sub(seq)) && new.timestamp > ts
        });
        if restart {
            self.newest = Some(new);
            self.behind = None;
            return (true, true);
        }
        self.behind = Some((new.seq, new.timestamp));
        (false, false)
    }
}

/// Arm-side state fed from the tracker's serial stream; the decoder buffer is `N` bytes.
#[derive(Debug, Clone)]
pub struct ArmConsumer<const N: usize = DEFAULT_CAPACITY> {
    decoder: SerialDecoder<N>,
    pose: Held<TorsoPose>,
    probe: Held<ProbeReport>,
    state: Held<TrackerState>,
    not_newer: u32,
    restarts: u32,
    errors_at_last_good: u32,
}

impl<const N: usize> Default for ArmConsumer<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> ArmConsumer<N> {
    /// A consumer that has seen nothing.
    pub const fn new() -> Self {
        ArmConsumer {
            decoder: SerialDecoder::new(),
            pose: Held::EMPTY,
            probe: Held::EMPTY,
            state: Held::EMPTY,
            not_newer: 0,
            restarts: 0,
            errors_at_last_good: 0,
        }
    }

    /// Feed bytes as they come off the UART (any chunking).
    pub fn feed(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            let fed = self.decoder.feed(bytes);
            if let Some(Ok(m)) = fed.event {
                self.accept(&m);
            }
            bytes = fed.rest;
        }
    }

    /// Take one decoded message (from serial, or from a CAN reassembler); true if it replaced held data.
    pub fn accept(&mut self, m: &Message) -> bool {
        self.errors_at_last_good = self.decoder.stats().errors();
        let (seq, timestamp) = (m.seq, m.timestamp);
        let (taken, restart) = match m.body {
            Body::TorsoPose(value) => self.pose.offer(Stamped {
                seq,
                timestamp,
                value,
            }),
            Body::Probe(value) => self.probe.offer(Stamped {
                seq,
                timestamp,
                value,
            }),
            Body::Health(h) => self.state.offer(Stamped {
                seq,
                timestamp,
                value: h.state,
            }),
            // Other kinds are not the arm's business here (or are its own messages echoed back).
            _ => return false,
        };
        if !taken {
            self.not_newer = self.not_newer.saturating_add(1);
        }
        if restart {
            // The message before this one was counted as not newer; it was the restart's first.
            self.not_newer = self.not_newer.saturating_sub(1);
            self.restarts = self.restarts.saturating_add(1);
        }
        taken
    }

    /// The newest torso pose judged at `now`.
    pub fn pose(&self, now: Timestamp, limits: Limits) -> Freshness<TorsoPose> {
        judge(self.pose.newest, now, limits)
    }

    /// The newest probe report judged at `now`.
    pub fn probe(&self, now: Timestamp, limits: Limits) -> Freshness<ProbeReport> {
        judge(self.probe.newest, now, limits)
    }

    /// The tracker state of the newest health message, if any.
    pub fn tracker_state(&self) -> Option<TrackerState> {
        self.state.newest.map(|s| s.value)
    }

    /// A pose the arm may act on now: fresh, and the tracker's newest health, itself no older than
    /// [`Limits::max_health_age_us`] (nor from the future), says it is tracking (possibly occluded or degraded)
    /// rather than lost, initialising or without sensor.
    pub fn usable_pose(&self, now: Timestamp, limits: Limits) -> Option<TorsoPose> {
        let health_limits = Limits {
            max_age_us: limits.max_health_age_us,
            ..limits
        };
        let tracking = matches!(
            judge(self.state.newest, now, health_limits).fresh(),
            Some(TrackerState::Tracking | TrackerState::Occluded | TrackerState::Degraded)
        );
        if tracking {
            self.pose(now, limits).fresh()
        } else {
            None
        }
    }

    /// Corrupt frames seen since the last good message: non-zero means the link is damaging data right now.
    pub fn corrupt_since_last_good(&self) -> u32 {
        self.decoder
            .stats()
            .errors()
            .saturating_sub(self.errors_at_last_good)
    }

    /// Messages dropped because they were not newer than the held ones (replays, reordering).
    pub fn not_newer(&self) -> u32 {
        self.not_newer
    }

    /// Tracker restarts detected (a new sequence on a clock that went back), all kinds together.
    pub fn restarts(&self) -> u32 {
        self.restarts
    }

    /// The decoder's counters.
    pub fn link_stats(&self) -> &SerialStats {
        self.decoder.stats()
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use std::vec::Vec;

    use super::*;
    use crate::wire::sample::{CAPTURE, MESSAGES};
    use crate::wire::serial::MAX_WIRE_LEN;

    fn wire(m: &Message) -> Vec<u8> {
        let mut buf = [0u8; MAX_WIRE_LEN];
        let n = m.encode_serial(&mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn at(us: u64) -> Timestamp {
        Timestamp::from_us(us).unwrap()
    }

    fn pose_at(seq: u16, us: u64) -> Message {
        Message {
            seq,
            timestamp: at(us),
            ..MESSAGES[0]
        }
    }

    #[test]
    fn fresh_stale_and_future() {
        let mut c: ArmConsumer = ArmConsumer::new();
        let limits = Limits::default();
        assert_eq!(c.pose(CAPTURE, limits), Freshness::Missing);
        let mut bytes = Vec::new();
        for m in &MESSAGES {
            bytes.extend(wire(m));
        }
        for chunk in bytes.chunks(7) {
            c.feed(chunk);
        }
        let Body::TorsoPose(pose) = MESSAGES[0].body else {
            unreachable!()
        };
        let t = CAPTURE.as_us();
        assert_eq!(c.usable_pose(at(t + 20_000), limits), Some(pose));
        assert!(matches!(
            c.pose(at(t + 100_001), limits),
            Freshness::Stale { age_us: 100_001, .. }
        ));
        assert!(matches!(
            c.pose(at(t - 5_001), limits),
            Freshness::FromFuture { ahead_us: 5_001, .. }
        ));
        assert!(matches!(
            c.pose(at(t - 5_000), limits),
            Freshness::Fresh { age_us: -5_000, .. }
        ));
        assert!(c.probe(at(t), limits).fresh().is_some());
        assert_eq!(c.tracker_state(), Some(TrackerState::Tracking));
        assert_eq!(c.corrupt_since_last_good(), 0);
    }

    #[test]
    fn older_poses_never_replace_newer_ones() {
        let mut c: ArmConsumer = ArmConsumer::new();
        assert!(c.accept(&pose_at(10, 2_000_000)));
        assert!(!c.accept(&pose_at(9, 1_966_667)));
        assert!(!c.accept(&pose_at(10, 2_000_000)));
        assert!(c.accept(&pose_at(11, 2_033_333)));
        let Freshness::Fresh { data, .. } = c.pose(at(2_040_000), Limits::default()) else {
            panic!()
        };
        assert_eq!((data.seq, data.timestamp.as_us()), (11, 2_033_333));
        assert_eq!(c.not_newer(), 2);
    }

    #[test]
    fn corruption_is_flagged_until_a_good_frame() {
        let mut c: ArmConsumer = ArmConsumer::new();
        c.feed(&wire(&pose_at(1, 1_000_000)));
        let mut bad = wire(&pose_at(2, 1_033_333));
        bad[8] ^= 0x40;
        c.feed(&bad);
        c.feed(&[0x13, 0x37, 0x00]);
        assert_eq!(c.corrupt_since_last_good(), 2);
        assert_eq!(c.link_stats().bad_crc, 1);
        c.feed(&wire(&pose_at(3, 1_066_667)));
        assert_eq!(c.corrupt_since_last_good(), 0);
    }

    fn health_at(seq: u16, us: u64, state: TrackerState) -> Message {
        let Body::Health(mut h) = MESSAGES[4].body else {
            unreachable!()
        };
        h.state = state;
        Message {
            seq,
            timestamp: at(us),
            body: Body::Health(h),
        }
    }

    #[test]
    fn a_tracker_restart_with_its_clock_gone_back_is_followed() {
        let mut c: ArmConsumer = ArmConsumer::new();
        for i in 0..10u16 {
            let t = 50_000_000 + u64::from(i) * 33_333;
            assert!(c.accept(&pose_at(1000 + i, t)));
            c.accept(&health_at(1000 + i, t, TrackerState::Tracking));
        }
        // The tracker restarts: sequence from 0, capture clock from 1 s.
        assert!(
            !c.accept(&pose_at(0, 1_000_000)),
            "one older message alone is not a restart"
        );
        assert!(c.accept(&pose_at(1, 1_033_333)));
        c.accept(&health_at(0, 1_000_000, TrackerState::Tracking));
        c.accept(&health_at(1, 1_033_333, TrackerState::Tracking));
        assert_eq!(c.restarts(), 2);
        assert_eq!(c.not_newer(), 0);
        let limits = Limits::default();
        assert!(c.usable_pose(at(1_040_000), limits).is_some());
        assert!(c.accept(&pose_at(2, 1_066_667)));
        // A late frame of the new sequence still never wins.
        assert!(!c.accept(&pose_at(1, 1_033_333)));
        let Freshness::Fresh { data, .. } = c.pose(at(1_070_000), limits) else {
            panic!()
        };
        assert_eq!(data.seq, 2);
        // A stray frame from before the restart has a later capture time, so it is held, but it is judged from the
        // future (not usable) and the new sequence takes over again after two frames.
        assert!(c.accept(&pose_at(1005, 50_166_665)));
        assert!(matches!(
            c.pose(at(1_080_000), limits),
            Freshness::FromFuture { .. }
        ));
        assert!(!c.accept(&pose_at(3, 1_100_000)));
        assert!(c.accept(&pose_at(4, 1_133_333)));
        assert!(c.pose(at(1_140_000), limits).fresh().is_some());
    }

    #[test]
    fn a_pose_is_not_usable_once_health_goes_quiet() {
        let mut c: ArmConsumer = ArmConsumer::new();
        let limits = Limits::default();
        c.accept(&health_at(1, 1_000_000, TrackerState::Tracking));
        c.accept(&pose_at(1, 1_000_000));
        assert!(c.usable_pose(at(1_050_000), limits).is_some());
        // Poses keep coming but the last health message is 0.7 s old.
        c.accept(&pose_at(2, 1_700_000));
        assert_eq!(c.usable_pose(at(1_710_000), limits), None);
        c.accept(&health_at(2, 1_700_000, TrackerState::Tracking));
        assert!(c.usable_pose(at(1_710_000), limits).is_some());
    }

    #[test]
    fn no_pose_is_usable_while_the_tracker_is_lost() {
        let mut c: ArmConsumer = ArmConsumer::new();
        c.accept(&pose_at(1, 1_000_000));
        assert_eq!(
            c.usable_pose(at(1_000_000), Limits::default()),
            None,
            "no health yet"
        );
        let Body::Health(mut h) = MESSAGES[4].body else {
            unreachable!()
        };
        h.state = TrackerState::Lost;
        c.accept(&Message {
            seq: 1,
            timestamp: at(1_000_000),
            body: Body::Health(h),
        });
        assert_eq!(c.usable_pose(at(1_000_000), Limits::default()), None);
    }
}
