//! `supine calibrate --source SOURCE --link LINK [--poses N] [--out FILE]`: the camera-to-robot extrinsic from arm
//! states paired with the probe tip seen in depth; `--from FILE` solves from recorded pairs.
//!
//! The arm moves its probe through poses above the bed (empty, or with the patient still), dwelling a moment at
//! each. Every depth frame is matched to the arm state nearest its capture time and the probe tip is found near
//! where the current guess (`--guess FILE`, the mount drawing or a previous calibration) puts it; the still frames
//! of each pose are averaged into one pair (`supine_core::calib::Session`). Without `--guess` the still frames are
//! kept, the first guess comes from the guess-free start (`supine_core::calib::start`) and the session runs twice
//! over the kept frames ([`guess_free`]). After `--poses` poses the pairs are
//! solved (Kabsch inside RANSAC, refined), the residuals printed, and the extrinsic written in the config's syntax:
//!
//! ```toml
//! [robot_base_from_camera]
//! translation_m = [x, y, z]               # the camera's origin in robot_base, metres
//! rotation_quat_wxyz = [w, x, y, z]        # rotation robot_base_from_camera, unit quaternion
//! ```
//!
//! `--pairs FILE` records the pairs (one JSON object a line) for `--from FILE`. Nothing is written when the
//! solve is refused (too few poses, degenerate poses, no probe seen, arm states out of time).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::Args;
use supine_core::calib::{
    ArmSample, FrameOutcome, PoseObservation, Session, SessionConfig, Solution, SolveOptions, WARN_CONDITION,
    solve::{
        NOMINAL_POSE_ERROR_M, WARN_NOMINAL_ROTATION_DEG, WARN_SIGMA_ROTATION_DEG, WARN_SIGMA_TRANSLATION_M,
    },
    unit_quaternion_wxyz,
};
use supine_core::geometry::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use supine_drivers::link::{self, FileMode, LinkOptions, LinkSpec};
use supine_drivers::source::{self, SourceErrorKind, SourceSpec};

use crate::failure::Failure;

mod guess_free;

/// A session sized for the head computer: 4096 arm states (4 s at 1 kHz), 64 poses, 8192 detection points.
type CalibrationSession = Session<4096, 64, 8192>;

/// Arguments of `supine calibrate`.
#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// Depth source: openni2[:URI], freenect[:INDEX], v4l2:/dev/videoN or file:PATH.
    #[arg(long, required_unless_present = "from")]
    pub source: Option<String>,
    /// Link the arm states come from: serial:PATH[@BAUD], slcan:PATH[@BAUD], can:IFACE or file:PATH (a capture).
    #[arg(long, required_unless_present = "from")]
    pub link: Option<String>,
    /// Poses to collect before solving.
    #[arg(long, default_value_t = 10)]
    pub poses: usize,
    /// Write the extrinsic here (TOML, the config's `[robot_base_from_camera]`); default: stdout.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Solve from recorded pairs (written by `--pairs`) instead of collecting.
    #[arg(long, conflicts_with_all = ["source", "link"])]
    pub from: Option<PathBuf>,
    /// The current guess of the extrinsic, a TOML file with `[robot_base_from_camera]` (a config file will do);
    /// it tells the detector where to look for the probe. Without it the probe is found from what moves above
    /// the bed (the guess-free start: the robot base must stand level, the probe point down).
    #[arg(long)]
    pub guess: Option<PathBuf>,
    /// How far the guess may put the probe tip from where it is, metres.
    #[arg(long, default_value_t = 0.06)]
    pub guess_uncertainty_m: f32,
    /// Record the collected pairs here (JSON lines), for `--from`.
    #[arg(long)]
    pub pairs: Option<PathBuf>,
    /// Give up after this long without a depth frame, seconds.
    #[arg(long, default_value_t = 5.0)]
    pub timeout_s: f64,
}

/// Run `supine calibrate`.
pub fn run(args: CalibrateArgs) -> Result<(), Failure> {
    if args.poses < 4 {
        return Err(Failure::usage(
            "--poses must be at least 4 (3 fix a rigid transform, one more checks it)",
        ));
    }
    if !(args.guess_uncertainty_m > 0.0 && args.guess_uncertainty_m <= 0.5) {
        return Err(Failure::usage("--guess-uncertainty-m must be in (0, 0.5] metres"));
    }
    let poses = match &args.from {
        Some(path) => read_pairs(path)?,
        None => collect(&args)?,
    };
    if let Some(path) = &args.pairs
        && args.from.is_none()
    {
        write_atomic(path, pairs_jsonl(&poses).as_bytes())?;
        eprintln!("pairs written to {}", path.display());
    }
    let (solution, residuals, inliers) =
        supine_drivers::calib_host::solve_poses(&poses, &SolveOptions::default())
            .map_err(|e| anyhow::anyhow!("no extrinsic: {e}"))?;
    for (i, (r, ok)) in residuals.iter().zip(&inliers).enumerate() {
        eprintln!(
            "pose {:>2}: residual {:>6.2} mm{}",
            i + 1,
            r * 1000.0,
            if *ok { "" } else { "  (outlier, not used)" }
        );
    }
    eprintln!(
        "solved from {} of {} poses: rms residual {:.2} mm, max {:.2} mm, condition {:.1}",
        solution.inliers,
        poses.len(),
        solution.rms_residual_m * 1000.0,
        solution.max_residual_m * 1000.0,
        solution.condition
    );
    if let Some(u) = &solution.uncertainty {
        eprintln!(
            "uncertainty (1 sigma, from the residuals): translation {:.2} mm, rotation {:.3} deg",
            u.translation_sigma_m * 1000.0,
            u.rotation_sigma_deg
        );
    }
    if solution.condition > WARN_CONDITION {
        eprintln!(
            "warning: the poses lie close to a plane (condition {:.1} > {WARN_CONDITION}): vary the probe height more",
            solution.condition
        );
    }
    if let Some(u) = solution.uncertainty.filter(|u| u.tight()) {
        eprintln!(
            "warning: the poses are too close together for the camera's distance (their geometry alone gives \
             {:.2} deg / {:.1} mm at 1 sigma for {:.1} mm per pose, warned above {WARN_NOMINAL_ROTATION_DEG} deg): \
             spread them wider across the bed and in height, or add poses",
            u.nominal_rotation_sigma_deg,
            u.nominal_translation_sigma_m * 1000.0,
            NOMINAL_POSE_ERROR_M * 1000.0,
        );
    }
    if let Some(u) = solution.uncertainty.filter(|u| u.beyond_target()) {
        eprintln!(
            "warning: the result's own uncertainty ({:.1} mm / {:.2} deg at 1 sigma) exceeds the {:.0} mm / {} deg \
             probe mapping needs: collect again before using it (poses spread wider when the set is tight, else the \
             pairs disagree: a wrong tip detection or arm states out of step)",
            u.translation_sigma_m * 1000.0,
            u.rotation_sigma_deg,
            WARN_SIGMA_TRANSLATION_M * 1000.0,
            WARN_SIGMA_ROTATION_DEG,
        );
    }
    let text = extrinsic_toml(&solution, poses.len());
    match &args.out {
        Some(path) => {
            write_atomic(path, text.as_bytes())?;
            eprintln!("extrinsic written to {}", path.display());
        }
        None => {
            let mut out = std::io::stdout().lock();
            out.write_all(text.as_bytes()).and_then(|()| out.flush())?;
        }
    }
    Ok(())
}

/// Collect poses from a depth source and an arm link.
fn collect(args: &CalibrateArgs) -> Result<Vec<PoseObservation>, Failure> {
    let (Some(source_str), Some(link_str)) = (&args.source, &args.link) else {
        return Err(Failure::usage("give --source and --link, or --from FILE"));
    };
    let guess = match &args.guess {
        Some(path) => Some(read_extrinsic(path)?),
        None => None,
    };
    let source_spec: SourceSpec = source_str
        .parse()
        .map_err(|e: source::SourceError| Failure::usage(format!("--source: {e}")))?;
    let link_spec: LinkSpec = link_str
        .parse()
        .map_err(|e| Failure::usage(format!("--link: {e}")))?;
    if !link_spec.can_receive() {
        return Err(Failure::usage(format!(
            "--link: `{link_str}` can only send; arm states must come in"
        )));
    }
    let mut src = source::open(&source_spec).map_err(|e| anyhow::anyhow!("opening {source_spec}: {e}"))?;
    let k = src.intrinsics();
    let options = LinkOptions {
        file_mode: FileMode::Read,
        ..LinkOptions::default()
    };
    let mut arm_link = link::open(&link_spec, &options).map_err(|e| anyhow::anyhow!("{e}"))?;
    crate::links::catch_interrupts().map_err(|e| anyhow::anyhow!("installing the SIGINT handler: {e}"))?;
    let Some(guess) = guess else {
        return guess_free::collect(args, src.as_mut(), &k, arm_link.as_mut());
    };
    let config = SessionConfig {
        guess_uncertainty_m: args.guess_uncertainty_m,
        ..SessionConfig::new(guess)
    };
    let mut session = Box::new(CalibrationSession::new(config));
    eprintln!(
        "calibrating: frames from {}, arm states from {}; move the arm through {} poses above the bed, \
         dwelling half a second at each",
        src.describe(),
        arm_link.describe(),
        args.poses
    );
    let timeout = Duration::try_from_secs_f64(args.timeout_s.max(0.1)).unwrap_or(Duration::from_secs(5));
    let mut last_frame = Instant::now();
    let mut newest_arm: Option<supine_core::time::Timestamp> = None;
    let mut arm_states = 0u64;
    let mut reported = 0usize;
    let mut link_ended = false;
    let reason = loop {
        if crate::links::interrupted() {
            break "interrupted";
        }
        if session.pose_count() >= args.poses {
            break "enough poses";
        }
        let frame = match src.next_frame(Duration::from_millis(100)) {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break "end of the depth source",
            Err(e) if e.kind() == SourceErrorKind::Timeout => {
                if last_frame.elapsed() >= timeout {
                    return Err(anyhow::anyhow!(
                        "no depth frame from {source_spec} for {:.1} s",
                        args.timeout_s
                    )
                    .into());
                }
                continue;
            }
            Err(e) => return Err(anyhow::anyhow!("reading {source_spec}: {e}").into()),
        };
        last_frame = Instant::now();
        // Arm states up to a little past this frame: all a live link has, and no further ahead than the session
        // needs from a capture file (so its history window stays around the frames).
        let horizon = frame.capture.offset_by(200_000);
        while !link_ended && newest_arm.is_none_or(|t| t < horizon) {
            match arm_link.receive() {
                Ok(Some(m)) => {
                    if let Some(s) = ArmSample::from_message(&m) {
                        newest_arm = Some(s.time);
                        arm_states += 1;
                        session.on_arm(s);
                    }
                }
                Ok(None) => {
                    link_ended = arm_link.state() == link::LinkState::Ended;
                    break;
                }
                Err(e) => return Err(anyhow::anyhow!("receiving on {}: {e}", arm_link.describe()).into()),
            }
        }
        if let FrameOutcome::OutOfTime { offset_us } = session.on_frame(&frame, &k)
            && session.stats().frames % 30 == 1
        {
            eprintln!(
                "frame at {} µs: nearest arm state {:.0} ms away",
                frame.capture.as_us(),
                offset_us as f64 / 1000.0
            );
        }
        while reported < session.pose_count() {
            if let Some(p) = session.poses().nth(reported) {
                eprintln!(
                    "pose {}/{}: arm tip [{:.1} {:.1} {:.1}] mm, seen at [{:.1} {:.1} {:.1}] mm, {} frames, spread {:.1} mm",
                    reported + 1,
                    args.poses,
                    p.robot_base.x * 1000.0,
                    p.robot_base.y * 1000.0,
                    p.robot_base.z * 1000.0,
                    p.camera.x * 1000.0,
                    p.camera.y * 1000.0,
                    p.camera.z * 1000.0,
                    p.frames,
                    p.spread_m * 1000.0
                );
            }
            reported += 1;
        }
    };
    // Arm states after the last frame decide its stillness: the rest of a capture, or 0.3 s more of a live link.
    let deadline = Instant::now() + Duration::from_millis(300);
    while !link_ended && Instant::now() < deadline {
        match arm_link.receive() {
            Ok(Some(m)) => {
                if let Some(s) = ArmSample::from_message(&m) {
                    arm_states += 1;
                    session.on_arm(s);
                }
            }
            Ok(None) if arm_link.state() == link::LinkState::Ended => break,
            Ok(None) => arm_link.wait_readable(Duration::from_millis(20)),
            Err(_) => break,
        }
    }
    session.finish();
    let stats = *session.stats();
    let poses: Vec<PoseObservation> = session.poses().take(args.poses).collect();
    eprintln!(
        "stopped ({reason}): {} frames, {} arm states, {} frames with the tip, {} still, {} out of time, {} without \
         probe, {} ambiguous; {} poses",
        stats.frames,
        arm_states,
        stats.detected,
        stats.still,
        stats.out_of_time,
        stats.no_probe,
        stats.ambiguous,
        poses.len()
    );
    if poses.len() < 4 {
        let why = if arm_states == 0 {
            format!("no arm state arrived on {}", arm_link.describe())
        } else if stats.out_of_time == stats.frames {
            format!(
                "arm states out of time: the nearest arm state was {:.0} ms from the depth frames (the arm must stamp \
                 its states on the tracker's capture clock)",
                stats.last_offset_us as f64 / 1000.0
            )
        } else if stats.detected == 0 {
            match stats.last_tip_error {
                Some(e) => format!("{e}; check the guess (--guess) and that the probe is in view"),
                None => "no probe visible".to_owned(),
            }
        } else if stats.still == 0 {
            "the arm never stood still: dwell half a second at each pose".to_owned()
        } else {
            format!("only {} poses seen", poses.len())
        };
        return Err(anyhow::anyhow!("no extrinsic: {why}").into());
    }
    if poses.len() < args.poses {
        eprintln!("warning: {} of {} poses collected", poses.len(), args.poses);
    }
    Ok(poses)
}

/// The extrinsic in the config's syntax, with a comment saying how it was obtained.
pub fn extrinsic_toml(s: &Solution, poses: usize) -> String {
    let t = s.robot_base_from_camera.translation.vector;
    let q = s.robot_base_from_camera.rotation.quaternion();
    format!(
        "# written by `supine calibrate`: {} of {poses} poses, rms residual {:.2} mm, condition {:.1}{}\n\
         [robot_base_from_camera]\n\
         translation_m = [{:.6}, {:.6}, {:.6}]\n\
         rotation_quat_wxyz = [{:.8}, {:.8}, {:.8}, {:.8}]\n",
        s.inliers,
        s.rms_residual_m * 1000.0,
        s.condition,
        s.uncertainty.map_or(String::new(), |u| format!(
            ", 1 sigma {:.2} mm / {:.3} deg",
            u.translation_sigma_m * 1000.0,
            u.rotation_sigma_deg
        )),
        t.x,
        t.y,
        t.z,
        q.w,
        q.i,
        q.j,
        q.k
    )
}

/// Read `[robot_base_from_camera]` from a TOML file (the keys `translation_m` and `rotation_quat_wxyz`, arrays of
/// numbers; comments and other tables are skipped).
pub fn read_extrinsic(path: &Path) -> Result<Isometry3, Failure> {
    let text =
        std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
    parse_extrinsic(&text).map_err(|e| Failure::Runtime(anyhow::anyhow!("{}: {e}", path.display())))
}

fn parse_extrinsic(text: &str) -> Result<Isometry3, String> {
    let mut in_table = false;
    let mut found_table = false;
    let (mut t, mut q): (Option<Vec<f32>>, Option<Vec<f32>>) = (None, None);
    for (n, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        if line.starts_with('[') {
            in_table = line == "[robot_base_from_camera]";
            found_table |= in_table;
            continue;
        }
        if !in_table {
            continue;
        }
        let Some((key, value)) = line.split_once('=') else {
            return Err(format!("line {}: expected `key = value`", n + 1));
        };
        let numbers = || -> Result<Vec<f32>, String> {
            let v = value.trim();
            let inner = v
                .strip_prefix('[')
                .and_then(|v| v.strip_suffix(']'))
                .ok_or_else(|| format!("line {}: expected an array like [1.0, 2.0, 3.0]", n + 1))?;
            inner
                .split(',')
                .map(|x| {
                    x.trim()
                        .parse::<f32>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| format!("line {}: `{}` is not a number", n + 1, x.trim()))
                })
                .collect()
        };
        match key.trim() {
            "translation_m" => t = Some(numbers()?),
            "rotation_quat_wxyz" => q = Some(numbers()?),
            other => {
                return Err(format!(
                    "line {}: unknown key `{other}` in [robot_base_from_camera]",
                    n + 1
                ));
            }
        }
    }
    if !found_table {
        return Err("no [robot_base_from_camera] table".to_owned());
    }
    let t = t.ok_or("[robot_base_from_camera] has no translation_m")?;
    let q = q.ok_or("[robot_base_from_camera] has no rotation_quat_wxyz")?;
    let [x, y, z] = t[..] else {
        return Err(format!("translation_m has {} numbers, 3 expected", t.len()));
    };
    let [qw, qx, qy, qz] = q[..] else {
        return Err(format!("rotation_quat_wxyz has {} numbers, 4 expected", q.len()));
    };
    let norm = (qw * qw + qx * qx + qy * qy + qz * qz).sqrt();
    if (norm - 1.0).abs() > 0.01 {
        return Err(format!(
            "rotation_quat_wxyz has length {norm:.4}, not a unit quaternion"
        ));
    }
    let rotation: UnitQuaternion =
        unit_quaternion_wxyz([qw, qx, qy, qz]).ok_or("rotation_quat_wxyz is not a unit quaternion")?;
    Ok(Isometry3::from_parts(
        Translation3::from(Vector3::new(x, y, z)),
        rotation,
    ))
}

/// One JSON object per pose: arm tip (`robot_base_m`), the arm's probe axis (`axis_robot_base`), seen tip
/// (`camera_m`), frames, spread, confidence, time.
fn pairs_jsonl(poses: &[PoseObservation]) -> String {
    let mut s = String::new();
    for p in poses {
        let v = serde_json::json!({
            "robot_base_m": [p.robot_base.x, p.robot_base.y, p.robot_base.z],
            "axis_robot_base": [p.axis_robot_base.x, p.axis_robot_base.y, p.axis_robot_base.z],
            "camera_m": [p.camera.x, p.camera.y, p.camera.z],
            "frames": p.frames,
            "spread_mm": p.spread_m * 1000.0,
            "confidence": p.confidence,
            "arm_time_us": p.first_time.as_us(),
        });
        s.push_str(&v.to_string());
        s.push('\n');
    }
    s
}

/// Read pairs recorded by `--pairs` (or written by hand: `robot_base_m` and `camera_m` are what counts).
fn read_pairs(path: &Path) -> Result<Vec<PoseObservation>, Failure> {
    let text =
        std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("reading {}: {e}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let bad = |what: &str| anyhow::anyhow!("{}:{}: {what}", path.display(), n + 1);
        let v: serde_json::Value = serde_json::from_str(line).map_err(|e| bad(&format!("not JSON: {e}")))?;
        let point = |key: &str| -> Result<Point3, anyhow::Error> {
            let a = v[key]
                .as_array()
                .filter(|a| a.len() == 3)
                .ok_or_else(|| bad(&format!("`{key}` must be an array of 3 numbers (metres)")))?;
            let mut p = [0.0f32; 3];
            for (o, x) in p.iter_mut().zip(a) {
                *o = x
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(&format!("`{key}` holds a non-number")))? as f32;
            }
            Ok(Point3::from(p))
        };
        out.push(PoseObservation {
            robot_base: point("robot_base_m")?,
            camera: point("camera_m")?,
            frames: v["frames"].as_u64().unwrap_or(1) as u32,
            first_time: supine_core::time::Timestamp::from_us(v["arm_time_us"].as_u64().unwrap_or(0))
                .unwrap_or_default(),
            spread_m: v["spread_mm"].as_f64().unwrap_or(0.0) as f32 * 0.001,
            confidence: v["confidence"].as_f64().unwrap_or(1.0) as f32,
            // Optional (older files and hand-written pairs lack it): without it the pair counts the same in every
            // direction.
            axis_robot_base: match v.get("axis_robot_base") {
                None => Vector3::zeros(),
                Some(_) => point("axis_robot_base")?
                    .coords
                    .try_normalize(1e-6)
                    .unwrap_or_else(Vector3::zeros),
            },
        });
    }
    eprintln!("{} pairs from {}", out.len(), path.display());
    Ok(out)
}

/// Write `bytes` to `path` through a temporary file in the same directory and a rename, so a reader never sees
/// half an extrinsic.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), Failure> {
    let tmp = path.with_extension("tmp-supine");
    std::fs::write(&tmp, bytes)
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            anyhow::anyhow!("writing {}: {e}", path.display()).into()
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extrinsic_round_trips_through_the_config_syntax() {
        let t = Isometry3::new(Vector3::new(0.3, -0.8, 1.9), Vector3::new(-2.0, 0.1, 0.3));
        let s = Solution {
            robot_base_from_camera: t,
            inliers: 9,
            rms_residual_m: 0.0012,
            max_residual_m: 0.002,
            condition: 3.0,
            uncertainty: None,
        };
        let text = extrinsic_toml(&s, 10);
        assert!(
            text.contains("[robot_base_from_camera]\ntranslation_m = ["),
            "{text}"
        );
        let back = parse_extrinsic(&format!(
            "source = \"freenect\"\n{text}\n[log]\nfilter = \"info\"\n"
        ))
        .unwrap();
        assert!((back.translation.vector - t.translation.vector).norm() < 1e-5);
        assert!(back.rotation.angle_to(&t.rotation) < 1e-5);
    }

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("supine-calibrate-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn args(dir: &Path) -> CalibrateArgs {
        CalibrateArgs {
            source: None,
            link: None,
            poses: 10,
            out: Some(dir.join("extrinsic.toml")),
            from: None,
            guess: None,
            guess_uncertainty_m: 0.06,
            pairs: None,
            timeout_s: 1.0,
        }
    }

    /// Pairs of tips on a jittered 3D grid seen from `truth`, as `--pairs` writes them.
    fn pairs_file(path: &Path, truth: &Isometry3, n: usize, flat: bool) {
        let mut text = String::new();
        for i in 0..n {
            let rb = Point3::new(
                -0.3 + 0.2 * (i % 4) as f32,
                0.6 + 0.15 * ((i / 4) % 3) as f32 + 0.01 * i as f32,
                if flat {
                    0.9
                } else {
                    0.8 + 0.07 * ((i * 7) % 5) as f32
                },
            );
            let cam = truth.inverse() * rb;
            text.push_str(&format!(
                "{{\"robot_base_m\": [{}, {}, {}], \"camera_m\": [{}, {}, {}], \"frames\": 6}}\n",
                rb.x, rb.y, rb.z, cam.x, cam.y, cam.z
            ));
        }
        std::fs::write(path, text).unwrap();
    }

    #[test]
    fn from_recorded_pairs_writes_the_extrinsic() {
        let dir = temp("from");
        let truth = Isometry3::new(Vector3::new(0.1, -0.7, 1.8), Vector3::new(-2.2, 0.1, 0.2));
        pairs_file(&dir.join("pairs.jsonl"), &truth, 10, false);
        let a = CalibrateArgs {
            from: Some(dir.join("pairs.jsonl")),
            ..args(&dir)
        };
        run(a).unwrap();
        let got = read_extrinsic(&dir.join("extrinsic.toml")).unwrap();
        assert!((got.translation.vector - truth.translation.vector).norm() < 1e-4);
        assert!(got.rotation.angle_to(&truth.rotation).to_degrees() < 0.01);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn degenerate_or_broken_pairs_give_no_extrinsic() {
        let dir = temp("degenerate");
        let truth = Isometry3::new(Vector3::new(0.1, -0.7, 1.8), Vector3::new(-2.2, 0.1, 0.2));
        pairs_file(&dir.join("flat.jsonl"), &truth, 10, true);
        let a = CalibrateArgs {
            from: Some(dir.join("flat.jsonl")),
            ..args(&dir)
        };
        let e = run(a).unwrap_err().to_string();
        assert!(e.contains("plane"), "{e}");
        pairs_file(&dir.join("few.jsonl"), &truth, 3, false);
        let a = CalibrateArgs {
            from: Some(dir.join("few.jsonl")),
            ..args(&dir)
        };
        let e = run(a).unwrap_err().to_string();
        assert!(e.contains("at least 4"), "{e}");
        std::fs::write(dir.join("bad.jsonl"), "{\"robot_base_m\": [1, 2]}\n").unwrap();
        let a = CalibrateArgs {
            from: Some(dir.join("bad.jsonl")),
            ..args(&dir)
        };
        let e = run(a).unwrap_err().to_string();
        assert!(e.contains("bad.jsonl:1") && e.contains("robot_base_m"), "{e}");
        assert!(!dir.join("extrinsic.toml").exists(), "nothing written");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// An .oni of `frames` empty frames at 30 Hz and an arm capture at 100 Hz whose clock is `arm_offset_us` off.
    fn recording(dir: &Path, frames: u32, arm_offset_us: i64) {
        use supine_core::camera::Intrinsics;
        use supine_core::wire::{ArmState, Body, Message, UnitQuatQ14};
        use supine_drivers::oni::{Codec, OniWriter};
        let k = Intrinsics::KINECT_V1;
        let mut w = OniWriter::create(dir.join("rec.oni"), &k, Codec::Z16Table).unwrap();
        let depth = vec![0u16; 640 * 480];
        for f in 0..frames {
            w.write_frame(&depth, f as u64 * 33_333).unwrap();
        }
        w.finish().unwrap();
        let mut bytes = Vec::new();
        let mut buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
        for j in 0..(frames as u64 * 4) {
            let m = Message {
                seq: j as u16,
                timestamp: supine_core::time::Timestamp::from_us(j * 10_000)
                    .unwrap()
                    .offset_by(arm_offset_us),
                body: Body::ArmState(ArmState {
                    position_mm: [0, 700, 900],
                    orientation: UnitQuatQ14::IDENTITY,
                }),
            };
            let n = m.encode_serial(&mut buf).unwrap();
            bytes.extend_from_slice(&buf[..n]);
        }
        std::fs::write(dir.join("arm.cobs"), bytes).unwrap();
        std::fs::write(
            dir.join("guess.toml"),
            "[robot_base_from_camera]\ntranslation_m = [0.0, -0.2, 1.9]\nrotation_quat_wxyz = [0.0, 1.0, 0.0, 0.0]\n",
        )
        .unwrap();
    }

    fn live_args(dir: &Path) -> CalibrateArgs {
        CalibrateArgs {
            source: Some(format!("file:{}", dir.join("rec.oni").display())),
            link: Some(format!("file:{}", dir.join("arm.cobs").display())),
            guess: Some(dir.join("guess.toml")),
            ..args(dir)
        }
    }

    #[test]
    fn no_probe_in_view_gives_a_clear_message_and_no_extrinsic() {
        let dir = temp("noprobe");
        recording(&dir, 30, 0);
        let e = run(live_args(&dir)).unwrap_err().to_string();
        assert!(e.contains("no extrinsic") && e.contains("probe"), "{e}");
        assert!(!dir.join("extrinsic.toml").exists());
        // Without a guess: an arm that holds one pose is too few poses.
        let e = run(CalibrateArgs {
            guess: None,
            ..live_args(&dir)
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("no extrinsic") && e.contains("poses"), "{e}");
        assert!(!dir.join("extrinsic.toml").exists());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn arm_states_out_of_time_give_a_clear_message_and_no_extrinsic() {
        let dir = temp("late");
        recording(&dir, 30, 5_000_000);
        let e = run(live_args(&dir)).unwrap_err().to_string();
        assert!(e.contains("out of time") && e.contains("capture clock"), "{e}");
        assert!(!dir.join("extrinsic.toml").exists());
        // Without a guess too: the guess-free start needs still poses as well.
        let e = run(CalibrateArgs {
            guess: None,
            ..live_args(&dir)
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("no extrinsic") && e.contains("out of time"), "{e}");
        assert!(!dir.join("extrinsic.toml").exists());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn bad_extrinsics_say_what_is_wrong() {
        assert!(
            parse_extrinsic("[log]\n")
                .unwrap_err()
                .contains("no [robot_base_from_camera]")
        );
        let e = parse_extrinsic(
            "[robot_base_from_camera]\ntranslation_m = [1, 2]\nrotation_quat_wxyz = [1, 0, 0, 0]\n",
        )
        .unwrap_err();
        assert!(e.contains("3 expected"), "{e}");
        let e = parse_extrinsic(
            "[robot_base_from_camera]\ntranslation_m = [1, 2, 3]\nrotation_quat_wxyz = [2, 0, 0, 0]\n",
        )
        .unwrap_err();
        assert!(e.contains("unit quaternion"), "{e}");
        let e = parse_extrinsic("[robot_base_from_camera]\ntranslation_m = [1, x, 3]\n").unwrap_err();
        assert!(e.contains("`x` is not a number"), "{e}");
    }
}
