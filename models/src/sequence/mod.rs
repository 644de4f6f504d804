//! 30 Hz tracking sequences: one patient on the bed, seen by a static robot head, breathing (chest and belly rise
//! `breathing_amplitude_m` at `breathing_hz`), moving slowly (torso drift and roll, arms blending between two bed
//! sub-poses) and, with the occluder, the robot arm sweeping the probe over the torso (hips → shoulders and back),
//! hiding up to about half of it.
//!
//! With `--full-occlusion` the arm also parks between the head and the torso for about 1 s, and with `--motion` the
//! patient rolls or shifts ([`episodes`]; their frame ranges go into `sequence.json`).
//!
//! Output in `DIR`: `sequence.oni` (OpenNI2 recording through `supine_drivers::oni::OniWriter`, 16zT like OpenNI's
//! Recorder), `truth.jsonl` (one [`FrameTruth`] per frame, with the true probe mapping where the arm is present),
//! `torso.bin` (the true posed torso surface per frame, [`torso_truth`]), `arm.cobs` when the arm is present (its
//! states as the controller would send them, [`arm_stream`]) and `sequence.json` ([`SequenceMeta`], with the true
//! `robot_base_from_camera`).
//!
//! Cost per frame: one LBS (body source), one render, a second draw of the arm to measure occlusion, full-frame
//! noise, one 16zT encode: ~20–40 ms on one core; the torso truth adds 10 kB written and one nearest-point query.
//! Frames are produced in order and streamed to disk.

pub mod arm_stream;
pub mod calibration;
pub mod cli;
pub mod episodes;
pub mod torso_truth;

use crate::body::PosedBody;
use crate::dataset::{contact_at, mix_seed, project_salient};
use crate::render::effects::TemporalState;
use crate::render::noise::{KinectNoise, NoiseScratch, Rect};
use crate::render::{Label, Renderer};
use crate::scene::body::BodySource;
use crate::scene::shapes::vertex_normals;
use crate::scene::{BedParams, Scene, ViewParams, matrix_rows};
use anyhow::{Context, Result, ensure};
use calibration::Extrinsic;
use episodes::{ArmPhase, ArmTarget, EpisodeFrames, Episodes, MotionKind};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use std::io::Write;
use std::path::Path;
use supine_core::camera::Intrinsics;
use supine_core::geometry::Plane;
use supine_drivers::oni::{Codec, OniWriter};
use torso_truth::{ProbeTruth, SurfaceQuery, TorsoSelection, TorsoWriter};

/// The condition on the arm's sweep: it hides at most half the torso (`sequence --sweep-max-occluded`'s
/// default; `eval tracking` splits its figures by it).
pub const SWEEP_MAX_OCCLUDED: f32 = 0.5;

/// Parameters of a sequence.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SequenceConfig {
    /// Number of frames.
    pub frames: u32,
    /// Seed.
    pub seed: u64,
    /// Frame rate, Hz.
    pub fps: f32,
    /// Whether the robot arm sweeps over the torso.
    pub occluder: bool,
    /// Peak rise of the chest/belly front, metres.
    pub breathing_amplitude_m: f32,
    /// Breathing rate, Hz.
    pub breathing_hz: f32,
    /// Seconds for one probe sweep hips → shoulders → hips.
    pub sweep_period_s: f32,
    /// Noise model.
    pub noise: KinectNoise,
    /// Whether the arm parks over the whole torso for a while (the full-occlusion episode).
    #[serde(default)]
    pub full_occlusion: bool,
    /// The patient's motion episode, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<MotionKind>,
    /// Lengths of the episodes.
    #[serde(default)]
    pub episode_frames: EpisodeFrames,
    /// The arm's sweep hides at most this share of the torso (checked on the first frame's body at the sweep's
    /// extremes; the robot's shoulder is moved until it holds); `None`: no check, the shoulder of earlier versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sweep_max_occluded: Option<f32>,
    /// Whether that share counts the torso the arm's projector shadow hides as well as what it covers (what the
    /// sensor loses; `false` in files of earlier versions, which counted only what it covers).
    #[serde(default)]
    pub sweep_limit_counts_shadow: bool,
}

impl SequenceConfig {
    /// Defaults: 30 Hz, 7 mm at 0.25 Hz breathing, a 10 s sweep, the default noise.
    pub fn new(frames: u32, seed: u64, occluder: bool) -> Self {
        SequenceConfig {
            frames,
            seed,
            fps: 30.0,
            occluder,
            breathing_amplitude_m: 0.007,
            breathing_hz: 0.25,
            sweep_period_s: 10.0,
            noise: KinectNoise::default(),
            full_occlusion: false,
            motion: None,
            episode_frames: EpisodeFrames::default(),
            sweep_max_occluded: None,
            sweep_limit_counts_shadow: true,
        }
    }
}

/// `sequence.json`'s `torso_surface`: where the true torso surface is and its size.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TorsoSurfaceMeta {
    /// File name, relative to the sequence directory (layout in [`torso_truth`]).
    pub file: String,
    /// Vertices per frame.
    pub vertices: u32,
    /// Triangles.
    pub triangles: u32,
    /// Which vertices: `torso_subset` (the body model's) or `torso_parts_facing_up` (sources without a subset).
    pub selection: String,
}

/// `DIR/sequence.json`: what is constant over the sequence.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SequenceMeta {
    /// Generation parameters.
    pub config: SequenceConfig,
    /// Body source name.
    pub body_source: String,
    /// Shape coefficients of the patient.
    pub shape: Vec<f32>,
    /// Camera intrinsics (fx, fy, cx, cy, width, height).
    pub intrinsics: [f32; 6],
    /// Camera extrinsics (static head), 4x4 row-major.
    pub camera_from_world: [[f32; 4]; 4],
    /// Head pose parameters.
    pub view: ViewParams,
    /// Bed geometry.
    pub bed: BedParams,
    /// Floor, mattress and head-section planes in the camera frame.
    pub planes_camera: [Plane; 3],
    /// Calibration sequences (`--calibration`): the true extrinsic, the nominal guess, the poses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<calibration::CalibrationMeta>,
    /// The full-occlusion and motion episodes (frame ranges).
    #[serde(default)]
    pub episodes: Episodes,
    /// The true extrinsic of the head (`robot_base` is the scene's world frame), tracking sequences.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot_base_from_camera: Option<Extrinsic>,
    /// The arm states beside the recording, when the arm is present.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arm: Option<arm_stream::ArmStream>,
    /// The true torso surface per frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub torso_surface: Option<TorsoSurfaceMeta>,
}

/// Ground truth of one frame (`truth.jsonl`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameTruth {
    /// Frame index from 0 (the .oni frame id is this + 1).
    pub frame: u32,
    /// Capture time, µs from the first frame (the .oni timestamp).
    pub time_us: u64,
    /// Salient points in the camera frame.
    pub salient_camera: [[f32; 3]; 6],
    /// Salient points in the world (`robot_base`) frame.
    pub salient_world: [[f32; 3]; 6],
    /// Salient points in pixels; (−1, −1) if behind the camera.
    pub salient_pixels: [[f32; 2]; 6],
    /// Torso pose (origin at the hip centre, y toward the shoulders' centre, x the patient's left, z out of the
    /// chest) in the camera frame, 4x4 row-major.
    pub camera_from_torso: [[f32; 4]; 4],
    /// Probe tip pose in the camera frame, when the arm is present.
    pub camera_from_probe: Option<[[f32; 4]; 4]>,
    /// Probe tip pose in the world frame, when the arm is present.
    pub world_from_probe: Option<[[f32; 4]; 4]>,
    /// Fraction of visible torso pixels (chest, abdomen, pelvis) hidden by the arm.
    pub torso_occluded_fraction: f32,
    /// Fraction of all visible body pixels hidden by the arm.
    pub body_occluded_fraction: f32,
    /// Fraction of the torso pixels the projector lights without the arm that the arm hides from the sensor: in
    /// front of them or casting the projector's shadow over them (absent in files of earlier versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub torso_unseen_fraction: Option<f32>,
    /// Current breathing rise of the chest front, mm.
    pub breathing_mm: f32,
    /// Arm-motion blend parameter (0..1) of the body pose.
    pub arm_blend: f32,
    /// The true probe mapping on the true torso surface, when the arm is present.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_truth: Option<ProbeTruth>,
}

/// Summary of a generated sequence.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SequenceSummary {
    /// Frames written.
    pub frames: u32,
    /// Mean torso occluded fraction over frames.
    pub torso_occluded_mean: f32,
    /// Largest torso occluded fraction.
    pub torso_occluded_max: f32,
    /// Frames per second of generation.
    pub frames_per_second: f32,
    /// The episodes as generated (with the measured occlusion of the park).
    pub episodes: Episodes,
    /// With `sweep_max_occluded`: the largest share of the torso the sweep hides on the first frame's body.
    pub sweep_occluded_planned: Option<f32>,
}

/// Candidate shoulders tried per source when the sweep's occlusion is limited.
const SHOULDER_CANDIDATES: usize = 12;

/// Torso pixels of the render the projector lights (what the sensor can return depth for); `unlit` is scratch.
fn lit_torso_pixels(
    r: &Renderer,
    noise: &KinectNoise,
    k: &Intrinsics,
    is_torso: &dyn Fn(u8) -> bool,
    unlit: &mut Vec<bool>,
) -> usize {
    let b = r.buffers();
    noise.mark_unlit(b, k, 0..b.height, unlit);
    b.label
        .iter()
        .zip(&b.part)
        .zip(unlit.iter())
        .filter(|((l, p), u)| **l == Label::Body as u8 && is_torso(**p) && !**u)
        .count()
}

/// `1 − after/before` (0 when nothing was there before).
fn hidden_share(before: usize, after: usize) -> f32 {
    if before > 0 {
        1.0 - after as f32 / before as f32
    } else {
        0.0
    }
}

/// Torso and whole-body pixels in the renderer's last image.
fn body_pixels(r: &Renderer, is_torso: &dyn Fn(u8) -> bool) -> (usize, usize) {
    let b = r.buffers();
    let mut torso = 0usize;
    let mut all = 0usize;
    for (l, p) in b.label.iter().zip(&b.part) {
        if *l == Label::Body as u8 {
            all += 1;
            torso += is_torso(*p) as usize;
        }
    }
    (torso, all)
}

/// The arm's target on the sweep at torso coordinates (`u` across, `v` from shoulders to hips): the probe on the
/// skin, along its normal, the elbow away from the camera.
fn sweep_target(
    scene: &Scene,
    normals: &[[f32; 3]],
    shoulder: Vector3<f32>,
    eye: Vector3<f32>,
    u: f32,
    v: f32,
) -> ArmTarget {
    let (contact, normal) = contact_at(scene, normals, u, v);
    ArmTarget {
        tip: contact,
        axis: -normal,
        hint: crate::dataset::elbow_hint(shoulder, contact, eye),
    }
}

/// The first of `candidates` whose arm, at the sweep's extremes (hips to shoulders, both sides of the wobble), hides
/// at most `limit` of the torso seen from `camera_from_world`, with the share it hides at most; when none does, the
/// one that hides least.
fn shoulder_within(
    scene: &Scene,
    camera_from_world: &Isometry3<f32>,
    renderer: &mut Renderer,
    is_torso: &dyn Fn(u8) -> bool,
    candidates: &[Vector3<f32>],
    limit: f32,
    shadow: Option<(&KinectNoise, &Intrinsics)>,
) -> (Vector3<f32>, f32) {
    let eye = camera_from_world.inverse().translation.vector;
    let mut unlit = Vec::new();
    let mut torso = |r: &Renderer| match shadow {
        Some((noise, k)) => lit_torso_pixels(r, noise, k, is_torso, &mut unlit),
        None => body_pixels(r, is_torso).0,
    };
    scene.render(renderer, camera_from_world, false);
    let torso0 = torso(renderer);
    let normals = vertex_normals(&scene.body_vertices, &scene.body_triangles);
    let mut best = (candidates[0], f32::INFINITY);
    for &shoulder in candidates {
        let mut worst = 0.0f32;
        for v in [0.9, 0.65, 0.4, 0.15] {
            for u in [0.35, 0.65] {
                let arm = sweep_target(scene, &normals, shoulder, eye, u, v).reach(shoulder);
                scene.render(renderer, camera_from_world, false);
                renderer.draw(&crate::scene::arm_draw(&arm.mesh), camera_from_world);
                worst = worst.max(hidden_share(torso0, torso(renderer)));
            }
        }
        if worst <= limit {
            return (shoulder, worst);
        }
        if worst < best.1 {
            best = (shoulder, worst);
        }
    }
    best
}

/// Torso frame from the salient points (core's [`supine_core::torso::a_from_torso`]): origin at the hip centre, y
/// toward the shoulder centre, x the patient's left; identity for degenerate points.
pub fn torso_pose(salient: &[[f32; 3]; 6]) -> Isometry3<f32> {
    supine_core::torso::a_from_torso(&salient.map(Point3::from)).unwrap_or_else(Isometry3::identity)
}

/// Lift the front of the chest and belly by `rise` metres along the skin normal (back and limbs stay), weighted by a
/// smooth window between hips and shoulders and by how much the skin faces out of the chest. The belly point moves
/// with the skin under it.
pub fn breathe(body: &mut PosedBody<'_>, torso_parts: &[u8], rise: f32) {
    if rise == 0.0 {
        return;
    }
    let t = torso_pose(&body.salient_points);
    let up = t.rotation * Vector3::z();
    let axis = t.rotation * Vector3::y();
    let len = ((Vector3::from(body.salient_points[1]) + Vector3::from(body.salient_points[2])) * 0.5
        - t.translation.vector)
        .norm();
    let normals = vertex_normals(&body.vertices, &body.triangles);
    let weight = |p: Vector3<f32>, n: Vector3<f32>| {
        let s = (p - t.translation.vector).dot(&axis) / len; // 0 at the hips, 1 at the shoulders
        let window = if (0.0..=1.05).contains(&s) {
            (std::f32::consts::PI * (s / 1.05)).sin()
        } else {
            0.0
        };
        window * n.dot(&up).max(0.0)
    };
    for (i, v) in body.vertices.iter_mut().enumerate() {
        if torso_parts.contains(&body.part_of_vertex[i]) {
            let n = Vector3::from(normals[i]);
            let p = Vector3::from(*v);
            *v = (p + n * (rise * weight(p, n))).into();
        }
    }
    let belly = Vector3::from(body.salient_points[3]);
    body.salient_points[3] = (belly + up * (rise * weight(belly, up))).into();
}

/// Generate a sequence into `dir`; `on_frame` is called after each frame with its index and the noisy depth image
/// written to the .oni (the ground truth a replay must reproduce pixel for pixel). A generation that fails leaves
/// no half-written sequence behind ([`remove_partial`]).
pub fn generate(
    source: &dyn BodySource,
    cfg: &SequenceConfig,
    dir: &Path,
    on_frame: &mut dyn FnMut(u32, &[u16]),
) -> Result<SequenceSummary> {
    ensure!(cfg.frames > 0, "need at least one frame");
    into_dir(dir, || generate_into(source, cfg, dir, on_frame))
}

/// Run `write` into `dir` (created when missing); when it fails, remove what it wrote ([`remove_partial`]).
pub(crate) fn into_dir<T>(dir: &Path, write: impl FnOnce() -> Result<T>) -> Result<T> {
    let created = !dir.exists();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    write().map_err(|e| {
        remove_partial(dir, created);
        e.context(format!(
            "generating {} (its partial output removed)",
            dir.display()
        ))
    })
}

/// The files a sequence's generation (tracking or calibration) writes into its directory, besides the
/// `preview_*.png`.
const OUTPUTS: [&str; 5] = [
    "sequence.oni",
    "truth.jsonl",
    torso_truth::FILE_NAME,
    arm_stream::FILE_NAME,
    "sequence.json",
];

/// Remove what a failed generation left in `dir`: the directory when the generation created it, else the files a
/// generation writes (a directory of other files keeps them). Frames written before the failure would otherwise
/// read as a sequence cut short, or beside an earlier `sequence.json`, as that one's sequence.
fn remove_partial(dir: &Path, created: bool) {
    if created {
        let _ = std::fs::remove_dir_all(dir);
        return;
    }
    for name in OUTPUTS {
        let _ = std::fs::remove_file(dir.join(name));
    }
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with("preview_") && name.ends_with(".png") {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

fn generate_into(
    source: &dyn BodySource,
    cfg: &SequenceConfig,
    dir: &Path,
    on_frame: &mut dyn FnMut(u32, &[u16]),
) -> Result<SequenceSummary> {
    let started = std::time::Instant::now();
    let k = Intrinsics::KINECT_V1;
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(cfg.seed, 0x5E0));
    let (shape_seed, pose_a, pose_b) = (rng.r#gen::<u64>(), rng.r#gen::<u64>(), rng.r#gen::<u64>());
    let first = source.sample_motion(shape_seed, pose_a, pose_b, 0.0)?;
    let torso_parts: Vec<u8> = first
        .part_names
        .iter()
        .enumerate()
        .filter(|(_, n)| matches!(n.as_str(), "chest" | "abdomen" | "belly" | "pelvis"))
        .map(|(i, _)| i as u8)
        .collect();
    let bed = BedParams::sample(&mut rng, first.head_raise_rad, first.hinge_y_m);
    let scene0 = Scene::new(&first.body, bed);
    let view = ViewParams::sample_nominal(&mut rng, scene0.torso_centre()).sample_view(&mut rng);
    let cfw = view.camera_from_world(scene0.midline_y(), bed.mattress_top);
    let eye = cfw.inverse().translation.vector;
    let usual_shoulder = crate::dataset::sample_shoulder(&scene0, scene0.torso_centre()[0], &mut rng);
    let is_torso = |p: u8| torso_parts.contains(&p);
    let mut renderer = Renderer::new(k);
    let (arm_shoulder, sweep_occluded_planned) = match (cfg.occluder, cfg.sweep_max_occluded) {
        (true, Some(limit)) => {
            let shadow = cfg.sweep_limit_counts_shadow.then_some((&cfg.noise, &k));
            let mut candidates = if cfg.full_occlusion {
                episodes::shoulders_for_full_occlusion(&scene0, eye, cfg.seed, SHOULDER_CANDIDATES)
            } else {
                Vec::new()
            };
            candidates.push(usual_shoulder);
            let mut extra = ChaCha8Rng::seed_from_u64(mix_seed(cfg.seed, 0x541));
            for _ in 0..SHOULDER_CANDIDATES {
                candidates.push(crate::dataset::sample_shoulder(
                    &scene0,
                    scene0.torso_centre()[0],
                    &mut extra,
                ));
            }
            let (s, occluded) = shoulder_within(
                &scene0,
                &cfw,
                &mut renderer,
                &is_torso,
                &candidates,
                limit,
                shadow,
            );
            (s, Some(occluded))
        }
        _ if cfg.full_occlusion => (
            episodes::shoulder_for_full_occlusion(&scene0, eye, cfg.seed).unwrap_or(usual_shoulder),
            None,
        ),
        _ => (usual_shoulder, None),
    };
    let tau = std::f32::consts::TAU;
    let drift_phase: [f32; 3] = [
        rng.gen_range(0.0..tau),
        rng.gen_range(0.0..tau),
        rng.gen_range(0.0..tau),
    ];
    let s0 = first.body.salient_points.map(Vector3::from);
    let mut episodes = episodes::plan(
        cfg.frames,
        cfg.seed,
        cfg.full_occlusion,
        cfg.motion,
        &cfg.episode_frames,
        (s0[4] + s0[5]) * 0.5,
        0.5 * (s0[1] - s0[2]).norm(),
    )?;
    let subset = source.torso_subset();
    let mut meta = SequenceMeta {
        config: cfg.clone(),
        body_source: source.name(),
        shape: first.shape.clone(),
        intrinsics: [k.fx, k.fy, k.cx, k.cy, k.width as f32, k.height as f32],
        camera_from_world: matrix_rows(&cfw),
        view,
        bed,
        planes_camera: scene0.planes_world().map(|p| p.transformed(&cfw)),
        calibration: None,
        episodes,
        robot_base_from_camera: Some(Extrinsic::from_isometry(&cfw.inverse())),
        arm: None,
        torso_surface: None,
    };
    let oni_path = dir.join("sequence.oni");
    let mut oni = OniWriter::create(&oni_path, &k, Codec::Z16Table)
        .with_context(|| format!("creating {}", oni_path.display()))?;
    let truth_path = dir.join("truth.jsonl");
    let mut truth = std::io::BufWriter::new(
        std::fs::File::create(&truth_path).with_context(|| format!("creating {}", truth_path.display()))?,
    );
    let mut scratch = NoiseScratch::default();
    let mut temporal = TemporalState::default();
    let mut depth = vec![0u16; k.width as usize * k.height as usize];
    let mut unlit = Vec::new();
    let (mut occ_sum, mut occ_max) = (0.0f32, 0.0f32);
    let mut torso_out: Option<(TorsoSelection, TorsoWriter)> = None;
    let mut park: Option<ArmTarget> = None;
    let mut probe_poses: Vec<Option<Isometry3<f32>>> = Vec::with_capacity(cfg.frames as usize);
    for f in 0..cfg.frames {
        let time = f as f32 / cfg.fps;
        let time_us = (f as f64 * 1e6 / cfg.fps as f64).round() as u64;
        // Arms blend slowly (30 s period) between two sub-poses; the torso drifts a few cm and rolls a degree or two.
        let arm_blend = 0.5 - 0.5 * (tau * time / 30.0).cos();
        let mut body = source.sample_motion(shape_seed, pose_a, pose_b, arm_blend)?.body;
        let breath = 0.5 - 0.5 * (tau * cfg.breathing_hz * time).cos();
        breathe(&mut body, &torso_parts, cfg.breathing_amplitude_m * breath);
        let drift = Isometry3::from_parts(
            Translation3::new(
                0.015 * (tau * time / 23.0 + drift_phase[0]).sin(),
                0.02 * (tau * time / 31.0 + drift_phase[1]).sin(),
                0.0,
            ),
            UnitQuaternion::from_axis_angle(
                &Vector3::y_axis(),
                0.03 * (tau * time / 19.0 + drift_phase[2]).sin(),
            ),
        );
        let bed_motion = episodes
            .motion
            .map_or_else(Isometry3::identity, |m| m.bed_transform(f));
        let place = bed_motion * drift;
        for v in body.vertices.iter_mut().chain(body.salient_points.iter_mut()) {
            let p = place * Point3::from(*v);
            *v = [p.x, p.y, p.z];
        }
        if torso_out.is_none() {
            let torso_from_bed = torso_pose(&body.salient_points).inverse();
            let sel = TorsoSelection::choose(&body, &first.part_names, subset.as_deref(), &torso_from_bed)?;
            let writer = TorsoWriter::create(&dir.join(torso_truth::FILE_NAME), cfg.frames, &sel)?;
            meta.torso_surface = Some(TorsoSurfaceMeta {
                file: torso_truth::FILE_NAME.to_string(),
                vertices: sel.vertices.len() as u32,
                triangles: sel.triangles.len() as u32,
                selection: if subset.is_some() {
                    "torso_subset"
                } else {
                    "torso_parts_facing_up"
                }
                .to_string(),
            });
            torso_out = Some((sel, writer));
        }
        let mut scene = Scene::new(&body, bed);
        let phase = episodes.full_occlusion.map_or(ArmPhase::Path, |o| o.phase(f));
        if phase != ArmPhase::Path
            && park.is_none()
            && let Some(o) = episodes.full_occlusion.as_mut()
        {
            let (target, fraction, distance) =
                episodes::find_park_pose(&scene, &cfw, &mut renderer, arm_shoulder, &is_torso, cfg.seed)?;
            o.planned_torso_occluded_fraction = fraction;
            o.park_distance_m = distance;
            park = Some(target);
        }
        scene.render(&mut renderer, &cfw, false);
        let count = |r: &Renderer| body_pixels(r, &is_torso);
        let (torso0, all0) = count(&renderer);
        let (mut torso_occ, mut body_occ, mut torso_unseen) = (0.0, 0.0, 0.0);
        let mut probe = None;
        let sweep = cfg.occluder.then(|| {
            // Sweep along the midline (v: hips 0.9 → shoulders 0.15 and back) with a slow sideways wobble.
            let phase = (time / cfg.sweep_period_s).fract();
            let v = 0.9 - 0.75 * (1.0 - (2.0 * phase - 1.0).abs());
            let u = 0.5 + 0.15 * (tau * time / 7.0).sin();
            let normals = vertex_normals(&scene.body_vertices, &scene.body_triangles);
            sweep_target(&scene, &normals, arm_shoulder, eye, u, v)
        });
        let target = match (phase, park) {
            (ArmPhase::Path, _) | (_, None) => sweep,
            (phase, Some(park)) => {
                let path = sweep.unwrap_or_else(|| ArmTarget::home(arm_shoulder, eye));
                Some(match phase {
                    ArmPhase::Approach(s) => path.lerp(&park, s),
                    ArmPhase::Leave(s) => park.lerp(&path, s),
                    _ => park,
                })
            }
        };
        if let Some(target) = target {
            // What the projector lights before the arm is drawn (frames without the arm need neither count).
            let lit0 = lit_torso_pixels(&renderer, &cfg.noise, &k, &is_torso, &mut unlit);
            let arm = target.reach(arm_shoulder);
            renderer.draw(&crate::scene::arm_draw(&arm.mesh), &cfw);
            let (torso1, all1) = count(&renderer);
            torso_occ = hidden_share(torso0, torso1);
            body_occ = hidden_share(all0, all1);
            torso_unseen = hidden_share(
                lit0,
                lit_torso_pixels(&renderer, &cfg.noise, &k, &is_torso, &mut unlit),
            );
            probe = Some(arm.world_from_probe);
            scene.arm = Some(arm);
        }
        if phase == ArmPhase::Parked
            && let Some(o) = episodes.full_occlusion.as_mut()
        {
            o.torso_occluded_fraction_min = o.torso_occluded_fraction_min.min(torso_occ);
        }
        probe_poses.push(probe);
        occ_sum += torso_occ;
        occ_max = occ_max.max(torso_occ);
        let noise_seed = mix_seed(mix_seed(cfg.seed, 0x5E0), f as u64 + 1);
        cfg.noise.apply_frame(
            renderer.buffers(),
            &k,
            Rect::full(k.width as usize, k.height as usize),
            noise_seed,
            &mut scratch,
            &mut temporal,
            &mut depth,
        );
        oni.write_frame(&depth, time_us)
            .with_context(|| format!("writing frame {f} to {}", oni_path.display()))?;
        let (salient_camera, salient_pixels) = project_salient(&scene, &cfw, &k);
        let mut probe_truth = None;
        if let Some((sel, writer)) = torso_out.as_mut() {
            let torso_camera = sel.camera_vertices(&scene.body_vertices, &cfw);
            writer.write_frame(&torso_camera)?;
            if let Some(p) = probe {
                let tip = cfw * Point3::from(p.translation.vector);
                let query = SurfaceQuery::new(&torso_camera, &sel.triangles);
                probe_truth = torso_truth::map_tip(&query, &sel.regions, &tip);
            }
        }
        let ft = FrameTruth {
            frame: f,
            time_us,
            salient_camera,
            salient_world: scene.salient_world,
            salient_pixels,
            camera_from_torso: matrix_rows(&(cfw * torso_pose(&scene.salient_world))),
            camera_from_probe: probe.map(|p| matrix_rows(&(cfw * p))),
            world_from_probe: probe.map(|p| matrix_rows(&p)),
            torso_occluded_fraction: torso_occ,
            body_occluded_fraction: body_occ,
            torso_unseen_fraction: Some(torso_unseen),
            breathing_mm: cfg.breathing_amplitude_m * breath * 1000.0,
            arm_blend,
            probe_truth,
        };
        serde_json::to_writer(&mut truth, &ft)?;
        truth.write_all(b"\n")?;
        let mid_park = episodes
            .full_occlusion
            .is_some_and(|o| f == (o.start + o.end) / 2);
        if f == 0 || (cfg.occluder && (f == cfg.frames / 2)) || mid_park {
            let mut rgb = crate::dataset::preview::colour_depth(&depth, Some(&renderer.buffers().label));
            crate::dataset::preview::draw_truth(
                &mut rgb,
                k.width as usize,
                k.height as usize,
                &salient_pixels,
                ft.camera_from_probe,
            );
            crate::dataset::preview::write_rgb_png(
                &dir.join(format!("preview_{f:05}.png")),
                &rgb,
                k.width as usize,
                k.height as usize,
            )?;
        }
        on_frame(f, &depth);
    }
    truth.flush()?;
    oni.finish()
        .with_context(|| format!("finishing {}", oni_path.display()))?;
    if let Some((_, writer)) = torso_out {
        writer.finish()?;
    }
    if probe_poses.iter().any(Option::is_some) {
        meta.arm = Some(arm_stream::write_arm_states(
            dir,
            &probe_poses,
            cfg.fps,
            cfg.seed,
        )?);
    }
    meta.episodes = episodes;
    std::fs::write(dir.join("sequence.json"), serde_json::to_vec_pretty(&meta)?)?;
    let secs = started.elapsed().as_secs_f32();
    Ok(SequenceSummary {
        frames: cfg.frames,
        torso_occluded_mean: occ_sum / cfg.frames as f32,
        torso_occluded_max: occ_max,
        frames_per_second: cfg.frames as f32 / secs.max(1e-6),
        episodes,
        sweep_occluded_planned,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::body::{MANNEQUIN_PARTS, Mannequin};

    #[test]
    fn a_failed_generation_leaves_no_sequence_behind() {
        let root = std::env::temp_dir().join(format!("supine-partial-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let write_outputs = |dir: &Path| {
            std::fs::create_dir_all(dir).unwrap();
            for name in OUTPUTS
                .iter()
                .copied()
                .chain(["preview_00000.png", "preview_00045.png"])
            {
                std::fs::write(dir.join(name), b"partial").unwrap();
            }
        };
        // A directory the generation created goes entirely.
        let created = root.join("created");
        write_outputs(&created);
        remove_partial(&created, true);
        assert!(!created.exists());
        // In a directory that was there before, only what a generation writes goes.
        let given = root.join("given");
        write_outputs(&given);
        std::fs::write(given.join("notes.txt"), b"the user's").unwrap();
        remove_partial(&given, false);
        let left: Vec<String> = std::fs::read_dir(&given)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(left, ["notes.txt"]);
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn breathing_lifts_the_chest_front_only() {
        let mut body = Mannequin::build(&Mannequin::sample_params(&mut ChaCha8Rng::seed_from_u64(2))).body;
        let before = body.clone();
        let torso: Vec<u8> = vec![2, 3];
        breathe(&mut body, &torso, 0.008);
        let moved: Vec<f32> = before
            .vertices
            .iter()
            .zip(&body.vertices)
            .map(|(a, b)| (Vector3::from(*a) - Vector3::from(*b)).norm())
            .collect();
        let max = moved.iter().cloned().fold(0.0, f32::max);
        assert!(max > 0.006 && max <= 0.008 + 1e-6, "peak rise {max}");
        for (i, m) in moved.iter().enumerate() {
            if !torso.contains(&before.part_of_vertex[i]) {
                assert_eq!(*m, 0.0, "limbs and head stay");
            }
        }
        assert!(
            body.salient_points[3][2] > before.salient_points[3][2],
            "belly point rises"
        );
        assert_eq!(MANNEQUIN_PARTS[2], "chest");
    }

    #[test]
    fn the_shoulder_is_the_first_whose_sweep_hides_at_most_the_limit() {
        let (scene, cfw, mut rng) = crate::scene::mannequin_scene(3);
        let eye = cfw.inverse().translation.vector;
        let torso: Vec<u8> = MANNEQUIN_PARTS
            .iter()
            .enumerate()
            .filter(|(_, n)| matches!(**n, "chest" | "abdomen" | "belly" | "pelvis"))
            .map(|(i, _)| i as u8)
            .collect();
        let is_torso = |p: u8| torso.contains(&p);
        let mut renderer = Renderer::new(Intrinsics::KINECT_V1);
        // Near the camera's line of sight (the full-occlusion park's shoulder) and the usual one beside the bed.
        let near = episodes::shoulder_for_full_occlusion(&scene, eye, 3).expect("a park shoulder");
        let usual = crate::dataset::sample_shoulder(&scene, scene.torso_centre()[0], &mut rng);
        let noise = KinectNoise::default();
        // What the arm covers, then what the sensor loses (its projector shadow counted): the same choice rule.
        for shadow in [None, Some((&noise, &Intrinsics::KINECT_V1))] {
            let mut hides = |c: &[Vector3<f32>], limit| {
                shoulder_within(&scene, &cfw, &mut renderer, &is_torso, c, limit, shadow)
            };
            let (_, w_near) = hides(&[near], 1.0);
            let (_, w_usual) = hides(&[usual], 1.0);
            let ((hi, w_hi), (lo, w_lo)) = if w_near > w_usual {
                ((near, w_near), (usual, w_usual))
            } else {
                ((usual, w_usual), (near, w_near))
            };
            assert!(
                w_hi > w_lo + 0.02 && w_lo > 0.0,
                "the two shoulders hide {w_hi} and {w_lo} (shadow counted: {})",
                shadow.is_some()
            );
            // The first candidate that holds the limit wins, even after one that does not.
            let limit = 0.5 * (w_hi + w_lo);
            assert_eq!(hides(&[hi, lo], limit), (lo, w_lo));
            assert_eq!(hides(&[lo, hi], 1.0), (lo, w_lo));
            // None holds: the one that hides least.
            assert_eq!(hides(&[hi, lo], 0.5 * w_lo), (lo, w_lo));
        }
    }

    #[test]
    fn occluded_sequence_writes_playable_oni_and_truth() {
        let dir = std::env::temp_dir().join(format!("supine-seq-test-{}", std::process::id()));
        let cfg = SequenceConfig {
            sweep_period_s: 0.2,
            ..SequenceConfig::new(6, 4, true)
        };
        let summary = generate(&Mannequin, &cfg, &dir, &mut |_, _| {}).unwrap();
        assert_eq!(summary.frames, 6);
        assert!(
            summary.torso_occluded_max > 0.02,
            "the arm hides part of the torso: {}",
            summary.torso_occluded_max
        );
        let lines: Vec<FrameTruth> = std::fs::read_to_string(dir.join("truth.jsonl"))
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines.len(), 6);
        assert!(lines.iter().all(|l| l.camera_from_probe.is_some()));
        // Every frame says what share of the torso the sensor loses to the arm, and the sweeping arm hides some.
        assert!(lines.iter().all(|l| {
            l.torso_unseen_fraction
                .is_some_and(|u| (0.0..=1.0).contains(&u) && u > 0.0)
        }));
        assert_eq!(lines[1].time_us, 33_333);
        let mut reader = supine_drivers::oni::OniReader::open(dir.join("sequence.oni")).unwrap();
        let mut frames = 0;
        loop {
            match reader.read_frame() {
                Ok(frame) => {
                    assert!(frame.depth_mm().iter().filter(|&&d| d > 0).count() > 50_000);
                    assert_eq!(frame.capture.as_us(), lines[frames].time_us);
                    frames += 1;
                }
                Err(e) if e.kind() == supine_drivers::SourceErrorKind::EndOfStream => break,
                Err(e) => panic!("reading the recording: {e}"),
            }
        }
        assert_eq!(frames, 6);
        std::fs::remove_dir_all(&dir).ok();
    }
}
