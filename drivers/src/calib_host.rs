//! Host-side buffers for calibration's core solvers (the guess-free start, `supine_core::calib::rough_extrinsic`,
//! and the pose solve, `supine_core::calib::solve`): `supine calibrate` and `supine-models eval calibration` both
//! allocate them here, once per solve (no per-frame cost).

use supine_core::calib::start::CANDIDATES_PER_POSE;
use supine_core::calib::{
    ArmSample, Candidate, Pair, PoseObservation, Solution, SolveError, SolveOptions, StartBuffers,
    StartError, StartOptions, StartScratch, rough_extrinsic, solve_with_axes,
};
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::Point3;

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
