//! The forest comparison's supine side: a seeded dataset, supine's trainer (one thread) and quantised inference
//! (`supine_core::forest::infer::estimate`, 512 samples, one thread, after warm-up), and what scikit-learn's
//! `RandomForestRegressor` needs (`tests/bench/forest_peers.py`): a fixed bank of depth-difference features (offset
//! pairs drawn like the trainer's candidates) evaluated on the same training samples supine trains on, and for the
//! held-out images the depth image, the same 512 sampled pixels and the true points.
//!
//! Cost: dominated by training (minutes for the full size); inference is timed per frame.

use super::npy;
use crate::dataset::{Dataset, DatasetConfig, generate};
use crate::forest::data::{TrainImage, view_planes};
use crate::forest::refine::RefineParams;
use crate::forest::train::{TrainConfig, image_seed, split_validation, train};
use crate::forest::tree::TreeParams;
use crate::scene::model_body::{BodyKind, open_source};
use anyhow::{Context, Result, ensure};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use serde_json::json;
use std::path::Path;
use std::time::Instant;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::forest::feature::{DepthImage, ProbeScale, probe};
use supine_core::forest::infer::{InferConfig, Method, Workspace, estimate};
use supine_core::forest::model::ForestView;
use supine_core::forest::sample::{Clip, SamplePixel, sample_pixels};
use supine_core::salient::SalientPoint;
use supine_core::time::Timestamp;

const P: usize = SalientPoint::COUNT;

/// Options of the forest comparison.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ForestBenchConfig {
    /// Seed of the dataset, the trainer, the feature bank and the sampling.
    pub seed: u64,
    /// Bodies in the dataset (70 % train, 30 % held out).
    pub bodies: u32,
    /// Views per body.
    pub views: u16,
    /// Trees (both sides).
    pub trees: usize,
    /// Maximum depth (both sides).
    pub depth: usize,
    /// Fewest samples a node needs to split (both sides).
    pub min_split: usize,
    /// Candidate tests per split (supine) = features tried per split (scikit-learn's `max_features`).
    pub candidates: usize,
    /// Features in scikit-learn's precomputed bank.
    pub bank: usize,
    /// Samples per image, training and inference.
    pub samples: usize,
    /// Refinement epochs of supine's trainer.
    pub epochs: usize,
    /// Held-out images used (at most).
    pub test_images: usize,
    /// Timed passes over the held-out images (after one warm-up pass).
    pub repeats: usize,
}

/// The feature bank: offset pairs drawn uniformly within the trainer's ±`offset_px_m`, seeded.
pub fn feature_bank(n: usize, offset_px_m: i32, seed: u64) -> Vec<([i8; 2], [i8; 2])> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xBA4C);
    let r = offset_px_m.clamp(1, supine_core::forest::feature::MAX_OFFSET);
    let mut o = || rng.gen_range(-r..=r) as i8;
    (0..n).map(|_| ([o(), o()], [o(), o()])).collect()
}

/// Bank features of one sample (mm, saturated to i16).
pub fn bank_features<D: DepthImage + ?Sized>(
    img: &D,
    bank: &[([i8; 2], [i8; 2])],
    px: &SamplePixel,
    out: &mut Vec<i16>,
) {
    let s = ProbeScale::new(px.d_mm);
    let (x, y) = (px.x as i32, px.y as i32);
    for (u, v) in bank {
        let f = probe(img, x, y, s, *u) - probe(img, x, y, s, *v);
        out.push(f.clamp(i16::MIN as i32, i16::MAX as i32) as i16);
    }
}

fn mean_error_mm(est: &[[Option<[f32; 3]>; P]], truth: &[[[f32; 3]; P]]) -> ([f64; P], f64, f64) {
    let mut per = [0.0f64; P];
    let mut missing = 0usize;
    for (e, t) in est.iter().zip(truth) {
        for p in 0..P {
            // A point without an estimate counts as 0.5 m off (never better than a guess).
            let d = match e[p] {
                Some(x) => {
                    let d: f32 = (0..3).map(|a| (x[a] - t[p][a]).powi(2)).sum();
                    d.sqrt() as f64
                }
                None => {
                    missing += 1;
                    0.5
                }
            };
            per[p] += 1000.0 * d / est.len().max(1) as f64;
        }
    }
    let mean = per.iter().sum::<f64>() / P as f64;
    (per, mean, missing as f64 / (est.len() * P).max(1) as f64)
}

/// Run the supine side and write the peer's inputs into `out`; returns the report (also `out/supine.json`).
pub fn run(cfg: &ForestBenchConfig, out: &Path, progress: bool) -> Result<serde_json::Value> {
    ensure!(
        cfg.bodies >= 4 && cfg.views > 0 && cfg.repeats > 0,
        "dataset too small"
    );
    ensure!(
        cfg.samples <= supine_core::forest::MAX_SAMPLES,
        "--samples at most 1024"
    );
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let k = Intrinsics::KINECT_V1;
    let dir = out.join("dataset");
    let _ = std::fs::remove_dir_all(&dir);
    let dcfg = DatasetConfig {
        bodies: cfg.bodies,
        views: cfg.views,
        seed: cfg.seed,
        occluder_fraction: 0.3,
        train_fraction: 0.7,
        previews: 0,
        ..DatasetConfig::default()
    };
    let source = open_source(BodyKind::Model, None)?;
    let t_gen = Instant::now();
    generate(source.as_ref(), &dcfg, &dir, &|| {})?;
    let gen_s = t_gen.elapsed().as_secs_f64();
    let ds = Dataset::open(&dir)?;

    let tcfg = TrainConfig {
        seed: cfg.seed,
        trees: cfg.trees,
        samples_per_image: cfg.samples,
        tree: TreeParams {
            max_depth: cfg.depth,
            candidates: cfg.candidates,
            min_split: cfg.min_split.max(2),
            ..TreeParams::default()
        },
        refine: RefineParams {
            epochs: cfg.epochs,
            ..RefineParams::default()
        },
        ..TrainConfig::default()
    };
    // One thread, as scikit-learn gets n_jobs=1.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let t_train = Instant::now();
    let (forest, summary) = pool.install(|| train(&ds, &tcfg, progress))?;
    let train_s = t_train.elapsed().as_secs_f64();
    let bytes = forest.to_shipped_bytes(&json!({"bench": "forest", "seed": cfg.seed}).to_string())?;
    std::fs::write(out.join("supine.jfor"), &bytes)?;
    let view = ForestView::parse(&bytes).context("the quantised forest does not validate")?;

    // scikit-learn's training set: the fitting bodies' images, sampled exactly as the trainer samples them.
    let bank = feature_bank(cfg.bank, tcfg.tree.offset_px_m, cfg.seed);
    let (fit, _val) = split_validation(&ds.train, tcfg.validation_fraction, tcfg.seed);
    let mut x_train: Vec<i16> = Vec::new();
    let mut y_train: Vec<f32> = Vec::new();
    let bar = super::progress_bar((fit.len() + ds.test.len()) as u64, "forest export", progress);
    for &b in &fit {
        let rec = ds.read_body(b)?;
        for v in &rec.views {
            let img = TrainImage::from_view(v, &k, tcfg.ceiling_m);
            let planes = view_planes(&v.truth);
            let clip = Clip::over_image(&planes, &k);
            let mut px = vec![SamplePixel::default(); cfg.samples];
            let n = sample_pixels(&img, &k, &clip, image_seed(tcfg.seed, b, v.truth.view), &mut px);
            for s in &px[..n] {
                bank_features(&img, &bank, s, &mut x_train);
                for t in &v.truth.salient_camera {
                    y_train.extend((0..3).map(|a| t[a] - s.p[a]));
                }
            }
        }
        bar.inc(1);
    }
    let n_train = y_train.len() / (3 * P);
    npy::write(&out.join("x_train.npy"), &[n_train, cfg.bank], &x_train)?;
    npy::write(&out.join("y_train.npy"), &[n_train, 3 * P], &y_train)?;
    drop(x_train);
    let offsets: Vec<i16> = bank
        .iter()
        .flat_map(|(u, v)| [u[0], u[1], v[0], v[1]].map(i16::from))
        .collect();
    npy::write(&out.join("bank.npy"), &[cfg.bank, 4], &offsets)?;

    // Held-out images: the full depth image, the samples supine's inference draws, the truth.
    let mut depths: Vec<Vec<u16>> = Vec::new();
    let mut planes_all = Vec::new();
    let mut truths: Vec<[[f32; 3]; P]> = Vec::new();
    let mut has_arm = Vec::new();
    'bodies: for &b in &ds.test {
        let rec = ds.read_body(b)?;
        for v in &rec.views {
            if depths.len() >= cfg.test_images {
                break 'bodies;
            }
            depths.push(v.full_depth(k.width as usize, k.height as usize));
            planes_all.push(view_planes(&v.truth));
            truths.push(v.truth.salient_camera);
            has_arm.push(v.truth.probe.is_some());
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    ensure!(!depths.is_empty(), "no held-out images");
    let mut ws = Box::new(Workspace::new());
    let none = [None; P];
    let seed_of = |i: usize| cfg.seed.wrapping_add(1 + i as u64);
    let mut test_px: Vec<u16> = Vec::new();
    let mut test_p: Vec<f32> = Vec::new();
    let mut test_bank: Vec<i16> = Vec::new();
    let mut counts = Vec::new();
    for (i, (d, pl)) in depths.iter().zip(&planes_all).enumerate() {
        let frame = DepthFrame::new(d, k.width, k.height, Timestamp::default(), 0)
            .map_err(|e| anyhow::anyhow!("frame: {e}"))?;
        let clip = Clip::over_image(pl, &k);
        let mut px = vec![SamplePixel::default(); cfg.samples];
        let n = sample_pixels(&frame, &k, &clip, seed_of(i), &mut px);
        counts.push(n);
        for s in &px[..cfg.samples] {
            test_px.extend([s.x, s.y, s.d_mm]);
            test_p.extend(s.p);
        }
        if i == 0 {
            for s in &px[..n] {
                bank_features(&frame, &bank, s, &mut test_bank);
            }
        }
    }
    let nt = depths.len();
    let flat: Vec<u16> = depths.iter().flatten().copied().collect();
    npy::write(
        &out.join("test_depth.npy"),
        &[nt, k.height as usize, k.width as usize],
        &flat,
    )?;
    npy::write(&out.join("test_pixels.npy"), &[nt, cfg.samples, 3], &test_px)?;
    npy::write(&out.join("test_points.npy"), &[nt, cfg.samples, 3], &test_p)?;
    let tflat: Vec<f32> = truths.iter().flatten().flatten().copied().collect();
    npy::write(&out.join("test_truth.npy"), &[nt, P, 3], &tflat)?;
    npy::write(&out.join("test0_bank.npy"), &[counts[0], cfg.bank], &test_bank)?;

    // Timing: one warm-up pass, then `repeats` passes; per-frame times, single thread.
    let mut estimates = Vec::with_capacity(nt);
    let mut times = Vec::new();
    for pass in 0..=cfg.repeats {
        for (i, (d, pl)) in depths.iter().zip(&planes_all).enumerate() {
            let frame = DepthFrame::new(d, k.width, k.height, Timestamp::default(), 0)
                .map_err(|e| anyhow::anyhow!("frame: {e}"))?;
            let t0 = Instant::now();
            let clip = Clip::over_image(pl, &k);
            let icfg = InferConfig {
                samples: cfg.samples,
                seed: seed_of(i),
                method: Method::Refined,
            };
            let est = estimate(&view, &frame, &k, &clip, &icfg, &none, &mut ws);
            let dt = t0.elapsed().as_secs_f64();
            if pass > 0 {
                times.push(dt);
            }
            if pass == 1 {
                estimates.push(est.map(|e| e.map(|x| x.position.coords.into())));
            }
        }
    }
    times.sort_by(f64::total_cmp);
    let (per, mean, missing) = mean_error_mm(&estimates, &truths);
    let bandwidths: Vec<f32> = forest.params.iter().map(|p| p.refined_bandwidth_m).collect();
    let report = json!({
        "config": cfg,
        "dataset": {"bodies": cfg.bodies, "views": cfg.views, "train_bodies": ds.train.len(),
                    "fit_bodies": fit.len(), "test_bodies": ds.test.len(), "generate_s": gen_s},
        "train_samples": n_train,
        "test_images": nt,
        "test_with_arm": has_arm.iter().filter(|a| **a).count(),
        "train_s": train_s,
        "train_threads": 1,
        "model_bytes": bytes.len(),
        "nodes": forest.node_count(),
        "leaves": forest.leaf_count(),
        "frame_ms_median": 1000.0 * times[times.len() / 2],
        "frame_ms_p90": 1000.0 * times[times.len() * 9 / 10],
        "joint_error_mm_mean": mean,
        "joint_error_mm": SalientPoint::ALL.iter().zip(per).map(|(p, e)| (p.name().to_string(), json!(e)))
            .collect::<serde_json::Map<_, _>>(),
        "missing_fraction": missing,
        "refined_bandwidth_m": bandwidths,
        "samples_drawn": counts,
        "estimates": estimates,
        "train_summary_seconds": summary.seconds,
    });
    std::fs::write(out.join("supine.json"), serde_json::to_vec_pretty(&report)?)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use supine_core::forest::feature::SplitTest;

    #[test]
    fn bank_reads_what_the_split_tests_read() {
        let (w, h) = (64u16, 48u16);
        let depth: Vec<u16> = (0..w as usize * h as usize)
            .map(|i| if i % 7 == 0 { 0 } else { 900 + (i % 311) as u16 })
            .collect();
        let frame = DepthFrame::new(&depth, w, h, Timestamp::default(), 0).unwrap();
        let bank = feature_bank(32, 50, 3);
        assert_eq!(bank, feature_bank(32, 50, 3), "seeded");
        assert!(
            bank.iter()
                .all(|(u, v)| u.iter().chain(v).all(|o| (-50..=50).contains(o)))
        );
        let px = SamplePixel {
            x: 20,
            y: 30,
            d_mm: 1000,
            p: [0.0; 3],
        };
        let mut out = Vec::new();
        bank_features(&frame, &bank, &px, &mut out);
        for ((u, v), f) in bank.iter().zip(&out) {
            let t = SplitTest {
                u: *u,
                v: *v,
                threshold_mm: 0,
            };
            assert_eq!(*f as i32, t.feature(&frame, 20, 30, ProbeScale::new(1000)));
        }
    }
}
