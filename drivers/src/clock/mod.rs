//! The host's capture clock for `supine run`: [`MonotonicClock`] reads Linux `CLOCK_MONOTONIC` in µs, the clock the
//! V4L2 and freenect sources stamp frames with, so latency (capture to packets out) is one subtraction. It
//! implements core's [`Clock`], which the tracker takes; replay and tests pass core's `VirtualClock` instead.
//! One `clock_gettime` call (vDSO, tens of ns) per reading.

mod sys;

use supine_core::time::{Clock, Timestamp};

/// Linux `CLOCK_MONOTONIC`, µs (time since boot, not counting suspend; never goes back).
#[derive(Debug, Clone, Copy, Default)]
pub struct MonotonicClock;

impl MonotonicClock {
    /// `CLOCK_MONOTONIC` now, µs. Saturates at 2^48 - 1 µs (8.9 years of uptime).
    pub fn now_us(&self) -> u64 {
        sys::monotonic_us().min(Timestamp::MAX_US)
    }
}

/// CPU time the calling thread has used so far, ns (Linux `CLOCK_THREAD_CPUTIME_ID`): what a benchmark on a shared
/// machine reads instead of wall time, since other processes' time slices do not count.
pub fn thread_cpu_ns() -> u64 {
    sys::thread_cpu_ns()
}

impl Clock for MonotonicClock {
    fn now(&self) -> Timestamp {
        Timestamp::from_us(self.now_us()).unwrap_or(Timestamp::from_us(Timestamp::MAX_US).unwrap_or_default())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_never_goes_back_and_follows_sleep() {
        let c = MonotonicClock;
        let a = c.now();
        std::thread::sleep(std::time::Duration::from_millis(5));
        let b = c.now();
        assert!(b.since(a) >= 5_000, "{} µs across a 5 ms sleep", b.since(a));
        assert!(a.as_us() > 0);
    }

    #[test]
    fn thread_cpu_time_counts_work_not_sleep() {
        let a = thread_cpu_ns();
        std::thread::sleep(std::time::Duration::from_millis(20));
        let b = thread_cpu_ns();
        let mut x = 0u64;
        for i in 0..2_000_000u64 {
            x = std::hint::black_box(x.wrapping_mul(31).wrapping_add(i));
        }
        let c = thread_cpu_ns();
        assert!(b - a < 10_000_000, "a 20 ms sleep used {} ns of CPU", b - a);
        assert!(c > b, "work used no CPU time ({x})");
    }
}
