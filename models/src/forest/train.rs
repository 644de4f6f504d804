//! The joint forest's training pipeline: split the training bodies into a fitting part and a validation part (by
//! body, seeded; the test split is never read), sample 512 kept pixels per image, grow the trees on a bounded
//! subset of fitting images (`tree_images` per tree: memory stays bounded for the paper-size run), drop every
//! sample down the trees (bodies are streamed again, one chunk at a time), compute the baseline leaves, run the
//! global refinement, and choose on the validation bodies the E_l scale (Eq. 6) and the mean-shift bandwidths.
//! Deterministic for a seed whatever the thread count (per-image and per-node seeds, ordered collection).

use super::data::{ImageInfo, TrainImage, TrainSample, sample_image};
use super::float::FloatForest;
use super::leaves::leaf_statistics;
use super::refine::{ImageSamples, RefineParams, refine};
use super::tree::{Tree, TreeParams, grow};
use crate::dataset::Dataset;
use crate::dataset::format::BodyRecord;
use anyhow::{Result, ensure};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use std::collections::HashMap;
use supine_core::camera::Intrinsics;
use supine_core::forest::infer::{Method, estimate_from_leaves};
use supine_core::forest::meanshift::Vote;
use supine_core::forest::model::PointParams;
use supine_core::forest::{MAX_TREES, MAX_VOTES};
use supine_core::rng::{SplitMix64, mix_seed};
use supine_core::salient::SalientPoint;

const P: usize = SalientPoint::COUNT;
/// Bodies decoded at once (bounds memory while streaming).
const CHUNK: usize = 16;
/// E_l scales tried on the validation bodies, metres.
pub const ERROR_SCALES_M: [f32; 7] = [0.03, 0.05, 0.08, 0.12, 0.18, 0.3, 1e3];
/// Mean-shift bandwidths tried on the validation bodies, metres.
pub const BANDWIDTHS_M: [f32; 7] = [0.02, 0.03, 0.05, 0.08, 0.12, 0.2, 0.3];
/// Validation scores errors truncated here (metres): the score rewards precise modes (the 3 cm detection rate of
/// Fig. 6a) while a few gross failures cannot push the choice to a blurry bandwidth; a point without an estimate
/// scores the truncation.
pub const SCORE_TRUNCATION_M: f32 = 0.1;

/// Training options.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct TrainConfig {
    /// Master seed.
    pub seed: u64,
    /// Trees.
    pub trees: usize,
    /// Training samples per image.
    pub samples_per_image: usize,
    /// Samples per frame the forest asks for at inference (validation choices and the file; `None`:
    /// `samples_per_image`).
    #[serde(default)]
    pub infer_samples: Option<usize>,
    /// Tree growing.
    pub tree: TreeParams,
    /// Most fitting images each tree is grown on (a random subset).
    pub tree_images: usize,
    /// Share of the training bodies held out for validation.
    pub validation_fraction: f32,
    /// Baseline vote length threshold, metres.
    pub vote_length_m: f32,
    /// Baseline offsets kept per leaf and point (uniform subsample) before mode finding.
    pub reservoir: usize,
    /// Bandwidth of the per-leaf mode finding, metres.
    pub leaf_bandwidth_m: f32,
    /// Refinement.
    pub refine: RefineParams,
    /// Training views are read through the tracker's height ceiling of this many metres over the bed planes (0:
    /// as rendered; files trained before it existed read as 0).
    #[serde(default)]
    pub ceiling_m: f32,
}

/// Most training samples per image (memory: 40 B per sample while training).
pub const MAX_TRAIN_SAMPLES: usize = 8192;

impl TrainConfig {
    /// Samples per frame at inference.
    pub fn infer_samples(&self) -> usize {
        self.infer_samples.unwrap_or(self.samples_per_image)
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            seed: 0,
            trees: 3,
            samples_per_image: 512,
            infer_samples: None,
            tree: TreeParams::default(),
            tree_images: 800,
            validation_fraction: 0.15,
            vote_length_m: 0.5,
            reservoir: 32,
            leaf_bandwidth_m: 0.05,
            refine: RefineParams::default(),
            ceiling_m: supine_core::tracker::FOREST_CEILING_M,
        }
    }
}

/// What training measured and chose.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TrainSummary {
    /// Fitting bodies.
    pub fit_bodies: Vec<u32>,
    /// Validation bodies.
    pub validation_bodies: Vec<u32>,
    /// Fitting images.
    pub fit_images: usize,
    /// Validation images.
    pub validation_images: usize,
    /// Samples in all.
    pub samples: usize,
    /// Nodes per tree.
    pub nodes: Vec<usize>,
    /// Leaves per tree.
    pub leaves: Vec<usize>,
    /// Chosen E_l scale per point, metres.
    pub error_scale_m: [f32; P],
    /// Validation score (mean over the points of the truncated error at each point's best bandwidth, m) per E_l
    /// scale tried (refined).
    pub error_scale_scores: Vec<(f32, f32)>,
    /// Validation score per point of the chosen configuration, refined and baseline, mm.
    pub validation_error_mm: HashMap<String, [f32; 2]>,
    /// Seconds per stage.
    pub seconds: Vec<(String, f64)>,
}

fn bar(len: u64, msg: &str, show: bool) -> ProgressBar {
    let b = ProgressBar::with_draw_target(
        Some(len),
        if show {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    b.set_style(
        ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b.set_message(msg.to_string());
    b
}

/// Seed of image (body, view)'s pixel sampling.
pub fn image_seed(seed: u64, body: u32, view: u16) -> u64 {
    mix_seed(seed, ((body as u64) << 16) | view as u64)
}

/// Split `train` bodies into (fit, validation), seeded.
pub fn split_validation(train: &[u32], fraction: f32, seed: u64) -> (Vec<u32>, Vec<u32>) {
    let mut ids = train.to_vec();
    let mut rng = SplitMix64::new(mix_seed(seed, 0x0FA1));
    for k in (1..ids.len()).rev() {
        ids.swap(k, rng.below(k + 1));
    }
    let n_val = if ids.len() >= 2 {
        ((ids.len() as f32 * fraction).round() as usize).clamp(1, ids.len() - 1)
    } else {
        0
    };
    let mut val = ids[..n_val].to_vec();
    let mut fit = ids[n_val..].to_vec();
    val.sort_unstable();
    fit.sort_unstable();
    (fit, val)
}

/// Decode `bodies` in chunks (parallel within a chunk), calling `f` on each body in order.
fn stream_bodies(
    ds: &Dataset,
    bodies: &[u32],
    mut f: impl FnMut(usize, BodyRecord) -> Result<()>,
) -> Result<()> {
    let mut at = 0;
    for chunk in bodies.chunks(CHUNK) {
        let recs: Vec<Result<BodyRecord>> = chunk.par_iter().map(|&b| ds.read_body(b)).collect();
        for r in recs {
            f(at, r?)?;
            at += 1;
        }
    }
    Ok(())
}

/// Validation score per point (mean of the 3D error truncated at [`SCORE_TRUNCATION_M`], metres) for `method` of
/// `forest` over images `imgs`.
fn validation_error(
    forest: &FloatForest,
    method: Method,
    data: &ImageSamples<'_>,
    imgs: &[usize],
    n: usize,
) -> [f32; P] {
    let per: Vec<[f32; P]> = imgs
        .par_iter()
        .map_init(
            || vec![Vote::default(); MAX_VOTES],
            |votes, &img| {
                // The first `n` of the image's uniform draws: as many as inference reads.
                let (lo, hi) = data.ranges[img];
                let hi = hi.min(lo + n);
                let pos: Vec<[f32; 3]> = data.samples[lo..hi].iter().map(|s| s.px.p).collect();
                let est = estimate_from_leaves(forest, method, &pos, &data.leaves[lo..hi], &[None; P], votes);
                let t = &data.infos[img].targets;
                let mut e = [SCORE_TRUNCATION_M; P];
                for p in 0..P {
                    if let Some(x) = est[p] {
                        let d = x.position.coords - nalgebra::Vector3::from(t[p]);
                        e[p] = d.norm().min(SCORE_TRUNCATION_M);
                    }
                }
                e
            },
        )
        .collect();
    let mut m = [0.0f32; P];
    for e in &per {
        for p in 0..P {
            m[p] += e[p] / per.len().max(1) as f32;
        }
    }
    m
}

/// Train a forest on the training split of `ds`.
pub fn train(ds: &Dataset, cfg: &TrainConfig, progress: bool) -> Result<(FloatForest, TrainSummary)> {
    train_on(ds, cfg, None, progress)
}

/// Train on the training split of `ds`; with `structure`, the trees are taken as given (only the leaves, the
/// refinement and the validation choices are computed again).
pub fn train_on(
    ds: &Dataset,
    cfg: &TrainConfig,
    structure: Option<Vec<Tree>>,
    progress: bool,
) -> Result<(FloatForest, TrainSummary)> {
    if let Some(t) = &structure {
        ensure!(
            t.len() == cfg.trees,
            "the given structure has {} trees, --trees says {}",
            t.len(),
            cfg.trees
        );
    }
    ensure!(
        (1..=MAX_TREES).contains(&cfg.trees),
        "--trees must be 1..={MAX_TREES}"
    );
    ensure!(
        (1..=MAX_TRAIN_SAMPLES).contains(&cfg.samples_per_image),
        "training samples per image must be 1..={MAX_TRAIN_SAMPLES}"
    );
    ensure!(
        (1..=supine_core::forest::MAX_SAMPLES).contains(&cfg.infer_samples()),
        "inference samples per frame (--infer-samples, default --samples) must be 1..={}",
        supine_core::forest::MAX_SAMPLES
    );
    super::data::check_ceiling(cfg.ceiling_m)?;
    ensure!(
        (1..=supine_core::forest::feature::MAX_OFFSET).contains(&cfg.tree.offset_px_m),
        "--offset-px-m must be in 1..={}",
        supine_core::forest::feature::MAX_OFFSET
    );
    ensure!(
        (1..=i32::from(i8::MAX)).contains(&cfg.tree.threshold_mm),
        "--threshold-mm must be in 1..=127 (the model file stores thresholds as i8 mm)"
    );
    ensure!(!ds.train.is_empty(), "the dataset has no training bodies");
    let k = Intrinsics::KINECT_V1;
    let mut seconds = Vec::new();
    let t0 = std::time::Instant::now();
    let (fit, val) = split_validation(&ds.train, cfg.validation_fraction, cfg.seed);
    let bodies: Vec<u32> = fit.iter().chain(&val).copied().collect();
    let is_fit = |b: u32| fit.binary_search(&b).is_ok();

    // The fitting images each tree grows on (seeded subsets of the fitting images, counted in body order).
    let views = ds.manifest.config.views as usize;
    let n_fit_images = fit.len() * views;
    let mut subsets: Vec<Vec<usize>> = Vec::new();
    for t in 0..cfg.trees {
        let mut ids: Vec<usize> = (0..n_fit_images).collect();
        let mut rng = SplitMix64::new(mix_seed(cfg.seed, 0x7EE0 + t as u64));
        let take = cfg.tree_images.min(n_fit_images);
        for j in 0..take {
            let r = j + rng.below(n_fit_images - j);
            ids.swap(j, r);
        }
        ids.truncate(take);
        ids.sort_unstable();
        subsets.push(ids);
    }
    let mut in_union = vec![false; n_fit_images];
    for s in subsets.iter().filter(|_| structure.is_none()) {
        for &i in s {
            in_union[i] = true;
        }
    }

    // Pass 1: sample every image, keep the crops the trees grow on.
    let pb = bar(bodies.len() as u64, "sampling", progress);
    let mut infos: Vec<ImageInfo> = Vec::new();
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    let mut samples: Vec<TrainSample> = Vec::new();
    let mut kept: HashMap<usize, TrainImage> = HashMap::new();
    let mut fit_imgs = Vec::new();
    let mut val_imgs = Vec::new();
    let mut fit_counter = 0usize;
    stream_bodies(ds, &bodies, |_, rec| {
        let b = rec.truth.body_index;
        ensure!(
            rec.views.len() == views,
            "body {b} has {} views, the manifest says {views}",
            rec.views.len()
        );
        for v in &rec.views {
            let img_id = infos.len();
            let ti = TrainImage::from_view(v, &k, cfg.ceiling_m);
            let lo = samples.len();
            sample_image(
                &ti,
                &v.truth,
                &k,
                cfg.samples_per_image,
                image_seed(cfg.seed, b, v.truth.view),
                img_id as u32,
                &mut samples,
            );
            ranges.push((lo, samples.len()));
            infos.push(ImageInfo {
                body: b,
                view: v.truth.view,
                targets: v.truth.salient_camera,
                has_arm: v.truth.probe.is_some(),
            });
            if is_fit(b) {
                if fit_counter < in_union.len() && in_union[fit_counter] {
                    kept.insert(img_id, ti);
                }
                fit_imgs.push(img_id);
                fit_counter += 1;
            } else {
                val_imgs.push(img_id);
            }
        }
        pb.inc(1);
        Ok(())
    })?;
    pb.finish();
    seconds.push(("sampling".into(), t0.elapsed().as_secs_f64()));

    // Grow the trees (in parallel, each on its subset).
    let t1 = std::time::Instant::now();
    let mut kept_ids: Vec<usize> = kept.keys().copied().collect();
    kept_ids.sort_unstable();
    let slot: HashMap<usize, u32> = kept_ids.iter().enumerate().map(|(s, &i)| (i, s as u32)).collect();
    let kept_imgs: Vec<TrainImage> = kept_ids.iter().filter_map(|i| kept.remove(i)).collect();
    let kept_targets: Vec<_> = kept_ids.iter().map(|&i| infos[i].targets).collect();
    let tree_inputs: Vec<Vec<TrainSample>> = subsets
        .iter()
        .filter(|_| structure.is_none())
        .map(|sub| {
            let mut v = Vec::new();
            for &fi in sub {
                let img = fit_imgs[fi];
                let (lo, hi) = ranges[img];
                let image = slot[&img];
                v.extend(samples[lo..hi].iter().map(|s| TrainSample { image, ..*s }));
            }
            v
        })
        .collect();
    let bars: Vec<ProgressBar> = tree_inputs
        .iter()
        .enumerate()
        .map(|(t, s)| bar(s.len() as u64, &format!("tree {t}"), progress))
        .collect();
    let trees: Vec<Tree> = match structure {
        Some(t) => t,
        None => tree_inputs
            .into_par_iter()
            .enumerate()
            .map(|(t, mut s)| {
                let tree = grow(
                    &kept_imgs,
                    &kept_targets,
                    &mut s,
                    &cfg.tree,
                    mix_seed(cfg.seed, 0x7000 + t as u64),
                    &bars[t],
                );
                bars[t].finish();
                tree
            })
            .collect(),
    };
    seconds.push(("trees".into(), t1.elapsed().as_secs_f64()));

    // Pass 2: every sample's leaves (kept crops are reused, the others decoded again).
    let t2 = std::time::Instant::now();
    let mut leaf_base = Vec::new();
    let mut n_leaves = 0u32;
    for t in &trees {
        leaf_base.push(n_leaves);
        n_leaves += t.leaves;
    }
    // What a `NODE` record holds (the inference's descent carries records, the file stores them).
    let most = supine_core::forest::model::MAX_NODE_INDEX as usize + 1;
    ensure!(
        n_leaves as usize <= most && trees.iter().all(|t| t.nodes.len() <= most),
        "the trees grew more than {most} leaves or nodes per tree, more than a model file holds: raise --min-split"
    );
    let mut leaves = vec![[0u32; MAX_TREES]; samples.len()];
    let pb = bar(bodies.len() as u64, "leaves", progress);
    // Every body has `views` images (checked in pass 1), so body `bi`'s images start at `bi * views`.
    let body_first_img: Vec<usize> = (0..bodies.len()).map(|bi| bi * views).collect();
    let drop_down = |ti: &TrainImage, lo: usize, hi: usize, out: &mut [[u32; MAX_TREES]]| {
        for (i, row) in (lo..hi).zip(out.iter_mut()) {
            let s = &samples[i];
            for (t, tree) in trees.iter().enumerate() {
                row[t] = leaf_base[t] + tree.descend(ti, s.px.x as i32, s.px.y as i32, s.px.d_mm);
            }
        }
    };
    let mut missing: Vec<u32> = Vec::new();
    for (bi, &b) in bodies.iter().enumerate() {
        let first = body_first_img[bi];
        if (first..first + views).all(|i| slot.contains_key(&i)) {
            for i in first..first + views {
                let (lo, hi) = ranges[i];
                drop_down(&kept_imgs[slot[&i] as usize], lo, hi, &mut leaves[lo..hi]);
            }
            pb.inc(1);
        } else {
            missing.push(b);
        }
    }
    stream_bodies(ds, &missing, |_, rec| {
        let bi = bodies
            .iter()
            .position(|&b| b == rec.truth.body_index)
            .ok_or_else(|| anyhow::anyhow!("body {} not requested", rec.truth.body_index))?;
        let first = body_first_img[bi];
        let per_view: Vec<(usize, usize, Vec<[u32; MAX_TREES]>)> = rec
            .views
            .par_iter()
            .enumerate()
            .map(|(v, view)| {
                let (lo, hi) = ranges[first + v];
                let ti = TrainImage::from_view(view, &k, cfg.ceiling_m);
                let mut out = vec![[0u32; MAX_TREES]; hi - lo];
                drop_down(&ti, lo, hi, &mut out);
                (lo, hi, out)
            })
            .collect();
        for (lo, hi, out) in per_view {
            leaves[lo..hi].copy_from_slice(&out);
        }
        pb.inc(1);
        Ok(())
    })?;
    pb.finish();
    drop(kept_imgs);
    seconds.push(("leaves".into(), t2.elapsed().as_secs_f64()));

    // Leaf statistics and baseline modes from the fitting images.
    let t3 = std::time::Instant::now();
    let mut use_sample = vec![false; samples.len()];
    for &img in &fit_imgs {
        let (lo, hi) = ranges[img];
        use_sample[lo..hi].iter_mut().for_each(|u| *u = true);
    }
    let stats = leaf_statistics(
        &samples,
        &leaves,
        &infos,
        &use_sample,
        cfg.trees,
        n_leaves as usize,
        cfg.vote_length_m,
        cfg.reservoir,
        cfg.leaf_bandwidth_m,
        cfg.seed,
    );
    seconds.push(("baseline".into(), t3.elapsed().as_secs_f64()));

    // Global refinement.
    let t4 = std::time::Instant::now();
    let data = ImageSamples {
        samples: &samples,
        leaves: &leaves,
        ranges: &ranges,
        infos: &infos,
    };
    let pb = bar(cfg.refine.epochs as u64, "refine epochs", progress);
    let (refined, leaf_error) = refine(
        &data,
        &fit_imgs,
        cfg.trees,
        &stats.mean_offset,
        &cfg.refine,
        cfg.seed,
        &pb,
    );
    pb.finish();
    seconds.push(("refinement".into(), t4.elapsed().as_secs_f64()));

    // Validation choices: E_l scale, then the bandwidth per point and method.
    let t5 = std::time::Instant::now();
    let default_params = PointParams {
        refined_bandwidth_m: 0.05,
        baseline_bandwidth_m: 0.05,
        vote_length_m: cfg.vote_length_m,
    };
    let mut forest = FloatForest {
        trees,
        leaf_base,
        refined,
        leaf_error,
        body_leaf: stats.body_leaf,
        baseline: stats.baseline,
        error_scale_m: [0.1; P],
        params: [default_params; P],
        samples: cfg.infer_samples() as u32,
    };
    // Per point, the (E_l scale, bandwidth) pair with the best validation score: a point's estimate depends only on
    // its own confidences and bandwidth, so the choices are independent across points.
    let mut error_scale_scores = Vec::new();
    let tune_imgs: &[usize] = if val_imgs.is_empty() { &fit_imgs } else { &val_imgs };
    let mut best_r = [(f32::INFINITY, 0.1f32, 0.05f32); P];
    for &s in &ERROR_SCALES_M {
        forest.error_scale_m = [s; P];
        let mut best_here = [f32::INFINITY; P];
        for &h in &BANDWIDTHS_M {
            forest.params = [PointParams {
                refined_bandwidth_m: h,
                baseline_bandwidth_m: h,
                vote_length_m: cfg.vote_length_m,
            }; P];
            let er = validation_error(&forest, Method::Refined, &data, tune_imgs, cfg.infer_samples());
            for p in 0..P {
                best_here[p] = best_here[p].min(er[p]);
                if er[p] < best_r[p].0 {
                    best_r[p] = (er[p], s, h);
                }
            }
        }
        error_scale_scores.push((s, best_here.iter().sum::<f32>() / P as f32));
    }
    forest.error_scale_m = best_r.map(|b| b.1);
    let mut best_b = [(f32::INFINITY, 0.05f32); P];
    for &h in &BANDWIDTHS_M {
        forest.params = [PointParams {
            refined_bandwidth_m: h,
            baseline_bandwidth_m: h,
            vote_length_m: cfg.vote_length_m,
        }; P];
        let eb = validation_error(&forest, Method::Baseline, &data, tune_imgs, cfg.infer_samples());
        for p in 0..P {
            if eb[p] < best_b[p].0 {
                best_b[p] = (eb[p], h);
            }
        }
    }
    let mut validation_error_mm = HashMap::new();
    for p in 0..P {
        forest.params[p] = PointParams {
            refined_bandwidth_m: best_r[p].2,
            baseline_bandwidth_m: best_b[p].1,
            vote_length_m: cfg.vote_length_m,
        };
        validation_error_mm.insert(
            SalientPoint::ALL[p].name().to_string(),
            [best_r[p].0 * 1000.0, best_b[p].0 * 1000.0],
        );
    }
    seconds.push(("validation".into(), t5.elapsed().as_secs_f64()));
    let summary = TrainSummary {
        fit_images: fit_imgs.len(),
        validation_images: val_imgs.len(),
        fit_bodies: fit,
        validation_bodies: val,
        samples: samples.len(),
        nodes: forest.trees.iter().map(|t| t.nodes.len()).collect(),
        leaves: forest.trees.iter().map(|t| t.leaves as usize).collect(),
        error_scale_m: forest.error_scale_m,
        error_scale_scores,
        validation_error_mm,
        seconds,
    };
    Ok((forest, summary))
}
