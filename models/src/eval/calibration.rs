//! `supine-models eval calibration --data DIR [--json FILE] [--svg FILE]`: run the calibration session of
//! `supine calibrate` (`supine_core::calib`) over calibration sequences (`sequence --calibration`) and compare the
//! recovered `robot_base_from_camera` with the truth in `sequence.json`, for the first 6, 10 and 20 poses, with and
//! without a patient on the bed, and how the error moves points on the torso (probe-mapping error).
//!
//! Two passes per pose count, as an integrator would run it: the nominal guess (the mount drawing, in
//! `sequence.json`) as the detector's prior, then the first pass's result as the prior of the second; when the
//! second pass's poses agree loosely, up to three more (`calib_host::settle_passes`, as `supine calibrate` does).
//! Cost: one .oni decode and one tip detection per frame and pass (~5 ms a frame).

use crate::provenance::commit;
use anyhow::{Context, Result, bail};
use nalgebra::Point3;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use supine_core::calib::solve::{rotation_error_deg, translation_error_m};
use supine_core::calib::{
    ArmHistory, ArmSample, Match, PoseObservation, Session, SessionConfig, SessionStats, Solution,
    SolveOptions, StartError,
};
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::Isometry3;
use supine_core::time::Timestamp;
use supine_core::wire::stream::SerialDecoder;
use supine_drivers::SourceErrorKind;
use supine_drivers::calib_host::{refined_session, settle_passes};
use supine_drivers::oni::OniReader;

use crate::sequence::SequenceMeta;
use crate::sequence::calibration::CalibrationFrameTruth;

/// Pose counts the report covers (keys of the JSON report).
pub const POSE_COUNTS: [usize; 3] = [6, 10, 20];

/// Arguments of `supine-models eval calibration`.
#[derive(Debug, clap::Args)]
pub struct CalibrationEvalArgs {
    /// A calibration sequence directory, or a folder of them.
    #[arg(long)]
    pub data: PathBuf,
    /// Write the report here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the figure (errors against pose count, with and without a patient) here as SVG.
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Start from the nominal guess in `sequence.json` (as `supine calibrate --guess`) instead of the guess-free
    /// start.
    #[arg(long)]
    pub nominal_guess: bool,
}

/// A session as the command runs it: 2048 arm states (20 s at 100 Hz), 64 poses, 8192 detection points.
pub type CalibrationSession = Session<2048, 64, 8192>;

/// The arm states of a serial capture (`arm.cobs`), in file order.
pub fn read_arm_capture(path: &Path) -> Result<(Vec<ArmSample>, u64)> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut decoder: SerialDecoder = SerialDecoder::new();
    let mut out = Vec::new();
    decoder.feed_all(&bytes, |m| out.extend(ArmSample::from_message(&m)));
    Ok((out, decoder.stats().errors() as u64))
}

/// Run one session over a recording: frames of `oni` and arm states interleaved by time as a live link would
/// deliver them. Returns the poses and the counters.
pub fn run_session(
    oni: &Path,
    arm: &[ArmSample],
    config: SessionConfig,
    max_poses: usize,
) -> Result<(Vec<PoseObservation>, SessionStats)> {
    let mut reader = OniReader::open(oni).with_context(|| format!("opening {}", oni.display()))?;
    let k = reader_intrinsics(&reader);
    let mut session = Box::new(CalibrationSession::new(config));
    let mut next_arm = 0;
    loop {
        let frame = match reader.read_frame() {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) => bail!("reading {}: {e}", oni.display()),
        };
        while next_arm < arm.len() && arm[next_arm].time <= frame.capture {
            session.on_arm(arm[next_arm]);
            next_arm += 1;
        }
        session.on_frame(&frame, &k);
        if session.pose_count() >= max_poses {
            break;
        }
    }
    for s in &arm[next_arm..] {
        session.on_arm(*s);
    }
    session.finish();
    Ok((session.poses().take(max_poses).collect(), *session.stats()))
}

/// One still frame per pose: the first frame the arm stood still at (as `run_session` decides stillness), at
/// least [`NEW_POSE_M`] from the previous pose's tip; up to `max` poses. Returns the frames' depth and arm states.
pub fn pose_keyframes(oni: &Path, arm: &[ArmSample], max: usize) -> Result<(Vec<Vec<u16>>, Vec<ArmSample>)> {
    let mut reader = OniReader::open(oni).with_context(|| format!("opening {}", oni.display()))?;
    let mut history: Box<ArmHistory<8192>> = Box::default();
    for s in arm {
        history.push(*s);
    }
    let c = SessionConfig::new(Isometry3::identity());
    let (mut frames, mut arms) = (Vec::new(), Vec::<ArmSample>::new());
    while arms.len() < max {
        let frame = match reader.read_frame() {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) => bail!("reading {}: {e}", oni.display()),
        };
        if let Match::Found {
            sample, still: true, ..
        } = history.match_frame(frame.capture, c.max_offset_us, c.settle_us, c.still_m)
            && arms
                .last()
                .is_none_or(|l| (l.tip_robot_base - sample.tip_robot_base).norm() > NEW_POSE_M)
        {
            frames.push(frame.depth_mm().to_vec());
            arms.push(sample);
        }
    }
    Ok((frames, arms))
}

/// A still frame this far from the previous pose's arm tip starts a new pose, metres.
pub const NEW_POSE_M: f32 = 0.01;

/// The guess-free start over keyframes (`supine_core::calib::rough_extrinsic`): the rough extrinsic and the
/// poses that gave a tip.
pub fn guess_free_start(
    frames: &[Vec<u16>],
    arms: &[ArmSample],
    k: &Intrinsics,
) -> Result<(Solution, usize), StartError> {
    let (w, h) = (k.width, k.height);
    if frames.len() < arms.len() || frames.iter().any(|f| f.len() != w as usize * h as usize) {
        return Err(StartError::BufferTooShort);
    }
    let frame = |i: usize| {
        DepthFrame::new(&frames[i], w, h, Timestamp::default(), i as u32)
            .expect("keyframes have the frame size")
    };
    supine_drivers::calib_host::guess_free_start(frame, arms, k)
}

fn reader_intrinsics(_reader: &OniReader) -> Intrinsics {
    // The sequences are rendered with the Kinect v1 intrinsics (sequence.json says so too).
    Intrinsics::KINECT_V1
}

/// Solve from poses with the default options (`lenient`: no residual limit, for a first pass that only has to
/// improve the prior).
pub fn solve_poses(
    poses: &[PoseObservation],
    lenient: bool,
) -> Result<Solution, supine_core::calib::SolveError> {
    let options = if lenient {
        SolveOptions::lenient()
    } else {
        SolveOptions::default()
    };
    supine_drivers::calib_host::solve_poses(poses, &options).map(|(s, _, _)| s)
}

/// The result of one sequence at one pose count.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Outcome {
    /// Sequence directory.
    pub sequence: String,
    /// Patient on the bed.
    pub patient: bool,
    /// Poses asked for.
    pub poses: usize,
    /// Poses used (inliers).
    pub inliers: usize,
    /// Translation error, mm (`None`: refused).
    pub translation_error_mm: Option<f32>,
    /// Rotation error, degrees.
    pub rotation_error_deg: Option<f32>,
    /// RMS residual over the inliers, mm.
    pub residual_mm: Option<f32>,
    /// Mean displacement of the torso points (hip centre, belly, shoulder centre) mapped with the estimate
    /// instead of the truth, mm: the error it adds to probe mapping at the torso.
    pub torso_mapping_error_mm: Option<f32>,
    /// Condition number of the pose set.
    pub condition: Option<f32>,
    /// The solver's 1-sigma translation uncertainty, mm (expected size of `translation_error_mm`).
    pub translation_sigma_mm: Option<f32>,
    /// The solver's 1-sigma rotation uncertainty, degrees.
    pub rotation_sigma_deg: Option<f32>,
    /// The rotation uncertainty the pose set's geometry gives for the nominal per-pose error, degrees.
    pub nominal_rotation_sigma_deg: Option<f32>,
    /// Whether `supine calibrate` warns that the pose set is tight (see `Uncertainty::tight`).
    pub tight_pose_set: Option<bool>,
    /// Why no extrinsic came out.
    pub refused: Option<String>,
    /// Poses of the guess-free start that gave a tip (`None`: started from the nominal guess).
    pub start_tips: Option<usize>,
    /// Translation error of the guess-free start's rough extrinsic, mm.
    pub start_translation_error_mm: Option<f32>,
    /// Rotation error of the rough extrinsic, degrees.
    pub start_rotation_error_deg: Option<f32>,
    /// Mean distance of the detected tips (dwell means) from the true tips mapped into the camera, mm: what the
    /// detector and the dwell averaging leave.
    pub tip_detection_error_mm: Option<f32>,
    /// Mean signed error of the detected tips along the camera's view ray, mm (positive: seen too far).
    pub tip_depth_bias_mm: Option<f32>,
    /// Mean distance of the arm's reported tips (dwell means) from the true tips, mm: encoder and kinematic error.
    pub arm_tip_error_mm: Option<f32>,
    /// Per pose of the second pass (in order): the detected tip's error against the true tip in the true probe
    /// frame (across the head's width, across its thickness, along the axis toward the tip), mm, and the pose's
    /// residual in the solve, mm (empty when refused before the solve).
    pub pose_errors_mm: Vec<PoseError>,
    /// Frame counters of the second pass.
    pub frames_still: u32,
    /// Frames without a tip.
    pub frames_no_tip: u32,
}

/// One pose's detection error and solve residual (see [`Outcome::pose_errors_mm`]).
#[derive(Debug, Clone, serde::Serialize)]
pub struct PoseError {
    /// Detected minus true tip in the true probe frame `[x, y, axial]`, mm.
    pub probe_xyz: [f32; 3],
    /// Residual of the pose in the solve, mm (`None`: no solve).
    pub residual: Option<f32>,
    /// Whether the solve used the pose.
    pub inlier: bool,
}

/// Evaluate one sequence directory at every pose count.
pub fn evaluate_sequence(dir: &Path, nominal_guess: bool) -> Result<Vec<Outcome>> {
    let meta: SequenceMeta = serde_json::from_slice(
        &std::fs::read(dir.join("sequence.json"))
            .with_context(|| format!("reading {}/sequence.json", dir.display()))?,
    )
    .with_context(|| format!("parsing {}/sequence.json", dir.display()))?;
    let Some(cal) = meta.calibration else {
        bail!(
            "{} is not a calibration sequence (no `calibration` in sequence.json)",
            dir.display()
        );
    };
    let truth = cal.robot_base_from_camera.to_isometry();
    let nominal = cal.robot_base_from_camera_nominal.to_isometry();
    let (arm, _) = read_arm_capture(&dir.join("arm.cobs"))?;
    let truth_rotations = pose_rotations(dir, cal.poses_robot_base.len())?;
    let oni = dir.join("sequence.oni");
    let max = *POSE_COUNTS.iter().max().unwrap_or(&20);
    let keyframes = if nominal_guess {
        None
    } else {
        Some(pose_keyframes(&oni, &arm, max)?)
    };
    let k = Intrinsics::KINECT_V1;
    let mut out = Vec::new();
    for &n in &POSE_COUNTS {
        let mut o = Outcome {
            sequence: dir.display().to_string(),
            patient: cal.config.patient,
            poses: n,
            inliers: 0,
            translation_error_mm: None,
            rotation_error_deg: None,
            residual_mm: None,
            torso_mapping_error_mm: None,
            condition: None,
            translation_sigma_mm: None,
            rotation_sigma_deg: None,
            nominal_rotation_sigma_deg: None,
            tight_pose_set: None,
            refused: None,
            start_tips: None,
            start_translation_error_mm: None,
            start_rotation_error_deg: None,
            tip_detection_error_mm: None,
            tip_depth_bias_mm: None,
            arm_tip_error_mm: None,
            pose_errors_mm: Vec::new(),
            frames_still: 0,
            frames_no_tip: 0,
        };
        // The prior of the first pass: the nominal guess, or the guess-free start from the first `n` poses'
        // keyframes (6 cm uncertainty, as the nominal guess has).
        let prior = match &keyframes {
            None => nominal,
            Some((frames, arms)) => {
                let m = n.min(arms.len());
                match guess_free_start(&frames[..m], &arms[..m], &k) {
                    Ok((s, tips)) => {
                        o.start_tips = Some(tips);
                        o.start_translation_error_mm =
                            Some(translation_error_m(&s.robot_base_from_camera, &truth) * 1000.0);
                        o.start_rotation_error_deg =
                            Some(rotation_error_deg(&s.robot_base_from_camera, &truth));
                        s.robot_base_from_camera
                    }
                    Err(e) => {
                        o.refused = Some(e.to_string());
                        out.push(o);
                        continue;
                    }
                }
            }
        };
        let (first, _) = run_session(&oni, &arm, SessionConfig::new(prior), n)?;
        // The first pass only has to give a better prior: it may use fewer poses than asked for (some are lost to
        // the rough prior); the second pass must deliver all `n`.
        let pass1 = match solve_poses(&first, true) {
            Ok(s) => s,
            Err(e) => {
                o.refused = Some(format!("first pass: {e}"));
                out.push(o);
                continue;
            }
        };
        let (second, stats) = run_session(&oni, &arm, refined_session(pass1.robot_base_from_camera), n)?;
        let second = settle_passes(second, n, |prior| {
            run_session(&oni, &arm, refined_session(prior), n).map(|(poses, _)| poses)
        })?;
        o.frames_still = stats.still;
        o.frames_no_tip = stats.no_probe + stats.ambiguous;
        if second.len() < n {
            o.refused = Some(format!("only {} poses detected", second.len()));
            out.push(o);
            continue;
        }
        let (det, bias, arm_err) = tip_errors(&second[..n], &cal.poses_robot_base, &truth);
        o.tip_detection_error_mm = det;
        o.tip_depth_bias_mm = bias;
        o.arm_tip_error_mm = arm_err;
        let sol = supine_drivers::calib_host::solve_poses(&second[..n], &SolveOptions::default());
        let per_pose = probe_frame_errors(&second[..n], &cal.poses_robot_base, &truth_rotations, &truth);
        o.pose_errors_mm = per_pose
            .iter()
            .enumerate()
            .map(|(i, e)| PoseError {
                probe_xyz: e.map(|v| (v * 10.0).round() / 10.0),
                residual: sol.as_ref().ok().map(|(_, r, _)| (r[i] * 1e4).round() / 10.0),
                inlier: false,
            })
            .collect();
        if let Ok((_, _, inl)) = &sol {
            for (p, &i) in o.pose_errors_mm.iter_mut().zip(inl.iter()) {
                p.inlier = i;
            }
        }
        match sol.map(|(s, _, _)| s) {
            Ok(s) => {
                let t = s.robot_base_from_camera;
                o.inliers = s.inliers;
                o.translation_error_mm = Some(translation_error_m(&t, &truth) * 1000.0);
                o.rotation_error_deg = Some(rotation_error_deg(&t, &truth));
                o.residual_mm = Some(s.rms_residual_m * 1000.0);
                o.condition = Some(s.condition);
                if let Some(u) = s.uncertainty {
                    o.translation_sigma_mm = Some(u.translation_sigma_m * 1000.0);
                    o.rotation_sigma_deg = Some(u.rotation_sigma_deg);
                    o.nominal_rotation_sigma_deg = Some(u.nominal_rotation_sigma_deg);
                    o.tight_pose_set = Some(u.tight());
                }
                o.torso_mapping_error_mm = Some(torso_error_mm(&t, &truth, &cal.torso_points_camera));
            }
            Err(e) => o.refused = Some(e.to_string()),
        }
        out.push(o);
    }
    Ok(out)
}

/// Where the pair errors come from: each pose matched to the nearest true pose tip (within 2 cm); the mean
/// detection error, its mean component along the view ray, and the mean arm error, mm.
fn tip_errors(
    poses: &[PoseObservation],
    true_tips: &[[f32; 3]],
    truth: &Isometry3,
) -> (Option<f32>, Option<f32>, Option<f32>) {
    let camera_from_robot_base = truth.inverse();
    let (mut det, mut bias, mut arm) = (Vec::new(), Vec::new(), Vec::new());
    for p in poses {
        let nearest = true_tips
            .iter()
            .map(|t| Point3::from(*t))
            .min_by(|a, b| (a - p.robot_base).norm().total_cmp(&(b - p.robot_base).norm()));
        let Some(t) = nearest.filter(|t| (t - p.robot_base).norm() < 0.02) else {
            continue;
        };
        let tc = camera_from_robot_base * t;
        let e = p.camera - tc;
        det.push(e.norm() * 1000.0);
        bias.push(e.dot(&tc.coords.normalize()) * 1000.0);
        arm.push((p.robot_base - t).norm() * 1000.0);
    }
    (
        mean(det.into_iter()),
        mean(bias.into_iter()),
        mean(arm.into_iter()),
    )
}

/// The true `camera_from_probe` rotation of every pose (its first dwell frame in `truth.jsonl`).
fn pose_rotations(dir: &Path, poses: usize) -> Result<Vec<Option<nalgebra::Matrix3<f32>>>> {
    let path = dir.join("truth.jsonl");
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = vec![None; poses];
    for (i, line) in text.lines().enumerate() {
        let t: CalibrationFrameTruth = serde_json::from_str(line)
            .with_context(|| format!("parsing {} line {}", path.display(), i + 1))?;
        if let Some(slot) = t.pose.and_then(|p| out.get_mut(p as usize))
            && slot.is_none()
        {
            let m = t.camera_from_probe;
            *slot = Some(nalgebra::Matrix3::new(
                m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
            ));
        }
    }
    Ok(out)
}

/// Each pose's detection error in the true probe frame (mm), matched to the nearest true pose tip as in
/// [`tip_errors`]; NaN where no true pose is near.
fn probe_frame_errors(
    poses: &[PoseObservation],
    true_tips: &[[f32; 3]],
    rotations: &[Option<nalgebra::Matrix3<f32>>],
    truth: &Isometry3,
) -> Vec<[f32; 3]> {
    let camera_from_robot_base = truth.inverse();
    poses
        .iter()
        .map(|p| {
            let nearest = true_tips
                .iter()
                .enumerate()
                .map(|(i, t)| (i, Point3::from(*t)))
                .min_by(|(_, a), (_, b)| (a - p.robot_base).norm().total_cmp(&(b - p.robot_base).norm()));
            match nearest.filter(|(_, t)| (t - p.robot_base).norm() < 0.02) {
                Some((i, t)) => match rotations.get(i).copied().flatten() {
                    Some(r) => {
                        let e = r.transpose() * (p.camera - camera_from_robot_base * t) * 1000.0;
                        [e.x, e.y, e.z]
                    }
                    None => [f32::NAN; 3],
                },
                None => [f32::NAN; 3],
            }
        })
        .collect()
}

fn torso_error_mm(est: &Isometry3, truth: &Isometry3, points: &[[f32; 3]]) -> f32 {
    let sum: f32 = points
        .iter()
        .map(|p| {
            let p = Point3::from(*p);
            (est * p - truth * p).norm()
        })
        .sum();
    1000.0 * sum / points.len().max(1) as f32
}

/// The calibration sequences under `data`: itself, or its subdirectories with a calibration `sequence.json`.
pub fn sequence_dirs(data: &Path) -> Result<Vec<PathBuf>> {
    if data.join("sequence.json").is_file() {
        return Ok(vec![data.to_owned()]);
    }
    let dirs = super::tracking_truth::subdirectories(data, |p| {
        p.join("sequence.json").is_file() && p.join("arm.cobs").is_file()
    })?;
    if dirs.is_empty() {
        bail!(
            "{} holds no calibration sequence (make one with `supine-models sequence --calibration --out DIR`)",
            data.display()
        );
    }
    Ok(dirs)
}

fn mean(v: impl Iterator<Item = f32>) -> Option<f32> {
    let (n, s) = v.fold((0usize, 0.0f32), |(n, s), x| (n + 1, s + x));
    (n > 0).then(|| s / n as f32)
}

fn max(v: impl Iterator<Item = f32>) -> Option<f32> {
    v.fold(None, |m: Option<f32>, x| Some(m.map_or(x, |m| m.max(x))))
}

/// Translation error at most this counts as within the target (issue 13), mm.
pub const TARGET_TRANSLATION_MM: f32 = 5.0;
/// Rotation error at most this counts as within the target, degrees.
pub const TARGET_ROTATION_DEG: f32 = 0.3;

/// Whether a solved outcome meets both targets.
fn within_limits(o: &Outcome) -> bool {
    o.translation_error_mm.is_some_and(|t| t <= TARGET_TRANSLATION_MM)
        && o.rotation_error_deg.is_some_and(|r| r <= TARGET_ROTATION_DEG)
}

/// The report part for a set of outcomes, keyed by pose count.
pub fn summarise(outcomes: &[&Outcome]) -> serde_json::Value {
    let mut obj = serde_json::Map::new();
    for n in POSE_COUNTS {
        let at: Vec<&&Outcome> = outcomes.iter().filter(|o| o.poses == n).collect();
        let solved: Vec<&&&Outcome> = at.iter().filter(|o| o.translation_error_mm.is_some()).collect();
        let f = |g: fn(&Outcome) -> Option<f32>| solved.iter().filter_map(move |o| g(o));
        obj.insert(
            n.to_string(),
            serde_json::json!({
                "translation_error_mm": mean(f(|o| o.translation_error_mm)),
                "rotation_error_deg": mean(f(|o| o.rotation_error_deg)),
                "residual_mm": mean(f(|o| o.residual_mm)),
                "torso_mapping_error_mm": mean(f(|o| o.torso_mapping_error_mm)),
                "translation_error_mm_max": max(f(|o| o.translation_error_mm)),
                "tip_detection_error_mm": mean(f(|o| o.tip_detection_error_mm)),
                "tip_depth_bias_mm": mean(f(|o| o.tip_depth_bias_mm)),
                "arm_tip_error_mm": mean(f(|o| o.arm_tip_error_mm)),
                "start_translation_error_mm": mean(f(|o| o.start_translation_error_mm)),
                "start_rotation_error_deg": mean(f(|o| o.start_rotation_error_deg)),
                "rotation_error_deg_max": max(f(|o| o.rotation_error_deg)),
                "translation_sigma_mm": mean(f(|o| o.translation_sigma_mm)),
                "rotation_sigma_deg": mean(f(|o| o.rotation_sigma_deg)),
                "sequences": at.len(),
                "solved": solved.len(),
                "within_both_limits": solved.iter().filter(|o| within_limits(o)).count(),
                "tight_pose_sets": solved.iter().filter(|o| o.tight_pose_set == Some(true)).count(),
            }),
        );
    }
    serde_json::Value::Object(obj)
}

/// Run the command.
pub fn run(args: &CalibrationEvalArgs) -> ExitCode {
    match run_inner(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

fn run_inner(args: &CalibrationEvalArgs) -> Result<()> {
    let dirs = sequence_dirs(&args.data)?;
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(dirs.len() as u64),
        indicatif::ProgressDrawTarget::stderr(),
    );
    let mut all = Vec::new();
    for d in &dirs {
        all.extend(evaluate_sequence(d, args.nominal_guess)?);
        bar.inc(1);
    }
    bar.finish();
    let refs: Vec<&Outcome> = all.iter().collect();
    let with: Vec<&Outcome> = all.iter().filter(|o| o.patient).collect();
    let without: Vec<&Outcome> = all.iter().filter(|o| !o.patient).collect();
    let mut report = summarise(&refs);
    report["with_patient"] = summarise(&with);
    report["empty_bed"] = summarise(&without);
    report["sequences"] = dirs.len().into();
    report["per_sequence"] = serde_json::to_value(&all)?;
    report["commit"] = commit().into();
    println!(
        "poses  translation_mm  rotation_deg  residual_mm  torso_mm   (mean over {} sequences)",
        dirs.len()
    );
    for n in POSE_COUNTS {
        let r = &report[n.to_string()];
        let g = |k: &str| r[k].as_f64().map_or("-".to_owned(), |v| format!("{v:.2}"));
        println!(
            "{n:>5}  {:>14}  {:>12}  {:>11}  {:>8}   solved {}/{}, within both limits {}",
            g("translation_error_mm"),
            g("rotation_error_deg"),
            g("residual_mm"),
            g("torso_mapping_error_mm"),
            r["solved"],
            r["sequences"],
            r["within_both_limits"]
        );
    }
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_vec_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &args.svg {
        std::fs::write(path, super::figure::calibration_svg(&all))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
