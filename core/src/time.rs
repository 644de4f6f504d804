//! Time in supine: [`Timestamp`] (µs on the capture clock, 48 bits as the wire carries it) and the [`Clock`] the
//! tracker takes. Core never reads a clock itself: `supine run` passes a monotonic clock, replay and tests a
//! [`VirtualClock`] they set from the recording, so every replay is deterministic. Reading either costs a few ns.

use core::cell::Cell;

use serde::{Deserialize, Serialize};

use crate::error::RangeError;

/// Capture time of a depth frame (or, for arm messages, the arm's sample time) in microseconds.
///
/// The clock is the tracker's capture clock (by default Linux `CLOCK_MONOTONIC`); it must fit 48 bits
/// (2^48 µs ≈ 8.9 years), which is what a CAN TIME frame carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize)]
#[serde(try_from = "u64", into = "u64")]
pub struct Timestamp(u64);

impl Timestamp {
    /// The largest representable timestamp, 2^48 - 1 µs.
    pub const MAX_US: u64 = (1 << 48) - 1;

    /// A timestamp of `us` microseconds; `None` at 2^48 µs or later.
    pub const fn from_us(us: u64) -> Option<Self> {
        if us <= Self::MAX_US {
            Some(Timestamp(us))
        } else {
            None
        }
    }

    /// Microseconds.
    pub const fn as_us(self) -> u64 {
        self.0
    }

    /// Microseconds from `earlier` to `self`; negative when `earlier` is later.
    pub const fn since(self, earlier: Timestamp) -> i64 {
        // Both fit 48 bits, so the difference fits an i64 without overflow.
        self.0 as i64 - earlier.0 as i64
    }
}

impl TryFrom<u64> for Timestamp {
    type Error = RangeError;
    fn try_from(us: u64) -> Result<Self, RangeError> {
        Timestamp::from_us(us).ok_or(RangeError)
    }
}

impl From<Timestamp> for u64 {
    fn from(t: Timestamp) -> u64 {
        t.0
    }
}

impl Timestamp {
    /// `us` microseconds later (negative: earlier), clamped to the representable range.
    pub const fn offset_by(self, us: i64) -> Timestamp {
        let t = (self.0 as i64).saturating_add(us);
        Timestamp(if t < 0 {
            0
        } else if t as u64 > Self::MAX_US {
            Self::MAX_US
        } else {
            t as u64
        })
    }
}

/// A source of the current time on the capture clock, passed to the tracker so it can time its stages against the
/// frame budget without reading a clock itself.
pub trait Clock {
    /// The current time.
    fn now(&self) -> Timestamp;
}

/// A clock that says what it was told: replay sets it from the recording, tests step it by hand.
#[derive(Debug, Default)]
pub struct VirtualClock {
    now: Cell<Timestamp>,
}

impl VirtualClock {
    /// A clock reading `start`.
    pub const fn new(start: Timestamp) -> Self {
        VirtualClock {
            now: Cell::new(start),
        }
    }

    /// Set the time to `t` (it may go back: a replay that loops restarts its clock).
    pub fn set(&self, t: Timestamp) {
        self.now.set(t);
    }

    /// Move the time on by `us` microseconds.
    pub fn advance(&self, us: u64) {
        self.now
            .set(self.now.get().offset_by(us.min(Timestamp::MAX_US) as i64));
    }
}

impl Clock for VirtualClock {
    fn now(&self) -> Timestamp {
        self.now.get()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamp_range() {
        assert_eq!(
            Timestamp::from_us(Timestamp::MAX_US).map(Timestamp::as_us),
            Some((1 << 48) - 1)
        );
        assert_eq!(Timestamp::from_us(1 << 48), None);
        let a = Timestamp::from_us(10).unwrap();
        let b = Timestamp::from_us(25).unwrap();
        assert_eq!(b.since(a), 15);
        assert_eq!(a.since(b), -15);
    }

    #[test]
    fn offsets_clamp() {
        let t = Timestamp::from_us(100).unwrap();
        assert_eq!(t.offset_by(-250).as_us(), 0);
        assert_eq!(t.offset_by(50).as_us(), 150);
        assert_eq!(t.offset_by(i64::MAX).as_us(), Timestamp::MAX_US);
    }

    #[test]
    fn virtual_clock_is_what_it_is_told() {
        let c = VirtualClock::new(Timestamp::from_us(1_000).unwrap());
        c.advance(33_333);
        assert_eq!(c.now().as_us(), 34_333);
        c.set(Timestamp::from_us(5).unwrap());
        assert_eq!(c.now().as_us(), 5);
        let dyn_clock: &dyn Clock = &c;
        assert_eq!(dyn_clock.now().as_us(), 5);
    }
}
