//! `eval shape` (paper §4.2, Fig. 5) on the held-out bodies: subspace regression, plain model fitting (from the
//! mean, several starts, results beyond ±3σ rejected and counted) and their combination; coefficient NRMSE and
//! error SD (σ units), the dense upper-body vertex error in the true pose, ms per frame; arm views apart; and the
//! multi-frame estimate (per-coefficient median over N views) against N, of the subspace estimates and of the
//! combined fits.
//!
//! Cost per frame: subspace ~3 ms, combined fit ~10 ms, plain fit 5 starts, plus four posings (LBS) for the errors.

use crate::provenance::commit;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::{Point3, Vector3};
use std::time::Instant;
use supine_core::body_model::BodyModelView;
use supine_core::depth::DepthFrame;
use supine_core::fit::{
    BedContact, FitParams, fit_shape, fit_shape_along_axis, fit_shape_on_bed, initial_pose,
};
use supine_core::forest::infer::{InferConfig, Method, Workspace, estimate_above};
use supine_core::forest::model::ForestView;
use supine_core::icp::IcpParams;
use supine_core::shape::ShapeModelView;
use supine_core::time::Timestamp;

use super::data::{ShapeFrame, body_pose, frames_of, intrinsics};
use crate::body::{BodyModel, BodyPart, PosedBody, SalientPoint, Shape};
use crate::dataset::Dataset;
use crate::forest::train::image_seed;
use crate::pose::Pose;

/// Coefficients (by index) whose variation lies mostly on the torso: each one's share of the torso subset's
/// shape variance is at least `min_share`, and it moves torso vertices at least as much as the body's average.
pub fn torso_coeffs(model: &BodyModel, min_share: f64) -> (Vec<usize>, Vec<(f64, f64)>) {
    let k = crate::body::COMPONENTS;
    let energy = |verts: &mut dyn Iterator<Item = usize>| {
        let mut e = vec![0.0f64; k];
        for v in verts {
            for c in 0..3 {
                for (j, ej) in e.iter_mut().enumerate() {
                    let b = model.basis[(3 * v + c) * k + j] as f64 * model.sigma[j] as f64;
                    *ej += b * b;
                }
            }
        }
        e
    };
    let torso = energy(&mut model.torso_subset.iter().map(|&v| v as usize));
    let all = energy(&mut (0..model.n_vertices));
    let total: f64 = torso.iter().sum();
    let frac = model.torso_subset.len() as f64 / model.n_vertices as f64;
    let stats: Vec<(f64, f64)> = (0..k)
        .map(|j| (torso[j] / total, (torso[j] / all[j].max(1e-30)) / frac))
        .collect();
    let picked = (0..k)
        .filter(|&j| stats[j].0 >= min_share && stats[j].1 >= 1.0)
        .collect();
    (picked, stats)
}

/// Whether a vertex belongs to the upper body (head, neck, trunk, upper arms).
pub fn upper_body(part: u8) -> bool {
    matches!(
        BodyPart::from_u8(part),
        Some(
            BodyPart::Head
                | BodyPart::Neck
                | BodyPart::Chest
                | BodyPart::Abdomen
                | BodyPart::Pelvis
                | BodyPart::LeftUpperArm
                | BodyPart::RightUpperArm
        )
    )
}

/// Accumulated errors of one method.
#[derive(Default, Clone)]
pub struct Stats {
    n: usize,
    se: [f64; 20],
    sum: [f64; 20],
    v_sum: f64,
    v_sq: f64,
    v_n: f64,
    h_sum: f64,
    h_sq: f64,
    a_sum: f64,
    a_sq: f64,
    ms: f64,
    ms_n: usize,
    rejected: usize,
    tried: usize,
    rms_sum: f64,
    pairs_sum: f64,
    occl_sum: f64,
    fit_n: usize,
}

impl Stats {
    fn add(&mut self, est: &[f32; 20], truth: &[f32; 20], errs: &VertexErrors) {
        let (vertex_err, hip_err) = (&errs.raw, &errs.hip);
        for &e in hip_err {
            self.h_sum += e as f64;
            self.h_sq += (e as f64).powi(2);
        }
        for &e in &errs.aligned {
            self.a_sum += e as f64;
            self.a_sq += (e as f64).powi(2);
        }
        self.n += 1;
        for k in 0..20 {
            let e = (est[k] - truth[k]) as f64;
            self.se[k] += e * e;
            self.sum[k] += e;
        }
        for &e in vertex_err {
            self.v_sum += e as f64;
            self.v_sq += (e as f64).powi(2);
        }
        self.v_n += vertex_err.len() as f64;
    }

    fn json(&self) -> serde_json::Value {
        let n = self.n.max(1) as f64;
        let nrmse: Vec<f64> = self.se.iter().map(|s| (s / n).sqrt()).collect();
        let sd: Vec<f64> = (0..20)
            .map(|k| (self.se[k] / n - (self.sum[k] / n).powi(2)).max(0.0).sqrt())
            .collect();
        let vm = self.v_sum / self.v_n.max(1.0);
        let vsd = (self.v_sq / self.v_n.max(1.0) - vm * vm).max(0.0).sqrt();
        let hm = self.h_sum / self.v_n.max(1.0);
        let hsd = (self.h_sq / self.v_n.max(1.0) - hm * hm).max(0.0).sqrt();
        let am = self.a_sum / self.v_n.max(1.0);
        let asd = (self.a_sq / self.v_n.max(1.0) - am * am).max(0.0).sqrt();
        serde_json::json!({
            "vertex_error_aligned_mm_mean": am * 1000.0,
            "vertex_error_aligned_mm_sd": asd * 1000.0,
            "frames": self.n,
            "vertex_error_hip_mm_mean": hm * 1000.0,
            "vertex_error_hip_mm_sd": hsd * 1000.0,
            "coeff_nrmse": nrmse,
            "coeff_sd": sd,
            "vertex_error_mm_mean": vm * 1000.0,
            "vertex_error_mm_sd": vsd * 1000.0,
            "ms_per_frame": self.ms / self.ms_n.max(1) as f64,
            "fit_residual_mm": self.rms_sum / self.fit_n.max(1) as f64 * 1000.0,
            "fit_pairs": self.pairs_sum / self.fit_n.max(1) as f64,
            "fit_occluded": self.occl_sum / self.fit_n.max(1) as f64,
            "rejected_fraction": if self.tried > 0 { self.rejected as f64 / self.tried as f64 } else { 0.0 },
        })
    }
}

/// Upper-body vertex errors (metres) of one estimate against the true posed upper body.
pub struct VertexErrors {
    /// As posed in the body frame, no alignment (the definition).
    pub raw: Vec<f32>,
    /// With the estimated body moved so its hip centre meets the true one.
    pub hip: Vec<f32>,
    /// With the estimated upper body moved by the least-squares translation (its upper-body centroid onto the
    /// true one): the shape error without the model-frame offset of the upper body (see `shape_sensitivity`).
    pub aligned: Vec<f32>,
}

/// [`VertexErrors`] of `est` (σ units) posed with `pose` against `truth`.
pub fn vertex_errors(
    model: &BodyModel,
    pose: &Pose,
    est: &[f32; 20],
    truth: &PosedBody<'_>,
    mask: &[bool],
) -> VertexErrors {
    let posed = model.pose(&Shape::from_normalised(model, est), pose);
    let hip = |b: &PosedBody<'_>| {
        (Vector3::from(b.salient_points[SalientPoint::LeftHip.index()])
            + Vector3::from(b.salient_points[SalientPoint::RightHip.index()]))
            * 0.5
    };
    let shift = hip(truth) - hip(&posed);
    let pairs: Vec<(Vector3<f32>, Vector3<f32>)> = posed
        .vertices
        .iter()
        .zip(&truth.vertices)
        .zip(mask)
        .filter(|(_, m)| **m)
        .map(|((a, b), _)| (Vector3::from(*a), Vector3::from(*b)))
        .collect();
    let centroid =
        pairs.iter().fold(Vector3::zeros(), |acc, (a, b)| acc + (b - a)) / pairs.len().max(1) as f32;
    VertexErrors {
        raw: pairs.iter().map(|(a, b)| (a - b).norm()).collect(),
        hip: pairs.iter().map(|(a, b)| (a + shift - b).norm()).collect(),
        aligned: pairs.iter().map(|(a, b)| (a + centroid - b).norm()).collect(),
    }
}

/// How much 1 σ of each shape coefficient moves the upper body of the rest pose: RMS vertex displacement (mm) as
/// is, and after removing its mean (the part a translation absorbs). Says which coefficients the vertex error is
/// made of, and how much of it is a shift of the whole upper body in the model frame.
pub fn shape_sensitivity(model: &BodyModel, mask: &[bool]) -> Vec<(f64, f64)> {
    let k = crate::body::COMPONENTS;
    let verts: Vec<usize> = (0..model.n_vertices).filter(|&v| mask[v]).collect();
    let n = verts.len().max(1) as f64;
    (0..k)
        .map(|j| {
            let d = |v: usize, c: usize| model.basis[(3 * v + c) * k + j] as f64 * model.sigma[j] as f64;
            let mut mean = [0.0f64; 3];
            let mut sq = 0.0;
            for &v in &verts {
                for (c, m) in mean.iter_mut().enumerate() {
                    *m += d(v, c) / n;
                    sq += d(v, c).powi(2);
                }
            }
            let rms = (sq / n).sqrt();
            let shift2: f64 = mean.iter().map(|m| m * m).sum();
            (rms * 1000.0, ((sq / n) - shift2).max(0.0).sqrt() * 1000.0)
        })
        .collect()
}

/// Evaluation settings.
#[derive(Debug, Clone, serde::Serialize)]
pub struct EvalConfig {
    /// Seed of the salient-point noise.
    pub seed: u64,
    /// Per-axis salient-point noise (metres).
    pub point_noise_m: f32,
    /// Residual unit of Eq. 7 (metres).
    pub length_unit_m: f32,
    /// The fits' correspondence distance from their second round on (metres; `None`: the first round's 0.1 m).
    pub fine_distance_m: Option<f32>,
    /// Starts of the plain fit.
    pub plain_starts: usize,
    /// Test bodies used at most (0 = all).
    pub max_bodies: usize,
    /// Which bodies: "test" or "validation".
    pub split: String,
    /// Salient points handed to every method: `noisy` (ground truth plus `point_noise_m` per axis) or `forest` (the
    /// joint forest's refined estimate on the frame, `models/artifacts/joints.jfor` unless given).
    pub points: String,
    /// Joint forest file for `points = forest` (default: the committed one).
    pub joint_forest: Option<std::path::PathBuf>,
    /// The tracker's height ceiling the forest reads frames through, metres (0: as rendered).
    pub forest_ceiling_m: f32,
    /// Weight of the bed-contact residual of `combined_bed` (see `supine_core::fit::BedContact`).
    pub bed_weight: f32,
    /// Coefficients the combined fits leave nearly free (small Λ); `None` = `torso_coeffs`, as the paper did.
    pub free_coeffs: Option<Vec<usize>>,
    /// Λ on those coefficients (`supine_core::fit::FREE_PRIOR_WEIGHT` by default).
    pub free_weight: f32,
    /// Offsets along the body the combined fit starts from, metres (`supine_core::fit::AXIS_STARTS_M` by default;
    /// `[0.0]`: the one start of the rounds before 2026-12-08).
    pub axis_starts_m: Vec<f32>,
}

impl EvalConfig {
    /// The fit settings every fitted method of the evaluation shares (Eq. 7's unit, coarse to fine) into `p`.
    fn tune(&self, p: &mut FitParams) {
        p.length_unit_m = self.length_unit_m;
        p.fine_distance_m = self.fine_distance_m;
    }
}

/// Starting shapes of the plain fit: the mean, then ±1.5σ on the first two coefficients (`n` of them, none for 0).
fn plain_starts(n: usize) -> Vec<[f32; 20]> {
    let mut v = vec![[0.0f32; 20]];
    for (k, s) in [(0, 1.5f32), (0, -1.5), (1, 1.5), (1, -1.5)] {
        let mut z = [0.0; 20];
        z[k] = s;
        v.push(z);
    }
    v.truncate(n);
    v
}

/// Run the evaluation; returns the JSON report.
pub fn evaluate(
    ds: &Dataset,
    model: &BodyModel,
    shape_bytes: &[u8],
    cfg: &EvalConfig,
) -> Result<serde_json::Value> {
    let shape = ShapeModelView::parse(shape_bytes).map_err(|e| anyhow::anyhow!("shape model: {e}"))?;
    let joint_bytes = match cfg.points.as_str() {
        "noisy" => None,
        "forest" => {
            let path = cfg
                .joint_forest
                .clone()
                .unwrap_or_else(crate::forest::cli::default_path);
            Some(std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?)
        }
        other => anyhow::bail!("--points must be `noisy` or `forest`, not `{other}`"),
    };
    let joints = match &joint_bytes {
        Some(b) => Some(ForestView::parse(b).map_err(|e| anyhow::anyhow!("joint forest: {e}"))?),
        None => None,
    };
    let mut joint_ws = Box::new(Workspace::new());
    let mut point_errors = (0.0f64, 0usize);
    let body: BodyModelView<'_> = model.view();
    let k = intrinsics(ds);
    let (torso, torso_stats) = torso_coeffs(model, 0.03);
    let mask: Vec<bool> = model.part_of_vertex.iter().map(|&p| upper_body(p)).collect();
    let sensitivity = shape_sensitivity(model, &mask);
    let mut bodies = match cfg.split.as_str() {
        "validation" => super::data::train_validation(ds).1,
        _ => ds.test.clone(),
    };
    if cfg.max_bodies > 0 {
        bodies.truncate(cfg.max_bodies);
    }
    // `subspace_forest`: the forest's answer on the same subspace coefficients, for comparison when the model
    // file's estimate uses its linear regression (the same as `subspace` otherwise); `subspace_coeffs`: the
    // regression on the coefficients alone (`ShapeModelView::coefficients_only`, what the tracker uses), for
    // comparison when the estimate's also reads the salient points' distances.
    let names = [
        "subspace",
        "fitting",
        "combined",
        "mean_shape",
        "combined_bed",
        "subspace_forest",
        "subspace_coeffs",
    ];
    let mut all: Vec<Stats> = vec![Stats::default(); names.len()];
    let mut arm: Vec<Stats> = vec![Stats::default(); names.len()];
    let mut no_arm: Vec<Stats> = vec![Stats::default(); names.len()];
    let ns = [1usize, 2, 4, 8, 12];
    let mut multi: Vec<Stats> = vec![Stats::default(); ns.len()];
    let mut multi_comb: Vec<Stats> = vec![Stats::default(); ns.len()];
    let coefficients_only = shape.coefficients_only();
    let mut canonical = vec![0.0f32; shape.pixels()];
    let mut subset = vec![[0.0f32; 3]; body.counts().subset];
    let mut normals = subset.clone();
    let mut images = 0;
    let mut failures = 0;
    let bar = ProgressBar::new(bodies.len() as u64).with_style(
        ProgressStyle::with_template("eval shape {bar:40} {pos}/{len} bodies {elapsed}")
            .expect("valid template"),
    );
    for &b in &bodies {
        let rec = ds.read_body(b)?;
        let pose = body_pose(&rec)?;
        let frames: Vec<ShapeFrame> = frames_of(&rec, &k, cfg.seed, cfg.point_noise_m);
        let Some(first) = frames.first() else { continue };
        let truth_shape = first.shape;
        let truth_posed = model.pose(&Shape::from_normalised(model, &truth_shape), &pose);
        let mut per_view = Vec::new();
        let mut per_view_comb = Vec::new();
        for f in &frames {
            images += 1;
            let frame = DepthFrame::new(&f.depth, k.width, k.height, Timestamp::default(), f.view as u32)
                .map_err(|e| anyhow::anyhow!("dataset frame: {e}"))?;
            let pts: [Point3<f32>; 6] = match &joints {
                None => f.noisy_points,
                Some(jf) => {
                    let ic = InferConfig {
                        samples: jf.samples_per_frame(),
                        seed: image_seed(cfg.seed, b, f.view),
                        method: Method::Refined,
                    };
                    let est = estimate_above(
                        jf,
                        &frame,
                        &k,
                        &f.clip_planes,
                        cfg.forest_ceiling_m,
                        &ic,
                        &[None; 6],
                        &mut joint_ws,
                    );
                    if est.iter().any(Option::is_none) {
                        failures += 1;
                        continue;
                    }
                    let p = est.map(|e| e.map(|e| e.position).unwrap_or(Point3::origin()));
                    for (e, t) in p.iter().zip(&f.truth_points) {
                        point_errors.0 += (e - t).norm() as f64;
                        point_errors.1 += 1;
                    }
                    p
                }
            };
            let icp = IcpParams::new(f.mattress);
            let up = f.mattress.normal();
            // Subspace regression.
            let t0 = Instant::now();
            let est = shape.estimate(&frame, &k, &pts, &f.mattress, &mut canonical);
            let ms_sub = t0.elapsed().as_secs_f64() * 1e3;
            let Ok(est) = est else {
                failures += 1;
                continue;
            };
            per_view.push(est.shape);
            // Combined: fit from the subspace estimate.
            let t1 = Instant::now();
            let mut p =
                FitParams::combined_with(icp, cfg.free_coeffs.as_deref().unwrap_or(&torso), cfg.free_weight);
            cfg.tune(&mut p);
            let combined = initial_pose(&body, &est.shape, &pts, &up).ok().and_then(|pose0| {
                fit_shape_along_axis(
                    &body,
                    &frame,
                    &k,
                    &est.shape,
                    pose0,
                    &cfg.axis_starts_m,
                    &p,
                    &mut subset,
                    &mut normals,
                )
                .ok()
            });
            let ms_comb = t1.elapsed().as_secs_f64() * 1e3;
            if let Some(r) = &combined {
                per_view_comb.push(r.shape);
            }
            // Combined with the bed-contact term.
            let t3 = Instant::now();
            let contact = BedContact {
                weight: cfg.bed_weight,
                height_m: 0.0,
            };
            let on_bed = initial_pose(&body, &est.shape, &pts, &up).ok().and_then(|pose0| {
                fit_shape_on_bed(
                    &body,
                    &frame,
                    &k,
                    &est.shape,
                    pose0,
                    &p,
                    &contact,
                    &mut subset,
                    &mut normals,
                )
                .ok()
            });
            let ms_bed = t3.elapsed().as_secs_f64() * 1e3;
            // Plain fitting: several starts from the mean, the best residual wins.
            let t2 = Instant::now();
            let mut pp = FitParams::plain(icp);
            cfg.tune(&mut pp);
            let mut best: Option<supine_core::fit::FitResult> = None;
            for z0 in plain_starts(cfg.plain_starts) {
                let Ok(pose0) = initial_pose(&body, &z0, &pts, &up) else {
                    continue;
                };
                if let Ok(r) = fit_shape(&body, &frame, &k, &z0, pose0, &pp, &mut subset, &mut normals)
                    && best.is_none_or(|b| r.association.rms_m() < b.association.rms_m())
                {
                    best = Some(r);
                }
            }
            let ms_plain = t2.elapsed().as_secs_f64() * 1e3;
            let assoc = [
                None,
                best.map(|r| r.association),
                combined.map(|r| r.association),
                None,
                on_bed.map(|r| r.association),
                None,
                None,
            ];
            let results: [Option<[f32; 20]>; 7] = [
                Some(est.shape),
                best.map(|r| r.shape),
                combined.map(|r| r.shape),
                Some([0.0; 20]),
                on_bed.map(|r| r.shape),
                Some(shape.forest().predict(&est.subspace)),
                Some(coefficients_only.regress(&est.subspace, &pts)),
            ];
            let ms = [
                ms_sub,
                ms_plain,
                ms_sub + ms_comb,
                0.0,
                ms_sub + ms_bed,
                ms_sub,
                ms_sub,
            ];
            for m in 0..names.len() {
                let groups: Vec<&mut Vec<Stats>> = if f.with_arm && f.occluded_fraction <= 0.5 {
                    vec![&mut all, &mut arm]
                } else if f.with_arm {
                    vec![&mut all]
                } else {
                    vec![&mut all, &mut no_arm]
                };
                let mut errs = None;
                for g in groups {
                    let s = &mut g[m];
                    s.ms += ms[m];
                    s.ms_n += 1;
                    s.tried += 1;
                    if let Some(a) = assoc[m] {
                        s.fit_n += 1;
                        s.rms_sum += a.rms_m() as f64;
                        s.pairs_sum += a.pairs as f64;
                        s.occl_sum += a.occluded as f64;
                    }
                    match results[m] {
                        Some(z) if m != 1 || z.iter().all(|x| x.abs() <= 3.0) => {
                            let e = errs
                                .get_or_insert_with(|| vertex_errors(model, &pose, &z, &truth_posed, &mask));
                            s.add(&z, &truth_shape, e);
                        }
                        _ => s.rejected += 1,
                    }
                }
            }
        }
        for (views, stats) in [(&per_view, &mut multi), (&per_view_comb, &mut multi_comb)] {
            for (i, &n) in ns.iter().enumerate() {
                if views.len() >= n {
                    let z = supine_core::shape::combine::median_shape(&views[..n]);
                    let e = vertex_errors(model, &pose, &z, &truth_posed, &mask);
                    stats[i].add(&z, &truth_shape, &e);
                }
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let mut report = serde_json::json!({
        "torso_coeffs": torso,
        "torso_variance_share": torso_stats.iter().map(|s| s.0).collect::<Vec<_>>(),
        "torso_concentration": torso_stats.iter().map(|s| s.1).collect::<Vec<_>>(),
        "upper_body_mm_per_sigma": sensitivity.iter().map(|s| s.0).collect::<Vec<_>>(),
        "upper_body_mm_per_sigma_unshifted": sensitivity.iter().map(|s| s.1).collect::<Vec<_>>(),
        "seed": cfg.seed,
        "images": images,
        "bodies": bodies.len(),
        "split": cfg.split,
        "estimate_failures": failures,
        "points": cfg.points,
        "free_coeffs": cfg.free_coeffs.clone().unwrap_or_else(|| torso.clone()),
        "point_error_mm_mean": if point_errors.1 > 0 { point_errors.0 / point_errors.1 as f64 * 1000.0 } else { f64::NAN },
        "config": cfg,
        "canonical": {"width": shape.camera().width, "height": shape.camera().height, "stride": shape.camera().stride,
                       "pitch_m": shape.camera().distance_m / shape.camera().focal_px},
        "model_bytes": shape_bytes.len(),
        "regressor": match shape.linear() {
            Some(l) if l.uses_points() => "linear_points",
            Some(_) => "linear",
            None => "forest",
        },
        "commit": commit(),
    });
    for (m, name) in names.iter().enumerate() {
        let mut j = all[m].json();
        j["with_arm"] = arm[m].json();
        j["without_arm"] = no_arm[m].json();
        report[*name] = j;
    }
    for (key, stats) in [("multi_frame", &multi), ("multi_frame_combined", &multi_comb)] {
        report[key] = serde_json::Value::Array(
            ns.iter()
                .zip(stats)
                // N beyond the dataset's views per body has no frames.
                .filter(|(_, s)| s.n > 0)
                .map(|(n, s)| {
                    let mut j = s.json();
                    j["views"] = (*n).into();
                    j
                })
                .collect(),
        );
    }
    Ok(report)
}
