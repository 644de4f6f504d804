//! What limits the single-frame shape estimate (issue 10), measured on the VALIDATION part of the training
//! bodies only: the truth truncated to a few coefficients (the floor of estimating only those), the shape forest
//! on the subspace coefficients against a ridge regression on the same coefficients (paper Eq. 1 is linear) and a
//! ridge regression on all canonical pixels (how much the 20-dimensional subspace discards), and the ridge
//! regression `train shape` fits (the coefficients and the salient points' distances), each with the canonical
//! views of exact and of noisy salient points.
//!
//! `cargo run --release -p supine-models --example shape_limits -- DATASET [--threads N] [--skip-pixels]`
//! (`--skip-pixels` leaves out the ridge regressions on all canonical pixels, the slow part.)
//! Cost: the canonical views of the training bodies (~1 min on 2 cores) and a few n x n solves (n = fit images).

use anyhow::{Context, Result};
use indicatif::ProgressBar;
use nalgebra::DMatrix;
use std::collections::HashMap;
use supine_core::shape::ShapeModelView;
use supine_core::shape::canonical::{CanonicalCamera, NO_VALUE};
use supine_core::shape::linear::{self, LINEAR_INPUTS};
use supine_models::body::{BodyModel, Shape};
use supine_models::dataset::Dataset;
use supine_models::pose::Pose;
use supine_models::shape::data::{body_pose, train_validation};
use supine_models::shape::eval::{upper_body, vertex_errors};
use supine_models::shape::file::write_shape_model;
use supine_models::shape::forest::{Forest, ForestConfig};
use supine_models::shape::ridge;
use supine_models::shape::train::{TrainConfig, canonicals, empty_forest, learn_subspace, project_all};

type V20 = [f32; 20];

/// Mean translation-aligned upper-body error (mm) and NRMSE of s0..s4 of estimates against the truth.
struct Scorer<'a> {
    model: &'a BodyModel,
    poses: HashMap<u32, Pose>,
    mask: Vec<bool>,
}

impl Scorer<'_> {
    fn score(&self, name: &str, est: &[V20], truth: &[V20], bodies: &[u32]) {
        let mut sum = 0.0f64;
        let mut n = 0usize;
        let mut se = [0.0f64; 20];
        for ((e, t), b) in est.iter().zip(truth).zip(bodies) {
            let pose = &self.poses[b];
            let tp = self.model.pose(&Shape::from_normalised(self.model, t), pose);
            let v = vertex_errors(self.model, pose, e, &tp, &self.mask);
            sum += v.aligned.iter().map(|x| *x as f64).sum::<f64>();
            n += v.aligned.len();
            for k in 0..20 {
                se[k] += ((e[k] - t[k]) as f64).powi(2);
            }
        }
        let m = est.len().max(1) as f64;
        let nr: Vec<String> = (0..6).map(|k| format!("{:.3}", (se[k] / m).sqrt())).collect();
        println!(
            "{name:<52} aligned {:6.2} mm   NRMSE s0..s5 {}",
            1e3 * sum / n.max(1) as f64,
            nr.join(" ")
        );
    }
}

/// Ridge regression rows -> outputs in the dual (kernel) form, centred: predictions for `test` rows.
fn ridge_dual(x: &DMatrix<f32>, y: &DMatrix<f32>, test: &DMatrix<f32>, lambda: f32) -> DMatrix<f32> {
    let mx = x.row_mean();
    let my = y.row_mean();
    let xc = DMatrix::from_fn(x.nrows(), x.ncols(), |r, c| x[(r, c)] - mx[c]);
    let yc = DMatrix::from_fn(y.nrows(), y.ncols(), |r, c| y[(r, c)] - my[c]);
    let tc = DMatrix::from_fn(test.nrows(), test.ncols(), |r, c| test[(r, c)] - mx[c]);
    let mut k = (&xc * xc.transpose()).map(|v| v as f64);
    let scale = k.diagonal().mean();
    for i in 0..k.nrows() {
        k[(i, i)] += lambda as f64 * scale;
    }
    let alpha = k
        .cholesky()
        .expect("ridge system is SPD")
        .solve(&yc.map(|v| v as f64))
        .map(|v| v as f32);
    let mut p = (tc * xc.transpose()) * alpha;
    for r in 0..p.nrows() {
        for c in 0..p.ncols() {
            p[(r, c)] += my[c];
        }
    }
    p
}

fn rows(m: &DMatrix<f32>) -> Vec<V20> {
    (0..m.nrows())
        .map(|r| std::array::from_fn(|c| m[(r, c)]))
        .collect()
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let dir = args.get(1).context("usage: shape_limits DATASET [--threads N]")?;
    if let Some(i) = args.iter().position(|a| a == "--threads") {
        let n: usize = args.get(i + 1).context("--threads N")?.parse()?;
        rayon::ThreadPoolBuilder::new().num_threads(n).build_global().ok();
    }
    let skip_pixels = args.iter().any(|a| a == "--skip-pixels");
    let ds = Dataset::open(std::path::Path::new(dir))?;
    let model = BodyModel::load_default()?;
    let cfg = TrainConfig {
        pitch_m: 0.0125,
        stride: 2,
        seed: 0,
        point_noise_m: 0.03,
        pixel_noise_m: 0.01,
        trees: 16,
        em_rounds: 1,
        holdout_validation: true,
        hip_heights: false,
    };
    let cam = CanonicalCamera::with_pitch(cfg.pitch_m, cfg.stride);
    let (fit_b, val_b) = train_validation(&ds);
    let all: Vec<u32> = fit_b.iter().chain(&val_b).copied().collect();
    let bar = ProgressBar::new(all.len() as u64);
    let c = canonicals(&ds, &all, &cam, &cfg, &bar)?;
    bar.finish_and_clear();
    let is_val: Vec<bool> = c.bodies.iter().map(|b| val_b.contains(b)).collect();
    let mut poses = HashMap::new();
    for &b in &val_b {
        poses.insert(b, body_pose(&ds.read_body(b)?)?);
    }
    let scorer = Scorer {
        model: &model,
        poses,
        mask: model.part_of_vertex.iter().map(|&p| upper_body(p)).collect(),
    };
    let pick = |v: bool| -> Vec<usize> { (0..c.bodies.len()).filter(|&i| is_val[i] == v).collect() };
    let (fi, vi) = (pick(false), pick(true));
    let yt: Vec<V20> = vi.iter().map(|&i| c.shapes[i]).collect();
    let vb: Vec<u32> = vi.iter().map(|&i| c.bodies[i]).collect();
    println!(
        "fit images {}  validation images {} ({} bodies)  canonical {}x{}",
        fi.len(),
        vi.len(),
        val_b.len(),
        cam.width,
        cam.height
    );
    let visible: f64 = vi
        .iter()
        .map(|&i| c.noisy[i].iter().filter(|x| **x != NO_VALUE).count() as f64)
        .sum::<f64>()
        / vi.len() as f64;
    println!(
        "visible canonical pixels (noisy points): {visible:.0} of {}",
        cam.pixels()
    );

    // Floors: the truth kept on a few coefficients only, the rest at the mean.
    scorer.score("mean shape", &vec![[0.0; 20]; yt.len()], &yt, &vb);
    for keep in [
        vec![0usize],
        vec![0, 3],
        vec![0, 1, 3],
        (0..5).collect(),
        (0..10).collect(),
    ] {
        let est: Vec<V20> = yt
            .iter()
            .map(|t| std::array::from_fn(|k| if keep.contains(&k) { t[k] } else { 0.0 }))
            .collect();
        scorer.score(&format!("truth on {keep:?}, mean elsewhere"), &est, &yt, &vb);
    }

    // The subspace as `train shape --holdout-validation` learns it (fit bodies' exact-point views).
    let pca: Vec<Vec<f32>> = fi.iter().map(|&i| c.clean[i].clone()).collect();
    let (mean, eigen, prior) = learn_subspace(&pca, &cam, &cfg)?;
    drop(pca);
    let sub_bytes = write_shape_model(&cam, &mean, &eigen, &prior, &empty_forest(), "{}")?;
    let sub = ShapeModelView::parse(&sub_bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
    let fill = |im: &Vec<f32>| -> Vec<f32> {
        im.iter()
            .zip(&mean)
            .map(|(&x, &m)| if x == NO_VALUE { m } else { x })
            .collect()
    };
    let yf: Vec<V20> = fi.iter().map(|&i| c.shapes[i]).collect();
    let ymat = |ys: &[V20]| DMatrix::from_fn(ys.len(), 20, |r, k| ys[r][k]);
    // `which`: the index of the points each view was made with in `c.points`.
    for (label, imgs, which) in [("exact points", &c.clean, 0), ("noisy points", &c.noisy, 1)] {
        let co = project_all(&sub, imgs);
        let co: Vec<V20> = co.into_iter().map(|x| x.unwrap_or([0.0; 20])).collect();
        let xf: Vec<V20> = fi.iter().map(|&i| co[i]).collect();
        let xv: Vec<V20> = vi.iter().map(|&i| co[i]).collect();
        for (trees, min_leaf) in [(16usize, 40usize), (16, 10), (64, 20)] {
            let f = Forest::train(
                &xf,
                &yf,
                &ForestConfig {
                    trees,
                    min_leaf,
                    seed: 0,
                    ..Default::default()
                },
            );
            let est: Vec<V20> = xv.iter().map(|x| f.predict(x)).collect();
            scorer.score(
                &format!("{label}: forest {trees} trees min_leaf {min_leaf}"),
                &est,
                &yt,
                &vb,
            );
        }
        let cm = |xs: &[V20]| DMatrix::from_fn(xs.len(), 20, |r, k| xs[r][k]);
        for lambda in [1e-4f32, 1e-2] {
            // Primal ridge on 20 inputs, done through the dual solver for brevity (n x n).
            let p = ridge_dual(&cm(&xf), &ymat(&yf), &cm(&xv), lambda);
            scorer.score(
                &format!("{label}: ridge on subspace coeffs, lambda {lambda:e}"),
                &rows(&p),
                &yt,
                &vb,
            );
        }
        // The salient points' distances beside the coefficients (`linear::inputs`), as `train shape` fits them.
        let li = |idx: &[usize]| -> Vec<[f32; LINEAR_INPUTS]> {
            idx.iter()
                .map(|&i| linear::inputs(&co[i], &c.points[i][which]))
                .collect()
        };
        let (lf, lv) = (li(&fi), li(&vi));
        for lambda in [1e-6f64, 1e-4, 1e-2] {
            let w = ridge::fit(&lf, &yf, lambda).context("ridge on coefficients and points is singular")?;
            let est: Vec<V20> = lv.iter().map(|x| ridge::predict(&w, x)).collect();
            scorer.score(
                &format!("{label}: ridge on coeffs + point distances, lambda {lambda:e}"),
                &est,
                &yt,
                &vb,
            );
        }
        if skip_pixels {
            continue;
        }
        let pix = |idx: &[usize]| {
            let filled: Vec<Vec<f32>> = idx.iter().map(|&i| fill(&imgs[i])).collect();
            DMatrix::from_fn(idx.len(), cam.pixels(), |r, k| filled[r][k])
        };
        let (pf, pv) = (pix(&fi), pix(&vi));
        for lambda in [1e-3f32, 1e-2, 1e-1] {
            let p = ridge_dual(&pf, &ymat(&yf), &pv, lambda);
            scorer.score(
                &format!("{label}: ridge on all pixels, lambda {lambda:e}"),
                &rows(&p),
                &yt,
                &vb,
            );
        }
    }
    Ok(())
}
