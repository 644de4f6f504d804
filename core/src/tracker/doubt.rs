//! Doubt of a lock: a wrong lock whose shape the lock refits have fitted to it keeps a high residual.
//!
//! A lock the acquisition takes with the init phase's shape fits at 5-9 mm whether it is right or wrong. The lock
//! refits then fit the shape from the tracked pose: a right lock settles at 3-5 mm, a wrong one (the torso turned
//! 15-30° or slid along the bed) keeps 6-13 mm, and the refitted shape makes the right pose fit no better than the
//! wrong one, so no later fit replaces it. So once the first refit round is in, a run of good tracked frames with a
//! high residual drops the lock, once per init phase ([`crate::tracker::TrackerConfig::doubt_frames`]); the tracker
//! then re-acquires with the init phase's shape.
//!
//! Cost per frame: a comparison and a counter.

/// The run of doubtful frames and whether the doubt has fired.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LockDoubt {
    run: u16,
    fired: bool,
}

impl LockDoubt {
    /// No doubtful frame yet.
    pub const fn new() -> Self {
        LockDoubt { run: 0, fired: false }
    }

    /// One frame after the init phase: `observed` is `None` on a frame the doubt does not judge (no refit round in
    /// yet, or a refit waiting to run), which leaves the run as it is; else whether the frame was a good tracked one
    /// and its fit's residual (metres). Returns true on the frame that completes `frames` doubtful ones in a row
    /// (good, residual over `max_rms_m`), never again after that; `frames` 0 never fires.
    pub fn observe(&mut self, observed: Option<(bool, f32)>, max_rms_m: f32, frames: u16) -> bool {
        if self.fired || frames == 0 {
            return false;
        }
        self.run = match observed {
            None => self.run,
            Some((true, rms)) if rms > max_rms_m => self.run.saturating_add(1),
            Some(_) => 0,
        };
        self.fired = self.run >= frames;
        self.fired
    }
}

impl Default for LockDoubt {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_of_high_residuals_fires_once_and_a_judged_frame_under_it_restarts_the_run() {
        let mut d = LockDoubt::new();
        let high = Some((true, 0.009));
        for _ in 0..2 {
            assert!(!d.observe(high, 0.0075, 3));
        }
        // A good frame under the residual, or a frame that is not a good tracked one, restarts the run.
        for other in [Some((true, 0.004)), Some((false, 0.009))] {
            assert!(!d.observe(other, 0.0075, 3));
            assert!(!d.observe(high, 0.0075, 3));
            assert!(!d.observe(high, 0.0075, 3));
        }
        // A frame the doubt does not judge leaves the run as it is.
        assert!(!d.observe(None, 0.0075, 3));
        assert!(d.observe(high, 0.0075, 3));
        for _ in 0..5 {
            assert!(!d.observe(high, 0.0075, 3));
        }
    }

    #[test]
    fn zero_frames_is_off() {
        let mut d = LockDoubt::new();
        for _ in 0..10 {
            assert!(!d.observe(Some((true, 1.0)), 0.0075, 0));
        }
    }
}
