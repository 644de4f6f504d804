//! `supine-models sequence`: argument parsing, progress bar and JSON summary around [`super::generate`].

use super::episodes::MotionKind;
use super::{SWEEP_MAX_OCCLUDED, SequenceConfig, generate};
use crate::scene::model_body::{BodyKind, open_source};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `supine-models sequence`.
#[derive(Debug, clap::Args)]
pub struct SequenceArgs {
    /// Number of 30 Hz frames.
    #[arg(long, default_value_t = 300)]
    pub frames: u32,
    /// Seed: the same seed gives byte-identical output.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Let the robot arm sweep the probe over the torso (occluding up to about half of it: see
    /// --sweep-max-occluded).
    #[arg(long)]
    pub occluder: bool,
    /// With --occluder: the sweep hides at most this share of the torso (the robot's shoulder is placed so, checked
    /// on the first frame). Seeds whose first shoulder already holds it give the sequence of earlier versions byte
    /// for byte; 1 reproduces earlier versions for every seed.
    #[arg(long, default_value_t = SWEEP_MAX_OCCLUDED, value_parser = share)]
    pub sweep_max_occluded: f32,
    /// Whether --sweep-max-occluded counts the torso the arm's projector shadow hides beside what the arm covers
    /// (what the sensor loses; `false`: only what it covers, as versions before 2026-12-06 did).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub sweep_limit_shadow: bool,
    /// The arm parks between the head and the whole torso for about 1 s (30 frames, under ~10 % of the torso left
    /// visible), then leaves; the frame range goes into DIR/sequence.json.
    #[arg(long, conflicts_with = "calibration")]
    pub full_occlusion: bool,
    /// The patient rolls 15–20° onto one side or shifts 10 cm over 1.5 s (bare: chosen by the seed); the frame
    /// range goes into DIR/sequence.json.
    #[arg(long, value_enum, num_args = 0..=1, default_missing_value = "auto", conflicts_with = "calibration")]
    pub motion: Option<MotionArg>,
    /// A calibration sequence: the arm visits poses above the bed (12 frames each), arm states beside the .oni in
    /// DIR/arm.cobs, the true extrinsic in DIR/sequence.json.
    #[arg(long, conflicts_with = "occluder")]
    pub calibration: bool,
    /// With --calibration: the bed is empty (default: a still patient lies on it).
    #[arg(long, requires = "calibration")]
    pub empty_bed: bool,
    /// Output directory: sequence.oni, truth.jsonl, sequence.json, preview PNGs.
    #[arg(long)]
    pub out: PathBuf,
    /// Peak breathing rise of the chest front, millimetres.
    #[arg(long, default_value_t = 7.0)]
    pub breathing_mm: f32,
    /// Body source.
    #[arg(long, value_enum, default_value_t = BodyKind::Model)]
    pub body: BodyKind,
    /// Body model file (default: the committed models/artifacts/body.sbm).
    #[arg(long)]
    pub body_model: Option<PathBuf>,
    /// Register depth to the RGB camera (border, IR-occlusion holes), like OpenNI2's registered depth.
    #[arg(long)]
    pub registered: bool,
    /// The noise model before blobs, edge effects, registration and temporal correlation (reproduces earlier
    /// sequences byte for byte).
    #[arg(long, conflicts_with = "registered")]
    pub legacy_noise: bool,
    /// Noise model from this JSON file (a `KinectNoise`, as in sequence.json's config.noise) instead of the default.
    #[arg(long, conflicts_with_all = ["registered", "legacy_noise"])]
    pub noise: Option<PathBuf>,
    /// Write a machine-readable summary here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// `--motion`'s value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MotionArg {
    /// Roll or shift, chosen by the seed.
    Auto,
    /// A roll onto one side.
    Roll,
    /// A shift on the mattress.
    Shift,
}

impl MotionArg {
    /// The motion this value asks for with `seed`.
    pub fn resolve(self, seed: u64) -> MotionKind {
        match self {
            MotionArg::Auto => MotionKind::for_seed(seed),
            MotionArg::Roll => MotionKind::Roll,
            MotionArg::Shift => MotionKind::Shift,
        }
    }
}

/// Run the command; exit 0 on success, 1 on a runtime failure, 2 on bad arguments.
pub fn run(args: SequenceArgs) -> ExitCode {
    if args.frames == 0 {
        eprintln!("error: --frames must be at least 1");
        return ExitCode::from(2);
    }
    if !(0.0..=50.0).contains(&args.breathing_mm) {
        eprintln!("error: --breathing-mm must be between 0 and 50");
        return ExitCode::from(2);
    }
    match run_inner(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

fn progress(frames: u32) -> anyhow::Result<ProgressBar> {
    let bar = ProgressBar::with_draw_target(Some(frames as u64), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} frames  {per_sec}  eta {eta}")
            .map_err(|e| anyhow::anyhow!("progress template: {e}"))?
            .progress_chars("=> "),
    );
    Ok(bar)
}

fn run_calibration(
    args: &SequenceArgs,
    source: &dyn crate::scene::body::BodySource,
    cfg: &SequenceConfig,
) -> anyhow::Result<()> {
    let cal = super::calibration::CalibrationConfig {
        patient: !args.empty_bed,
        ..Default::default()
    };
    let bar = progress(args.frames)?;
    let meta =
        super::calibration::generate_calibration(source, cfg, &cal, &args.out, &mut |_, _| bar.inc(1))?;
    bar.finish();
    eprintln!(
        "{} frames, {} poses ({}) in {}; arm latency {} ms",
        args.frames,
        meta.poses_robot_base.len(),
        if cal.patient { "still patient" } else { "empty bed" },
        args.out.display(),
        meta.arm_latency_us as f32 / 1000.0
    );
    if let Some(path) = &args.json {
        let v = serde_json::json!({
            "command": "sequence",
            "calibration": true,
            "seed": args.seed,
            "frames": args.frames,
            "poses": meta.poses_robot_base.len(),
            "patient": cal.patient,
            "body_source": source.name(),
            "out": args.out,
        });
        std::fs::write(path, serde_json::to_vec_pretty(&v)?)
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    Ok(())
}

/// A share of the torso, in (0, 1].
fn share(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|e| format!("{s:?} is not a number: {e}"))?;
    if v > 0.0 && v <= 1.0 {
        Ok(v)
    } else {
        Err(format!("{v} is not a share of the torso in (0, 1]"))
    }
}

fn run_inner(args: &SequenceArgs) -> anyhow::Result<()> {
    let source = open_source(args.body, args.body_model.as_deref())?;
    let base = SequenceConfig::new(args.frames, args.seed, args.occluder);
    let cfg = SequenceConfig {
        breathing_amplitude_m: args.breathing_mm / 1000.0,
        full_occlusion: args.full_occlusion,
        motion: args.motion.map(|m| m.resolve(args.seed)),
        sweep_max_occluded: (args.occluder && args.sweep_max_occluded < 1.0)
            .then_some(args.sweep_max_occluded),
        sweep_limit_counts_shadow: args.sweep_limit_shadow,
        noise: if let Some(path) = &args.noise {
            crate::render::noise::KinectNoise::from_file(path)?
        } else if args.legacy_noise {
            crate::render::noise::KinectNoise::LEGACY
        } else if args.registered {
            base.noise.registered()
        } else {
            base.noise
        },
        ..base
    };
    if args.calibration {
        return run_calibration(args, source.as_ref(), &cfg);
    }
    let bar = progress(args.frames)?;
    let summary = generate(source.as_ref(), &cfg, &args.out, &mut |_, _| bar.inc(1))?;
    bar.finish();
    eprintln!(
        "{} frames in {}: torso occluded {:.0} % on average, {:.0} % at most; {:.1} frames/s",
        summary.frames,
        args.out.display(),
        100.0 * summary.torso_occluded_mean,
        100.0 * summary.torso_occluded_max,
        summary.frames_per_second
    );
    if let Some(planned) = summary.sweep_occluded_planned {
        eprintln!(
            "arm placed so its sweep hides {:.0} % of the torso at most on the first frame (limit {:.0} %{})",
            100.0 * planned,
            100.0 * args.sweep_max_occluded,
            if args.sweep_limit_shadow {
                ", its projector shadow counted"
            } else {
                ""
            }
        );
    }
    if let Some(o) = summary.episodes.full_occlusion {
        eprintln!(
            "full occlusion: frames {}..{} (arm moving {}..{}), torso hidden {:.0} % at least, arm wrist {:.2} m from the camera",
            o.start,
            o.end,
            o.approach_start,
            o.leave_end,
            100.0 * o.torso_occluded_fraction_min,
            o.park_distance_m
        );
    }
    if let Some(m) = summary.episodes.motion {
        eprintln!(
            "motion: {:?} frames {}..{} (roll {:.1}°, shift [{:.3}, {:.3}] m)",
            m.kind, m.start, m.end, m.roll_deg, m.shift_m[0], m.shift_m[1]
        );
    }
    if let Some(path) = &args.json {
        let mut v = serde_json::to_value(&summary)?;
        v["command"] = "sequence".into();
        v["seed"] = args.seed.into();
        v["occluder"] = args.occluder.into();
        v["full_occlusion"] = args.full_occlusion.into();
        v["body_source"] = source.name().into();
        v["out"] = serde_json::to_value(&args.out)?;
        std::fs::write(path, serde_json::to_vec_pretty(&v)?)
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: SequenceArgs,
    }

    fn parse(argv: &[&str]) -> Result<SequenceArgs, clap::Error> {
        Cli::try_parse_from(std::iter::once("sequence").chain(argv.iter().copied())).map(|c| c.args)
    }

    #[test]
    fn the_sweeps_occlusion_limit_is_a_share() {
        assert_eq!(
            parse(&["--out", "d", "--occluder"]).unwrap().sweep_max_occluded,
            0.5
        );
        assert_eq!(
            parse(&["--out", "d", "--occluder", "--sweep-max-occluded", "0.4"])
                .unwrap()
                .sweep_max_occluded,
            0.4
        );
        assert!(parse(&["--out", "d", "--occluder"]).unwrap().sweep_limit_shadow);
        assert!(
            !parse(&["--out", "d", "--occluder", "--sweep-limit-shadow", "false"])
                .unwrap()
                .sweep_limit_shadow
        );
        for bad in ["0", "1.5", "half"] {
            let e = parse(&["--out", "d", "--sweep-max-occluded", bad])
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("share of the torso") || e.contains("not a number"),
                "{e}"
            );
        }
    }

    #[test]
    fn motion_works_bare_or_with_a_kind_and_combines_with_the_occluders() {
        let a = parse(&["--motion", "--out", "d"]).unwrap();
        assert_eq!(a.motion, Some(MotionArg::Auto));
        let a = parse(&["--out", "d", "--occluder", "--full-occlusion", "--motion"]).unwrap();
        assert!(a.occluder && a.full_occlusion && a.motion == Some(MotionArg::Auto));
        assert_eq!(
            parse(&["--motion", "roll", "--out", "d"]).unwrap().motion,
            Some(MotionArg::Roll)
        );
        assert_eq!(
            parse(&["--motion=shift", "--out", "d"]).unwrap().motion,
            Some(MotionArg::Shift)
        );
        assert_eq!(parse(&["--out", "d"]).unwrap().motion, None);
        assert!(parse(&["--motion", "spin", "--out", "d"]).is_err());
        assert!(parse(&["--full-occlusion", "--calibration", "--out", "d"]).is_err());
        // A bare --motion picks both kinds over seeds, the same one for the same seed.
        let kinds: Vec<MotionKind> = (0..16).map(|s| MotionArg::Auto.resolve(s)).collect();
        assert!(kinds.contains(&MotionKind::Roll) && kinds.contains(&MotionKind::Shift));
        assert_eq!(MotionArg::Auto.resolve(5), MotionArg::Auto.resolve(5));
    }
}
