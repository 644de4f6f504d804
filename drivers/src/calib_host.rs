//! Host-side buffers for calibration's core solvers (the guess-free start, `supine_core::calib::rough_extrinsic`,
//! and the pose solve, `supine_core::calib::solve`): `supine calibrate` and `supine-models eval calibration` both
//! allocate them here, once per solve (no per-frame cost), and both settle loose passes with [`settle_passes`].

use supine_core::calib::start::CANDIDATES_PER_POSE;
use supine_core::calib::{
    ArmSample, Candidate, Pair, PoseObservation, SessionConfig, Solution, SolveError, SolveOptions,
    StartBuffers, StartError, StartOptions, StartScratch, rough_extrinsic, solve_with_axes,
};
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::{Isometry3, Point3};

/// The rough `robot_base_from_camera` from one still frame per pose (`frame(i)` for the pose of `arms[i]`) and
/// the number of poses that gave a tip, with the default start options.
pub fn guess_free_start<'f>(
    frame: impl Fn(usize) -> DepthFrame<'f>,
    arms: &[ArmSample],
    k: &Intrinsics,
) -> Result<(Solution, usize), StartError> {
    let n = arms.len();
    let (w, h) = (k.width as usize, k.height as usize);
    let mut background = vec![0u16; w * h];
    let np = supine_core::planes::scratch_points(w, h, 6);
    let (mut plane_points, mut plane_labels) = (vec![Point3::origin(); np], vec![0u8; np]);
    let blank = Candidate {
        pose: 0,
        tip_camera: Point3::origin(),
        tip_height_m: 0.0,
    };
    let mut candidates = vec![blank; n * CANDIDATES_PER_POSE];
    let mut chosen = vec![None; n];
    let blank_pair = Pair {
        robot_base: Point3::origin(),
        camera: Point3::origin(),
    };
    let mut pairs = vec![blank_pair; n * CANDIDATES_PER_POSE];
    let (mut residuals, mut inliers) = (
        vec![0.0; n * CANDIDATES_PER_POSE],
        vec![false; n * CANDIDATES_PER_POSE],
    );
    // Boxed: the scratch holds 16384 candidate points, too large for the stack of a test thread.
    let mut scratch: Box<StartScratch<16384>> = Box::default();
    rough_extrinsic(
        frame,
        arms,
        k,
        &StartOptions::default(),
        &mut scratch,
        StartBuffers {
            background: &mut background,
            plane_points: &mut plane_points,
            plane_labels: &mut plane_labels,
            candidates: &mut candidates,
            chosen: &mut chosen,
            pairs: &mut pairs,
            residuals: &mut residuals,
            inliers: &mut inliers,
        },
    )
}

/// Solve `robot_base_from_camera` from dwell-averaged poses with `options` (each pose's error along its probe
/// axis weighted by [`SolveOptions::axial_weight`]); the per-pose residuals (metres) and whether each pose was an
/// inlier come back with the solution.
pub fn solve_poses(
    poses: &[PoseObservation],
    options: &SolveOptions,
) -> Result<(Solution, Vec<f32>, Vec<bool>), SolveError> {
    let pairs: Vec<Pair> = poses
        .iter()
        .map(|p| Pair {
            robot_base: p.robot_base,
            camera: p.camera,
        })
        .collect();
    let axes: Vec<_> = poses.iter().map(|p| p.axis_robot_base).collect();
    let (mut residuals, mut inliers) = (vec![0.0; pairs.len()], vec![false; pairs.len()]);
    let s = solve_with_axes(&pairs, &axes, options, &mut residuals, &mut inliers)?;
    Ok((s, residuals, inliers))
}

/// Prior uncertainty of a refined pass (one whose prior is an earlier pass's solve), metres.
pub const REFINED_UNCERTAINTY_M: f32 = 0.02;

/// The session settings of a refined pass from `prior`: the defaults with the [`REFINED_UNCERTAINTY_M`] window.
pub fn refined_session(prior: Isometry3) -> SessionConfig {
    SessionConfig {
        guess_uncertainty_m: REFINED_UNCERTAINTY_M,
        ..SessionConfig::new(prior)
    }
}

/// The refined pass's poses agree worse than this (RMS residual of their solve, metres) before [`settle_passes`]
/// runs further passes. Every validation sequence stays under it (at most 2.6 mm); the sequences whose refined
/// pass locked onto wrong tips agreed to 3.4-4.3 mm (docs/calibration.md).
pub const LOOSE_RMS_M: f32 = 0.003;
/// Further passes [`settle_passes`] runs at most.
pub const SETTLE_PASSES: usize = 3;

/// The refined pass's `poses`, or, when they agree worse than [`LOOSE_RMS_M`] over the first `n`, the
/// best-agreeing of up to [`SETTLE_PASSES`] further passes (`pass(prior)` runs the session with the previous
/// pass's solve as its prior) among those with as many poses. A prior a few centimetres off makes the detector take
/// the wrist or the head's edge for the tip in some poses, and those poses still agree on a transform 25-35 mm from
/// the truth; the next pass from that transform finds other tips, and the passes alternate between a loose and a
/// tight consensus. The tightest is kept. Cost: up to three more sessions over the kept frames, only when loose.
pub fn settle_passes<E>(
    poses: Vec<PoseObservation>,
    n: usize,
    mut pass: impl FnMut(Isometry3) -> Result<Vec<PoseObservation>, E>,
) -> Result<Vec<PoseObservation>, E> {
    let agreement = |p: &[PoseObservation]| {
        solve_poses(&p[..n.min(p.len())], &SolveOptions::lenient())
            .ok()
            .map(|(s, _, _)| (s.rms_residual_m, s.robot_base_from_camera))
    };
    let Some((mut best_rms, mut prior)) = agreement(&poses) else {
        return Ok(poses);
    };
    if best_rms <= LOOSE_RMS_M {
        return Ok(poses);
    }
    let used = n.min(poses.len());
    let mut best = poses;
    for _ in 0..SETTLE_PASSES {
        let next = pass(prior)?;
        let Some((rms, solved)) = agreement(&next) else {
            break;
        };
        if next.len().min(n) >= used && rms < best_rms {
            best_rms = rms;
            best = next;
        }
        prior = solved;
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use supine_core::geometry::{Translation3, UnitQuaternion, Vector3};
    use supine_core::time::Timestamp;

    /// Poses seen through `truth` (`camera = truth⁻¹ · robot_base`), the tips of `wrong` displaced by `off`.
    fn poses(truth: &Isometry3, wrong: &[usize], off: Vector3) -> Vec<PoseObservation> {
        let tips = [
            [0.3, 0.1, 0.2],
            [0.5, -0.2, 0.25],
            [0.4, 0.3, 0.1],
            [0.6, 0.0, 0.3],
            [0.35, -0.3, 0.15],
            [0.55, 0.25, 0.35],
            [0.45, -0.1, 0.05],
            [0.65, 0.2, 0.2],
        ];
        let inv = truth.inverse();
        tips.iter()
            .enumerate()
            .map(|(i, t)| {
                let robot_base = Point3::new(t[0], t[1], t[2]);
                let mut camera = inv * robot_base;
                if wrong.contains(&i) {
                    camera += off;
                }
                PoseObservation {
                    robot_base,
                    camera,
                    frames: 6,
                    first_time: Timestamp::from_us(1 + i as u64 * 1_000_000).unwrap(),
                    spread_m: 0.0,
                    confidence: 1.0,
                    axis_robot_base: Vector3::zeros(),
                }
            })
            .collect()
    }

    #[test]
    fn a_tight_pass_is_kept_and_a_loose_one_settles_on_the_tightest_further_pass() {
        let truth = Isometry3::from_parts(
            Translation3::new(0.2, -0.1, 1.2),
            UnitQuaternion::from_euler_angles(2.5, 0.1, -0.3),
        );
        // Tight: no further pass runs.
        let tight = poses(&truth, &[], Vector3::zeros());
        let mut calls = 0;
        let kept = settle_passes::<()>(tight.clone(), 8, |_| {
            calls += 1;
            Ok(tight.clone())
        })
        .unwrap();
        assert_eq!(calls, 0);
        assert_eq!(kept, tight);
        // Loose: three of eight tips 16 mm off. The passes alternate loose, tight, loose; the tight one is kept.
        let loose = poses(&truth, &[1, 4, 6], Vector3::new(0.012, -0.008, 0.006));
        let mut k = 0;
        let kept = settle_passes::<()>(loose.clone(), 8, |_| {
            k += 1;
            Ok(if k == 2 { tight.clone() } else { loose.clone() })
        })
        .unwrap();
        assert_eq!(k, SETTLE_PASSES);
        assert_eq!(kept, tight);
        // A further pass with fewer poses is not taken, however well they agree.
        let kept = settle_passes::<()>(loose.clone(), 8, |_| Ok(tight[..5].to_vec())).unwrap();
        assert_eq!(kept, loose);
        // A failing pass ends the session with its error.
        assert_eq!(
            settle_passes(loose.clone(), 8, |_| Err("unplugged")),
            Err("unplugged")
        );
    }
}
