//! Camera-to-robot calibration from the probe the arm already holds: pair the probe tip the arm reports
//! (arm-state messages, `robot_base`) with the tip seen in depth (`camera`) over a handful of still arm poses and
//! solve for `robot_base_from_camera`.
//!
//! - [`tip`]: probe-tip detection in a depth frame near a prior, with a confidence; ambiguous frames are refused.
//! - [`pairing`]: arm history and time matching (each frame to the arm state nearest its capture time), stillness,
//!   and the dwell collector that averages the still frames of one pose.
//! - [`solve`]: Kabsch/Umeyama inside RANSAC over triples of pairs, a Huber-reweighted refinement, residuals and
//!   the condition number that refuses too few, collinear or near-coplanar pose sets.
//!
//! - [`session`]: the streaming glue `supine calibrate` and its evaluation share (arm states and frames in, poses out).
//!
//! Per frame: one detection (~0.2 ms) and one history scan; the solve runs once at the end (~1 ms for 20 poses).
//! No allocation anywhere: scratch and capacities are the caller's.

pub mod pairing;
pub mod session;
pub mod solve;
pub mod tip;

pub use pairing::{ArmHistory, ArmSample, DwellCollector, Match, PoseObservation};
pub use session::{FrameOutcome, Session, SessionConfig, SessionStats};
pub use solve::{Pair, Solution, SolveError, SolveOptions, WARN_CONDITION, solve};
pub use tip::{ProbeShape, TipDetection, TipError, TipOptions, TipPrior, TipScratch, detect_tip};
