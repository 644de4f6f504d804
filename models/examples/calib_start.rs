//! Why the guess-free start of a calibration sequence fails or starts far off, measured against the generator's
//! truth: over the first N poses' keyframes (as `eval calibration` takes them), each background plane tried as
//! "up" with its angle to the true up, the tip vote under it (poses found, how many of the chosen candidates lie
//! within 2 cm of the true tip), the best candidate per pose against the true tip, and the start's own result.
//!
//! `cargo run --release -p supine-models --example calib_start -- SEQ_DIR_OR_PARENT [POSES]`
//! Cost: one keyframe pass over the sequence and one start (~1 s a sequence).

use anyhow::{Context, Result};
use nalgebra::{Point3, Vector3};
use std::path::PathBuf;
use supine_core::calib::solve::{rotation_error_deg, translation_error_m};
use supine_core::calib::start::{
    StartOptions, background_planes, choose_tips, low_points, median_background,
};
use supine_core::calib::{Candidate, LowPoint, StartScratch};
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::Plane;
use supine_core::time::Timestamp;
use supine_models::eval::calibration::{guess_free_start, pose_keyframes, read_arm_capture, sequence_dirs};
use supine_models::sequence::SequenceMeta;

const CANDS: usize = 32;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let data = PathBuf::from(
        args.get(1)
            .context("usage: calib_start SEQ_DIR_OR_PARENT [POSES]")?,
    );
    let n: usize = args.get(2).map_or(Ok(10), |s| s.parse())?;
    let k = Intrinsics::KINECT_V1;
    let opts = StartOptions::default();
    for dir in sequence_dirs(&data)? {
        let meta: SequenceMeta = serde_json::from_slice(&std::fs::read(dir.join("sequence.json"))?)?;
        let cal = meta.calibration.context("not a calibration sequence")?;
        let truth = cal.robot_base_from_camera.to_isometry();
        let cam_from_rb = truth.inverse();
        let (arm, _) = read_arm_capture(&dir.join("arm.cobs"))?;
        let (frames, arms) = pose_keyframes(&dir.join("sequence.oni"), &arm, n)?;
        let m = arms.len();
        let frame = |i: usize| {
            DepthFrame::new(&frames[i], k.width, k.height, Timestamp::default(), i as u32)
                .expect("keyframes have the frame size")
        };
        println!("== {} ({} poses)", dir.display(), m);
        let start = guess_free_start(&frames[..m], &arms[..m], &k);
        match &start {
            Ok((s, tips)) => println!(
                "start: {:.1} mm / {:.2} deg, {} tips, {} inliers, rms {:.1} mm, condition {:.1}",
                translation_error_m(&s.robot_base_from_camera, &truth) * 1000.0,
                rotation_error_deg(&s.robot_base_from_camera, &truth),
                tips,
                s.inliers,
                s.rms_residual_m * 1000.0,
                s.condition
            ),
            Err(e) => println!("start refused: {e}"),
        }
        let mut background = vec![0u16; frames[0].len()];
        median_background(&mut background, m, frame);
        let np = supine_core::planes::scratch_points(k.width as usize, k.height as usize, 6);
        let (mut pts, mut labels) = (vec![Point3::origin(); np], vec![0u8; np]);
        let mut planes = [Plane::through(Vector3::zeros(), Vector3::z()); 3];
        let np = background_planes(
            &background,
            k.width,
            k.height,
            &k,
            &mut pts,
            &mut labels,
            &mut planes,
        );
        // The true up in the camera.
        let up_cam = cam_from_rb.rotation * Vector3::z();
        let mut scratch: Box<StartScratch<16384>> = Box::default();
        for (p, plane) in planes[..np].iter().enumerate() {
            let angle = plane.normal().dot(&up_cam).clamp(-1.0, 1.0).acos().to_degrees();
            let mut cands = Vec::new();
            let mut best_per_pose = Vec::new();
            for (i, a) in arms.iter().enumerate() {
                let mut low = [LowPoint {
                    point: Point3::origin(),
                    height_m: 0.0,
                    support: 0,
                }; CANDS];
                let c = low_points(&frame(i), &k, &background, plane, &opts, &mut scratch, &mut low);
                let tip_cam = cam_from_rb * a.tip_robot_base;
                let mut best = f32::INFINITY;
                for lp in &low[..c] {
                    let cand = Candidate::new(i, lp, plane, &a.robot_base_from_probe, &opts.shape);
                    best = best.min((cand.tip_camera - tip_cam).norm() * 1000.0);
                    cands.push(cand);
                }
                best_per_pose.push((c, best));
            }
            let z: Vec<f32> = arms.iter().map(|a| a.tip_robot_base.z).collect();
            let mut chosen = vec![None; m];
            let (found, offset) = choose_tips(&cands, &z, opts.vote_tolerance_m, &mut chosen);
            let right = chosen
                .iter()
                .enumerate()
                .filter(|(i, c)| {
                    c.is_some_and(|c: usize| {
                        (cands[c].tip_camera - cam_from_rb * arms[*i].tip_robot_base).norm() < 0.05
                    })
                })
                .count();
            println!(
                "plane {p}: {angle:.1} deg from true up, vote {found}/{m} (offset {offset:.3} m), {right} chosen within 5 cm"
            );
            let line: Vec<String> = best_per_pose
                .iter()
                .zip(chosen.iter())
                .map(|((c, b), ch)| {
                    format!(
                        "{c}c/{b:.0}mm{}",
                        ch.map_or("-".to_owned(), |ci| format!(
                            "/{:.0}",
                            (cands[ci].tip_camera - cam_from_rb * arms[cands[ci].pose].tip_robot_base).norm()
                                * 1000.0
                        ))
                    )
                })
                .collect();
            println!("  per pose (candidates/best/chosen): {}", line.join(" "));
        }
    }
    Ok(())
}
