//! Exponential back-off for reconnect attempts: 50 ms doubling to 2 s, reset on success. One comparison per call.

use std::time::{Duration, Instant};

/// First reconnect delay after a disconnect.
pub const INITIAL_DELAY: Duration = Duration::from_millis(50);
/// Longest delay between reconnect attempts.
pub const MAX_DELAY: Duration = Duration::from_secs(2);

/// When the next reconnect attempt is due.
#[derive(Clone, Debug)]
pub struct Backoff {
    delay: Duration,
    next: Instant,
}

impl Backoff {
    /// A back-off whose first attempt is due `INITIAL_DELAY` after `now`.
    pub fn start(now: Instant) -> Self {
        Backoff {
            delay: INITIAL_DELAY,
            next: now + INITIAL_DELAY,
        }
    }

    /// Whether an attempt is due at `now`.
    pub fn due(&self, now: Instant) -> bool {
        now >= self.next
    }

    /// Record a failed attempt at `now`: the delay doubles up to `MAX_DELAY`.
    pub fn failed(&mut self, now: Instant) {
        self.delay = (self.delay * 2).min(MAX_DELAY);
        self.next = now + self.delay;
    }

    /// The delay that will follow the next failure's predecessor (for logs and tests).
    pub fn delay(&self) -> Duration {
        self.delay
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doubles_and_caps() {
        let t0 = Instant::now();
        let mut b = Backoff::start(t0);
        assert!(!b.due(t0));
        assert!(b.due(t0 + INITIAL_DELAY));
        let mut now = t0 + INITIAL_DELAY;
        let mut seen = Vec::new();
        for _ in 0..10 {
            b.failed(now);
            seen.push(b.delay());
            now += b.delay();
            assert!(b.due(now));
        }
        assert_eq!(seen[0], Duration::from_millis(100));
        assert_eq!(seen[1], Duration::from_millis(200));
        assert_eq!(*seen.last().unwrap(), MAX_DELAY);
    }
}
