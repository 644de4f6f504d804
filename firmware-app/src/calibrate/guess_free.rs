//! `supine calibrate` without `--guess`: collect the still frames of each pose (at most [`FRAMES_PER_POSE`]) and
//! every arm state, start from the guess-free detection over one frame per pose
//! (`supine_core::calib::rough_extrinsic`), then run the calibration session twice over the kept frames: with the
//! rough result as prior (6 cm), then with that pass's solution (2 cm), and when those poses agree loosely up to
//! three more passes, each from the last solve, keeping the tightest (`calib_host::settle_passes`), as
//! `supine-models eval calibration` measures it.
//!
//! Memory: one depth frame (600 KB at 640x480) per kept frame, at most `FRAMES_PER_POSE` per pose (about 5 MB a
//! pose), freed when the command ends. Cost: one stillness test per frame while collecting; afterwards one
//! guess-free detection per pose and two tip detections per kept frame.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use supine_core::calib::start::MAX_POSES;
use supine_core::calib::{
    ArmHistory, ArmSample, Match, PoseObservation, Session, SessionConfig, SolveOptions,
};
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::Isometry3;
use supine_core::time::Timestamp;
use supine_drivers::calib_host::{refined_session, settle_passes};
use supine_drivers::link::{self, Link};
use supine_drivers::source::{DepthSource, SourceErrorKind};

use super::{CalibrateArgs, CalibrationSession};
use crate::failure::Failure;

/// Still frames kept per pose (the dwell average of the session uses them all).
pub const FRAMES_PER_POSE: usize = 8;
/// A still frame this far from the previous pose's arm tip starts a new pose, metres.
const NEW_POSE_M: f32 = 0.01;

/// A kept still frame.
struct Kept {
    depth: Vec<u16>,
    capture: Timestamp,
    pose: usize,
}

/// Collect without a guess and return the poses of the final pass.
pub fn collect(
    args: &CalibrateArgs,
    src: &mut dyn DepthSource,
    k: &Intrinsics,
    arm_link: &mut (dyn Link + Send),
) -> Result<Vec<PoseObservation>, Failure> {
    let poses_wanted = args.poses.min(MAX_POSES);
    eprintln!(
        "calibrating without a guess: frames from {}, arm states from {}; move the arm through {} poses above \
         the bed (empty, or the patient still), the probe pointing down, dwelling half a second at each",
        src.describe(),
        arm_link.describe(),
        poses_wanted
    );
    let defaults = SessionConfig::new(Isometry3::identity());
    let mut history: Box<ArmHistory<4096>> = Box::default();
    let mut arms: Vec<ArmSample> = Vec::new();
    let mut waiting: VecDeque<(Vec<u16>, Timestamp)> = VecDeque::new();
    let mut kept: Vec<Kept> = Vec::new();
    let mut pose_tips: Vec<ArmSample> = Vec::new();
    let (mut frames, mut still) = (0u32, 0u32);
    let timeout = Duration::try_from_secs_f64(args.timeout_s.max(0.1)).unwrap_or(Duration::from_secs(5));
    let mut last_frame = Instant::now();
    let mut link_ended = false;
    let (w, h) = (k.width, k.height);
    // Decide the waiting frames the arm history now covers `settle_us` past.
    let mut decide = |history: &ArmHistory<4096>,
                      waiting: &mut VecDeque<(Vec<u16>, Timestamp)>,
                      kept: &mut Vec<Kept>,
                      pose_tips: &mut Vec<ArmSample>,
                      force: bool| {
        while let Some((_, t)) = waiting.front() {
            let t = *t;
            let covered = history
                .newest()
                .is_some_and(|n| n.time.since(t) >= defaults.settle_us as i64);
            if !covered && !force {
                break;
            }
            let (depth, capture) = waiting.pop_front().expect("front exists");
            if let Match::Found {
                sample, still: true, ..
            } = history.match_frame(t, defaults.max_offset_us, defaults.settle_us, defaults.still_m)
            {
                still += 1;
                let new_pose = pose_tips
                    .last()
                    .is_none_or(|l| (l.tip_robot_base - sample.tip_robot_base).norm() > NEW_POSE_M);
                if new_pose {
                    pose_tips.push(sample);
                }
                let pose = pose_tips.len() - 1;
                if pose < poses_wanted && kept.iter().filter(|f| f.pose == pose).count() < FRAMES_PER_POSE {
                    kept.push(Kept { depth, capture, pose });
                }
            }
        }
    };
    let reason = loop {
        if crate::links::interrupted() {
            break "interrupted";
        }
        // Enough: the pose after the last wanted one has begun.
        if pose_tips.len() > poses_wanted {
            break "enough poses";
        }
        let frame = match src.next_frame(Duration::from_millis(100)) {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break "end of the depth source",
            Err(e) if e.kind() == SourceErrorKind::Timeout => {
                if last_frame.elapsed() >= timeout {
                    return Err(anyhow::anyhow!("no depth frame for {:.1} s", args.timeout_s).into());
                }
                continue;
            }
            Err(e) => return Err(anyhow::anyhow!("reading the depth source: {e}").into()),
        };
        last_frame = Instant::now();
        frames += 1;
        if frame.width() != w || frame.height() != h {
            return Err(anyhow::anyhow!(
                "the depth source changed its frame size to {}x{}",
                frame.width(),
                frame.height()
            )
            .into());
        }
        let capture = frame.capture;
        waiting.push_back((frame.depth_mm().to_vec(), capture));
        let horizon = capture.offset_by(200_000);
        while !link_ended && history.newest().is_none_or(|s| s.time < horizon) {
            match arm_link.receive() {
                Ok(Some(m)) => {
                    if let Some(s) = ArmSample::from_message(&m)
                        && history.push(s)
                    {
                        arms.push(s);
                    }
                }
                Ok(None) => {
                    link_ended = arm_link.state() == link::LinkState::Ended;
                    break;
                }
                Err(e) => return Err(anyhow::anyhow!("receiving on {}: {e}", arm_link.describe()).into()),
            }
        }
        let before = pose_tips.len();
        decide(&history, &mut waiting, &mut kept, &mut pose_tips, false);
        if pose_tips.len() > before && pose_tips.len() <= poses_wanted {
            let p = pose_tips[pose_tips.len() - 1].tip_robot_base;
            eprintln!(
                "pose {}/{poses_wanted}: arm tip [{:.1} {:.1} {:.1}] mm",
                pose_tips.len(),
                p.x * 1000.0,
                p.y * 1000.0,
                p.z * 1000.0
            );
        }
        // Frames older than a second without arm states to decide them are decided with what there is.
        while waiting.len() > 32 {
            decide(&history, &mut waiting, &mut kept, &mut pose_tips, true);
        }
    };
    decide(&history, &mut waiting, &mut kept, &mut pose_tips, true);
    let poses = pose_tips.len().min(poses_wanted);
    eprintln!(
        "stopped ({reason}): {frames} frames, {} arm states, {still} still frames, {poses} poses",
        arms.len()
    );
    if arms.is_empty() {
        return Err(anyhow::anyhow!("no extrinsic: no arm state arrived on {}", arm_link.describe()).into());
    }
    if poses < 4 {
        return Err(anyhow::anyhow!(
            "no extrinsic: only {poses} still poses seen (arm states out of time with the depth frames, or the \
             arm never stood still: dwell half a second at each pose, stamped on the capture clock)"
        )
        .into());
    }
    // The guess-free start over the first kept frame of each pose.
    let first: Vec<&Kept> = (0..poses)
        .filter_map(|p| kept.iter().find(|f| f.pose == p))
        .collect();
    let rough = {
        let arm_at: Vec<ArmSample> = first.iter().map(|f| pose_tips[f.pose]).collect();
        let frame = |i: usize| {
            DepthFrame::new(&first[i].depth, w, h, first[i].capture, i as u32)
                .expect("kept frames have the source's size")
        };
        supine_drivers::calib_host::guess_free_start(frame, &arm_at, k)
            .map_err(|e| anyhow::anyhow!("no extrinsic: {e}"))?
    };
    eprintln!(
        "guess-free start: a tip in {} of {poses} poses, rough extrinsic from {} (rms residual {:.1} mm)",
        rough.1,
        rough.0.inliers,
        rough.0.rms_residual_m * 1000.0
    );
    // Two passes of the session over the kept frames: the rough prior, then the first pass's solution.
    let config = SessionConfig::new(rough.0.robot_base_from_camera);
    let pass1 = replay(&kept, &arms, k, config, poses)?;
    let (first_solution, _, _) = supine_drivers::calib_host::solve_poses(&pass1, &SolveOptions::lenient())
        .map_err(|e| anyhow::anyhow!("no extrinsic: first pass after the guess-free start: {e}"))?;
    eprintln!(
        "first pass: {} poses, {} agree (rms residual {:.1} mm)",
        pass1.len(),
        first_solution.inliers,
        first_solution.rms_residual_m * 1000.0
    );
    let pass2 = replay(
        &kept,
        &arms,
        k,
        refined_session(first_solution.robot_base_from_camera),
        poses,
    )?;
    let pass2 = settle_passes(pass2, poses, |prior| {
        eprintln!("the poses agree loosely: another pass from the last solve");
        replay(&kept, &arms, k, refined_session(prior), poses)
    })?;
    if pass2.len() < 4 {
        return Err(anyhow::anyhow!(
            "no extrinsic: the probe was found in only {} poses after the guess-free start",
            pass2.len()
        )
        .into());
    }
    if pass2.len() < poses {
        eprintln!("warning: the probe was found in {} of {poses} poses", pass2.len());
    }
    Ok(pass2)
}

/// Run a calibration session over the kept frames and all arm states, interleaved by time.
fn replay(
    kept: &[Kept],
    arms: &[ArmSample],
    k: &Intrinsics,
    config: SessionConfig,
    max_poses: usize,
) -> Result<Vec<PoseObservation>, Failure> {
    let mut session: Box<CalibrationSession> = Box::new(Session::new(config));
    let mut next = 0usize;
    for (i, f) in kept.iter().enumerate() {
        while next < arms.len() && arms[next].time <= f.capture {
            session.on_arm(arms[next]);
            next += 1;
        }
        let frame = DepthFrame::new(&f.depth, k.width, k.height, f.capture, i as u32)
            .map_err(|e| anyhow::anyhow!("kept frame {i}: {e}"))?;
        session.on_frame(&frame, k);
    }
    for s in &arms[next..] {
        session.on_arm(*s);
    }
    session.finish();
    Ok(session.poses().take(max_poses).collect())
}
