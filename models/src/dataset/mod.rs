//! HumanVP-style synthetic dataset (paper §4.1, rebuilt for a patient on a bed seen from a robot head): N bodies
//! (shape from the population model, pose from the bed-pose generator) × V views (random rotations of the head about
//! two axes), Kinect noise, per-image ground truth, split 70/30 by body.
//!
//! Layout of `DIR` (see `docs/dataset-format.md`):
//! - `dataset.json`: the [`Manifest`] (parameters, seed, intrinsics, noise model, legends);
//! - `split.json`: `{"train": [body indices], "test": [...]}`;
//! - `bodies/body_NNNNN.svd`: one file per body, [`mod@format`];
//! - `previews/*.png`: a few colour-mapped depth images with the salient points drawn.
//!
//! Generation is deterministic for a seed (every body has its own ChaCha8 stream derived from the seed and its index,
//! so the bytes do not depend on thread scheduling) and runs in parallel over bodies with rayon; each worker keeps one
//! renderer and writes its body file as it goes, so memory stays bounded (one body and one image per worker).
//! Per body: posing (LBS) once; per view: render (~3 ms), noise on the crop (~6 ms with the legacy chain; the
//! blob, edge and registration effects add 20–30 % to the whole image), zlib (~4 ms): ~15 ms of CPU per image, so
//! 4000 × 12 images take ~6 minutes on 2 free cores.
//! [`Dataset`] is the reader the trainers use.

pub mod cli;
pub mod format;
pub mod preview;

use crate::pose::Rest;
use crate::render::noise::{KinectNoise, NoiseScratch, Rect};
use crate::render::{Label, Renderer};
use crate::scene::arm::ArmState;
use crate::scene::body::{BodySource, Patient};
use crate::scene::shapes::vertex_normals;
use crate::scene::{BedParams, Scene, ViewParams, matrix_rows};
use anyhow::{Context, Result, ensure};
use format::{BodyRecord, BodyWriter};
use nalgebra::{Isometry3, Point3, Vector3};
use rand::Rng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use supine_core::camera::Intrinsics;
use supine_core::geometry::Plane;
use supine_core::salient::SalientPoint;

/// SplitMix64 finaliser: decorrelates (seed, index) pairs into independent stream seeds.
pub fn mix_seed(seed: u64, index: u64) -> u64 {
    let mut z = seed
        ^ index
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Parameters of one dataset run.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DatasetConfig {
    /// Number of bodies.
    pub bodies: u32,
    /// Views per body.
    pub views: u16,
    /// Master seed.
    pub seed: u64,
    /// Probability that a view shows the robot arm with the probe on the torso.
    pub occluder_fraction: f32,
    /// Fraction of bodies in the training split.
    pub train_fraction: f32,
    /// Number of preview PNGs to write (view 0 of the first bodies).
    pub previews: u32,
    /// Noise model.
    pub noise: KinectNoise,
    /// Scale of the head's nominal distance to the patient (height and lateral offset; 1 = the robot's range,
    /// 1.1–2 m). The noise report renders at real frames' distances with it.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub view_distance_scale: f32,
    /// Margin around the patient's bounding box in the stored crops, px ([`CROP_MARGIN_PX`] when absent).
    #[serde(
        default = "default_crop_margin",
        skip_serializing_if = "is_default_crop_margin"
    )]
    pub crop_margin_px: u16,
    /// Where the views that show the arm place it ([`ArmPlacement::Contact`] when absent).
    #[serde(default, skip_serializing_if = "ArmPlacement::is_contact")]
    pub arm_placement: ArmPlacement,
    /// What the patient rests on ([`Rest::LowestPoint`] when absent: every dataset before this option).
    #[serde(default, skip_serializing_if = "Rest::is_lowest_point")]
    pub rest: Rest,
}

/// Where a dataset view's robot arm is.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum ArmPlacement {
    /// The probe on the torso, the robot's shoulder from [`sample_shoulder`] (every dataset before this option).
    #[default]
    Contact,
    /// Half the arm views as `Contact`, the other half as the tracking sequences hold the arm
    /// ([`place_arm_as_sequences`]).
    Sequence,
}

impl ArmPlacement {
    fn is_contact(&self) -> bool {
        *self == ArmPlacement::Contact
    }
}

impl Default for DatasetConfig {
    /// What `supine-models dataset` renders without options.
    fn default() -> Self {
        DatasetConfig {
            bodies: cli::DEFAULT_BODIES,
            views: 12,
            seed: 0,
            occluder_fraction: 0.3,
            train_fraction: 0.7,
            previews: 4,
            noise: KinectNoise::default(),
            view_distance_scale: 1.0,
            crop_margin_px: CROP_MARGIN_PX,
            arm_placement: ArmPlacement::Contact,
            rest: Rest::LowestPoint,
        }
    }
}

fn default_crop_margin() -> u16 {
    CROP_MARGIN_PX
}

fn is_default_crop_margin(x: &u16) -> bool {
    *x == CROP_MARGIN_PX
}

fn one() -> f32 {
    1.0
}

fn is_one(x: &f32) -> bool {
    *x == 1.0
}

/// `DIR/dataset.json`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Manifest {
    /// Always `"supine-hvp"`.
    pub format: String,
    /// Body-file format version.
    pub version: u16,
    /// Generation parameters.
    pub config: DatasetConfig,
    /// Body source (`"makehuman-pca"` or `"mannequin"`).
    pub body_source: String,
    /// Camera intrinsics (fx, fy, cx, cy, width, height).
    pub intrinsics: [f32; 6],
    /// Salient point names in ground-truth order.
    pub salient_names: Vec<String>,
    /// Label byte values and names.
    pub labels: Vec<(u8, String)>,
    /// Body-part names indexed by part id.
    pub part_names: Vec<String>,
    /// Body-file name pattern relative to DIR.
    pub body_files: String,
}

/// Per-body ground truth (JSON in each body file).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BodyTruth {
    /// Body index in the dataset.
    pub body_index: u32,
    /// `"train"` or `"test"`.
    pub split: String,
    /// Shape coefficients.
    pub shape: Vec<f32>,
    /// Pose parameters as the body source reports them.
    pub pose: serde_json::Value,
    /// Bed geometry (includes the head-section raise).
    pub bed: BedParams,
    /// Salient points in the world (`robot_base`) frame.
    pub salient_world: [[f32; 3]; 6],
    /// Floor, mattress and head-section planes in the world frame.
    pub planes_world: [Plane; 3],
    /// The nominal head pose the views rotate about.
    pub nominal_view: ViewParams,
}

/// Probe ground truth of a view with the robot arm.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProbeTruth {
    /// Probe tip pose in the world frame (4x4 row-major; z along the probe into the body).
    pub world_from_probe: [[f32; 4]; 4],
    /// Probe tip pose in the camera frame.
    pub camera_from_probe: [[f32; 4]; 4],
    /// Whether the arm reached the requested contact point.
    pub reached: bool,
}

/// Per-view ground truth (JSON before each view's pixels).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ViewTruth {
    /// View index within the body.
    pub view: u16,
    /// Seed of this view's noise stream.
    pub noise_seed: u64,
    /// Head pose parameters of this view.
    pub view_params: ViewParams,
    /// Camera extrinsics, 4x4 row-major.
    pub camera_from_world: [[f32; 4]; 4],
    /// Salient points in the camera frame (metres).
    pub salient_camera: [[f32; 3]; 6],
    /// Salient points projected to pixels (u, v); (−1, −1) if behind the camera.
    pub salient_pixels: [[f32; 2]; 6],
    /// Floor, mattress and head-section planes in the camera frame.
    pub planes_camera: [Plane; 3],
    /// Robot arm and probe, if present in this view.
    pub probe: Option<ProbeTruth>,
    /// Fraction of the body's visible pixels hidden by the arm (0 without it).
    pub occluded_fraction: f32,
    /// Body pixels visible in the clean render.
    pub body_pixels: u32,
}

/// Where a dataset's files live.
pub fn body_file(dir: &Path, index: u32) -> PathBuf {
    dir.join("bodies").join(format!("body_{index:05}.svd"))
}

/// Per-thread working memory of the generator.
pub struct Worker {
    renderer: Renderer,
    scratch: NoiseScratch,
    depth: Vec<u16>,
    label: Vec<u8>,
    part: Vec<u8>,
}

impl Worker {
    /// Buffers for `intrinsics`.
    pub fn new(intrinsics: Intrinsics) -> Self {
        Worker {
            renderer: Renderer::new(intrinsics),
            scratch: NoiseScratch::default(),
            depth: Vec::new(),
            label: Vec::new(),
            part: Vec::new(),
        }
    }
}

/// Default margin around the patient's bounding box in the stored crop: covers the paper's ±50 px·m probe offsets
/// (scaled by 1/depth, ≤ 40 px beyond 1.25 m) so every probe reads real bed or arm depth, not the crop border. Wider
/// probes need a wider margin (`dataset --crop-margin`).
pub const CROP_MARGIN_PX: u16 = 48;

/// Bounding box of the patient's pixels (label body) plus `margin`, clamped to the image: the region of interest
/// the trainers read. Bed, floor and arm inside it are kept; outside it nothing is stored.
pub fn crop_rect(label: &[u8], width: usize, height: usize, margin: usize) -> Rect {
    let (mut x0, mut y0, mut x1, mut y1) = (width, height, 0usize, 0usize);
    for (y, row) in label.chunks_exact(width).enumerate() {
        let mut any = false;
        for (x, &l) in row.iter().enumerate() {
            if l == Label::Body as u8 {
                x0 = x0.min(x);
                x1 = x1.max(x);
                any = true;
            }
        }
        if any {
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if x0 > x1 {
        return Rect {
            x0: 0,
            y0: 0,
            w: 0,
            h: 0,
        };
    }
    let (x0, y0) = (x0.saturating_sub(margin), y0.saturating_sub(margin));
    let (x1, y1) = ((x1 + margin).min(width - 1), (y1 + margin).min(height - 1));
    Rect {
        x0: x0 as u16,
        y0: y0 as u16,
        w: (x1 - x0 + 1) as u16,
        h: (y1 - y0 + 1) as u16,
    }
}

/// A random point on the front of the torso for the probe (see [`contact_at`]).
pub fn torso_contact(
    scene: &Scene,
    normals: &[[f32; 3]],
    rng: &mut ChaCha8Rng,
) -> (Vector3<f32>, Vector3<f32>) {
    let (u, v) = (rng.gen_range(0.25..0.75f32), rng.gen_range(0.1..0.9f32));
    contact_at(scene, normals, u, v)
}

/// The skin point at torso coordinates (u across from the left to the right side, v from shoulders to hips): the
/// blend of the salient points lifted onto the highest skin vertex within 4 cm (world xy); returns the contact point
/// (3 mm outside the skin) and the outward normal there.
pub fn contact_at(scene: &Scene, normals: &[[f32; 3]], u: f32, v: f32) -> (Vector3<f32>, Vector3<f32>) {
    let s = scene.salient_world.map(Vector3::from);
    let top = s[1].lerp(&s[2], u);
    let bottom = s[4].lerp(&s[5], u);
    let goal = top.lerp(&bottom, v);
    let mut best: Option<(usize, f32)> = None;
    for (i, p) in scene.body_vertices.iter().enumerate() {
        let (dx, dy) = (p[0] - goal.x, p[1] - goal.y);
        if dx * dx + dy * dy < 0.04 * 0.04 && best.is_none_or(|(_, z)| p[2] > z) {
            best = Some((i, p[2]));
        }
    }
    match best {
        Some((i, _)) => {
            let n = Vector3::from(normals[i]);
            let n = if n.norm() > 0.5 { n } else { Vector3::z() };
            (Vector3::from(scene.body_vertices[i]) + n * 0.003, n)
        }
        None => (goal + Vector3::new(0.0, 0.0, 0.15), Vector3::z()),
    }
}

/// Where the arm's shoulder is: on the robot beside the bed (0.25–0.45 m outside its near edge, 0.1–0.35 m above
/// the mattress, below the head), 0.3–0.7 m along the bed from `along_x` toward either end, so the arm reaches in
/// diagonally.
pub fn sample_shoulder(scene: &Scene, along_x: f32, rng: &mut ChaCha8Rng) -> Vector3<f32> {
    let b = &scene.bed;
    let side = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
    Vector3::new(
        along_x + side * rng.gen_range(0.3..0.7),
        b.near_edge_y - rng.gen_range(0.25..0.45),
        b.mattress_top + rng.gen_range(0.1..0.35),
    )
}

/// Where the elbow should bend: up, and away from the camera at `eye` (world), so the arm arches over the patient
/// instead of folding into the head's view.
pub fn elbow_hint(shoulder: Vector3<f32>, contact: Vector3<f32>, eye: Vector3<f32>) -> Vector3<f32> {
    let mid = (shoulder + contact) * 0.5;
    let to_eye = (eye - mid).normalize();
    Vector3::z() - to_eye * 1.2
}

/// Place the robot arm for a scene: shoulder from [`sample_shoulder`], probe on the torso at `contact`, elbow away
/// from the camera at `eye`.
pub fn place_arm(
    scene: &Scene,
    contact: Vector3<f32>,
    normal: Vector3<f32>,
    eye: Vector3<f32>,
    rng: &mut ChaCha8Rng,
) -> ArmState {
    let shoulder = sample_shoulder(scene, contact.x, rng);
    reach_tilted(shoulder, contact, normal, eye, rng)
}

/// The arm from `shoulder` with the probe tip at `tip`, the probe tilted up to ~15° off the surface `normal`, as a
/// sonographer holds it.
fn reach_tilted(
    shoulder: Vector3<f32>,
    tip: Vector3<f32>,
    normal: Vector3<f32>,
    eye: Vector3<f32>,
    rng: &mut ChaCha8Rng,
) -> ArmState {
    let tilt = Vector3::new(rng.gen_range(-0.25..0.25), rng.gen_range(-0.25..0.25), 0.0);
    ArmState::reach(
        shoulder,
        tip,
        -(normal + tilt).normalize(),
        elbow_hint(shoulder, tip, eye),
    )
}

/// How [`ArmPlacement::Sequence`] places the arm: half the time [`place_arm`]; otherwise as a tracking sequence with
/// a full occlusion holds it. The shoulder is one of the eight best of
/// [`crate::sequence::episodes::shoulders_for_full_occlusion`] (beside the bed near the head, so the arm crosses the
/// head's view above the patient's shoulders), and the probe is on the torso at `contact` or, one time in two,
/// lifted 5–45 cm off it toward the head, as on the way to the park pose and in it. [`place_arm`]'s arm where no
/// such shoulder reaches the torso.
pub fn place_arm_as_sequences(
    scene: &Scene,
    contact: Vector3<f32>,
    normal: Vector3<f32>,
    eye: Vector3<f32>,
    rng: &mut ChaCha8Rng,
) -> ArmState {
    if rng.gen_bool(0.5) {
        return place_arm(scene, contact, normal, eye, rng);
    }
    let shoulders = crate::sequence::episodes::shoulders_for_full_occlusion(scene, eye, rng.r#gen(), 8);
    let Some(&shoulder) = shoulders.get(rng.gen_range(0..shoulders.len().max(1))) else {
        return place_arm(scene, contact, normal, eye, rng);
    };
    let lift = if rng.gen_bool(0.5) {
        rng.gen_range(0.05..0.45)
    } else {
        0.0
    };
    let tip = contact + (eye - contact).normalize() * lift;
    reach_tilted(shoulder, tip, normal, eye, rng)
}

/// Salient points of the scene in the camera frame and in pixels.
pub fn project_salient(
    scene: &Scene,
    cfw: &Isometry3<f32>,
    k: &Intrinsics,
) -> ([[f32; 3]; 6], [[f32; 2]; 6]) {
    let cam = scene.salient_world.map(|p| {
        let q = cfw * Point3::from(p);
        [q.x, q.y, q.z]
    });
    // Behind the camera (never in these scenes) is (−1, −1): JSON has no NaN.
    let px = cam.map(|p| k.project(&p.into()).map_or([-1.0, -1.0], |uv| uv.coords.into()));
    (cam, px)
}

/// Generate body `index` of the dataset into `dir` (its file and, if asked, its preview).
#[allow(clippy::too_many_arguments)] // one call site; bundling these into a struct would only rename them
pub fn generate_body(
    source: &dyn BodySource,
    cfg: &DatasetConfig,
    index: u32,
    split: &str,
    dir: &Path,
    worker: &mut Worker,
    preview: bool,
    on_image: &(dyn Fn() + Sync),
) -> Result<()> {
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(cfg.seed, index as u64));
    let body: Patient = source
        .sample(&mut rng, cfg.rest)
        .with_context(|| format!("sampling body {index}"))?;
    let bed = BedParams::sample(&mut rng, body.head_raise_rad, body.hinge_y_m);
    let mut scene = Scene::new(&body.body, bed);
    let mut nominal = ViewParams::sample_nominal(&mut rng, scene.torso_centre());
    if cfg.view_distance_scale != 1.0 {
        nominal.height_above_mattress *= cfg.view_distance_scale;
        nominal.lateral_offset *= cfg.view_distance_scale;
    }
    let truth = BodyTruth {
        body_index: index,
        split: split.to_string(),
        shape: body.shape.clone(),
        pose: body.pose.clone(),
        bed,
        salient_world: scene.salient_world,
        planes_world: scene.planes_world(),
        nominal_view: nominal,
    };
    let path = body_file(dir, index);
    let file = std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
    let mut writer = BodyWriter::new(
        std::io::BufWriter::new(file),
        index,
        cfg.views,
        cfg.noise.level_scale(),
        &truth,
    )?;
    let normals = vertex_normals(&scene.body_vertices, &scene.body_triangles);
    let k = *worker.renderer.intrinsics();
    let (w, h) = (k.width as usize, k.height as usize);
    for view in 0..cfg.views {
        let vp = nominal.sample_view(&mut rng);
        let cfw = vp.camera_from_world(scene.midline_y(), bed.mattress_top);
        let with_arm = rng.gen_bool(cfg.occluder_fraction.clamp(0.0, 1.0) as f64);
        scene.arm = if with_arm {
            let (contact, normal) = torso_contact(&scene, &normals, &mut rng);
            let eye = cfw.inverse().translation.vector;
            Some(match cfg.arm_placement {
                ArmPlacement::Contact => place_arm(&scene, contact, normal, eye, &mut rng),
                ArmPlacement::Sequence => place_arm_as_sequences(&scene, contact, normal, eye, &mut rng),
            })
        } else {
            None
        };
        scene.render(&mut worker.renderer, &cfw, false);
        let body_pixels = worker.renderer.buffers().count_label(Label::Body);
        let crop = crop_rect(
            &worker.renderer.buffers().label,
            w,
            h,
            cfg.crop_margin_px as usize,
        );
        let mut probe = None;
        let mut occluded_fraction = 0.0;
        if let Some(arm) = &scene.arm {
            // Drawing the arm over the finished render keeps one pass and measures what it hides.
            worker.renderer.draw(&crate::scene::arm_draw(&arm.mesh), &cfw);
            let visible = worker.renderer.buffers().count_label(Label::Body);
            occluded_fraction = if body_pixels > 0 {
                1.0 - visible as f32 / body_pixels as f32
            } else {
                0.0
            };
            probe = Some(ProbeTruth {
                world_from_probe: matrix_rows(&arm.world_from_probe),
                camera_from_probe: matrix_rows(&(cfw * arm.world_from_probe)),
                reached: arm.reached,
            });
        }
        let noise_seed = mix_seed(mix_seed(cfg.seed, index as u64), 0x5EED_0000 + view as u64);
        let n = crop.w as usize * crop.h as usize;
        worker.depth.resize(n, 0);
        cfg.noise.apply_levels(
            worker.renderer.buffers(),
            &k,
            crop,
            noise_seed,
            &mut worker.scratch,
            &mut worker.depth,
        );
        worker.label.clear();
        worker.part.clear();
        let b = worker.renderer.buffers();
        for y in crop.y0 as usize..(crop.y0 + crop.h) as usize {
            let r = y * w + crop.x0 as usize..y * w + (crop.x0 + crop.w) as usize;
            worker.label.extend_from_slice(&b.label[r.clone()]);
            worker.part.extend_from_slice(&b.part[r]);
        }
        let (salient_camera, salient_pixels) = project_salient(&scene, &cfw, &k);
        let planes_camera = scene.planes_world().map(|p| p.transformed(&cfw));
        let vt = ViewTruth {
            view,
            noise_seed,
            view_params: vp,
            camera_from_world: matrix_rows(&cfw),
            salient_camera,
            salient_pixels,
            planes_camera,
            probe,
            occluded_fraction,
            body_pixels: body_pixels as u32,
        };
        writer.write_view(&vt, crop, &worker.depth, &worker.label, &worker.part)?;
        if preview && view == 0 {
            let scale = cfg.noise.level_scale();
            let depth_mm = worker
                .depth
                .iter()
                .map(|&l| KinectNoise::level_to_mm(scale, l))
                .collect();
            let rec = format::ViewRecord {
                truth: vt,
                crop,
                levels: worker.depth.clone(),
                depth_mm,
                label: worker.label.clone(),
                part: worker.part.clone(),
            };
            let img = preview::render_view(&rec, w, h);
            preview::write_rgb_png(
                &dir.join("previews").join(format!("body_{index:05}_view_00.png")),
                &img,
                w,
                h,
            )?;
        }
        on_image();
    }
    writer.finish()?;
    Ok(())
}

/// How many of `n` bodies go to the training split at `train_fraction`.
pub fn split_train_count(n: u32, train_fraction: f32) -> usize {
    (((n as f32) * train_fraction).round() as usize).min(n as usize)
}

/// Split body indices `0..n` 70/30 (by `train_fraction`) with a seeded shuffle; both lists sorted.
pub fn split_bodies(n: u32, train_fraction: f32, seed: u64) -> (Vec<u32>, Vec<u32>) {
    let mut idx: Vec<u32> = (0..n).collect();
    idx.shuffle(&mut ChaCha8Rng::seed_from_u64(mix_seed(seed, u64::MAX)));
    let n_train = split_train_count(n, train_fraction);
    let (mut train, mut test) = (idx[..n_train].to_vec(), idx[n_train..].to_vec());
    train.sort_unstable();
    test.sort_unstable();
    (train, test)
}

/// Generate a whole dataset into `dir` with rayon over bodies; `on_image` is called after every image.
pub fn generate(
    source: &dyn BodySource,
    cfg: &DatasetConfig,
    dir: &Path,
    on_image: &(dyn Fn() + Sync),
) -> Result<()> {
    ensure!(
        cfg.views > 0 && cfg.bodies > 0,
        "need at least one body and one view"
    );
    let n_train = split_train_count(cfg.bodies, cfg.train_fraction);
    ensure!(
        n_train > 0 && n_train < cfg.bodies as usize,
        "a train fraction of {} over {} bodies leaves the train or the test split empty",
        cfg.train_fraction,
        cfg.bodies
    );
    std::fs::create_dir_all(dir.join("bodies")).with_context(|| format!("creating {}", dir.display()))?;
    if cfg.previews > 0 {
        std::fs::create_dir_all(dir.join("previews"))?;
    }
    let k = Intrinsics::KINECT_V1;
    let (train, test) = split_bodies(cfg.bodies, cfg.train_fraction, cfg.seed);
    let manifest = Manifest {
        format: "supine-hvp".into(),
        version: format::VERSION,
        config: cfg.clone(),
        body_source: source.name(),
        intrinsics: [k.fx, k.fy, k.cx, k.cy, k.width as f32, k.height as f32],
        salient_names: SalientPoint::ALL.iter().map(|p| p.name().to_string()).collect(),
        labels: [
            Label::None,
            Label::Floor,
            Label::Bed,
            Label::Body,
            Label::Occluder,
        ]
        .iter()
        .map(|l| (*l as u8, format!("{l:?}").to_lowercase()))
        .collect(),
        part_names: source.part_names(),
        body_files: "bodies/body_{index:05}.svd".into(),
    };
    std::fs::write(dir.join("dataset.json"), serde_json::to_vec_pretty(&manifest)?)?;
    std::fs::write(
        dir.join("split.json"),
        serde_json::to_vec(&serde_json::json!({"train": train, "test": test}))?,
    )?;
    let mut is_test = vec![false; cfg.bodies as usize];
    for &t in &test {
        is_test[t as usize] = true;
    }
    (0..cfg.bodies).into_par_iter().try_for_each_init(
        || Worker::new(k),
        |worker, i| {
            let split = if is_test[i as usize] { "test" } else { "train" };
            generate_body(source, cfg, i, split, dir, worker, i < cfg.previews, on_image)
        },
    )
}

/// Reader of a generated dataset directory (what the trainers use).
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Directory.
    pub dir: PathBuf,
    /// `dataset.json`.
    pub manifest: Manifest,
    /// Training body indices.
    pub train: Vec<u32>,
    /// Test body indices.
    pub test: Vec<u32>,
}

impl Dataset {
    /// Open `dir`: reads and checks `dataset.json` and `split.json`.
    pub fn open(dir: &Path) -> Result<Dataset> {
        let m = dir.join("dataset.json");
        let manifest: Manifest =
            serde_json::from_slice(&std::fs::read(&m).with_context(|| format!("reading {}", m.display()))?)
                .with_context(|| format!("parsing {}", m.display()))?;
        ensure!(
            manifest.format == "supine-hvp",
            "{} is not a supine dataset manifest",
            m.display()
        );
        let s = dir.join("split.json");
        #[derive(serde::Deserialize)]
        struct Split {
            train: Vec<u32>,
            test: Vec<u32>,
        }
        let split: Split =
            serde_json::from_slice(&std::fs::read(&s).with_context(|| format!("reading {}", s.display()))?)
                .with_context(|| format!("parsing {}", s.display()))?;
        Ok(Dataset {
            dir: dir.to_path_buf(),
            manifest,
            train: split.train,
            test: split.test,
        })
    }

    /// Decode body `index`.
    pub fn read_body(&self, index: u32) -> Result<BodyRecord> {
        format::read_body_file(&body_file(&self.dir, index))
    }

    /// Decode every body of `split` (`"train"` or `"test"`), one at a time, calling `f` with each record.
    pub fn for_each_body(&self, split: &str, mut f: impl FnMut(BodyRecord) -> Result<()>) -> Result<()> {
        let ids = match split {
            "train" => &self.train,
            "test" => &self.test,
            other => anyhow::bail!("unknown split {other:?} (expected train or test)"),
        };
        for &i in ids {
            f(self.read_body(i)?)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::body::Mannequin;

    fn tiny(seed: u64) -> DatasetConfig {
        DatasetConfig {
            bodies: 3,
            views: 2,
            seed,
            occluder_fraction: 0.5,
            train_fraction: 0.7,
            previews: 1,
            ..DatasetConfig::default()
        }
    }

    fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
        let mut out = Vec::new();
        for sub in ["", "bodies", "previews"] {
            if !dir.join(sub).exists() {
                continue;
            }
            let mut names: Vec<_> = std::fs::read_dir(dir.join(sub))
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.is_file())
                .collect();
            names.sort();
            for p in names {
                out.push((
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
        out
    }

    #[test]
    fn same_seed_gives_identical_bytes_and_reader_round_trips() {
        let base = std::env::temp_dir().join(format!("supine-dataset-test-{}", std::process::id()));
        let (a, b, c) = (base.join("a"), base.join("b"), base.join("c"));
        generate(&Mannequin, &tiny(5), &a, &|| {}).unwrap();
        generate(&Mannequin, &tiny(5), &b, &|| {}).unwrap();
        generate(&Mannequin, &tiny(6), &c, &|| {}).unwrap();
        let (fa, fb, fc) = (files(&a), files(&b), files(&c));
        assert_eq!(fa.len(), 2 + 3 + 1);
        assert_eq!(fa, fb, "same seed, same bytes");
        assert_ne!(fa, fc, "another seed, other bytes");

        let ds = Dataset::open(&a).unwrap();
        assert_eq!(ds.train.len() + ds.test.len(), 3);
        assert_eq!(ds.train.len(), 2);
        let rec = ds.read_body(0).unwrap();
        assert_eq!(rec.views.len(), 2);
        for v in &rec.views {
            let n = v.crop.w as usize * v.crop.h as usize;
            assert!(n > 10_000, "crop holds the patient");
            assert_eq!((v.depth_mm.len(), v.label.len(), v.part.len()), (n, n, n));
            let body = v.label.iter().filter(|&&l| l == Label::Body as u8).count();
            assert!(body > 2000, "the patient is visible: {body} px");
            // Salient points project inside the image and their depth is close to the measured surface.
            for p in v.truth.salient_pixels {
                assert!(
                    p[0] > 0.0 && p[0] < 640.0 && p[1] > 0.0 && p[1] < 480.0,
                    "salient {p:?}"
                );
            }
            let full = v.full_depth(640, 480);
            assert_eq!(
                full.iter().filter(|&&d| d > 0).count(),
                v.depth_mm.iter().filter(|&&d| d > 0).count()
            );
        }
        // Write the decoded record again and read it back: the same record. (Pose values are JSON f64 and
        // serde_json's default float parser may move their last bit, so they compare to 1e-12.)
        let mut buf = Vec::new();
        let mut w =
            BodyWriter::new(&mut buf, 0, rec.views.len() as u16, rec.level_scale, &rec.truth).unwrap();
        for v in &rec.views {
            w.write_view(&v.truth, v.crop, &v.levels, &v.label, &v.part)
                .unwrap();
        }
        w.finish().unwrap();
        let again = format::decode_body(&buf).unwrap();
        assert_eq!(again.views, rec.views, "pixels and view truth round-trip exactly");
        assert!(json_close(&again.truth.pose, &rec.truth.pose));
        let strip = |t: &BodyTruth| BodyTruth {
            pose: serde_json::Value::Null,
            ..t.clone()
        };
        assert_eq!(strip(&again.truth), strip(&rec.truth));
        // Corruption is an error, not a panic.
        let mut bad = buf.clone();
        let last = bad.len() - 10;
        bad[last] ^= 0xFF;
        assert!(format::decode_body(&bad).is_err());
        assert!(format::decode_body(&buf[..buf.len() / 2]).is_err());
        std::fs::remove_dir_all(&base).ok();
    }

    fn json_close(a: &serde_json::Value, b: &serde_json::Value) -> bool {
        use serde_json::Value::*;
        match (a, b) {
            (Number(x), Number(y)) => {
                let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                (x - y).abs() <= 1e-12 * x.abs().max(1.0)
            }
            (Array(x), Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(p, q)| json_close(p, q)),
            (Object(x), Object(y)) => {
                x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| json_close(v, w)))
            }
            _ => a == b,
        }
    }

    #[test]
    fn body_model_dataset_is_deterministic_and_shows_the_patient() {
        // The committed statistical body model (models/artifacts/body.sbm) with the bed-pose generator.
        let source =
            crate::scene::model_body::ModelBodySource::load(None).expect("committed body model artifact");
        let base = std::env::temp_dir().join(format!("supine-dataset-model-{}", std::process::id()));
        let cfg = DatasetConfig {
            bodies: 2,
            views: 2,
            previews: 0,
            ..tiny(9)
        };
        generate(&source, &cfg, &base.join("a"), &|| {}).unwrap();
        generate(&source, &cfg, &base.join("b"), &|| {}).unwrap();
        assert_eq!(files(&base.join("a")), files(&base.join("b")));
        let ds = Dataset::open(&base.join("a")).unwrap();
        assert_eq!(ds.manifest.body_source, "makehuman-pca");
        for i in 0..2 {
            let rec = ds.read_body(i).unwrap();
            assert_eq!(rec.truth.shape.len(), 20, "20 PCA coefficients");
            for v in &rec.views {
                let body = v.label.iter().filter(|&&l| l == Label::Body as u8).count();
                assert!(body > 5000, "body {i} view {}: {body} body pixels", v.truth.view);
                let parts: std::collections::BTreeSet<u8> = v
                    .part
                    .iter()
                    .zip(&v.label)
                    .filter(|(_, l)| **l == Label::Body as u8)
                    .map(|(p, _)| *p)
                    .collect();
                assert!(parts.len() >= 5, "several body parts visible: {parts:?}");
            }
        }
        std::fs::remove_dir_all(&base).ok();
    }

    #[test]
    fn a_trunk_rest_moves_only_the_patients_lying_on_a_hand_and_is_recorded() {
        let source =
            crate::scene::model_body::ModelBodySource::load(None).expect("committed body model artifact");
        let base = std::env::temp_dir().join(format!("supine-dataset-rest-{}", std::process::id()));
        let cfg = DatasetConfig {
            bodies: 9,
            views: 1,
            previews: 0,
            ..tiny(2)
        };
        let trunk = DatasetConfig {
            rest: Rest::Trunk,
            ..cfg.clone()
        };
        generate(&source, &cfg, &base.join("low"), &|| {}).unwrap();
        generate(&source, &trunk, &base.join("trunk"), &|| {}).unwrap();
        let body = |dir: &str, i| std::fs::read(body_file(&base.join(dir), i)).unwrap();
        let moved = (0..cfg.bodies)
            .filter(|&i| body("low", i) != body("trunk", i))
            .count();
        // One patient in seven to nine lies on a hand; the others rest on the back either way.
        assert!((1..cfg.bodies as usize).contains(&moved), "{moved} of 9 moved");
        let manifest = |dir: &str| std::fs::read_to_string(base.join(dir).join("dataset.json")).unwrap();
        assert!(manifest("trunk").contains("\"rest\": \"trunk\""));
        // Datasets from before the option have no `rest`: they read as the lowest point they were made with.
        assert!(!manifest("low").contains("\"rest\""));
        let old: Manifest = serde_json::from_str(&manifest("low")).unwrap();
        assert_eq!(old.config.rest, Rest::LowestPoint);
        std::fs::remove_dir_all(&base).ok();
    }

    /// sha256 of the body files of a dataset made with `cfg` (written to a temporary directory, then removed), and
    /// its manifest.
    fn body_hashes(cfg: &DatasetConfig, name: &str) -> (Vec<String>, String) {
        use sha2::Digest as _;
        let dir = std::env::temp_dir().join(format!("supine-dataset-{name}-{}", std::process::id()));
        generate(&Mannequin, cfg, &dir, &|| {}).unwrap();
        let hashes = (0..cfg.bodies)
            .map(|i| {
                let bytes = std::fs::read(body_file(&dir, i)).unwrap();
                sha2::Sha256::digest(&bytes)
                    .iter()
                    .map(|b| format!("{b:02x}"))
                    .collect()
            })
            .collect();
        let manifest = std::fs::read_to_string(dir.join("dataset.json")).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        (hashes, manifest)
    }

    #[test]
    fn a_wider_crop_margin_keeps_more_of_the_same_scene() {
        // Whole frames (`--crop-margin 640`): the same scene, views and truth, every label a narrow crop holds at
        // the same place. The noise is drawn over the stored region, so its realisation (not its model) differs.
        // The manifest records a margin other than the default.
        let dir =
            |name: &str| std::env::temp_dir().join(format!("supine-crop-{name}-{}", std::process::id()));
        let (narrow, wide) = (dir("narrow"), dir("wide"));
        // The mannequin fills most of the frame: a narrow margin shows the difference.
        let cfg = DatasetConfig {
            crop_margin_px: 4,
            ..tiny(9)
        };
        generate(&Mannequin, &cfg, &narrow, &|| {}).unwrap();
        generate(
            &Mannequin,
            &DatasetConfig {
                crop_margin_px: 640,
                ..cfg.clone()
            },
            &wide,
            &|| {},
        )
        .unwrap();
        let manifest = |d: &Path| std::fs::read_to_string(d.join("dataset.json")).unwrap();
        assert!(manifest(&narrow).contains("\"crop_margin_px\": 4"));
        assert!(manifest(&wide).contains("\"crop_margin_px\": 640"));
        for b in 0..cfg.bodies {
            let n = format::read_body_file(&body_file(&narrow, b)).unwrap();
            let w = format::read_body_file(&body_file(&wide, b)).unwrap();
            assert_eq!(n.truth.salient_world, w.truth.salient_world);
            for (vn, vw) in n.views.iter().zip(&w.views) {
                assert_eq!(vn.truth.salient_pixels, vw.truth.salient_pixels);
                assert_eq!((vw.crop.x0, vw.crop.y0, vw.crop.w, vw.crop.h), (0, 0, 640, 480));
                let c = vn.crop;
                assert!(
                    c.w < 640 || c.h < 480,
                    "the narrow crop is smaller than the frame"
                );
                for y in 0..c.h as usize {
                    for x in 0..c.w as usize {
                        let wide_at = (c.y0 as usize + y) * 640 + c.x0 as usize + x;
                        assert_eq!(vn.label[y * c.w as usize + x], vw.label[wide_at]);
                    }
                }
                assert_eq!(vw.label.len(), 640 * 480);
            }
        }
        std::fs::remove_dir_all(&narrow).ok();
        std::fs::remove_dir_all(&wide).ok();
    }

    #[test]
    fn legacy_noise_reproduces_datasets_made_before_the_new_effects() {
        // sha256 of the body files of `supine-models dataset --bodies 3 --views 2 --seed 5 --body mannequin
        // --previews 1`, generated by the code before blobs, edges, registration and temporal correlation existed
        // (commit e4e141a). If a deliberate change to the scene or renderer moves these bytes, regenerate them
        // with `--legacy-noise` at that change and say so in its commit.
        let cfg = DatasetConfig {
            noise: KinectNoise::LEGACY,
            occluder_fraction: 0.3,
            previews: 1,
            ..tiny(5)
        };
        let (hashes, manifest) = body_hashes(&cfg, "legacy");
        assert_eq!(
            hashes,
            [
                "6bd6ae4410547bde4ce93f875d5509cdbaf42300da3b9f1977e9f16213e5aab9",
                "626dfb23e911181ba25ca269a7619fa3396ecf5cd2fd42f90f5be44bf4a58e6a",
                "34d437f63bdd38139fcdc3a93bc6793b630207eab620dd9adb1f29d08ea14ae2",
            ]
        );
        assert!(
            !manifest.contains("blobs")
                && !manifest.contains("view_distance_scale")
                && !manifest.contains("crop_margin_px")
        );
    }

    #[test]
    fn the_default_before_the_mixed_ramp_reproduces_its_datasets() {
        // The default noise of commit 3852201 (independent mixed pixels fading out by 0.08 /m), as a manifest made
        // then spells it: its datasets stay byte-identical with the ramp in the code. The same test run on 3852201's
        // own tree gives these hashes (and that commit's binary made a 72-image dataset equal file for file).
        let before: KinectNoise = serde_json::from_str(
            r#"{"disparity_focal_px": 575.8, "baseline_m": 0.075, "subpixel_steps": 8.0, "axial_const_m": 0.0012,
            "axial_quad_m": 0.0019, "lateral_px": 0.8, "max_incidence_rad": 1.4835298, "min_m": 0.5, "max_m": 4.5,
            "projector_shadow": true, "blobs": {"cell_px": 32, "rate": 0.04, "grazing_rate": 0.3,
            "min_radius_px": 10.0, "max_radius_px": 26.0}, "edges": {"fatten_px": 1, "min_step_m": 0.05,
            "hole_px": 3, "hole_min_inv_m": 0.1, "shadow_hole_px": 3, "shadow_hole_min_width_px": 4, "mixed_px": 2,
            "mixed": 1.0, "mixed_max_inv_m": 0.08}, "jitter_keeps_valid": true, "temporal_correlation": 0.5,
            "shadow_at_pixel": true, "min_shadow_px": 2}"#,
        )
        .unwrap();
        assert!(!before.edges.unwrap().mixed_ramp);
        let (hashes, manifest) = body_hashes(
            &DatasetConfig {
                noise: before,
                ..tiny(5)
            },
            "before-ramp",
        );
        assert_eq!(
            hashes,
            [
                "3c4683b3cb0a00c29106e10877aa43b2d04af860de5884570c1ab63fb29816ff",
                "70e605a0d46105c7c99c38b7e010e6c9565dcbbf7582be983f9765ff8d4f6e1b",
                "695c5c30888899180c7e30f389d0d153634b1a3325f3a54ff6163aa1ceab3fab",
            ]
        );
        assert!(!manifest.contains("mixed_ramp"));
    }

    #[test]
    fn the_shape_models_noise_file_reproduces_its_datasets() {
        // `docs/noise-shape-model.json` is the default noise of commit 9028c7c, on whose datasets the committed
        // shape model was trained (`docs/shape-eval.md`, "Reproduce"). These are the body files of `supine-models
        // dataset --bodies 3 --views 2 --seed 5 --body mannequin --previews 1 --occluder-fraction 0.5` made by that
        // commit's binary; today's binary with `--noise docs/noise-shape-model.json` gives the same bytes.
        let noise: KinectNoise =
            serde_json::from_str(include_str!("../../../docs/noise-shape-model.json")).unwrap();
        let (hashes, _) = body_hashes(&DatasetConfig { noise, ..tiny(5) }, "shape-model-noise");
        assert_eq!(
            hashes,
            [
                "8b1a4b134ff899841268e2c81b149f656cf0e0be31a0d2a59efb9fcb836faf80",
                "0cb4dfb38f943cb31e4608252c65a349f2990a956418b7ea4d5f905017e42d86",
                "70ab6ab8414ec3dfaa2bc749e942a3df53b16a3b5ab1297409906c551d28cef4",
            ]
        );
    }

    #[test]
    fn sequence_placement_puts_half_the_arms_where_the_sequences_hold_them() {
        // Half the arms as `place_arm` (shoulder beside the bed 0.3-0.7 m along it from the contact, low; the probe
        // on the torso); the others from a full-occlusion shoulder (within 0.5 m of the head along the bed), half of
        // those with the probe lifted 5-45 cm toward the head.
        let (scene, cfw, mut rng) = crate::scene::mannequin_scene(4);
        let bed = scene.bed;
        let eye = cfw.inverse().translation.vector;
        let normals = vertex_normals(&scene.body_vertices, &scene.body_triangles);
        let (mut near_head, mut lifted, mut reached) = (0, 0, 0);
        for _ in 0..200 {
            let (contact, normal) = torso_contact(&scene, &normals, &mut rng);
            let arm = place_arm_as_sequences(&scene, contact, normal, eye, &mut rng);
            let s = Vector3::from(arm.shoulder);
            let usual = (0.3 - 1e-4..=0.7 + 1e-4).contains(&(s.x - contact.x).abs())
                && (bed.mattress_top + 0.1 - 1e-4..=bed.mattress_top + 0.35 + 1e-4).contains(&s.z);
            if usual {
                continue;
            }
            // The mannequin's usual arms often fall short of the torso; the near-head shoulders reach the sweep.
            near_head += 1;
            assert!((s.x - eye.x).abs() <= 0.5 + 1e-4, "shoulder {s:?}, head {eye:?}");
            if !arm.reached {
                continue;
            }
            reached += 1;
            let off = arm.world_from_probe.translation.vector - contact;
            if off.norm() > 0.01 {
                lifted += 1;
                assert!(
                    (0.05 - 1e-3..0.45 + 1e-3).contains(&off.norm()),
                    "lift {}",
                    off.norm()
                );
                assert!(
                    off.normalize().dot(&(eye - contact).normalize()) > 0.999,
                    "lifted toward the head"
                );
            }
        }
        assert!(
            (60..140).contains(&near_head),
            "{near_head} of 200 shoulders outside the usual ones"
        );
        assert!(
            reached * 10 >= near_head * 9,
            "{reached} of {near_head} near-head arms reach"
        );
        assert!(
            (reached / 4..reached * 3 / 4).contains(&lifted),
            "{lifted} of {reached} lifted"
        );
    }

    #[test]
    fn split_is_seventy_thirty_and_disjoint() {
        let (train, test) = split_bodies(1000, 0.7, 3);
        assert_eq!((train.len(), test.len()), (700, 300));
        assert!(train.iter().all(|t| test.binary_search(t).is_err()));
    }
}
