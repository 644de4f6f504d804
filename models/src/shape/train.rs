//! `train shape`: canonical views of the training bodies, the eigen-image subspace (randomised SVD, with one
//! EM round that re-fills unseen pixels from the masked projection), masked projection of the normalised frames and
//! the shape forest, with `min_leaf` chosen on the validation part of the training bodies.
//!
//! As in the paper, the subspace is learnt from canonical views built with exact salient points and the forest from
//! views built with the points the pipeline will really have (ground truth plus [`super::data::POINT_NOISE_M`]
//! until the joint forest lands). Deterministic for a seed. Cost: ~20 ms per image (decode, two canonical views),
//! then seconds for the SVD and the forest.

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::DMatrix;
use rayon::prelude::*;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::Point3;
use supine_core::shape::ShapeModelView;
use supine_core::shape::canonical::{CanonicalCamera, HeightReference, NO_VALUE, body_frame, canonical_view};
use supine_core::shape::linear;
use supine_core::shape::subspace::SUBSPACE_DIM;
use supine_core::time::Timestamp;

use super::data::{frames_of, intrinsics, train_validation};
use super::file::{write_shape_model, write_shape_model_with_linear};
use super::forest::{DIM, Forest, ForestConfig, Node};
use crate::dataset::Dataset;

/// Training parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TrainConfig {
    /// Canonical pixel pitch at the hip plane (metres).
    pub pitch_m: f32,
    /// Depth-pixel stride of the canonical view.
    pub stride: u16,
    /// Seed (point noise, SVD, forest).
    pub seed: u64,
    /// Per-axis SD of the salient-point noise of the forest's training views (metres).
    pub point_noise_m: f32,
    /// Pixel noise σ_n of Eq. 1's prior (metres).
    pub pixel_noise_m: f32,
    /// Trees.
    pub trees: usize,
    /// EM rounds of the subspace.
    pub em_rounds: usize,
    /// Keep the validation bodies out of the final model too (to score choices such as the pitch on them).
    pub holdout_validation: bool,
    /// Canonical heights from the hip centre instead of the mattress plane (the format-1 reference, for comparison).
    pub hip_heights: bool,
}

/// Canonical images of a set of bodies.
pub struct Canonicals {
    /// From exact salient points.
    pub clean: Vec<Vec<f32>>,
    /// From noisy salient points.
    pub noisy: Vec<Vec<f32>>,
    /// True shapes (σ units).
    pub shapes: Vec<[f32; DIM]>,
    /// Body of each image.
    pub bodies: Vec<u32>,
    /// The exact and the noisy salient points of each image (camera frame).
    pub points: Vec<[[Point3; 6]; 2]>,
}

/// The canonical view of one depth image (NO_VALUE everywhere if the frame cannot be built).
pub fn canonical_of(
    depth: &[u16],
    k: &Intrinsics,
    pts: &[nalgebra::Point3<f32>; 6],
    mattress: &supine_core::geometry::Plane,
    cam: &CanonicalCamera,
) -> Vec<f32> {
    let mut out = vec![NO_VALUE; cam.pixels()];
    if let (Ok(frame), Ok(t)) = (
        DepthFrame::new(depth, k.width, k.height, Timestamp::default(), 0),
        body_frame(pts, &mattress.normal()),
    ) {
        let _ = canonical_view(&frame, k, &t, mattress, cam, &mut out);
    }
    out
}

/// One view's canonical images (exact points, noisy points), its true shape, its body and its salient points.
type CanonicalPair = (Vec<f32>, Vec<f32>, [f32; DIM], u32, [[Point3; 6]; 2]);

/// Canonical images of `bodies`.
pub fn canonicals(
    ds: &Dataset,
    bodies: &[u32],
    cam: &CanonicalCamera,
    cfg: &TrainConfig,
    bar: &ProgressBar,
) -> Result<Canonicals> {
    let k = intrinsics(ds);
    let per: Vec<Result<Vec<CanonicalPair>>> = bodies
        .par_iter()
        .map(|&b| {
            let rec = ds.read_body(b)?;
            let out = frames_of(&rec, &k, cfg.seed, cfg.point_noise_m)
                .into_iter()
                .map(|f| {
                    let clean = canonical_of(&f.depth, &k, &f.truth_points, &f.mattress, cam);
                    let noisy = canonical_of(&f.depth, &k, &f.noisy_points, &f.mattress, cam);
                    (clean, noisy, f.shape, f.body, [f.truth_points, f.noisy_points])
                })
                .collect();
            bar.inc(1);
            Ok(out)
        })
        .collect();
    let mut c = Canonicals {
        clean: Vec::new(),
        noisy: Vec::new(),
        shapes: Vec::new(),
        bodies: Vec::new(),
        points: Vec::new(),
    };
    for r in per {
        for (a, b, s, body, pts) in r? {
            c.points.push(pts);
            c.clean.push(a);
            c.noisy.push(b);
            c.shapes.push(s);
            c.bodies.push(body);
        }
    }
    Ok(c)
}

/// A placeholder forest (one leaf of zeros) for files that only serve their subspace.
pub fn empty_forest() -> Forest {
    Forest {
        trees: vec![vec![Node::Leaf([0.0; DIM])]],
    }
}

/// Mean image, eigen-images (P × 20) and coefficient variances from canonical images with unseen pixels.
pub fn learn_subspace(
    images: &[Vec<f32>],
    cam: &CanonicalCamera,
    cfg: &TrainConfig,
) -> Result<(Vec<f32>, DMatrix<f32>, [f32; SUBSPACE_DIM])> {
    let p = cam.pixels();
    let n = images.len();
    if n < SUBSPACE_DIM + 1 {
        bail!("{n} canonical images are too few for a {SUBSPACE_DIM}-dimensional subspace");
    }
    // Start: unseen pixels take the mean of the images that saw them (0 where none did).
    let mut sum = vec![0.0f64; p];
    let mut cnt = vec![0u32; p];
    for im in images {
        for (i, &x) in im.iter().enumerate() {
            if x != NO_VALUE {
                sum[i] += x as f64;
                cnt[i] += 1;
            }
        }
    }
    let fill: Vec<f32> = (0..p)
        .map(|i| {
            if cnt[i] > 0 {
                (sum[i] / cnt[i] as f64) as f32
            } else {
                0.0
            }
        })
        .collect();
    let mut filled: Vec<Vec<f32>> = images
        .iter()
        .map(|im| {
            im.iter()
                .zip(&fill)
                .map(|(&x, &f)| if x == NO_VALUE { f } else { x })
                .collect()
        })
        .collect();
    let mut result = None;
    for round in 0..=cfg.em_rounds {
        let mean: Vec<f32> = (0..p)
            .map(|i| filled.iter().map(|im| im[i] as f64).sum::<f64>() as f32 / n as f32)
            .collect();
        let x = DMatrix::<f32>::from_fn(n, p, |r, c| filled[r][c] - mean[c]);
        let (v, s) = super::rsvd::randomized_svd(&x, SUBSPACE_DIM, 10, 2, cfg.seed ^ 0x5B5D);
        let mut var = [0.0f32; SUBSPACE_DIM];
        let mut prior = [0.0f32; SUBSPACE_DIM];
        for k in 0..SUBSPACE_DIM {
            var[k] = s[k] * s[k] / (n as f32 - 1.0);
            prior[k] = cfg.pixel_noise_m * cfg.pixel_noise_m / var[k].max(1e-12);
        }
        if round < cfg.em_rounds {
            // Re-fill unseen pixels from the masked projection of each image onto this subspace.
            let bytes = write_shape_model(cam, &mean, &v, &prior, &empty_forest(), "{}")?;
            let view = ShapeModelView::parse(&bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
            let sub = view.subspace();
            filled = images
                .par_iter()
                .zip(filled.par_iter())
                .map(|(im, old)| match sub.project(im) {
                    Ok((c, _)) => (0..p)
                        .map(|i| {
                            if im[i] == NO_VALUE {
                                sub.reconstruct_at(i, &c)
                            } else {
                                im[i]
                            }
                        })
                        .collect(),
                    Err(_) => old.clone(),
                })
                .collect();
        }
        result = Some((mean, v, prior));
    }
    let (mean, v, prior) = result.context("no subspace round ran")?;
    Ok((mean, v, prior))
}

/// Subspace coefficients of images through the core projection of a model file's subspace (failed ones dropped).
pub fn project_all(view: &ShapeModelView<'_>, images: &[Vec<f32>]) -> Vec<Option<[f32; SUBSPACE_DIM]>> {
    images
        .par_iter()
        .map(|im| view.subspace().project(im).ok().map(|(c, _)| c))
        .collect()
}

/// Coefficients the validation choice scores: the first five (paper Fig. 5); the higher ones are mostly noise.
pub const SCORED: usize = 5;

/// Mean over the first [`SCORED`] coefficients of the normalised RMSE of `forest` on (x, y).
pub fn mean_nrmse(forest: &Forest, x: &[[f32; DIM]], y: &[[f32; DIM]]) -> f32 {
    mean_nrmse_of(|c| forest.predict(c), x, y)
}

/// Mean over the first [`SCORED`] coefficients of the normalised RMSE of a regression `f` on (x, y).
pub fn mean_nrmse_of<X>(f: impl Fn(&X) -> [f32; DIM], x: &[X], y: &[[f32; DIM]]) -> f32 {
    let mut se = [0.0f64; SCORED];
    for (c, s) in x.iter().zip(y) {
        let p = f(c);
        for k in 0..SCORED {
            se[k] += ((p[k] - s[k]) as f64).powi(2);
        }
    }
    (se.iter().map(|e| (e / x.len().max(1) as f64).sqrt()).sum::<f64>() / SCORED as f64) as f32
}

/// A ridge regression's penalty chosen on validation data, and its weights fitted with that penalty.
struct RidgeChoice {
    /// The validation mean NRMSE of s0..s4 at the chosen penalty (infinite, and no weights, when no fit worked).
    score: f32,
    lambda: f64,
    /// Every penalty tried and its score, for the report.
    choices: Vec<serde_json::Value>,
    weights: Vec<f32>,
}

/// The ridge penalty that scores best on `val` when fitted on `fit`, and the weights fitted on `fin` with it.
/// The grid reaches 1e-6: the point features (metres, SD ~2 cm) vary far less than the coefficients, so the
/// penalty scaled to the inputs' mean variance weighs on them much harder.
fn ridge_choice<const N: usize>(
    fit: (&[[f32; N]], &[[f32; DIM]]),
    val: (&[[f32; N]], &[[f32; DIM]]),
    fin: (&[[f32; N]], &[[f32; DIM]]),
) -> Result<RidgeChoice> {
    let mut choices = Vec::new();
    let mut best = (f32::INFINITY, 0.0f64);
    for lambda in [1e-6f64, 1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 1e-1, 3e-1] {
        let Some(w) = super::ridge::fit(fit.0, fit.1, lambda) else {
            continue;
        };
        let e = mean_nrmse_of(|x| super::ridge::predict(&w, x), val.0, val.1);
        choices.push(serde_json::json!({"lambda": lambda, "validation_mean_nrmse": e}));
        if e < best.0 {
            best = (e, lambda);
        }
    }
    let weights = if best.0.is_finite() {
        super::ridge::fit(fin.0, fin.1, best.1).context("ridge regression is singular")?
    } else {
        Vec::new()
    };
    Ok(RidgeChoice {
        score: best.0,
        lambda: best.1,
        choices,
        weights,
    })
}

/// Everything `train shape` produces.
pub struct Trained {
    /// The model file.
    pub bytes: Vec<u8>,
    /// Training report (JSON).
    pub report: serde_json::Value,
}

/// Train a shape model on the training split of `ds`.
pub fn train(ds: &Dataset, cfg: &TrainConfig, png: Option<&std::path::Path>) -> Result<Trained> {
    let mut cam = CanonicalCamera::with_pitch(cfg.pitch_m, cfg.stride);
    if cfg.hip_heights {
        cam.height_reference = HeightReference::HipCentre;
    }
    let (fit_b, val_b) = train_validation(ds);
    let all: Vec<u32> = if cfg.holdout_validation {
        fit_b.iter().chain(&val_b).copied().collect()
    } else {
        ds.train.clone()
    };
    let bar = ProgressBar::new(all.len() as u64).with_style(
        ProgressStyle::with_template("canonical views {bar:40} {pos}/{len} bodies {elapsed}")
            .expect("valid template"),
    );
    let t0 = std::time::Instant::now();
    let c = canonicals(ds, &all, &cam, cfg, &bar)?;
    bar.finish_and_clear();
    let pca_images: Vec<Vec<f32>> = if cfg.holdout_validation {
        c.clean
            .iter()
            .zip(&c.bodies)
            .filter(|(_, b)| !val_b.contains(b))
            .map(|(im, _)| im.clone())
            .collect()
    } else {
        c.clean.clone()
    };
    let (mean, eigen, prior) = learn_subspace(&pca_images, &cam, cfg)?;
    drop(pca_images);
    if let Some(dir) = png {
        std::fs::create_dir_all(dir)?;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let mut strip = vec![mean.clone()];
        strip.extend((0..3).map(|k| eigen.column(k).iter().copied().collect::<Vec<f32>>()));
        super::chart::image_strip(&dir.join("shape_eigen_images.png"), &strip, w, h, 3)?;
        let views: Vec<Vec<f32>> = (0..4)
            .flat_map(|i| [c.clean[i * 12].clone(), c.noisy[i * 12].clone()])
            .collect();
        super::chart::image_strip(&dir.join("shape_canonical_views.png"), &views, w, h, 3)?;
    }
    let sub_bytes = write_shape_model(&cam, &mean, &eigen, &prior, &empty_forest(), "{}")?;
    let sub_view = ShapeModelView::parse(&sub_bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
    let coeffs = project_all(&sub_view, &c.noisy);
    let is_val = |b: u32| val_b.contains(&b);
    let (mut xf, mut yf, mut xv, mut yv, mut xa, mut ya) = (vec![], vec![], vec![], vec![], vec![], vec![]);
    // The linear regression's inputs: the coefficients and the (noisy) salient points' distances.
    let (mut lf, mut lv, mut la) = (vec![], vec![], vec![]);
    for (((cf, s), &b), pts) in coeffs.iter().zip(&c.shapes).zip(&c.bodies).zip(&c.points) {
        let Some(cf) = cf else { continue };
        let li = linear::inputs(cf, &pts[1]);
        xa.push(*cf);
        ya.push(*s);
        la.push(li);
        if is_val(b) {
            xv.push(*cf);
            yv.push(*s);
            lv.push(li);
        } else {
            xf.push(*cf);
            yf.push(*s);
            lf.push(li);
        }
    }
    // Choice on the validation bodies: the leaf size.
    let mut choices = Vec::new();
    let mut best = (f32::INFINITY, 5usize);
    for min_leaf in [2usize, 5, 10, 20, 40] {
        let fc = ForestConfig {
            trees: cfg.trees,
            min_leaf,
            seed: cfg.seed,
            ..Default::default()
        };
        let f = Forest::train(&xf, &yf, &fc);
        let e = mean_nrmse(&f, &xv, &yv);
        choices.push(serde_json::json!({"min_leaf": min_leaf, "validation_mean_nrmse": e}));
        if e < best.0 {
            best = (e, min_leaf);
        }
    }
    let fc = ForestConfig {
        trees: cfg.trees,
        min_leaf: best.1,
        seed: cfg.seed,
        ..Default::default()
    };
    let forest = if cfg.holdout_validation {
        Forest::train(&xf, &yf, &fc)
    } else {
        Forest::train(&xa, &ya, &fc)
    };
    // The linear regressions (ridge), each penalty chosen on the validation bodies: on the coefficients (`LINR`)
    // and on the coefficients and the salient points' distances (`LINP`, the estimate's when present). They
    // replace the forest in the file when they score better there (they did on every run so far:
    // docs/shape-eval.md).
    let holdout = cfg.holdout_validation;
    let coeffs = ridge_choice(
        (&xf, &yf),
        (&xv, &yv),
        if holdout { (&xf, &yf) } else { (&xa, &ya) },
    )?;
    let points = ridge_choice(
        (&lf, &yf),
        (&lv, &yv),
        if holdout { (&lf, &yf) } else { (&la, &ya) },
    )?;
    let (use_coeffs, use_points) = (coeffs.score < best.0, points.score < best.0);
    let mut linear: Vec<&[f32]> = Vec::new();
    if use_coeffs {
        linear.push(&coeffs.weights);
    }
    if use_points {
        linear.push(&points.weights);
    }
    let report = serde_json::json!({
        "config": cfg,
        "forest": fc,
        "canonical": {"width": cam.width, "height": cam.height, "pitch_m": cfg.pitch_m, "stride": cam.stride},
        "images": c.clean.len(),
        "projected": xa.len(),
        "train_bodies": all.len(),
        "fit_bodies": fit_b.len(),
        "validation_bodies": val_b.len(),
        "validation_choices": choices,
        "ridge_choices": coeffs.choices,
        "ridge_lambda": coeffs.lambda,
        "ridge_points_choices": points.choices,
        "ridge_points_lambda": points.lambda,
        "regressor": match (use_points, use_coeffs) {
            (true, _) => "linear_points",
            (false, true) => "linear",
            _ => "forest",
        },
        "nodes": forest.node_count(),
    });
    // The file's provenance leaves the wall time out, so equal seeds give byte-identical files.
    let bytes =
        write_shape_model_with_linear(&cam, &mean, &eigen, &prior, &forest, &linear, &report.to_string())?;
    let mut report = report;
    report["seconds"] = t0.elapsed().as_secs_f32().into();
    ShapeModelView::parse(&bytes)
        .map_err(|e| anyhow::anyhow!("written shape model does not validate: {e}"))?;
    Ok(Trained { bytes, report })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyModel;
    use crate::shape::eval::{EvalConfig, evaluate};

    #[test]
    fn a_tiny_model_trains_deterministically_and_evaluates() {
        let dir = std::env::temp_dir().join(format!("supine-shape-train-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let ds = super::super::data::small_dataset(&dir, 10, 4, 5).unwrap();
        let cfg = TrainConfig {
            pitch_m: 0.05,
            stride: 4,
            seed: 3,
            point_noise_m: 0.03,
            pixel_noise_m: 0.01,
            trees: 3,
            em_rounds: 1,
            holdout_validation: false,
            hip_heights: false,
        };
        let a = train(&ds, &cfg, None).unwrap();
        let b = train(&ds, &cfg, None).unwrap();
        assert_eq!(a.bytes, b.bytes, "training is not deterministic");
        let view = ShapeModelView::parse(&a.bytes).unwrap();
        assert_eq!(view.forest().tree_count(), 3);
        // Whichever regression validation chose, the estimate uses it.
        let c = [0.3f32; 20];
        let pts: [Point3; 6] =
            std::array::from_fn(|i| Point3::new(0.1 * i as f32, 0.05 * (i * i) as f32, 1.5));
        let expect = match view.linear() {
            Some(l) => l.predict(&linear::inputs(&c, &pts)),
            None => view.forest().predict(&c),
        };
        assert_eq!(view.regress(&c, &pts), expect);
        let model = BodyModel::load_default().unwrap();
        let ec = EvalConfig {
            seed: 1,
            point_noise_m: 0.03,
            length_unit_m: 0.01,
            fine_distance_m: None,
            plain_starts: 2,
            max_bodies: 1,
            split: "test".into(),
            points: "noisy".into(),
            joint_forest: None,
            forest_ceiling_m: 0.0,
            bed_weight: 1.0,
            free_coeffs: None,
            free_weight: supine_core::fit::FREE_PRIOR_WEIGHT,
            axis_starts_m: supine_core::fit::AXIS_STARTS_M.to_vec(),
        };
        let r = evaluate(&ds, &model, &a.bytes, &ec).unwrap();
        for m in ["subspace", "fitting", "combined", "combined_bed"] {
            let v = r[m]["vertex_error_mm_mean"].as_f64().unwrap();
            assert!(v.is_finite() && v > 0.0 && v < 300.0, "{m}: {v} mm");
            assert_eq!(r[m]["coeff_nrmse"].as_array().unwrap().len(), 20);
        }
        assert_eq!(r["images"].as_u64(), Some(4));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
