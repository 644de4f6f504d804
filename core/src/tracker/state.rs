//! The tracker's state machine: what each frame's evidence does to the state the health message reports.
//!
//! | from | evidence | to |
//! | --- | --- | --- |
//! | any | re-initialise command | initialising |
//! | any | the source reports a fault | sensor_fault |
//! | sensor_fault | a usable frame | initialising (no init yet) or reacquiring |
//! | initialising | bed, shape and torso model built | acquiring |
//! | acquiring, reacquiring | a good fit (residual under `acquire_max_rms_m`, or the same pose `acquire_confirm` frames in a row) | tracking |
//! | acquiring, reacquiring | no good fit | unchanged (no pose sent) |
//! | tracking | a good fit | tracking (degraded when the budget cut work) |
//! | tracking | too little torso visible | occluded |
//! | tracking | a failed fit, `lost_after` frames in a row | lost |
//! | tracking | the lock doubted: a run of high residuals after the first lock refits, once per init ([`super::doubt`]) | lost |
//! | occluded | a good fit | tracking |
//! | occluded | still hidden or failing, `coast_frames` frames in a row | lost |
//! | lost | the next frame | reacquiring |
//!
//! While tracking, a single failed fit coasts on the last pose (reported as tracking with a lower confidence); poses
//! are sent in tracking, degraded and occluded, never in the other states.
//!
//! Cost: a few comparisons per frame.

use crate::wire::TrackerState;

/// How one frame's fit went, the input of a transition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FitQuality {
    /// Enough of the torso seen and fitted well.
    Good,
    /// Too little of the torso visible (the arm covers it): the pose coasts on the prior, or follows a clean fit
    /// near it (`TorsoIcpConfig::follow_occluded`).
    Occluded,
    /// No usable fit (no patient found, too few or too poor correspondences).
    Failed,
}

/// Thresholds of the transitions, in frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateLimits {
    /// Failed fits in a row while tracking before the patient counts as lost.
    pub lost_after: u16,
    /// Frames the pose may coast while occluded before the patient counts as lost (90 = 3 s at 30 Hz).
    pub coast_frames: u16,
}

impl Default for StateLimits {
    fn default() -> Self {
        StateLimits {
            lost_after: 5,
            coast_frames: 90,
        }
    }
}

/// The state and the counters its transitions need.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateMachine {
    state: TrackerState,
    limits: StateLimits,
    failed_run: u16,
    coast_run: u16,
    initialised: bool,
}

impl StateMachine {
    /// At start: initialising.
    pub const fn new(limits: StateLimits) -> Self {
        StateMachine {
            state: TrackerState::Initialising,
            limits,
            failed_run: 0,
            coast_run: 0,
            initialised: false,
        }
    }

    /// The current state.
    pub fn state(&self) -> TrackerState {
        self.state
    }

    /// Whether poses are sent in the current state.
    pub fn has_pose(&self) -> bool {
        self.state.has_pose()
    }

    /// Whether the init phase has completed since the last re-initialise.
    pub fn initialised(&self) -> bool {
        self.initialised
    }

    /// A re-initialise command: start over.
    pub fn reinitialise(&mut self) {
        *self = StateMachine::new(self.limits);
    }

    /// The source reported a fault (sensor gone, unusable frames).
    pub fn sensor_fault(&mut self) {
        self.state = TrackerState::SensorFault;
    }

    /// The init phase finished: bed, shape and torso model are built.
    pub fn init_done(&mut self) {
        self.initialised = true;
        self.state = TrackerState::Acquiring;
        self.clear_runs();
    }

    /// The tracker doubts its lock ([`super::doubt`]): the patient counts as lost and the next frame re-acquires.
    pub fn lose(&mut self) {
        if self.initialised {
            self.state = TrackerState::Lost;
            self.clear_runs();
        }
    }

    /// No failed or coasting frames counted: a state entered afresh.
    fn clear_runs(&mut self) {
        self.failed_run = 0;
        self.coast_run = 0;
    }

    /// A usable frame arrived; returns the state it is processed in (leaving sensor_fault or lost).
    pub fn frame_arrived(&mut self) -> TrackerState {
        self.state = match self.state {
            TrackerState::SensorFault | TrackerState::Lost if !self.initialised => TrackerState::Initialising,
            TrackerState::SensorFault | TrackerState::Lost => TrackerState::Reacquiring,
            s => s,
        };
        self.state
    }

    /// The fit of a frame processed after init; `cut` when the budget cut work in it.
    pub fn fitted(&mut self, quality: FitQuality, cut: bool) -> TrackerState {
        use TrackerState as S;
        let tracking = if cut { S::Degraded } else { S::Tracking };
        self.state = match (self.state, quality) {
            (S::Initialising | S::SensorFault | S::Lost, _) => self.state,
            (S::Acquiring | S::Reacquiring, FitQuality::Good) => tracking,
            (S::Acquiring | S::Reacquiring, _) => self.state,
            (_, FitQuality::Good) => tracking,
            (S::Tracking | S::Degraded, FitQuality::Occluded) => S::Occluded,
            (S::Tracking | S::Degraded, FitQuality::Failed) => {
                if self.failed_run + 1 >= self.limits.lost_after {
                    S::Lost
                } else {
                    self.state
                }
            }
            (S::Occluded, _) => {
                if self.coast_run + 1 >= self.limits.coast_frames {
                    S::Lost
                } else {
                    S::Occluded
                }
            }
        };
        match quality {
            FitQuality::Good => self.clear_runs(),
            FitQuality::Occluded => {
                self.failed_run = 0;
                self.coast_run = self.coast_run.saturating_add(1);
            }
            FitQuality::Failed => {
                self.failed_run = self.failed_run.saturating_add(1);
                if self.state == S::Occluded {
                    self.coast_run = self.coast_run.saturating_add(1);
                }
            }
        }
        if self.state == S::Lost {
            self.clear_runs();
        }
        self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use TrackerState as S;

    fn tracking() -> StateMachine {
        let mut m = StateMachine::new(StateLimits {
            lost_after: 3,
            coast_frames: 4,
        });
        m.init_done();
        assert_eq!(m.fitted(FitQuality::Good, false), S::Tracking);
        m
    }

    #[test]
    fn a_doubted_lock_is_lost_and_the_next_frame_reacquires() {
        let mut m = StateMachine::new(StateLimits::default());
        // Before init there is no lock to doubt.
        m.lose();
        assert_eq!(m.state(), S::Initialising);
        let mut m = tracking();
        m.lose();
        assert_eq!(m.state(), S::Lost);
        assert!(!m.has_pose());
        assert_eq!(m.frame_arrived(), S::Reacquiring);
        assert_eq!(m.fitted(FitQuality::Good, false), S::Tracking);
    }

    #[test]
    fn init_then_acquire_then_track() {
        let mut m = StateMachine::new(StateLimits::default());
        assert_eq!(m.state(), S::Initialising);
        assert!(!m.has_pose());
        // Before init, fits change nothing.
        assert_eq!(m.fitted(FitQuality::Good, false), S::Initialising);
        m.init_done();
        assert_eq!(m.state(), S::Acquiring);
        assert_eq!(m.fitted(FitQuality::Failed, false), S::Acquiring);
        assert_eq!(m.fitted(FitQuality::Occluded, false), S::Acquiring);
        assert_eq!(m.fitted(FitQuality::Good, true), S::Degraded);
        assert!(m.has_pose());
        assert_eq!(m.fitted(FitQuality::Good, false), S::Tracking);
    }

    #[test]
    fn failures_in_a_row_lose_the_patient_and_reacquire() {
        let mut m = tracking();
        assert_eq!(m.fitted(FitQuality::Failed, false), S::Tracking);
        assert_eq!(m.fitted(FitQuality::Failed, false), S::Tracking);
        // A good fit resets the run.
        assert_eq!(m.fitted(FitQuality::Good, false), S::Tracking);
        for _ in 0..2 {
            assert_eq!(m.fitted(FitQuality::Failed, false), S::Tracking);
        }
        assert_eq!(m.fitted(FitQuality::Failed, false), S::Lost);
        assert!(!m.has_pose());
        assert_eq!(m.frame_arrived(), S::Reacquiring);
        assert_eq!(m.fitted(FitQuality::Failed, false), S::Reacquiring);
        assert_eq!(m.fitted(FitQuality::Good, false), S::Tracking);
    }

    #[test]
    fn occlusion_coasts_then_recovers_or_is_lost() {
        let mut m = tracking();
        assert_eq!(m.fitted(FitQuality::Occluded, false), S::Occluded);
        assert!(m.has_pose());
        assert_eq!(m.fitted(FitQuality::Failed, false), S::Occluded);
        assert_eq!(m.fitted(FitQuality::Good, false), S::Tracking);
        for _ in 0..4 {
            m.fitted(FitQuality::Occluded, false);
        }
        assert_eq!(m.state(), S::Lost);
    }

    #[test]
    fn faults_and_reinitialise() {
        let mut m = tracking();
        m.sensor_fault();
        assert_eq!(m.state(), S::SensorFault);
        assert!(!m.has_pose());
        assert_eq!(m.frame_arrived(), S::Reacquiring);
        m.reinitialise();
        assert_eq!(m.state(), S::Initialising);
        assert!(!m.initialised());
        m.sensor_fault();
        assert_eq!(m.frame_arrived(), S::Initialising);
    }
}
