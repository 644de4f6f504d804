//! `supine-models dataset`: argument parsing, validation, progress bar and JSON summary around [`super::generate`].

use super::{DatasetConfig, generate, split_train_count};
use crate::render::noise::KinectNoise;
use crate::scene::model_body::{BodyKind, open_source};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::PathBuf;
use std::process::ExitCode;

/// Default number of bodies: 400 × 12 views = 4800 images, about 40 s on 2 idle cores (~1.5 min when the cores
/// are shared), ~0.5 GB.
pub const DEFAULT_BODIES: u32 = 400;

/// Arguments of `supine-models dataset`.
#[derive(Debug, clap::Args)]
pub struct DatasetArgs {
    /// Number of bodies (each a new shape and bed pose); HumanVP size is 4000.
    #[arg(long, default_value_t = DEFAULT_BODIES)]
    pub bodies: u32,
    /// Viewpoints per body (random head rotations about two axes).
    #[arg(long, default_value_t = 12)]
    pub views: u16,
    /// Seed: the same seed gives byte-identical output.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory (created; must not already hold a dataset unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Probability that a view shows the robot arm with the probe on the torso.
    #[arg(long, default_value_t = 0.3)]
    pub occluder_fraction: f32,
    /// Fraction of bodies in the training split (the rest is the test split).
    #[arg(long, default_value_t = 0.7)]
    pub train_fraction: f32,
    /// Number of preview PNGs (view 0 of the first bodies) written to DIR/previews.
    #[arg(long, default_value_t = 4)]
    pub previews: u32,
    /// Body source.
    #[arg(long, value_enum, default_value_t = BodyKind::Model)]
    pub body: BodyKind,
    /// Body model file (default: the committed models/artifacts/body.sbm).
    #[arg(long)]
    pub body_model: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Register depth to the RGB camera (border, IR-occlusion holes), like OpenNI2's registered depth.
    #[arg(long)]
    pub registered: bool,
    /// The noise model before blobs, edge effects and registration (reproduces earlier datasets byte for byte).
    #[arg(long, conflicts_with = "registered")]
    pub legacy_noise: bool,
    /// Noise model from this JSON file (a `KinectNoise`, as in dataset.json's config.noise) instead of the default.
    #[arg(long, conflicts_with_all = ["registered", "legacy_noise"])]
    pub noise: Option<PathBuf>,
    /// Scale of the head's distance to the patient (1 = 1.1–2 m; 1.4 reaches the real frames' 1.5–2.8 m).
    #[arg(long, default_value_t = 1.0)]
    pub view_distance_scale: f32,
    /// Margin around the patient's bounding box in the stored crops, px (640: whole frames). The joint forest's
    /// probes reach ±offset/depth px; a probe beyond the crop reads no depth where the head computer sees bed.
    #[arg(long, default_value_t = crate::dataset::CROP_MARGIN_PX)]
    pub crop_margin: u16,
    /// Where views with the arm place it: `contact` (the probe on the torso, the robot's shoulder beside the bed) or
    /// `sequence` (half of them as the tracking sequences hold the arm: the shoulder near the head, the probe on the
    /// torso or lifted off it toward the head).
    #[arg(long, value_enum, default_value_t = super::ArmPlacement::Contact)]
    pub arm_placement: super::ArmPlacement,
    /// What the patient rests on: `lowest-point` (the lowest skin point, hands included: one patient in seven to nine
    /// then lies on a hand, the torso 2-5 cm above the mattress; the committed shape model's data) or `trunk` (the
    /// back, as the tracking sequences lay their patients and the default joint forest was trained since 2026-12-07;
    /// a hand under the body sinks into the mattress).
    #[arg(long, value_enum, default_value_t = crate::pose::Rest::LowestPoint)]
    pub rest: crate::pose::Rest,
    /// Replace an existing dataset in DIR.
    #[arg(long)]
    pub force: bool,
    /// Write a machine-readable summary here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

fn usage(msg: &str) -> ExitCode {
    eprintln!("error: {msg}");
    ExitCode::from(2)
}

/// Run the command; exit 0 on success, 1 on a runtime failure, 2 on bad arguments.
pub fn run(args: DatasetArgs) -> ExitCode {
    if args.bodies == 0 {
        return usage("--bodies must be at least 1");
    }
    if args.views == 0 {
        return usage("--views must be at least 1");
    }
    if !(0.0..=1.0).contains(&args.occluder_fraction) {
        return usage("--occluder-fraction must be between 0 and 1");
    }
    if !(0.0..=1.0).contains(&args.train_fraction) {
        return usage("--train-fraction must be between 0 and 1");
    }
    if !(0.5..=3.0).contains(&args.view_distance_scale) {
        return usage("--view-distance-scale must be between 0.5 and 3");
    }
    if args.threads == Some(0) {
        return usage("--threads must be at least 1");
    }
    if let Err(msg) = check_split(args.bodies, args.train_fraction) {
        return usage(&msg);
    }
    match run_inner(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// Refuse a split that leaves the train or the test part without a body: a model trained on nothing, or figures
/// measured on nothing, would only look like results.
fn check_split(bodies: u32, train_fraction: f32) -> Result<(), String> {
    let n_train = split_train_count(bodies, train_fraction);
    let n_test = bodies as usize - n_train;
    if n_train == 0 || n_test == 0 {
        return Err(format!(
            "--train-fraction {train_fraction} of --bodies {bodies} gives {n_train} training and {n_test} test \
             bodies; both splits need at least one body"
        ));
    }
    Ok(())
}

fn run_inner(args: &DatasetArgs) -> anyhow::Result<()> {
    if args.out.join("dataset.json").exists() {
        anyhow::ensure!(
            args.force,
            "{} already holds a dataset (pass --force to replace it)",
            args.out.display()
        );
        for sub in ["bodies", "previews"] {
            let p = args.out.join(sub);
            if p.exists() {
                std::fs::remove_dir_all(&p)?;
            }
        }
    }
    let source = open_source(args.body, args.body_model.as_deref())?;
    let cfg = DatasetConfig {
        bodies: args.bodies,
        views: args.views,
        seed: args.seed,
        occluder_fraction: args.occluder_fraction,
        train_fraction: args.train_fraction,
        previews: args.previews.min(args.bodies),
        noise: if let Some(path) = &args.noise {
            KinectNoise::from_file(path)?
        } else if args.legacy_noise {
            KinectNoise::LEGACY
        } else if args.registered {
            KinectNoise::default().registered()
        } else {
            KinectNoise::default()
        },
        view_distance_scale: args.view_distance_scale,
        crop_margin_px: args.crop_margin,
        arm_placement: args.arm_placement,
        rest: args.rest,
    };
    let total = args.bodies as u64 * args.views as u64;
    let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} images  {per_sec}  eta {eta}")
            .map_err(|e| anyhow::anyhow!("progress template: {e}"))?
            .progress_chars("=> "),
    );
    let started = std::time::Instant::now();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()?;
    pool.install(|| generate(source.as_ref(), &cfg, &args.out, &|| bar.inc(1)))?;
    bar.finish();
    let secs = started.elapsed().as_secs_f64();
    let bytes: u64 = std::fs::read_dir(args.out.join("bodies"))?
        .filter_map(|e| e.ok()?.metadata().ok())
        .map(|m| m.len())
        .sum();
    let ds = super::Dataset::open(&args.out)?;
    eprintln!(
        "{total} images of {} bodies ({} train / {} test) in {secs:.1} s: {:.1} images/s, {:.1} MB in {}",
        args.bodies,
        ds.train.len(),
        ds.test.len(),
        total as f64 / secs,
        bytes as f64 / 1e6,
        args.out.display()
    );
    if let Some(path) = &args.json {
        let summary = serde_json::json!({
            "command": "dataset",
            "bodies": args.bodies,
            "views": args.views,
            "images": total,
            "seed": args.seed,
            "body_source": source.name(),
            "train": ds.train.len(),
            "test": ds.test.len(),
            "seconds": secs,
            "images_per_second": total as f64 / secs,
            "bytes": bytes,
            "out": args.out,
        });
        std::fs::write(path, serde_json::to_vec_pretty(&summary)?)
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    Ok(())
}
