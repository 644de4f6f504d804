//! The frame budget: how long one frame may take, the per-stage times measured with the caller's clock, and the
//! order in which work is cut when a frame runs late.
//!
//! Core reads no clock: the caller passes a [`Clock`] to `Tracker::process` (the service a monotonic one, replay
//! and tests a virtual one, which makes every run bit-identical). Cut order, cheapest loss first:
//! 1. ICP iterations: before each iteration after the first, the tracker checks that the time spent so far plus
//!    the slowest iteration seen in this frame plus the reserve for probe mapping and packets fits the budget.
//!    Acquisition starts keep `acquire_min_iterations` (torso_icp) whatever the budget: a tracker on a board too
//!    slow for the budget overruns while it acquires rather than never acquiring.
//! 2. Shape refinement (init phase only): skipped, keeping the regression estimate, when the frame has already used
//!    half its budget before it would start.
//!
//! A frame that still ends over budget is counted as an overrun. The tracker never queues frames: the caller
//! hands it the newest one and reports what it dropped ([`BudgetCounters`] counts them for the health message).
//!
//! Cost: one clock read per stage boundary and per ICP iteration.

use crate::time::{Clock, Timestamp};

/// Budget settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BudgetConfig {
    /// The whole frame's budget, µs (33 ms: one Kinect frame period).
    pub frame_us: u32,
    /// ICP iterations per frame at most (fewer after an early stop or a cut).
    pub icp_iterations: u8,
    /// Time kept for probe mapping and packets at the end of a frame, µs.
    pub reserve_us: u32,
}

impl Default for BudgetConfig {
    fn default() -> Self {
        BudgetConfig {
            frame_us: 33_000,
            icp_iterations: 10,
            reserve_us: 500,
        }
    }
}

/// The stages of a frame, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Init phase work (bed planes, shape estimate, refinement) and the lock refits on the first tracked frames;
    /// zero on other tracking frames.
    Init,
    /// Joint forest and mean-shift.
    Forest,
    /// Rigid ICP of the torso model.
    Icp,
    /// Probe mapping and packets.
    Output,
}

impl Stage {
    /// Every stage, in order.
    pub const ALL: [Stage; 4] = [Stage::Init, Stage::Forest, Stage::Icp, Stage::Output];

    /// Name used in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Stage::Init => "init",
            Stage::Forest => "forest",
            Stage::Icp => "icp",
            Stage::Output => "output",
        }
    }
}

/// Per-stage times of one frame, µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StageTimes {
    /// Indexed by [`Stage`] order.
    pub us: [u32; 4],
}

impl StageTimes {
    /// The time of `stage`.
    pub fn of(&self, stage: Stage) -> u32 {
        self.us[stage as usize]
    }

    /// All stages together.
    pub fn total(&self) -> u32 {
        self.us.iter().fold(0u32, |a, &b| a.saturating_add(b))
    }
}

/// One frame's stopwatch over the caller's clock.
#[derive(Debug, Clone, Copy)]
pub struct Stopwatch {
    start: Timestamp,
    lap: Timestamp,
    /// What has been measured so far.
    pub times: StageTimes,
}

fn elapsed_us(later: Timestamp, earlier: Timestamp) -> u32 {
    later.since(earlier).clamp(0, u32::MAX as i64) as u32
}

impl Stopwatch {
    /// Start timing a frame now.
    pub fn start(clock: &(impl Clock + ?Sized)) -> Self {
        let t = clock.now();
        Stopwatch {
            start: t,
            lap: t,
            times: StageTimes::default(),
        }
    }

    /// Close `stage` now (time since the previous lap).
    pub fn lap(&mut self, clock: &(impl Clock + ?Sized), stage: Stage) {
        let t = clock.now();
        self.times.us[stage as usize] = self.times.us[stage as usize].saturating_add(elapsed_us(t, self.lap));
        self.lap = t;
    }

    /// Time since the frame started, µs.
    pub fn elapsed(&self, clock: &(impl Clock + ?Sized)) -> u32 {
        elapsed_us(clock.now(), self.start)
    }
}

/// Budget bookkeeping across frames: the health message's counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BudgetCounters {
    /// Frames that ended over budget (cumulative, wrapping).
    pub overruns: u32,
    /// Frames the caller dropped unprocessed (cumulative, wrapping).
    pub dropped: u32,
    /// Frames in which ICP iterations were cut.
    pub icp_cuts: u32,
    /// Shape refinements (the init phase's or a lock refit) skipped for time.
    pub refinements_skipped: u32,
}

/// Whether another ICP iteration fits: time so far, the slowest iteration yet, and the reserve within the budget.
pub fn iteration_fits(cfg: &BudgetConfig, elapsed_us: u32, slowest_iteration_us: u32) -> bool {
    elapsed_us
        .saturating_add(slowest_iteration_us)
        .saturating_add(cfg.reserve_us)
        <= cfg.frame_us
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::VirtualClock;

    #[test]
    fn stopwatch_laps_with_the_callers_clock() {
        let clock = VirtualClock::new(Timestamp::from_us(1_000).unwrap());
        let mut w = Stopwatch::start(&clock);
        clock.advance(300);
        w.lap(&clock, Stage::Forest);
        clock.advance(1_200);
        w.lap(&clock, Stage::Icp);
        clock.advance(50);
        w.lap(&clock, Stage::Output);
        assert_eq!(w.times.of(Stage::Init), 0);
        assert_eq!(w.times.of(Stage::Forest), 300);
        assert_eq!(w.times.of(Stage::Icp), 1_200);
        assert_eq!(w.times.total(), 1_550);
        assert_eq!(w.elapsed(&clock), 1_550);
    }

    #[test]
    fn iterations_stop_before_the_budget_runs_out() {
        let cfg = BudgetConfig {
            frame_us: 10_000,
            icp_iterations: 10,
            reserve_us: 1_000,
        };
        assert!(iteration_fits(&cfg, 5_000, 4_000));
        assert!(!iteration_fits(&cfg, 5_001, 4_000));
        assert!(!iteration_fits(&cfg, u32::MAX, 1));
    }
}
