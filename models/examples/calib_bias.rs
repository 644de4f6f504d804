//! Where the calibration error of a sequence comes from, measured against the generator's truth: the session of
//! `eval calibration` run once with the true extrinsic as its prior (2 cm), so the rough start plays no part; each
//! pose's detected tip against the true tip in the true probe frame (across the head's width, its thickness,
//! along the axis), and the first N poses solved four ways: detected tips with the arm's tips (what the command
//! gets), true camera tips with the arm's (the arm's share), detected tips with the true arm tips (the
//! detector's share), detected tips corrected by the mean probe-frame bias of the sequence, and the detected
//! tips with the axial component weighted by w (0.03-1; probe axes from the truth). Then every dwell frame's
//! detection with the true prior, its mean error binned by the view's axial component and by depth.
//!
//! `cargo run --release -p supine-models --example calib_bias -- SEQ_DIR_OR_PARENT [POSES]`
//! Cost: one session over the sequence (~5 ms a frame).

use anyhow::{Context, Result};
use nalgebra::{Matrix3, Point3, Vector3};
use std::path::PathBuf;
use supine_core::calib::solve::{rotation_error_deg, translation_error_m};
use supine_core::calib::{Pair, SessionConfig, SolveOptions, solve};
use supine_core::geometry::Isometry3;
use supine_models::eval::calibration::{read_arm_capture, run_session, sequence_dirs};
use supine_models::sequence::SequenceMeta;
use supine_models::sequence::calibration::CalibrationFrameTruth;

/// One pose: detected and true camera tip, arm and true robot tip, probe-frame error, view in the probe frame,
/// true `camera_from_probe`, frames and spread.
type Row = (
    Point3<f32>,
    Point3<f32>,
    Point3<f32>,
    Point3<f32>,
    Vector3<f32>,
    Vector3<f32>,
    Matrix3<f32>,
    u32,
    f32,
);

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let data = PathBuf::from(
        args.get(1)
            .context("usage: calib_bias SEQ_DIR_OR_PARENT [POSES]")?,
    );
    let n_solve: usize = args.get(2).map_or(Ok(10), |s| s.parse())?;
    let mut all_bias = Vec::new();
    let mut frames_out: Vec<(Vector3<f32>, Vector3<f32>, f32)> = Vec::new();
    let mut summary: Vec<(f32, f32)> = Vec::new();
    let mut aniso_sum: std::collections::BTreeMap<i32, Vec<(f32, f32)>> = Default::default();
    for dir in sequence_dirs(&data)? {
        let meta: SequenceMeta = serde_json::from_slice(&std::fs::read(dir.join("sequence.json"))?)?;
        let cal = meta.calibration.context("not a calibration sequence")?;
        let truth = cal.robot_base_from_camera.to_isometry();
        let cam_from_rb = truth.inverse();
        let (arm, _) = read_arm_capture(&dir.join("arm.cobs"))?;
        // True rotation per pose.
        let text = std::fs::read_to_string(dir.join("truth.jsonl"))?;
        let mut rot: Vec<Option<Matrix3<f32>>> = vec![None; cal.poses_robot_base.len()];
        for line in text.lines() {
            let t: CalibrationFrameTruth = serde_json::from_str(line)?;
            if let Some(slot) = t.pose.and_then(|p| rot.get_mut(p as usize))
                && slot.is_none()
            {
                let m = t.camera_from_probe;
                *slot = Some(Matrix3::new(
                    m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
                ));
            }
        }
        // Per frame: the detector with the true prior (2 cm), error in the true probe frame, view and depth.
        {
            use supine_core::calib::{TipOptions, TipPrior, TipScratch, detect_tip};
            use supine_drivers::oni::OniReader;
            let mut reader = OniReader::open(dir.join("sequence.oni"))?;
            let mut scratch: Box<TipScratch<8192>> = Box::default();
            for line in text.lines() {
                let t: CalibrationFrameTruth = serde_json::from_str(line)?;
                let Ok(frame) = reader.read_frame() else { break };
                if t.pose.is_none() {
                    continue;
                }
                let m = t.camera_from_probe;
                let r = Matrix3::new(
                    m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
                );
                let tip = Point3::new(m[0][3], m[1][3], m[2][3]);
                let prior = TipPrior {
                    tip_camera: tip,
                    camera_from_probe: nalgebra::UnitQuaternion::from_matrix(&r),
                    uncertainty_m: 0.02,
                };
                if let Ok(d) = detect_tip(
                    &frame,
                    &supine_core::camera::Intrinsics::KINECT_V1,
                    &prior,
                    &TipOptions::default(),
                    &mut scratch,
                ) {
                    let e = r.transpose() * (d.tip_camera - tip);
                    let v = r.transpose() * tip.coords.normalize();
                    frames_out.push((e, v, tip.z));
                }
            }
        }
        let config = SessionConfig {
            guess_uncertainty_m: 0.02,
            ..SessionConfig::new(truth)
        };
        let (poses, _) = run_session(&dir.join("sequence.oni"), &arm, config, 20)?;
        // Per pose: detected and true camera tip, arm and true robot tip, probe-frame error.
        let mut rows = Vec::new();
        for p in &poses {
            let Some((i, t)) = cal
                .poses_robot_base
                .iter()
                .enumerate()
                .map(|(i, t)| (i, Point3::from(*t)))
                .min_by(|(_, a), (_, b)| (a - p.robot_base).norm().total_cmp(&(b - p.robot_base).norm()))
            else {
                continue;
            };
            if (t - p.robot_base).norm() > 0.02 {
                continue;
            }
            let Some(r) = rot[i] else { continue };
            let tc = cam_from_rb * t;
            let e = r.transpose() * (p.camera - tc);
            // The view ray in the probe frame (from the camera to the tip).
            let v = r.transpose() * tc.coords.normalize();
            rows.push((p.camera, tc, p.robot_base, t, e, v, r, p.frames, p.spread_m));
        }
        let name = dir.file_name().unwrap_or_default().to_string_lossy().to_string();
        println!("== {name} ({} poses, patient {})", rows.len(), cal.config.patient);
        for (k, (_, _, rb, t, e, v, _, frames, spread)) in rows.iter().enumerate() {
            println!(
                "  pose {k:2}: probe err [{:6.1} {:6.1} {:6.1}] mm  view [{:5.2} {:5.2} {:5.2}]  arm err {:4.1} mm  frames {frames} spread {:.1}",
                e.x * 1e3,
                e.y * 1e3,
                e.z * 1e3,
                v.x,
                v.y,
                v.z,
                (rb - t).norm() * 1e3,
                spread * 1e3
            );
        }
        let m = rows.len().min(n_solve);
        let mean_e: Vector3<f32> = rows[..m].iter().map(|r| r.4).sum::<Vector3<f32>>() / m.max(1) as f32;
        println!(
            "  mean probe-frame error (first {m}): [{:.2} {:.2} {:.2}] mm",
            mean_e.x * 1e3,
            mean_e.y * 1e3,
            mean_e.z * 1e3
        );
        let solve_with = |f: &dyn Fn(&Row) -> Pair| -> String {
            let pairs: Vec<Pair> = rows[..m].iter().map(f).collect();
            let (mut res, mut inl) = (vec![0.0; m], vec![false; m]);
            match solve(&pairs, &SolveOptions::default(), &mut res, &mut inl) {
                Ok(s) => format!(
                    "{:5.2} mm {:.3} deg (rms {:.2} mm, {} inliers)",
                    translation_error_m(&s.robot_base_from_camera, &truth) * 1e3,
                    rotation_error_deg(&s.robot_base_from_camera, &truth),
                    s.rms_residual_m * 1e3,
                    s.inliers
                ),
                Err(e) => format!("refused: {e}"),
            }
        };
        println!(
            "  solve detected+arm     : {}",
            solve_with(&|r| Pair {
                robot_base: r.2,
                camera: r.0
            })
        );
        // Detected tips paired with the arm's: what the tool solves from.
        let pairs: Vec<Pair> = rows[..m]
            .iter()
            .map(|r| Pair {
                robot_base: r.2,
                camera: r.0,
            })
            .collect();
        {
            let (mut res, mut inl) = (vec![0.0; m], vec![false; m]);
            if let Ok(s) = solve(&pairs, &SolveOptions::default(), &mut res, &mut inl) {
                summary.push((
                    translation_error_m(&s.robot_base_from_camera, &truth) * 1e3,
                    rotation_error_deg(&s.robot_base_from_camera, &truth),
                ));
            }
        }
        println!(
            "  solve truecam+arm      : {}",
            solve_with(&|r| Pair {
                robot_base: r.2,
                camera: r.1
            })
        );
        println!(
            "  solve detected+truerb  : {}",
            solve_with(&|r| Pair {
                robot_base: r.3,
                camera: r.0
            })
        );
        println!(
            "  solve detected-bias+arm: {}",
            solve_with(&|r| Pair {
                robot_base: r.2,
                camera: r.0 - r.6 * mean_e
            })
        );
        // Anisotropic: the axial direction (probe axis in robot_base, from the truth here) weighted by w.
        for w in [1.0f32, 0.3, 0.1, 0.03] {
            let (mut res, mut inl) = (vec![0.0; m], vec![false; m]);
            let Ok(s0) = solve(&pairs, &SolveOptions::default(), &mut res, &mut inl) else {
                continue;
            };
            let axes: Vec<Vector3<f32>> = rows[..m]
                .iter()
                .map(|r| truth.rotation * (r.6 * Vector3::z()))
                .collect();
            let t = aniso(&pairs, &inl, &axes, w, s0.robot_base_from_camera);
            let (te, re) = (
                translation_error_m(&t, &truth) * 1e3,
                rotation_error_deg(&t, &truth),
            );
            println!("  aniso w={w:.2}: {te:5.2} mm {re:.3} deg");
            aniso_sum.entry((w * 100.0) as i32).or_default().push((te, re));
        }
        all_bias.extend(rows.iter().map(|r| r.4));
    }
    for (w, v) in &aniso_sum {
        let k = v.len() as f32;
        println!(
            "ANISO w={:.2}: {} solved, mean {:.2} mm {:.3} deg, within {}",
            *w as f32 / 100.0,
            v.len(),
            v.iter().map(|x| x.0).sum::<f32>() / k,
            v.iter().map(|x| x.1).sum::<f32>() / k,
            v.iter().filter(|x| x.0 <= 5.0 && x.1 <= 0.3).count()
        );
    }
    let within = summary.iter().filter(|(t, r)| *t <= 5.0 && *r <= 0.3).count();
    let ns = summary.len().max(1) as f32;
    println!(
        "SUMMARY solved {} mean {:.2} mm {:.3} deg, within both limits {}",
        summary.len(),
        summary.iter().map(|s| s.0).sum::<f32>() / ns,
        summary.iter().map(|s| s.1).sum::<f32>() / ns,
        within
    );
    // Per-frame axial error binned by the view's axial component and by depth.
    let good: Vec<_> = frames_out.iter().filter(|f| f.0.norm() < 0.015).collect();
    println!(
        "FRAMES {} detected, {} within 15 mm",
        frames_out.len(),
        good.len()
    );
    for (lo, hi) in [(-1.0, 0.3), (0.3, 0.5), (0.5, 0.7), (0.7, 0.85), (0.85, 1.01)] {
        let b: Vec<_> = good.iter().filter(|f| f.1.z >= lo && f.1.z < hi).collect();
        let k = b.len().max(1) as f32;
        let me: Vector3<f32> = b.iter().map(|f| f.0).sum::<Vector3<f32>>() / k;
        let sd = (b.iter().map(|f| (f.0.z - me.z).powi(2)).sum::<f32>() / k).sqrt();
        println!(
            "  view.z [{lo:.2},{hi:.2}): {:4} frames, mean err [{:.2} {:.2} {:.2}] mm, axial sd {:.2}",
            b.len(),
            me.x * 1e3,
            me.y * 1e3,
            me.z * 1e3,
            sd * 1e3
        );
    }
    for (lo, hi) in [(0.0, 1.2), (1.2, 1.4), (1.4, 1.6), (1.6, 1.8), (1.8, 9.0)] {
        let b: Vec<_> = good.iter().filter(|f| f.2 >= lo && f.2 < hi).collect();
        let k = b.len().max(1) as f32;
        let me: Vector3<f32> = b.iter().map(|f| f.0).sum::<Vector3<f32>>() / k;
        let sd = (b.iter().map(|f| (f.0.z - me.z).powi(2)).sum::<f32>() / k).sqrt();
        println!(
            "  depth [{lo:.1},{hi:.1}): {:4} frames, mean err [{:.2} {:.2} {:.2}] mm, axial sd {:.2}",
            b.len(),
            me.x * 1e3,
            me.y * 1e3,
            me.z * 1e3,
            sd * 1e3
        );
    }
    let n = all_bias.len().max(1) as f32;
    let mean: Vector3<f32> = all_bias.iter().sum::<Vector3<f32>>() / n;
    let sd = (all_bias
        .iter()
        .map(|e| (e - mean).component_mul(&(e - mean)))
        .sum::<Vector3<f32>>()
        / n)
        .map(f32::sqrt);
    println!(
        "ALL {} poses: mean probe-frame error [{:.2} {:.2} {:.2}] mm, sd [{:.2} {:.2} {:.2}] mm",
        all_bias.len(),
        mean.x * 1e3,
        mean.y * 1e3,
        mean.z * 1e3,
        sd.x * 1e3,
        sd.y * 1e3,
        sd.z * 1e3
    );
    Ok(())
}

/// Gauss-Newton on sum_i r_i^T W_i r_i, W_i = I - (1 - w) a_i a_i^T, r_i = rb_i - (R c_i + t), from `t0`.
fn aniso(pairs: &[Pair], inl: &[bool], axes: &[Vector3<f32>], w: f32, t0: Isometry3) -> Isometry3 {
    use nalgebra::{Matrix6, Translation3, UnitQuaternion, Vector6};
    let mut t = t0;
    for _ in 0..10 {
        let mut h = Matrix6::<f32>::zeros();
        let mut g = Vector6::<f32>::zeros();
        for ((p, &ok), a) in pairs.iter().zip(inl).zip(axes) {
            if !ok {
                continue;
            }
            let wm = Matrix3::identity() - a * a.transpose() * (1.0 - w);
            let q = t.rotation * p.camera.coords;
            let r = p.robot_base.coords - (q + t.translation.vector);
            // d(R c + t) = dtheta x q + dt  => J = [-[q]x, I]
            let mut j = nalgebra::Matrix3x6::<f32>::zeros();
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-q.cross_matrix()));
            j.fixed_view_mut::<3, 3>(0, 3).copy_from(&Matrix3::identity());
            h += j.transpose() * wm * j;
            g += j.transpose() * wm * r;
        }
        let Some(d) = h.lu().solve(&g) else { break };
        let dr = UnitQuaternion::from_scaled_axis(Vector3::new(d[0], d[1], d[2]));
        t = Isometry3::from_parts(
            Translation3::from(t.translation.vector + Vector3::new(d[3], d[4], d[5])),
            dr * t.rotation,
        );
    }
    t
}
