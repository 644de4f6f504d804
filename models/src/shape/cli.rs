//! `supine-models train shape` and `supine-models eval shape`: arguments, progress, model file, JSON and PNGs.

use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

use super::eval::{EvalConfig, evaluate};
use super::train::{TrainConfig, train};
use crate::body::BodyModel;
use crate::dataset::Dataset;

/// `train shape` options.
#[derive(Args, Debug)]
pub struct TrainShapeArgs {
    /// Dataset directory (`supine-models dataset`).
    #[arg(long)]
    pub data: PathBuf,
    /// Output model file [default: models/artifacts/shape.ssm].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Canonical pixel pitch at the hip plane, millimetres.
    #[arg(long, default_value_t = 12.5)]
    pub pitch_mm: f32,
    /// Depth-pixel stride of the canonical view.
    #[arg(long, default_value_t = 2)]
    pub stride: u16,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Per-axis SD of the salient-point noise standing in for the joint forest, millimetres.
    #[arg(long, default_value_t = 30.0)]
    pub point_noise_mm: f32,
    /// Trees of the shape forest.
    #[arg(long, default_value_t = 16)]
    pub trees: usize,
    /// Measure canonical heights from the hip centre (format-1 behaviour) instead of the mattress plane.
    #[arg(long)]
    pub hip_heights: bool,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write the training report here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Keep the validation part of the training bodies out of the final forest (score choices with
    /// `eval shape --split validation`).
    #[arg(long)]
    pub holdout_validation: bool,
    /// Write the mean and first eigen-images and a few canonical views (clean, noisy) as PNGs into this folder.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// `eval shape` options.
#[derive(Args, Debug)]
pub struct EvalShapeArgs {
    /// Dataset directory.
    #[arg(long)]
    pub data: PathBuf,
    /// Shape model [default: models/artifacts/shape.ssm].
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Body model [default: models/artifacts/body.sbm].
    #[arg(long)]
    pub body_model: Option<PathBuf>,
    /// Seed of the salient-point noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Per-axis SD of the salient-point noise, millimetres.
    #[arg(long, default_value_t = 30.0)]
    pub point_noise_mm: f32,
    /// Residual unit of Eq. 7, millimetres (how hard the data pull against λ and Λ): 2.5, chosen on the
    /// validation bodies with round 5's estimate as the start (combined 10 / 5 / 3.5 / 2.5 / 1.5 / 1 mm gave 9.5 /
    /// 9.2 / 9.1 / 9.0 / 9.1 / 9.6 mm; docs/shape-eval.md). The tracker's fits keep `FitParams`' 10 mm.
    #[arg(long, default_value_t = 2.5)]
    pub length_unit_mm: f32,
    /// Coarse to fine: the fits' first round pairs points up to 0.1 m apart (the distance), later rounds
    /// up to this many millimetres (0: 0.1 m throughout). 50, chosen on the validation bodies (docs/shape-eval.md);
    /// the tracker's fits keep 0.1 m throughout.
    #[arg(long, default_value_t = 50.0)]
    pub fine_distance_mm: f32,
    /// Starts of the plain model fit (0 skips the plain fit).
    #[arg(long, default_value_t = 5)]
    pub plain_starts: usize,
    /// Use at most this many bodies (0 = all).
    #[arg(long, default_value_t = 0)]
    pub max_bodies: usize,
    /// Evaluate on `test` (default) or on the `validation` part of the training bodies (for choices).
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Salient points for every method: `noisy` (ground truth plus --point-noise-mm per axis) or `forest` (the
    /// joint forest's estimate on each frame).
    #[arg(long, default_value = "noisy")]
    pub points: String,
    /// Joint forest for `--points forest` [default: models/artifacts/joints.jfor].
    #[arg(long)]
    pub joint_forest: Option<PathBuf>,
    /// `--points forest` reads each frame as the tracker does (and as `train joints` and `eval joints` do), through
    /// the height ceiling over the bed planes, metres (0: as rendered, as every figure before 2026-12-06's round 9).
    #[arg(long, default_value_t = supine_core::tracker::FOREST_CEILING_M)]
    pub ceiling_m: f32,
    /// Weight of the bed-contact residual of the `combined_bed` method.
    #[arg(long, default_value_t = 1.0)]
    pub bed_weight: f32,
    /// Coefficients the combined fit leaves nearly free (Λ = --free-weight), comma-separated [default: torso_coeffs].
    #[arg(long, value_delimiter = ',')]
    pub free_coeffs: Option<Vec<usize>>,
    /// Eq. 7's Λ on those coefficients [default: the fit's FREE_PRIOR_WEIGHT, 0.1].
    #[arg(long)]
    pub free_weight: Option<f32>,
    /// The combined fit runs from the salient points' start moved this many millimetres along the body, each, and
    /// keeps the fit with the lowest residual [default: the fit's AXIS_STARTS_M, -90,-60,-30,0,30,60,90]; 0 gives the
    /// single start of the rounds before 2026-12-08 (docs/shape-eval.md, round 13).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub axis_starts_mm: Option<Vec<f32>>,
    /// Write the report here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the Fig. 5 PNG charts into this folder.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// Run `train shape`.
pub fn run_train(a: &TrainShapeArgs) -> Result<()> {
    if let Some(t) = a.threads {
        rayon::ThreadPoolBuilder::new().num_threads(t).build_global().ok();
    }
    anyhow::ensure!(
        a.pitch_mm >= 2.0 && a.pitch_mm <= 100.0,
        "--pitch-mm must lie in 2..100"
    );
    anyhow::ensure!(a.trees >= 1 && a.trees <= 256, "--trees must lie in 1..256");
    let ds = Dataset::open(&a.data).with_context(|| format!("opening dataset {}", a.data.display()))?;
    let cfg = TrainConfig {
        pitch_m: a.pitch_mm * 1e-3,
        stride: a.stride.max(1),
        seed: a.seed,
        point_noise_m: a.point_noise_mm * 1e-3,
        pixel_noise_m: 0.01,
        trees: a.trees,
        em_rounds: 1,
        holdout_validation: a.holdout_validation,
        hip_heights: a.hip_heights,
    };
    let t = train(&ds, &cfg, a.png.as_deref())?;
    let out = a.out.clone().unwrap_or_else(super::default_artifact_path);
    std::fs::write(&out, &t.bytes).with_context(|| format!("writing {}", out.display()))?;
    let mut report = t.report;
    report["out"] = out.display().to_string().into();
    report["model_bytes"] = t.bytes.len().into();
    eprintln!("{}", serde_json::to_string_pretty(&report)?);
    if let Some(j) = &a.json {
        std::fs::write(j, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", j.display()))?;
    }
    Ok(())
}

/// Run `eval shape`.
pub fn run_eval(a: &EvalShapeArgs) -> Result<()> {
    anyhow::ensure!(
        a.split == "test" || a.split == "validation",
        "--split must be test or validation"
    );
    crate::forest::data::check_ceiling(a.ceiling_m)?;
    let ds = Dataset::open(&a.data).with_context(|| format!("opening dataset {}", a.data.display()))?;
    let model = match &a.body_model {
        Some(p) => BodyModel::load(p)?,
        None => BodyModel::load_default()?,
    };
    let path = a.model.clone().unwrap_or_else(super::default_artifact_path);
    let bytes = std::fs::read(&path).with_context(|| format!("reading shape model {}", path.display()))?;
    anyhow::ensure!(
        a.free_coeffs.iter().flatten().all(|&c| c < 20),
        "--free-coeffs must name coefficients 0..19"
    );
    anyhow::ensure!(
        a.free_weight.is_none_or(|w| w.is_finite() && w >= 0.0),
        "--free-weight must be a finite number ≥ 0"
    );
    anyhow::ensure!(
        a.axis_starts_mm
            .iter()
            .flatten()
            .all(|d| d.is_finite() && d.abs() <= 500.0),
        "--axis-starts-mm must be finite offsets within ±500 mm"
    );
    let cfg = EvalConfig {
        seed: a.seed,
        point_noise_m: a.point_noise_mm * 1e-3,
        length_unit_m: a.length_unit_mm * 1e-3,
        fine_distance_m: (a.fine_distance_mm > 0.0).then_some(a.fine_distance_mm * 1e-3),
        plain_starts: a.plain_starts,
        max_bodies: a.max_bodies,
        split: a.split.clone(),
        points: a.points.clone(),
        joint_forest: a.joint_forest.clone(),
        forest_ceiling_m: a.ceiling_m,
        bed_weight: a.bed_weight,
        free_coeffs: a.free_coeffs.clone(),
        free_weight: a.free_weight.unwrap_or(supine_core::fit::FREE_PRIOR_WEIGHT),
        axis_starts_m: match &a.axis_starts_mm {
            Some(v) => v.iter().map(|d| d * 1e-3).collect(),
            None => supine_core::fit::AXIS_STARTS_M.to_vec(),
        },
    };
    let r = evaluate(&ds, &model, &bytes, &cfg)?;
    print_table(&r);
    if let Some(j) = &a.json {
        std::fs::write(j, serde_json::to_string_pretty(&r)?)
            .with_context(|| format!("writing {}", j.display()))?;
    }
    if let Some(dir) = &a.png {
        std::fs::create_dir_all(dir)?;
        let torso: Vec<usize> = r["torso_coeffs"]
            .as_array()
            .map(|v| v.iter().filter_map(|x| x.as_u64()).map(|x| x as usize).collect())
            .unwrap_or_default();
        let mut coeffs: Vec<usize> = (0..5).collect();
        coeffs.extend(torso.iter().filter(|t| **t >= 5));
        for (key, file) in [
            ("coeff_nrmse", "shape_fig5_nrmse.png"),
            ("coeff_sd", "shape_fig5_sd.png"),
        ] {
            let groups: Vec<Vec<f64>> = coeffs
                .iter()
                .map(|&c| {
                    ["subspace", "fitting", "combined"]
                        .iter()
                        .map(|m| r[*m][key][c].as_f64().unwrap_or(0.0))
                        .collect()
                })
                .collect();
            super::chart::bar_chart(&dir.join(file), &groups, 1.2, 0.1)?;
        }
        // The translation-aligned error: the raw one is mostly the model-frame offset of s0 (see the report).
        let v: Vec<Vec<f64>> = ["vertex_error_aligned_mm_mean", "vertex_error_aligned_mm_sd"]
            .iter()
            .map(|k| {
                ["subspace", "fitting", "combined"]
                    .iter()
                    .map(|m| r[*m][*k].as_f64().unwrap_or(0.0))
                    .collect()
            })
            .collect();
        super::chart::bar_chart(&dir.join("shape_vertex_error.png"), &v, 20.0, 2.0)?;
    }
    Ok(())
}

fn print_table(r: &serde_json::Value) {
    println!(
        "torso_coeffs {}   images {}   seed {}   regressor {}   commit {}",
        r["torso_coeffs"], r["images"], r["seed"], r["regressor"], r["commit"]
    );
    println!(
        "{:<18} {:>4} {:>34} {:>9} {:>11} {:>7} {:>10} {:>9} {:>9}",
        "method",
        "n",
        "coeff NRMSE s0..s4",
        "raw mm",
        "aligned mm",
        "sd mm",
        "hip-al. mm",
        "ms/frame",
        "rejected"
    );
    for m in [
        "subspace",
        "subspace_coeffs",
        "subspace_forest",
        "fitting",
        "combined",
        "combined_bed",
        "mean_shape",
    ] {
        for (label, j) in [(m.to_string(), &r[m]), (format!("{m}+arm"), &r[m]["with_arm"])] {
            let c: Vec<String> = (0..5)
                .map(|k| format!("{:.3}", j["coeff_nrmse"][k].as_f64().unwrap_or(f64::NAN)))
                .collect();
            println!(
                "{:<18} {:>4} {:>34} {:>9.1} {:>11.1} {:>7.1} {:>10.1} {:>9.1} {:>9.3}",
                label,
                j["frames"],
                c.join(" "),
                j["vertex_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
                j["vertex_error_aligned_mm_mean"].as_f64().unwrap_or(f64::NAN),
                j["vertex_error_aligned_mm_sd"].as_f64().unwrap_or(f64::NAN),
                j["vertex_error_hip_mm_mean"].as_f64().unwrap_or(f64::NAN),
                j["ms_per_frame"].as_f64().unwrap_or(f64::NAN),
                j["rejected_fraction"].as_f64().unwrap_or(f64::NAN)
            );
        }
    }
    for (key, label) in [("multi_frame", "subspace"), ("multi_frame_combined", "combined")] {
        for j in r[key].as_array().into_iter().flatten() {
            println!(
                "multi-frame {label:<8} N={:<3} vertex raw {:.1} mm  aligned {:.1} mm  s1 NRMSE {:.3}",
                j["views"],
                j["vertex_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
                j["vertex_error_aligned_mm_mean"].as_f64().unwrap_or(f64::NAN),
                j["coeff_nrmse"][1].as_f64().unwrap_or(f64::NAN)
            );
        }
    }
}
