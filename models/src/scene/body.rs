//! The patient as the scene sees it: a posed skin mesh in the `body` frame plus its six salient points, from any
//! [`BodySource`], and [`Mannequin`], a small procedural body (ellipsoids and capsules with shape and pose
//! parameters) used by tests and as a fallback when the statistical body model artifact is not built.
//!
//! The statistical model (MakeHuman mesh, PCA shapes, LBS, bed poses) is adapted to [`BodySource`] in
//! [`super::model_body`]. Sampling a mannequin costs a few thousand vertices; no per-frame cost.

use std::borrow::Cow;

use super::shapes::TriMesh;
use crate::body::PosedBody;
use crate::pose::Rest;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The patient lying on the bed: a posed body in the **bed frame** (metres, origin on the mattress top at its
/// centre, z up, y toward the head end, x the patient's left when supine) and what the ground truth records about it.
#[derive(Debug, Clone)]
pub struct Patient {
    /// The posed body (skin, part ids, salient points in [`SalientPoint`](supine_core::salient::SalientPoint)
    /// order, joints), bed frame.
    pub body: PosedBody<'static>,
    /// Names of the part ids of [`PosedBody::part_of_vertex`].
    pub part_names: Vec<String>,
    /// Shape coefficients (population-model units, e.g. PCA standard deviations).
    pub shape: Vec<f32>,
    /// Pose parameters as the source describes them (recorded verbatim in the ground truth).
    pub pose: serde_json::Value,
    /// How far the bed's head section is raised, radians (the body is posed to lie on it).
    pub head_raise_rad: f32,
    /// Bed-frame y of the head section's hinge, metres.
    pub hinge_y_m: f32,
}

/// Something that produces patients: the statistical model or the mannequin.
pub trait BodySource: Sync {
    /// Short name recorded in dataset metadata.
    fn name(&self) -> String;
    /// Body-part names indexed by the part ids of [`PosedBody::part_of_vertex`].
    fn part_names(&self) -> Vec<String>;
    /// A random body (shape from the population, pose from the bed-pose distribution), deterministic for `rng`,
    /// resting on `rest` (sources with a placement of their own, the mannequin's, ignore it).
    fn sample(&self, rng: &mut ChaCha8Rng, rest: Rest) -> anyhow::Result<Patient>;
    /// The body with `shape` fixed and the pose blended between two sampled poses (`t` in 0..1), for slow motion in
    /// sequences: `a` and `b` are pose seeds. Sources that cannot interpolate return the `a` pose.
    fn sample_motion(&self, shape_seed: u64, a: u64, b: u64, t: f32) -> anyhow::Result<Patient>;
    /// Skin vertex indices of the torso surface the tracker's model is made of (the body model's torso ICP
    /// subset); `None` for sources without one.
    fn torso_subset(&self) -> Option<Vec<u32>> {
        None
    }
}

/// Parameters of the procedural mannequin.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MannequinParams {
    /// Shape: [height, girth, belly] in standard deviations.
    pub shape: [f32; 3],
    /// Shoulder abduction left/right, radians (0 = arm along the body).
    pub shoulder_abduction: [f32; 2],
    /// Shoulder flexion left/right, radians (positive lifts the arm forward, towards −y).
    pub shoulder_flexion: [f32; 2],
    /// Elbow flexion left/right, radians.
    pub elbow_flexion: [f32; 2],
    /// Hip abduction left/right, radians.
    pub hip_abduction: [f32; 2],
    /// Knee flexion left/right, radians.
    pub knee_flexion: [f32; 2],
    /// Roll about the body's long axis when lying, radians (positive turns the patient's left side down).
    pub side_tilt: f32,
    /// Raised head section of the bed, radians; the mannequin bends at the hips to lie on it.
    pub head_raise: f32,
}

/// Bed-frame y of the head-section hinge used for the mannequin (the bed is 2 m long, centred on y = 0).
pub const MANNEQUIN_HINGE_Y: f32 = 0.1;

/// Procedural body made of ellipsoids and capsules (13 parts); a test fixture and fallback, not a population model.
#[derive(Debug, Clone, Copy, Default)]
pub struct Mannequin;

/// Part names of the mannequin, indexed by part id.
pub const MANNEQUIN_PARTS: [&str; 13] = [
    "head",
    "neck",
    "chest",
    "belly",
    "pelvis",
    "left_upper_arm",
    "right_upper_arm",
    "left_forearm",
    "right_forearm",
    "left_thigh",
    "right_thigh",
    "left_shin",
    "right_shin",
];

impl Mannequin {
    /// Random parameters: shape ~ N(0, 1) (clamped to ±2.5), pose from a small bed-pose range.
    pub fn sample_params(rng: &mut ChaCha8Rng) -> MannequinParams {
        let n = Normal::new(0.0f32, 1.0).expect("unit normal");
        let mut shape = [0.0; 3];
        for s in &mut shape {
            *s = n.sample(rng).clamp(-2.5, 2.5);
        }
        let mut pair = |lo: f32, hi: f32| [rng.gen_range(lo..hi), rng.gen_range(lo..hi)];
        MannequinParams {
            shape,
            shoulder_abduction: pair(0.05, 0.7),
            shoulder_flexion: pair(-0.1, 0.6),
            elbow_flexion: pair(0.0, 1.4),
            hip_abduction: pair(0.0, 0.2),
            knee_flexion: pair(0.0, 0.3),
            side_tilt: rng.gen_range(-0.17..0.17),
            head_raise: if rng.gen_bool(0.4) {
                0.0
            } else {
                rng.gen_range(0.1..0.55)
            },
        }
    }

    /// Build the posed mesh for `p`, lying supine on the bed (see [`lie_on_bed`]).
    pub fn build(p: &MannequinParams) -> Patient {
        let height = 1.72 * (1.0 + 0.055 * p.shape[0]);
        let girth = 1.0 + 0.08 * p.shape[1];
        let belly = 1.0 + 0.12 * p.shape[2];
        let h = |f: f32| f * height;
        let mut parts: Vec<(u8, TriMesh)> = Vec::new();
        let mut add = |id: u8, f: &dyn Fn(&mut TriMesh)| {
            let mut m = TriMesh::default();
            f(&mut m);
            parts.push((id, m));
        };
        let at = |x: f32, y: f32, z: f32| {
            Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::identity())
        };
        let head_c = [0.0, 0.0, h(0.935)];
        add(0, &|m| {
            m.add_ellipsoid(
                &at(head_c[0], head_c[1], head_c[2]),
                [0.078, 0.095, 0.115],
                12,
                20,
            )
        });
        add(1, &|m| {
            m.add_capsule([0.0, 0.0, h(0.80)], [0.0, 0.0, h(0.87)], 0.055 * girth, 14)
        });
        let chest_c = h(0.71);
        add(2, &|m| {
            m.add_ellipsoid(&at(0.0, 0.0, chest_c), [0.17 * girth, 0.11 * girth, 0.14], 14, 28)
        });
        let belly_c = [0.0, -0.01 * belly, h(0.60)];
        add(3, &|m| {
            m.add_ellipsoid(
                &at(belly_c[0], belly_c[1], belly_c[2]),
                [0.15 * girth, 0.11 * girth * belly, 0.12],
                14,
                28,
            )
        });
        add(4, &|m| {
            m.add_ellipsoid(&at(0.0, 0.0, h(0.52)), [0.17 * girth, 0.11 * girth, 0.09], 12, 26)
        });
        let shoulder = |side: f32| [side * 0.19 * girth, 0.0, h(0.815)];
        let hip = |side: f32| [side * 0.09 * girth, 0.0, h(0.50)];
        let mut salient = [[0.0f32; 3]; 6];
        salient[0] = head_c;
        salient[1] = shoulder(1.0);
        salient[2] = shoulder(-1.0);
        salient[3] = [0.0, -0.11 * girth * belly, h(0.60)];
        salient[4] = hip(1.0);
        salient[5] = hip(-1.0);
        for (k, side) in [(0usize, 1.0f32), (1, -1.0)] {
            // Arm: hangs along −z, abducted about the body's y axis, flexed forward about x.
            let s = Vector3::from(shoulder(side));
            let rot = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), p.shoulder_flexion[k])
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), side * p.shoulder_abduction[k]);
            let upper = rot * Vector3::new(0.0, 0.0, -h(0.17));
            let elbow = s + upper;
            let fore_rot = rot * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), p.elbow_flexion[k]);
            let wrist = elbow + fore_rot * Vector3::new(0.0, 0.0, -h(0.15));
            let r = 0.042 * girth;
            add(5 + k as u8, &|m| m.add_capsule(s.into(), elbow.into(), r, 14));
            add(7 + k as u8, &|m| {
                m.add_capsule(elbow.into(), wrist.into(), 0.85 * r, 14)
            });
            let hp = Vector3::from(hip(side));
            let leg_rot = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -side * p.hip_abduction[k]);
            let knee = hp + leg_rot * Vector3::new(0.0, 0.0, -h(0.245));
            let shin_rot = leg_rot * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -p.knee_flexion[k]);
            let ankle = knee + shin_rot * Vector3::new(0.0, 0.0, -h(0.23));
            add(9 + k as u8, &|m| {
                m.add_capsule(hp.into(), knee.into(), 0.075 * girth, 16)
            });
            add(11 + k as u8, &|m| {
                m.add_capsule(knee.into(), ankle.into(), 0.055 * girth, 14)
            });
        }
        let mut mesh = TriMesh::default();
        let mut vertex_part = Vec::new();
        for (id, m) in &parts {
            mesh.append(m, &Isometry3::identity());
            vertex_part.resize(mesh.vertices.len(), *id);
        }
        let mut body = Patient {
            body: PosedBody {
                vertices: mesh.vertices,
                triangles: Cow::Owned(mesh.triangles),
                part_of_vertex: Cow::Owned(vertex_part),
                salient_points: salient,
                joints: Vec::new(),
            },
            part_names: Mannequin.part_names(),
            shape: p.shape.to_vec(),
            pose: serde_json::to_value(p).unwrap_or(serde_json::Value::Null),
            head_raise_rad: 0.0,
            hinge_y_m: MANNEQUIN_HINGE_Y,
        };
        let hips = Vector3::from(salient[4]).lerp(&Vector3::from(salient[5]), 0.5);
        lie_on_bed(&mut body, hips, p.side_tilt, p.head_raise, MANNEQUIN_HINGE_Y);
        body
    }
}

/// Move a body given in the body frame (z up, facing −y) onto the mattress (bed frame, z = 0 the mattress top):
/// supine with the hips `hinge_y − 0.05` m along the bed, rolled by `side_tilt` about its long axis, resting on the
/// mattress (lowest point 1 cm into it), then bent about the hinge line by `head_raise` with a 16 cm blend band so
/// the upper body lies on the raised head section. Salient points move with the skin.
pub fn lie_on_bed(patient: &mut Patient, hips: Vector3<f32>, side_tilt: f32, head_raise: f32, hinge_y: f32) {
    let body = &mut patient.body;
    let bed_from_body = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), side_tilt)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -std::f32::consts::FRAC_PI_2);
    let place = |p: [f32; 3]| bed_from_body * (Vector3::from(p) - hips);
    let mut zmin = f32::INFINITY;
    for v in &body.vertices {
        zmin = zmin.min(place(*v).z);
    }
    let offset = Vector3::new(0.0, hinge_y - 0.05, -zmin - 0.01);
    const BAND: f32 = 0.08;
    let bend = |q: Vector3<f32>| {
        let t = ((q.y - (hinge_y - BAND)) / (2.0 * BAND)).clamp(0.0, 1.0);
        let a = head_raise * t * t * (3.0 - 2.0 * t); // smoothstep keeps the crease free of folds
        let (s, c) = a.sin_cos();
        let (y, z) = (q.y - hinge_y, q.z);
        Vector3::new(q.x, hinge_y + c * y - s * z, s * y + c * z)
    };
    for v in body.vertices.iter_mut().chain(body.salient_points.iter_mut()) {
        *v = bend(place(*v) + offset).into();
    }
    patient.head_raise_rad = head_raise;
    patient.hinge_y_m = hinge_y;
}

impl BodySource for Mannequin {
    fn name(&self) -> String {
        "mannequin".into()
    }

    fn part_names(&self) -> Vec<String> {
        MANNEQUIN_PARTS.iter().map(|s| s.to_string()).collect()
    }

    fn sample(&self, rng: &mut ChaCha8Rng, _rest: Rest) -> anyhow::Result<Patient> {
        Ok(Mannequin::build(&Mannequin::sample_params(rng)))
    }

    fn sample_motion(&self, shape_seed: u64, a: u64, b: u64, t: f32) -> anyhow::Result<Patient> {
        use rand_chacha::rand_core::SeedableRng;
        let shape = Mannequin::sample_params(&mut ChaCha8Rng::seed_from_u64(shape_seed)).shape;
        let pa = Mannequin::sample_params(&mut ChaCha8Rng::seed_from_u64(a));
        let pb = Mannequin::sample_params(&mut ChaCha8Rng::seed_from_u64(b));
        let mix = |x: [f32; 2], y: [f32; 2]| [x[0] + (y[0] - x[0]) * t, x[1] + (y[1] - x[1]) * t];
        let p = MannequinParams {
            shape,
            shoulder_abduction: mix(pa.shoulder_abduction, pb.shoulder_abduction),
            shoulder_flexion: mix(pa.shoulder_flexion, pb.shoulder_flexion),
            elbow_flexion: mix(pa.elbow_flexion, pb.elbow_flexion),
            hip_abduction: mix(pa.hip_abduction, pb.hip_abduction),
            knee_flexion: mix(pa.knee_flexion, pb.knee_flexion),
            side_tilt: pa.side_tilt,
            head_raise: pa.head_raise,
        };
        Ok(Mannequin::build(&p))
    }
}
