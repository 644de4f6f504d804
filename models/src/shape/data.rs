//! Frames of a dataset as the shape code sees them: full depth, the salient points handed to the canonical view
//! (ground truth, or ground truth plus the joint forest's expected error), the mattress plane and the truth.

use anyhow::{Context, Result};
use nalgebra::Point3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use supine_core::camera::Intrinsics;
use supine_core::geometry::Plane;

use crate::dataset::format::BodyRecord;
use crate::dataset::{Dataset, mix_seed};
use crate::pose::Pose;

/// Per-axis SD of the noise added to ground-truth salient points in place of the joint forest (metres): the error
/// the forest is expected to have until it lands (issue 9 targets a few cm).
pub const POINT_NOISE_M: f32 = 0.03;

/// One depth frame with what the shape code needs.
pub struct ShapeFrame {
    /// Body index in the dataset.
    pub body: u32,
    /// View index.
    pub view: u16,
    /// Full 640x480 depth, mm.
    pub depth: Vec<u16>,
    /// Ground-truth salient points (camera frame).
    pub truth_points: [Point3<f32>; 6],
    /// Salient points with the forest's expected error (camera frame).
    pub noisy_points: [Point3<f32>; 6],
    /// Flat mattress plane (camera frame, normal up).
    pub mattress: Plane,
    /// Mattress and head-section planes (camera frame), what the tracker's clip keeps points above.
    pub clip_planes: [Plane; 2],
    /// True shape coefficients (σ units).
    pub shape: [f32; 20],
    /// Whether the robot arm is in view.
    pub with_arm: bool,
    /// Fraction of the body's pixels the arm hides.
    pub occluded_fraction: f32,
}

/// The pose of a body record (for the dense error in the true pose).
pub fn body_pose(rec: &BodyRecord) -> Result<Pose> {
    serde_json::from_value(rec.truth.pose["pose"].clone()).context("body record has no articulated pose")
}

/// The frames of one body record; point noise is seeded by (`seed`, body, view).
pub fn frames_of(rec: &BodyRecord, k: &Intrinsics, seed: u64, noise_m: f32) -> Vec<ShapeFrame> {
    let normal = Normal::new(0.0f32, noise_m.max(1e-9)).expect("positive SD");
    let mut shape = [0.0f32; 20];
    for (s, x) in shape.iter_mut().zip(&rec.truth.shape) {
        *s = *x;
    }
    rec.views
        .iter()
        .map(|v| {
            let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(
                mix_seed(seed, rec.truth.body_index as u64),
                v.truth.view as u64,
            ));
            let truth_points = v.truth.salient_camera.map(Point3::from);
            let noisy_points = truth_points.map(|p| {
                if noise_m > 0.0 {
                    p + nalgebra::Vector3::new(
                        normal.sample(&mut rng),
                        normal.sample(&mut rng),
                        normal.sample(&mut rng),
                    )
                } else {
                    p
                }
            });
            ShapeFrame {
                body: rec.truth.body_index,
                view: v.truth.view,
                depth: v.full_depth(k.width as usize, k.height as usize),
                truth_points,
                noisy_points,
                mattress: v.truth.planes_camera[1],
                clip_planes: crate::forest::data::view_planes(&v.truth),
                shape,
                with_arm: v.truth.probe.is_some(),
                occluded_fraction: v.truth.occluded_fraction,
            }
        })
        .collect()
}

/// The dataset's camera intrinsics.
pub fn intrinsics(ds: &Dataset) -> Intrinsics {
    let i = ds.manifest.intrinsics;
    Intrinsics {
        fx: i[0],
        fy: i[1],
        cx: i[2],
        cy: i[3],
        width: i[4] as u16,
        height: i[5] as u16,
    }
}

/// Training bodies split into (fit, validation): every fifth training body validates (choices are made there,
/// never on the test split).
pub fn train_validation(ds: &Dataset) -> (Vec<u32>, Vec<u32>) {
    let mut fit = Vec::new();
    let mut val = Vec::new();
    for (i, &b) in ds.train.iter().enumerate() {
        if i % 5 == 4 { val.push(b) } else { fit.push(b) }
    }
    (fit, val)
}

/// Generate a small dataset of the statistical body model into `dir` (tests, benches): `bodies` × `views`, 70/30
/// split, half the views with the arm.
pub fn small_dataset(dir: &std::path::Path, bodies: u32, views: u16, seed: u64) -> Result<Dataset> {
    use crate::dataset::{DatasetConfig, generate};
    let cfg = DatasetConfig {
        bodies,
        views,
        seed,
        occluder_fraction: 0.5,
        train_fraction: 0.7,
        previews: 0,
        ..DatasetConfig::default()
    };
    let source = crate::scene::model_body::ModelBodySource::load(None)?;
    generate(&source, &cfg, dir, &|| {})?;
    Dataset::open(dir)
}
