//! The ICP comparison's supine side: torso-model-versus-depth problems from generated held-out patients and views
//! (truth pose known, a seeded perturbed start, half of the views with the robot arm), the fixed-iteration driver of `supine_core::icp::point_to_plane_step` with early
//! stop, and the files the Python peers (Open3D, small_gicp; `tests/bench/icp_peers.py`) read: the same model points,
//! the same observed points with normals, the same start pose.
//!
//! Cost: rendering a view is ~30 ms; one supine registration is `iterations` projective passes over the
//! ~1.2 k torso points (tens of µs each).

use super::npy;
use crate::body::{BodyModel, Shape};
use crate::dataset::{Dataset, DatasetConfig, generate as generate_dataset};
use crate::scene::model_body::{BodyKind, open_source};
use crate::shape::data::body_pose;
use anyhow::{Context, Result, ensure};
use nalgebra::{Matrix4, Vector3 as V3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use serde_json::json;
use std::path::Path;
use std::time::Instant;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::fit::subset_normals;
use supine_core::geometry::{Isometry3, Plane, Point3, Translation3, UnitQuaternion};
use supine_core::icp::{IcpError, IcpParams, point_to_plane_step};
use supine_core::time::Timestamp;
use supine_core::torso::a_from_torso;

/// When the driver stops early: the last step moved the pose less than both of these.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StopRule {
    /// Most Gauss-Newton steps.
    pub max_iterations: usize,
    /// Translation change below which a step counts as converged, metres.
    pub translation_m: f32,
    /// Rotation change below which a step counts as converged, radians.
    pub rotation_rad: f32,
}

impl Default for StopRule {
    /// Ten steps at most (the tracker's budget), stop under 0.1 mm and 0.01°.
    fn default() -> Self {
        StopRule {
            max_iterations: 10,
            translation_m: 1e-4,
            rotation_rad: 0.01f32.to_radians(),
        }
    }
}

/// What one registration did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Registration {
    /// The final `camera_from_model`.
    pub pose: Isometry3,
    /// Steps taken.
    pub iterations: usize,
    /// Pairs of the last association.
    pub pairs: usize,
    /// RMS point-to-plane residual of the last association, metres.
    pub rms_m: f32,
}

/// supine's ICP for a fixed iteration count with early stop (what the tracker runs per frame).
#[allow(clippy::too_many_arguments)] // the frame, its camera, the model and the start are all needed
pub fn register(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    points: &[[f32; 3]],
    normals: &[[f32; 3]],
    start: &Isometry3,
    params: &IcpParams,
    stop: &StopRule,
) -> Result<Registration, IcpError> {
    let mut pose = *start;
    let mut last = None;
    let mut iterations = 0;
    for _ in 0..stop.max_iterations {
        let (next, assoc) = point_to_plane_step(frame, k, points, Some(normals), 1, &pose, params)?;
        iterations += 1;
        let delta = next * pose.inverse();
        pose = next;
        last = Some(assoc);
        if delta.translation.vector.norm() < stop.translation_m && delta.rotation.angle() < stop.rotation_rad
        {
            break;
        }
    }
    let a = last.unwrap_or_default();
    Ok(Registration {
        pose,
        iterations,
        pairs: a.pairs,
        rms_m: a.rms_m(),
    })
}

/// Options of the problem set.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ProblemConfig {
    /// Seed of the bodies, views and start perturbations.
    pub seed: u64,
    /// Bodies (each a fresh patient of the statistical body model, never seen in training).
    pub bodies: u32,
    /// Views per body (half of them with the robot arm over the torso).
    pub views: u16,
    /// Start perturbation: rotation about a random axis, degrees.
    pub rotation_deg: f32,
    /// Start perturbation: translation in a random direction, metres.
    pub translation_m: f32,
    /// Timed repetitions of supine's registration per problem (the median is reported).
    pub repeats: usize,
}

fn iso_from_rows(m: &[[f32; 4]; 4]) -> Isometry3 {
    let mat = Matrix4::from_fn(|r, c| m[r][c]);
    let rot = nalgebra::Rotation3::from_matrix_unchecked(mat.fixed_view::<3, 3>(0, 0).into_owned());
    Isometry3::from_parts(
        Translation3::new(m[0][3], m[1][3], m[2][3]),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

fn rows(t: &Isometry3) -> [[f32; 4]; 4] {
    let m = t.to_homogeneous();
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// The observed points the peers register against, with normals from the same depth-neighbour rule as supine's
/// association (neighbours `step` px away within 5 cm in depth, oriented toward the camera): every pixel whose point
/// lies at least `params.above_mattress_m` above the mattress (the body, and the arm when present).
pub fn observed_cloud(depth: &[u16], k: &Intrinsics, params: &IcpParams) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let (w, h) = (k.width as i32, k.height as i32);
    let at = |u: i32, v: i32| -> Option<Point3> {
        if u < 0 || v < 0 || u >= w || v >= h {
            return None;
        }
        match depth[(v * w + u) as usize] {
            0 => None,
            d => Some(k.unproject(u as f32, v as f32, d as f32 * 0.001)),
        }
    };
    let s = params.normal_step_px.max(1) as i32;
    let (mut pts, mut nrm) = (Vec::new(), Vec::new());
    for v in 0..h {
        for u in 0..w {
            let Some(o) = at(u, v) else { continue };
            if params.mattress.signed_distance(&o) < params.above_mattress_m {
                continue;
            }
            let near = |q: Option<Point3>| q.filter(|q| (q.z - o.z).abs() < 0.05);
            let (Some(l), Some(r), Some(t), Some(b)) = (
                near(at(u - s, v)),
                near(at(u + s, v)),
                near(at(u, v - s)),
                near(at(u, v + s)),
            ) else {
                continue;
            };
            let n = (r - l).cross(&(b - t));
            let Some(mut n) = n.try_normalize(1e-12) else {
                continue;
            };
            if n.dot(&o.coords) > 0.0 {
                n = -n;
            }
            pts.push(o.coords.into());
            nrm.push(n.into());
        }
    }
    (pts, nrm)
}

fn perturbation(rng: &mut ChaCha8Rng, rotation_deg: f32, translation_m: f32) -> Isometry3 {
    let mut unit = || loop {
        let v = V3::new(
            rng.gen_range(-1.0f32..1.0),
            rng.gen_range(-1.0f32..1.0),
            rng.gen_range(-1.0f32..1.0),
        );
        let n = v.norm();
        if n > 0.1 && n <= 1.0 {
            return v / n;
        }
    };
    let axis = unit();
    let dir = unit();
    Isometry3::from_parts(
        Translation3::from(dir * translation_m),
        UnitQuaternion::from_scaled_axis(axis * rotation_deg.to_radians()),
    )
}

/// Generate the problems into `out` (problems.json, per-body model points, per-problem observed clouds), run
/// supine's registration on each (`repeats` times, single thread) and write `supine.json`. Returns the report.
///
/// Each problem is one rendered view of a generated patient: the model is the torso subset of the body model in
/// that patient's true shape and pose, expressed in its `torso` frame, so the true `camera_from_torso` puts the
/// model exactly on the rendered surface (up to the Kinect noise): pose errors measure registration alone.
pub fn run(cfg: &ProblemConfig, stop: &StopRule, out: &Path, progress: bool) -> Result<serde_json::Value> {
    ensure!(
        cfg.bodies >= 2 && cfg.views > 0 && cfg.repeats > 0,
        "need at least 2 bodies, 1 view, 1 repeat"
    );
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let k = Intrinsics::KINECT_V1;
    let model = BodyModel::load_default()?;
    let body = model.view();
    let subset: Vec<usize> = body.torso_subset().iter().map(|i| i as usize).collect();
    let source = open_source(BodyKind::Model, None)?;
    let dir = out.join("dataset");
    let _ = std::fs::remove_dir_all(&dir);
    let dcfg = DatasetConfig {
        bodies: cfg.bodies,
        views: cfg.views,
        seed: cfg.seed,
        occluder_fraction: 0.5,
        // The dataset's split is irrelevant here: every body is held out, none was ever trained on (the seed is
        // the benchmark's own), and both splits become problems.
        train_fraction: 0.5,
        previews: 0,
        ..DatasetConfig::default()
    };
    generate_dataset(source.as_ref(), &dcfg, &dir, &|| {})?;
    let ds = Dataset::open(&dir)?;
    let mut problems = Vec::new();
    let mut results = Vec::new();
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x1C9);
    let bar = super::progress_bar(cfg.bodies as u64, "icp problems", progress);
    let mut ids: Vec<u32> = ds.train.iter().chain(&ds.test).copied().collect();
    ids.sort_unstable();
    for b in ids {
        let rec = ds.read_body(b)?;
        let pose = body_pose(&rec)?;
        let posed = model.pose(&Shape::from_normalised(&model, &rec.truth.shape), &pose);
        // The scene places the posed body rigidly on the bed; the torso frame moves with it, so the model in the
        // torso frame comes from the posed body as is and the truth from the scene's salient points.
        let posed_from_torso =
            a_from_torso(&posed.salient_points.map(Point3::from)).context("degenerate salient points")?;
        let world_from_torso =
            a_from_torso(&rec.truth.salient_world.map(Point3::from)).context("degenerate salient points")?;
        let torso_from_posed = posed_from_torso.inverse();
        let pts: Vec<[f32; 3]> = subset
            .iter()
            .map(|&i| (torso_from_posed * Point3::from(posed.vertices[i])).coords.into())
            .collect();
        let mut nrm = vec![[0.0f32; 3]; pts.len()];
        subset_normals(&body, &pts, &mut nrm);
        let name = format!("body{b:03}");
        npy::write_points(&out.join(format!("model-{name}.npy")), &pts)?;
        npy::write_points(&out.join(format!("model-normals-{name}.npy")), &nrm)?;
        for v in &rec.views {
            let depth = v.full_depth(k.width as usize, k.height as usize);
            let truth = iso_from_rows(&v.truth.camera_from_world) * world_from_torso;
            let arm = v.truth.probe.is_some();
            let mattress: Plane = v.truth.planes_camera[1];
            let params = IcpParams::new(mattress);
            // The perturbation acts in the camera frame about the torso origin (a tracker's prediction error).
            let p = perturbation(&mut rng, cfg.rotation_deg, cfg.translation_m);
            let origin = truth.translation.vector;
            let start = Translation3::from(origin) * p * Translation3::from(-origin) * truth;
            let id = format!("{name}-v{:02}", v.truth.view);
            let (obs, obs_n) = observed_cloud(&depth, &k, &params);
            npy::write_points(&out.join(format!("target-{id}.npy")), &obs)?;
            npy::write_points(&out.join(format!("target-normals-{id}.npy")), &obs_n)?;
            let frame = DepthFrame::new(&depth, k.width, k.height, Timestamp::default(), 0)
                .map_err(|e| anyhow::anyhow!("frame: {e}"))?;
            let mut times = Vec::with_capacity(cfg.repeats);
            let mut reg = None;
            for _ in 0..cfg.repeats {
                let t0 = Instant::now();
                let r = register(&frame, &k, &pts, &nrm, &start, &params, stop);
                times.push(t0.elapsed().as_secs_f64());
                reg = Some(r);
            }
            times.sort_by(f64::total_cmp);
            let median_s = times[times.len() / 2];
            let (pose, iterations, pairs, rms) = match reg.expect("repeats > 0") {
                Ok(r) => (Some(rows(&r.pose)), r.iterations, r.pairs, Some(r.rms_m)),
                Err(e) => {
                    tracing::warn!("{id}: supine ICP failed: {e}");
                    (None, 0, 0, None)
                }
            };
            problems.push(json!({
                "id": id,
                "arm": arm,
                "body": b,
                "view": v.truth.view,
                "model": format!("model-{name}.npy"),
                "model_normals": format!("model-normals-{name}.npy"),
                "target": format!("target-{id}.npy"),
                "target_normals": format!("target-normals-{id}.npy"),
                "target_points": obs.len(),
                "truth": rows(&truth),
                "start": rows(&start),
                "occluded_fraction": v.truth.occluded_fraction,
            }));
            results.push(json!({
                "id": id,
                "time_s": median_s,
                "iterations": iterations,
                "pairs": pairs,
                "rms_point_to_plane_m": rms,
                "pose": pose,
                "failed": pose.is_none(),
            }));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let _ = std::fs::remove_dir_all(&dir);
    let set = json!({
        "config": cfg,
        "intrinsics": [k.fx, k.fy, k.cx, k.cy, k.width as f32, k.height as f32],
        "icp_params": {"max_distance_m": 0.1, "occluder_margin_m": 0.04, "above_mattress_m": 0.015,
                       "normal_step_px": 2},
        "problems": problems,
    });
    std::fs::write(out.join("problems.json"), serde_json::to_vec_pretty(&set)?)?;
    let report = json!({
        "method": "supine point_to_plane_step, projective association, fixed iterations with early stop",
        "stop": stop,
        "threads": 1,
        "results": results,
    });
    std::fs::write(out.join("supine.json"), serde_json::to_vec_pretty(&report)?)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn driver_recovers_a_perturbed_plane_pose_and_stops_early() {
        // A tilted, bumpy surface seen at 1.2 m (bumps, so that no sliding along it fits as well): a model of its
        // points must return to the truth.
        let k = Intrinsics::KINECT_V1;
        let (w, h) = (k.width as usize, k.height as usize);
        let surf = |x: f32, y: f32| {
            1.2 + 0.3 * x * x + 0.2 * y * y + 0.1 * x + 0.03 * (15.0 * x).sin() * (12.0 * y).cos()
        };
        let mut depth = vec![0u16; w * h];
        for v in 0..h {
            for u in 0..w {
                // Depth of the surface along the pixel ray (fixed point by iteration).
                let (rx, ry) = ((u as f32 - k.cx) / k.fx, (v as f32 - k.cy) / k.fy);
                let mut z = 1.2;
                for _ in 0..8 {
                    z = surf(rx * z, ry * z);
                }
                depth[v * w + u] = (z * 1000.0).round() as u16;
            }
        }
        let mut pts = Vec::new();
        let mut nrm = Vec::new();
        for i in -10..=10 {
            for j in -10..=10 {
                let (x, y) = (i as f32 * 0.02, j as f32 * 0.02);
                pts.push([x, y, surf(x, y)]);
                let gx = 0.6 * x + 0.1 + 0.45 * (15.0 * x).cos() * (12.0 * y).cos();
                let gy = 0.4 * y - 0.36 * (15.0 * x).sin() * (12.0 * y).sin();
                let n = V3::new(gx, gy, -1.0).normalize();
                nrm.push([n.x, n.y, n.z]);
            }
        }
        let frame = DepthFrame::new(&depth, k.width, k.height, Timestamp::default(), 0).unwrap();
        // A "mattress" far behind everything keeps every point.
        let params = IcpParams::new(Plane::through(V3::new(0.0, 0.0, 5.0), V3::new(0.0, 0.0, -1.0)));
        let start = Isometry3::from_parts(
            Translation3::new(0.01, -0.008, 0.01),
            UnitQuaternion::from_scaled_axis(V3::new(0.02, -0.03, 0.01)),
        );
        let stop = StopRule {
            max_iterations: 30,
            ..StopRule::default()
        };
        let r = register(&frame, &k, &pts, &nrm, &start, &params, &stop).unwrap();
        assert!(r.pose.translation.vector.norm() < 2e-3, "{:?}", r.pose);
        assert!(r.pose.rotation.angle() < 0.2f32.to_radians(), "{:?}", r.pose);
        assert!(r.iterations < 30, "no early stop: {}", r.iterations);
        assert!(r.pairs > 300);
        let (obs, obs_n) = observed_cloud(&depth, &k, &params);
        assert_eq!(obs.len(), obs_n.len());
        assert!(obs.len() > (w - 4) * (h - 4) * 9 / 10);
        // Normals face the camera.
        assert!(
            obs.iter()
                .zip(&obs_n)
                .all(|(p, n)| V3::from(*p).dot(&V3::from(*n)) < 0.0)
        );
    }
}
