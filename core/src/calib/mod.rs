//! Camera-to-robot calibration from the probe the arm already holds: pair the probe tip the arm reports
//! (arm-state messages, `robot_base`) with the tip seen in depth (`camera`) over a handful of still arm poses and
//! solve for `robot_base_from_camera`.
//!
//! - [`tip`]: probe-tip detection in a depth frame near a prior, with a confidence; ambiguous frames are refused.
//! - [`pairing`]: arm history and time matching (each frame to the arm state nearest its capture time), stillness,
//!   and the dwell collector that averages the still frames of one pose.
//! - [`mod@solve`]: Kabsch/Umeyama inside RANSAC over triples of pairs, a Huber-reweighted refinement, residuals and
//!   the condition number that refuses too few, collinear or near-coplanar pose sets.
//!
//! - [`start`]: the guess-free start: the probe tip as a local lowest point of what moves above the bed, picked
//!   across poses by its height, for a first rough Kabsch without any extrinsic guess.
//! - [`session`]: the streaming glue `supine calibrate` and its evaluation share (arm states and frames in, poses out).
//!
//! Per frame: one detection (~0.2 ms) and one history scan; the solve runs once at the end (~1 ms for 20 poses).
//! No allocation anywhere: scratch and capacities are the caller's.

pub mod pairing;
pub mod session;
pub mod solve;
pub mod start;
pub mod tip;

pub use pairing::{ArmHistory, ArmSample, DwellCollector, Match, PoseObservation};
pub use session::{FrameOutcome, Session, SessionConfig, SessionStats};
pub use solve::{
    Pair, Solution, SolveError, SolveOptions, Uncertainty, WARN_CONDITION, solve, solve_with_axes,
    uncertainty,
};
pub use start::{Candidate, LowPoint, StartBuffers, StartError, StartOptions, StartScratch, rough_extrinsic};
pub use tip::{ProbeShape, TipDetection, TipError, TipOptions, TipPrior, TipScratch, detect_tip};

/// The unit quaternion `[w, x, y, z]` (normalised); `None` when it is zero or not finite.
pub fn unit_quaternion_wxyz(wxyz: [f32; 4]) -> Option<crate::geometry::UnitQuaternion> {
    let [w, x, y, z] = wxyz;
    let q = nalgebra::Quaternion::new(w, x, y, z);
    let n = q.norm();
    (n.is_finite() && n > 1e-6).then(|| crate::geometry::UnitQuaternion::from_quaternion(q))
}
