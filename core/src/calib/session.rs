//! A calibration session: arm states and depth frames in (any interleaving, each in time order), still poses out.
//! `supine calibrate` and `supine-models eval calibration` both run this, so the command and its evaluation are
//! the same code.
//!
//! Each frame is matched to the arm state nearest its capture time; the tip is detected at once near the prior
//! (that arm state mapped into the camera by the current guess), but whether the arm stood still around the frame
//! is only decided once arm states `settle_us` past the frame have arrived, so a live session needs no look-ahead
//! and a pose that starts moving right after a frame is still caught. Cost per frame: one tip detection and a scan
//! of the arm history. Nothing allocates: `H` arm states, `P` poses, `N` detection points, [`PENDING`] frames.

use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::Isometry3;
use crate::time::Timestamp;

use super::pairing::{ArmHistory, ArmSample, DwellCollector, Match, PoseObservation};
use super::tip::{TipDetection, TipError, TipOptions, TipPrior, TipScratch, detect_tip};

/// Frames waiting for the arm states that decide whether the arm stood still around them.
pub const PENDING: usize = 32;

/// Settings of a session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionConfig {
    /// The current guess of the extrinsic (mount drawing, or a previous calibration).
    pub robot_base_from_camera_guess: Isometry3,
    /// How far the guess may put the tip from where it is, metres.
    pub guess_uncertainty_m: f32,
    /// Tip detection settings.
    pub tip: TipOptions,
    /// Largest distance in time between a frame and its arm state, µs.
    pub max_offset_us: u64,
    /// The arm must be still this long before and after a frame, µs (covers the arm's latency).
    pub settle_us: u64,
    /// "Still": the arm tip moved less than this within the settle window, metres.
    pub still_m: f32,
}

impl SessionConfig {
    /// Defaults around a guess: 6 cm uncertainty, the synthetic probe, 20 ms matching, 40 ms settle, 4 mm still (the wire carries whole millimetres).
    pub fn new(robot_base_from_camera_guess: Isometry3) -> Self {
        SessionConfig {
            robot_base_from_camera_guess,
            guess_uncertainty_m: 0.06,
            tip: TipOptions::default(),
            max_offset_us: 20_000,
            settle_us: 40_000,
            still_m: 0.004,
        }
    }
}

/// What happened to a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameOutcome {
    /// A tip was detected; stillness is decided later.
    Detected(TipDetection),
    /// No arm state near the frame's capture time.
    OutOfTime {
        /// Frame time minus nearest arm time, µs (0 without any arm state).
        offset_us: i64,
    },
    /// No tip in this frame.
    NoTip(TipError),
}

/// Counters of a session, for progress lines and the final message.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SessionStats {
    /// Frames given.
    pub frames: u32,
    /// Frames with a detected tip.
    pub detected: u32,
    /// Frames used for a pose (detected and still).
    pub still: u32,
    /// Frames without an arm state near them.
    pub out_of_time: u32,
    /// The last out-of-time offset, µs.
    pub last_offset_us: i64,
    /// Frames where the probe was not found (no probe, out of view, low confidence).
    pub no_probe: u32,
    /// Frames refused as ambiguous.
    pub ambiguous: u32,
    /// The last detection error.
    pub last_tip_error: Option<TipError>,
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    time: Timestamp,
    tip: Option<TipDetection>,
}

/// A calibration session (see the module docs).
#[derive(Debug, Clone)]
pub struct Session<const H: usize, const P: usize, const N: usize> {
    config: SessionConfig,
    camera_from_robot_base: Isometry3,
    history: ArmHistory<H>,
    dwell: DwellCollector<P>,
    scratch: TipScratch<N>,
    pending: [Option<Pending>; PENDING],
    pending_len: usize,
    stats: SessionStats,
}

impl<const H: usize, const P: usize, const N: usize> Session<H, P, N> {
    /// A session with `config`.
    pub fn new(config: SessionConfig) -> Self {
        Session {
            config,
            camera_from_robot_base: config.robot_base_from_camera_guess.inverse(),
            history: ArmHistory::new(),
            dwell: DwellCollector::new(),
            scratch: TipScratch::new(),
            pending: [None; PENDING],
            pending_len: 0,
            stats: SessionStats::default(),
        }
    }

    /// An arm state arrived; frames it decides are resolved.
    pub fn on_arm(&mut self, sample: ArmSample) {
        self.history.push(sample);
        self.resolve(false);
    }

    /// A depth frame arrived.
    pub fn on_frame(&mut self, frame: &DepthFrame<'_>, k: &Intrinsics) -> FrameOutcome {
        self.stats.frames += 1;
        let c = &self.config;
        let outcome = match self
            .history
            .match_frame(frame.capture, c.max_offset_us, 0, f32::INFINITY)
        {
            Match::OutOfTime { offset_us } => {
                self.stats.out_of_time += 1;
                self.stats.last_offset_us = offset_us;
                FrameOutcome::OutOfTime { offset_us }
            }
            Match::Found { sample, .. } => {
                let prior = TipPrior {
                    tip_camera: self.camera_from_robot_base * sample.tip_robot_base,
                    camera_from_probe: self.camera_from_robot_base.rotation * sample.robot_base_from_probe,
                    uncertainty_m: c.guess_uncertainty_m,
                };
                match detect_tip(frame, k, &prior, &c.tip, &mut self.scratch) {
                    Ok(d) => {
                        self.stats.detected += 1;
                        FrameOutcome::Detected(d)
                    }
                    Err(e) => {
                        if matches!(e, TipError::Ambiguous { .. }) {
                            self.stats.ambiguous += 1;
                        } else {
                            self.stats.no_probe += 1;
                        }
                        self.stats.last_tip_error = Some(e);
                        FrameOutcome::NoTip(e)
                    }
                }
            }
        };
        if self.pending_len == PENDING {
            // The arm has gone quiet for a second: decide the oldest frame with what there is.
            self.resolve_front(true);
        }
        self.pending[self.pending_len] = Some(Pending {
            time: frame.capture,
            tip: match outcome {
                FrameOutcome::Detected(d) => Some(d),
                _ => None,
            },
        });
        self.pending_len += 1;
        self.resolve(false);
        outcome
    }

    fn resolve(&mut self, all: bool) {
        while self.pending_len > 0 {
            if !self.resolve_front(all) {
                break;
            }
        }
    }

    /// Decide the oldest pending frame if the arm history reaches `settle_us` past it (or `force`); false if it
    /// has to wait.
    fn resolve_front(&mut self, force: bool) -> bool {
        let Some(front) = self.pending[0] else {
            return false;
        };
        let c = self.config;
        let newest = self.history.newest().map(|s| s.time);
        if !force && newest.is_none_or(|t| t.since(front.time) < c.settle_us as i64) {
            return false;
        }
        let m = self
            .history
            .match_frame(front.time, c.max_offset_us, c.settle_us, c.still_m);
        match (m, front.tip) {
            (
                Match::Found {
                    sample, still: true, ..
                },
                Some(d),
            ) => {
                self.stats.still += 1;
                self.dwell.still(&sample, d.tip_camera, d.confidence);
            }
            // A still frame without a tip neither adds to nor ends the pose.
            (Match::Found { still: true, .. }, None) => {}
            _ => self.dwell.moving(),
        }
        self.pending.copy_within(1.., 0);
        self.pending[PENDING - 1] = None;
        self.pending_len -= 1;
        true
    }

    /// The input ended: decide what can be decided and close the last pose.
    pub fn finish(&mut self) {
        self.resolve(false);
        self.pending = [None; PENDING];
        self.pending_len = 0;
        self.dwell.close();
    }

    /// Poses completed so far.
    pub fn poses(&self) -> impl Iterator<Item = PoseObservation> + '_ {
        self.dwell.poses()
    }

    /// Number of poses completed.
    pub fn pose_count(&self) -> usize {
        self.dwell.len()
    }

    /// The counters.
    pub fn stats(&self) -> &SessionStats {
        &self.stats
    }
}
