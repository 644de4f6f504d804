//! `supine-models sequence --calibration`: the arm visits poses above the bed (empty, or with a still patient),
//! dwelling at each, seen by the static head; arm states with encoder noise, a kinematic error per pose and
//! latency go beside the .oni as a serial capture, and the true extrinsic into `sequence.json`.
//!
//! Timeline: every pose takes [`FRAMES_PER_POSE`] frames (12 at 30 Hz, 0.4 s): [`TRANSIT_FRAMES`] of smooth
//! motion from the previous pose, then a dwell. 240 frames hold 20 poses. Arm states are sampled at
//! `arm_rate_hz` (100 Hz) on the capture clock; each carries the pose the arm had `latency` earlier (encoder
//! filtering and transport), its timestamp jittered by ±0.5 ms.
//!
//! Output in `DIR`: `sequence.oni`, `arm.cobs` (arm-state messages in the serial framing, readable by the
//! `file:` link), `truth.jsonl` (one [`CalibrationFrameTruth`] per frame) and `sequence.json`
//! ([`super::SequenceMeta`] with its `calibration` part, [`CalibrationMeta`]).
//!
//! Cost per frame: one render of bed, arm (and body), full-frame noise and one 16zT encode: ~15–30 ms.

use super::{SequenceConfig, SequenceMeta};
use crate::dataset::{elbow_hint, mix_seed, sample_shoulder};
use crate::render::noise::{NoiseScratch, Rect};
use crate::render::{Label, Renderer};
use crate::scene::arm::ArmState;
use crate::scene::body::BodySource;
use crate::scene::{BedParams, Scene, ViewParams, matrix_rows};
use anyhow::{Context, Result, ensure};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::io::Write;
use std::path::Path;
use supine_core::camera::Intrinsics;
use supine_core::time::Timestamp;
use supine_core::wire::{ArmState as WireArmState, Body, Message, UnitQuatQ14};
use supine_drivers::oni::{Codec, OniWriter};

/// Frames per pose (transit + dwell).
pub const FRAMES_PER_POSE: u32 = 12;
/// Frames of motion at the start of each pose.
pub const TRANSIT_FRAMES: u32 = 4;

/// A rigid transform as the config writes it: translation in metres and a unit quaternion `[w, x, y, z]`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Extrinsic {
    /// Translation, metres.
    pub translation_m: [f32; 3],
    /// Rotation as a unit quaternion `[w, x, y, z]`.
    pub rotation_quat_wxyz: [f32; 4],
}

impl Extrinsic {
    /// From an isometry.
    pub fn from_isometry(t: &Isometry3<f32>) -> Extrinsic {
        let q = t.rotation.quaternion();
        Extrinsic {
            translation_m: t.translation.vector.into(),
            rotation_quat_wxyz: [q.w, q.i, q.j, q.k],
        }
    }

    /// As an isometry.
    pub fn to_isometry(&self) -> Isometry3<f32> {
        let [w, x, y, z] = self.rotation_quat_wxyz;
        Isometry3::from_parts(
            Translation3::from(Vector3::from(self.translation_m)),
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)),
        )
    }
}

/// Parameters of a calibration sequence.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationConfig {
    /// A still patient lies on the bed (otherwise the bed is empty).
    pub patient: bool,
    /// Arm-state rate, Hz.
    pub arm_rate_hz: f32,
    /// Encoder noise on the reported tip, mm (sd per axis, every sample).
    pub encoder_noise_mm: f32,
    /// Kinematic error of the arm's own model, mm (sd per axis, constant over one pose).
    pub kinematic_error_mm: f32,
    /// Encoder noise on the reported orientation, degrees (sd of the rotation angle per axis).
    pub orientation_noise_deg: f32,
    /// Range of the arm's latency (sample time to reported pose), µs; one value per sequence.
    pub latency_us: [u32; 2],
    /// Sd of the error of the nominal extrinsic (the mount drawing's guess): translation per axis, metres.
    pub nominal_translation_sd_m: f32,
    /// Sd of the nominal extrinsic's rotation error per axis, degrees.
    pub nominal_rotation_sd_deg: f32,
}

impl Default for CalibrationConfig {
    /// A still patient, 100 Hz, 0.3 mm encoder noise, 0.5 mm kinematic error, 0.02°, 5–25 ms latency, nominal
    /// guess within 1 cm / 1° (sd per axis).
    fn default() -> Self {
        CalibrationConfig {
            patient: true,
            arm_rate_hz: 100.0,
            encoder_noise_mm: 0.3,
            kinematic_error_mm: 0.5,
            orientation_noise_deg: 0.02,
            latency_us: [5_000, 25_000],
            nominal_translation_sd_m: 0.01,
            nominal_rotation_sd_deg: 1.0,
        }
    }
}

/// The `calibration` part of `sequence.json`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationMeta {
    /// Generation parameters.
    pub config: CalibrationConfig,
    /// The true extrinsic (`robot_base` is the world frame of the scene).
    pub robot_base_from_camera: Extrinsic,
    /// A rough guess of it (what the mount drawing says), for the detector's prior.
    pub robot_base_from_camera_nominal: Extrinsic,
    /// True probe-tip positions of the poses, `robot_base`, metres.
    pub poses_robot_base: Vec<[f32; 3]>,
    /// The latency this sequence's arm has, µs.
    pub arm_latency_us: u32,
    /// Points on the patient's torso (or where it would lie), `camera` frame, metres: where probe-mapping error
    /// is evaluated (hip centre, belly, shoulder centre).
    pub torso_points_camera: Vec<[f32; 3]>,
}

/// Ground truth of one frame of a calibration sequence (`truth.jsonl`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationFrameTruth {
    /// Frame index from 0.
    pub frame: u32,
    /// Capture time, µs.
    pub time_us: u64,
    /// The pose the arm dwells at, `None` in transit.
    pub pose: Option<u32>,
    /// Probe tip pose in the camera frame, 4x4 row-major.
    pub camera_from_probe: [[f32; 4]; 4],
    /// Probe tip pose in the world (`robot_base`) frame, 4x4 row-major.
    pub world_from_probe: [[f32; 4]; 4],
}

#[derive(Debug, Clone, Copy)]
struct Pose {
    tip: Vector3<f32>,
    axis: Vector3<f32>,
}

fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// The commanded probe pose at time `t` seconds, the dwell's pose index (`None` in transit) and the index of the
/// pose being reached.
fn pose_at(poses: &[Pose], fps: f32, t: f32) -> (Pose, Option<u32>, usize) {
    let frames = (t * fps).max(0.0);
    let k = ((frames / FRAMES_PER_POSE as f32) as usize).min(poses.len() - 1);
    let phase = frames - (k as u32 * FRAMES_PER_POSE) as f32;
    if k == 0 || phase >= TRANSIT_FRAMES as f32 {
        return (poses[k], Some(k as u32), k);
    }
    let s = smoothstep(phase / TRANSIT_FRAMES as f32);
    let (a, b) = (poses[k - 1], poses[k]);
    (
        Pose {
            tip: a.tip.lerp(&b.tip, s),
            axis: a.axis.lerp(&b.axis, s).normalize(),
        },
        None,
        k,
    )
}

/// Generate a calibration sequence of `cfg.frames` frames into `dir`; `on_frame` is called after each frame. A
/// generation that fails leaves nothing behind (`super::remove_partial`).
pub fn generate_calibration(
    source: &dyn BodySource,
    cfg: &SequenceConfig,
    cal: &CalibrationConfig,
    dir: &Path,
    on_frame: &mut dyn FnMut(u32, &[u16]),
) -> Result<CalibrationMeta> {
    ensure!(
        cfg.frames >= FRAMES_PER_POSE * 4,
        "a calibration sequence needs at least {} frames (4 poses of {FRAMES_PER_POSE})",
        FRAMES_PER_POSE * 4
    );
    super::into_dir(dir, || calibration_into(source, cfg, cal, dir, on_frame))
}

fn calibration_into(
    source: &dyn BodySource,
    cfg: &SequenceConfig,
    cal: &CalibrationConfig,
    dir: &Path,
    on_frame: &mut dyn FnMut(u32, &[u16]),
) -> Result<CalibrationMeta> {
    let k = Intrinsics::KINECT_V1;
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(cfg.seed, 0xCA1));
    let (shape_seed, pose_a, pose_b) = (rng.r#gen::<u64>(), rng.r#gen::<u64>(), rng.r#gen::<u64>());
    let patient = source.sample_motion(shape_seed, pose_a, pose_b, 0.0)?;
    let bed = BedParams::sample(&mut rng, patient.head_raise_rad, patient.hinge_y_m);
    let mut scene = Scene::new(&patient.body, bed);
    let torso_centre = scene.torso_centre();
    let s = scene.salient_world;
    let mid = |a: [f32; 3], b: [f32; 3]| [(a[0] + b[0]) * 0.5, (a[1] + b[1]) * 0.5, (a[2] + b[2]) * 0.5];
    let torso_world = [mid(s[4], s[5]), s[3], mid(s[1], s[2])];
    let view = ViewParams::sample_nominal(&mut rng, torso_centre).sample_view(&mut rng);
    let cfw = view.camera_from_world(scene.midline_y(), bed.mattress_top);
    let shoulder = sample_shoulder(&scene, torso_centre[0], &mut rng);
    let eye = cfw.inverse().translation.vector;
    let body_vertices = std::mem::take(&mut scene.body_vertices);
    let body_triangles = std::mem::take(&mut scene.body_triangles);
    let body_parts = std::mem::take(&mut scene.body_triangle_parts);
    if cal.patient {
        scene.body_vertices = body_vertices.clone();
        scene.body_triangles = body_triangles;
        scene.body_triangle_parts = body_parts;
    }
    // Height of whatever lies under a tip (the patient's skin or the mattress), for the hover clearance.
    let surface_z = |x: f32, y: f32| {
        let mut z = bed.mattress_top;
        if cal.patient {
            for v in &body_vertices {
                if (v[0] - x).powi(2) + (v[1] - y).powi(2) < 0.06 * 0.06 {
                    z = z.max(v[2]);
                }
            }
        }
        z
    };

    // Poses: tips in a box above the torso region, hovering 10–45 cm above the surface, the probe tilted up to
    // 25° off vertical; each must be reachable and its probe head visible to the camera.
    let n_poses = (cfg.frames / FRAMES_PER_POSE) as usize;
    let mut renderer = Renderer::new(k);
    let mut poses = Vec::with_capacity(n_poses);
    let midline = scene.midline_y();
    let mut tries = 0;
    while poses.len() < n_poses {
        tries += 1;
        ensure!(
            tries < 200 * n_poses,
            "could not place {n_poses} visible, reachable poses"
        );
        let x = torso_centre[0] + rng.gen_range(-0.4..0.4);
        let y = midline + rng.gen_range(-0.28..0.28);
        let base = surface_z(x, y);
        let z = rng.gen_range(base + 0.10..(bed.mattress_top + 0.6).max(base + 0.3));
        let tilt = Vector3::new(rng.gen_range(-0.45..0.45), rng.gen_range(-0.45..0.45), 0.0);
        let axis = (-Vector3::z() + tilt).normalize();
        let tip = Vector3::new(x, y, z);
        let arm = ArmState::reach(shoulder, tip, axis, elbow_hint(shoulder, tip, eye));
        if !arm.reached {
            continue;
        }
        // Visible: the point 2 cm behind the tip on the camera side of the head renders at its own depth, and the
        // tip projects 30 px inside the image.
        let probe_point = cfw * Point3::from(tip - axis * 0.02);
        let Some(px) = k.project(&probe_point) else {
            continue;
        };
        if px.x < 30.0 || px.y < 30.0 || px.x > k.width as f32 - 30.0 || px.y > k.height as f32 - 30.0 {
            continue;
        }
        let mut trial = scene.clone();
        trial.arm = Some(arm);
        trial.render(&mut renderer, &cfw, true);
        let i = px.y.round() as usize * k.width as usize + px.x.round() as usize;
        let b = renderer.buffers();
        let own = b.label[i] == Label::Occluder as u8
            && b.z_at(i).is_some_and(|z| (z - probe_point.z).abs() < 0.04);
        if !own {
            continue;
        }
        poses.push(Pose { tip, axis });
    }

    let truth_t = cfw.inverse();
    let nominal = {
        let tn = Normal::new(0.0f32, cal.nominal_translation_sd_m.max(1e-9))?;
        let rn = Normal::new(0.0f32, cal.nominal_rotation_sd_deg.to_radians().max(1e-9))?;
        let dt = Vector3::new(tn.sample(&mut rng), tn.sample(&mut rng), tn.sample(&mut rng));
        let dr = Vector3::new(rn.sample(&mut rng), rn.sample(&mut rng), rn.sample(&mut rng));
        Isometry3::new(dt, dr) * truth_t
    };
    let latency_us = rng.gen_range(cal.latency_us[0]..=cal.latency_us[1].max(cal.latency_us[0]));
    let meta = CalibrationMeta {
        config: cal.clone(),
        robot_base_from_camera: Extrinsic::from_isometry(&truth_t),
        robot_base_from_camera_nominal: Extrinsic::from_isometry(&nominal),
        poses_robot_base: poses.iter().map(|p| p.tip.into()).collect(),
        arm_latency_us: latency_us,
        torso_points_camera: torso_world
            .iter()
            .map(|p| (cfw * Point3::from(*p)).coords.into())
            .collect(),
    };
    let seq_meta = SequenceMeta {
        config: cfg.clone(),
        body_source: source.name(),
        shape: patient.shape.clone(),
        intrinsics: [k.fx, k.fy, k.cx, k.cy, k.width as f32, k.height as f32],
        camera_from_world: matrix_rows(&cfw),
        view,
        bed,
        planes_camera: scene.planes_world().map(|p| p.transformed(&cfw)),
        calibration: Some(meta.clone()),
        episodes: Default::default(),
        robot_base_from_camera: None,
        arm: None,
        torso_surface: None,
    };
    std::fs::write(dir.join("sequence.json"), serde_json::to_vec_pretty(&seq_meta)?)?;

    // Arm states: the pose `latency` before each sample time, with encoder noise and a kinematic error per pose.
    let arm_path = dir.join("arm.cobs");
    let mut arm_out = std::io::BufWriter::new(
        std::fs::File::create(&arm_path).with_context(|| format!("creating {}", arm_path.display()))?,
    );
    let enc = Normal::new(0.0f32, cal.encoder_noise_mm.max(1e-9) * 0.001)?;
    let kin = Normal::new(0.0f32, cal.kinematic_error_mm.max(1e-9) * 0.001)?;
    let ori = Normal::new(0.0f32, cal.orientation_noise_deg.to_radians().max(1e-9))?;
    let kinematic: Vec<Vector3<f32>> = (0..poses.len())
        .map(|_| Vector3::new(kin.sample(&mut rng), kin.sample(&mut rng), kin.sample(&mut rng)))
        .collect();
    let duration_s = cfg.frames as f32 / cfg.fps + 0.1;
    let n_arm = (duration_s * cal.arm_rate_hz) as u32;
    let mut buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
    for j in 0..n_arm {
        let t_us = (j as f64 * 1e6 / cal.arm_rate_hz as f64).round() as i64 + rng.gen_range(-500..=500);
        let t_us = t_us.max(0) as u64;
        let sampled = (t_us as f32 - latency_us as f32) * 1e-6;
        let (pose, _, target) = pose_at(&poses, cfg.fps, sampled);
        let arm = ArmState::reach(shoulder, pose.tip, pose.axis, elbow_hint(shoulder, pose.tip, eye));
        let noise = Vector3::new(enc.sample(&mut rng), enc.sample(&mut rng), enc.sample(&mut rng));
        let tip = arm.world_from_probe.translation.vector + kinematic[target] + noise;
        let rot = UnitQuaternion::new(Vector3::new(
            ori.sample(&mut rng),
            ori.sample(&mut rng),
            ori.sample(&mut rng),
        )) * arm.world_from_probe.rotation;
        let q = rot.quaternion();
        let msg = Message {
            seq: j as u16,
            timestamp: Timestamp::from_us(t_us).context("arm time out of range")?,
            body: Body::ArmState(WireArmState {
                position_mm: [tip.x, tip.y, tip.z].map(|v| (v * 1000.0).round() as i32),
                orientation: UnitQuatQ14::from_f32([q.w, q.i, q.j, q.k]).context("arm orientation")?,
            }),
        };
        let n = msg
            .encode_serial(&mut buf)
            .map_err(|e| anyhow::anyhow!("encoding arm state {j}: {e:?}"))?;
        arm_out.write_all(&buf[..n])?;
    }
    arm_out.flush()?;

    let oni_path = dir.join("sequence.oni");
    let mut oni = OniWriter::create(&oni_path, &k, Codec::Z16Table)
        .with_context(|| format!("creating {}", oni_path.display()))?;
    let truth_path = dir.join("truth.jsonl");
    let mut truth = std::io::BufWriter::new(
        std::fs::File::create(&truth_path).with_context(|| format!("creating {}", truth_path.display()))?,
    );
    let mut scratch = NoiseScratch::default();
    let mut depth = vec![0u16; k.width as usize * k.height as usize];
    for f in 0..cfg.frames {
        let time_us = (f as f64 * 1e6 / cfg.fps as f64).round() as u64;
        let (pose, index, _) = pose_at(&poses, cfg.fps, time_us as f32 * 1e-6);
        let arm = ArmState::reach(shoulder, pose.tip, pose.axis, elbow_hint(shoulder, pose.tip, eye));
        let probe = arm.world_from_probe;
        scene.arm = Some(arm);
        scene.render(&mut renderer, &cfw, true);
        cfg.noise.apply(
            renderer.buffers(),
            &k,
            Rect::full(k.width as usize, k.height as usize),
            mix_seed(mix_seed(cfg.seed, 0xCA1), f as u64 + 1),
            &mut scratch,
            &mut depth,
        );
        oni.write_frame(&depth, time_us)
            .with_context(|| format!("writing frame {f} to {}", oni_path.display()))?;
        let ft = CalibrationFrameTruth {
            frame: f,
            time_us,
            pose: index,
            camera_from_probe: matrix_rows(&(cfw * probe)),
            world_from_probe: matrix_rows(&probe),
        };
        serde_json::to_writer(&mut truth, &ft)?;
        truth.write_all(b"\n")?;
        if f == TRANSIT_FRAMES + 2 {
            let rgb = crate::dataset::preview::colour_depth(&depth, Some(&renderer.buffers().label));
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
    Ok(meta)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::calibration::{
        guess_free_start, pose_keyframes, read_arm_capture, run_session, solve_poses,
    };
    use crate::scene::body::Mannequin;
    use supine_core::calib::solve::{rotation_error_deg, translation_error_m};
    use supine_core::calib::{SessionConfig, TipError, TipOptions, TipPrior, TipScratch, detect_tip};
    use supine_core::depth::DepthFrame;

    fn generate(name: &str, frames: u32, seed: u64, patient: bool) -> (std::path::PathBuf, CalibrationMeta) {
        let dir = std::env::temp_dir().join(format!("supine-cal-{name}-{}", std::process::id()));
        let cfg = SequenceConfig::new(frames, seed, false);
        let cal = CalibrationConfig {
            patient,
            ..Default::default()
        };
        let meta = generate_calibration(&Mannequin, &cfg, &cal, &dir, &mut |_, _| {}).unwrap();
        (dir, meta)
    }

    #[test]
    fn the_tip_is_found_in_a_rendered_frame_and_refused_where_there_is_none() {
        let (dir, meta) = generate("tip", 48, 5, true);
        let truth = meta.robot_base_from_camera.to_isometry();
        let lines: Vec<CalibrationFrameTruth> = std::fs::read_to_string(dir.join("truth.jsonl"))
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        let mut reader = supine_drivers::oni::OniReader::open(dir.join("sequence.oni")).unwrap();
        let k = Intrinsics::KINECT_V1;
        let mut scratch: Box<TipScratch<8192>> = Box::new(TipScratch::new());
        let mut errors = Vec::new();
        let mut far = 0;
        for t in &lines {
            let frame = reader.read_frame().unwrap();
            if t.pose.is_none() {
                continue;
            }
            let m = t.camera_from_probe;
            let tip = Point3::new(m[0][3], m[1][3], m[2][3]);
            let rot = nalgebra::Matrix3::new(
                m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
            );
            // The prior is 3 cm off, as a rough guess would put it.
            let prior = TipPrior {
                tip_camera: tip + Vector3::new(0.02, -0.015, 0.015),
                camera_from_probe: UnitQuaternion::from_matrix(&rot),
                uncertainty_m: 0.05,
            };
            if let Ok(d) = detect_tip(&frame, &k, &prior, &TipOptions::default(), &mut scratch) {
                errors.push((d.tip_camera - tip).norm());
                // A sure prior 4 cm deeper along the probe: the head is still in its search cylinder, but the tip
                // found there is farther from the expected one than the prior allows.
                let deeper = TipPrior {
                    tip_camera: tip + rot * Vector3::new(0.0, 0.0, 0.04),
                    uncertainty_m: 0.005,
                    ..prior
                };
                match detect_tip(&frame, &k, &deeper, &TipOptions::default(), &mut scratch) {
                    Err(TipError::FarFromPrior { distance_m }) => {
                        assert!(distance_m > 0.035, "{distance_m}");
                        far += 1;
                    }
                    Ok(d) => panic!(
                        "a tip {} m from a sure prior",
                        (d.tip_camera - deeper.tip_camera).norm()
                    ),
                    Err(_) => {}
                }
            }
            // Nothing there: a prior 40 cm to the side finds no probe (or only refusals).
            let away = TipPrior {
                tip_camera: tip + truth.inverse().rotation * Vector3::new(0.0, 0.4, 0.0),
                ..prior
            };
            let e = detect_tip(&frame, &k, &away, &TipOptions::default(), &mut scratch);
            assert!(
                e.is_err() || (e.unwrap().tip_camera - tip).norm() > 0.1,
                "a tip where there is none"
            );
        }
        assert!(errors.len() >= 20, "{} detections", errors.len());
        assert!(
            2 * far >= errors.len(),
            "{far} of {} refused as far from the prior",
            errors.len()
        );
        errors.sort_by(f32::total_cmp);
        let median = errors[errors.len() / 2];
        assert!(median < 0.005, "median tip error {median} m");
        // An empty frame: no probe.
        let empty = vec![0u16; k.width as usize * k.height as usize];
        let frame = DepthFrame::new(&empty, k.width, k.height, Timestamp::default(), 0).unwrap();
        let prior = TipPrior {
            tip_camera: Point3::new(0.0, 0.0, 1.0),
            camera_from_probe: UnitQuaternion::identity(),
            uncertainty_m: 0.05,
        };
        assert!(matches!(
            detect_tip(&frame, &k, &prior, &TipOptions::default(), &mut scratch),
            Err(TipError::NoProbe { .. })
        ));
        let behind = TipPrior {
            tip_camera: Point3::new(0.0, 0.0, -1.0),
            ..prior
        };
        assert_eq!(
            detect_tip(&frame, &k, &behind, &TipOptions::default(), &mut scratch),
            Err(TipError::OutOfView)
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_short_empty_bed_sequence_calibrates_and_late_arm_states_do_not() {
        let (dir, meta) = generate("session", 96, 7, false);
        assert_eq!(meta.poses_robot_base.len(), 8);
        let truth = meta.robot_base_from_camera.to_isometry();
        let nominal = meta.robot_base_from_camera_nominal.to_isometry();
        let (arm, errors) = read_arm_capture(&dir.join("arm.cobs")).unwrap();
        assert_eq!(errors, 0);
        assert!(arm.len() >= 320, "{} arm states", arm.len());
        let oni = dir.join("sequence.oni");
        let (poses, stats) = run_session(&oni, &arm, SessionConfig::new(nominal), 8).unwrap();
        assert!(poses.len() >= 5, "{} poses, {stats:?}", poses.len());
        let s = solve_poses(&poses, false).unwrap();
        let te = translation_error_m(&s.robot_base_from_camera, &truth);
        let re = rotation_error_deg(&s.robot_base_from_camera, &truth);
        assert!(
            te < 0.02 && re < 1.0,
            "{te} m, {re} deg from {} poses",
            poses.len()
        );
        // Without any guess: the guess-free start from one still frame per pose, then the session from it.
        let (frames, arms) = pose_keyframes(&oni, &arm, 8).unwrap();
        assert_eq!(arms.len(), 8, "one keyframe per pose");
        let (rough, tips) = guess_free_start(&frames, &arms, &Intrinsics::KINECT_V1).unwrap();
        let (te, re) = (
            translation_error_m(&rough.robot_base_from_camera, &truth),
            rotation_error_deg(&rough.robot_base_from_camera, &truth),
        );
        assert!(
            tips >= 6 && te < 0.1 && re < 3.0,
            "rough start {te} m, {re} deg, {tips} tips"
        );
        let (poses, stats) =
            run_session(&oni, &arm, SessionConfig::new(rough.robot_base_from_camera), 8).unwrap();
        assert!(
            poses.len() >= 5,
            "{} poses after the start, {stats:?}",
            poses.len()
        );
        let s = solve_poses(&poses, true).unwrap();
        let te = translation_error_m(&s.robot_base_from_camera, &truth);
        let re = rotation_error_deg(&s.robot_base_from_camera, &truth);
        assert!(
            te < 0.02 && re < 1.0,
            "{te} m, {re} deg after the guess-free start"
        );
        // The arm's clock a minute late (far beyond this 3.2 s sequence, so no frame overlaps a shifted arm state):
        // every frame is out of time, no pose comes out.
        let late: Vec<_> = arm
            .iter()
            .map(|a| supine_core::calib::ArmSample {
                time: a.time.offset_by(60_000_000),
                ..*a
            })
            .collect();
        let (poses, stats) = run_session(&oni, &late, SessionConfig::new(nominal), 8).unwrap();
        assert!(poses.is_empty());
        assert!(stats.out_of_time >= 80, "{stats:?}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
