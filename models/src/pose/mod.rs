//! Posing the body model: rest frames, forward kinematics and linear blend skinning with Blender's conventions
//! (`shared/reference/makehuman-assets.md` §3), and the bed-pose generator ([`bed`]).
//!
//! Conventions, all in the body frame (metres, z up, facing -y):
//! - rest frame of a bone: local y runs head → tail (the minimal rotation taking world Y onto it), then the bone's
//!   roll turns about local y; the root's rest rotation is the identity (as anny). `P_b = [R_b | head_b]`.
//! - a pose holds, per bone, Euler XYZ angles in the bone's local frame relative to rest (Blender pose-bone
//!   `rotation_euler`; `D = Rz·Ry·Rx`), plus a root translation.
//! - forward kinematics: `W_c = W_p · P_p⁻¹ · P_c · D_c`, skinning transform `T_b = W_b · P_b⁻¹`,
//!   `v' = Σ_b w_vb · T_b · v`. With every rotation zero, `W = P` and `T = I`: the rest pose comes back exactly.
//! - joints are re-derived from the shaped rest mesh (they are rows of the linear model), so the skeleton fits
//!   every body.
//!
//! Axes of the default rig (verified numerically in the notes): spine bones +x = forward flexion, +y = twist
//! turning the chest to the left, +z = lateral bend to the right. Rather than hand-tuning Euler angles for limbs,
//! [`aim_segment`] computes the local rotation that points a limb segment (e.g. shoulder → elbow) along a
//! direction given in the body frame, which keeps the bed poses readable and independent of the bones' rolls.

pub mod bed;

pub use bed::{ArmPose, BedPose, BedPoseSampler, LegPose, Lying, Rest, TrunkPose};

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use supine_core::salient::SalientPoint;

use crate::body::rig::NAVEL_VERTEX;
use std::borrow::Cow;

use crate::body::{BodyModel, PosedBody, Shape};

/// Per-bone rotations (Euler XYZ, radians, bone-local, relative to rest) and a root translation (metres).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// One `[rx, ry, rz]` per bone of the model's rig, in the model's bone order.
    pub rotations: Vec<[f32; 3]>,
    /// Translation of the root bone in its parent (armature) frame.
    pub root_translation: [f32; 3],
}

impl Pose {
    /// The rest pose (every rotation zero) for a rig of `bones` bones.
    pub fn rest(bones: usize) -> Pose {
        Pose {
            rotations: vec![[0.0; 3]; bones],
            root_translation: [0.0; 3],
        }
    }

    /// The rest pose for `model`.
    pub fn rest_for(model: &BodyModel) -> Pose {
        Pose::rest(model.bones.len())
    }

    /// Set the Euler angles of the bone called `name`; false when the model has no such bone.
    pub fn set(&mut self, model: &BodyModel, name: &str, euler_xyz: [f32; 3]) -> bool {
        match model.bone_index(name) {
            Some(b) => {
                self.rotations[b] = euler_xyz;
                true
            }
            None => false,
        }
    }

    /// The local rotation `D_b` of bone `b`.
    pub fn rotation(&self, b: usize) -> Rotation3<f64> {
        let [x, y, z] = self.rotations[b];
        Rotation3::from_euler_angles(x as f64, y as f64, z as f64)
    }
}

/// Read a MakeHuman pose file (`{"bone_rotations": {bone: [rx, ry, rz]}, "bone_translations": {"root": …}}`);
/// bones the model does not have (fingers, toes, face) are skipped and returned by name.
pub fn pose_from_makehuman_json(model: &BodyModel, json: &serde_json::Value) -> (Pose, Vec<String>) {
    let mut pose = Pose::rest_for(model);
    let mut skipped = Vec::new();
    if let Some(rot) = json["bone_rotations"].as_object() {
        for (name, r) in rot {
            let a = |i: usize| r.get(i).and_then(serde_json::Value::as_f64).unwrap_or(0.0) as f32;
            if !pose.set(model, name, [a(0), a(1), a(2)]) {
                skipped.push(name.clone());
            }
        }
    }
    if let Some(t) = json["bone_translations"]["root"].as_array() {
        let a = |i: usize| t.get(i).and_then(serde_json::Value::as_f64).unwrap_or(0.0) as f32;
        pose.root_translation = [a(0), a(1), a(2)];
    }
    skipped.sort();
    (pose, skipped)
}

fn v3(p: [f32; 3]) -> Vector3<f64> {
    Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// Blender's rest orientation of a bone from head, tail and roll.
pub fn bone_rest_rotation(head: Vector3<f64>, tail: Vector3<f64>, roll: f64) -> Rotation3<f64> {
    let y = (tail - head).normalize();
    let align = Rotation3::rotation_between(&Vector3::y(), &y).unwrap_or_else(|| {
        // Bone pointing straight down -Y: Blender uses diag(1, -1, -1).
        Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    });
    align * Rotation3::from_axis_angle(&Vector3::y_axis(), roll)
}

/// The rest skeleton of one shaped body.
#[derive(Clone, Debug)]
pub struct RestRig {
    /// Rest frame `P_b` of every bone (armature = body frame).
    pub frames: Vec<Isometry3<f64>>,
    /// Parent of every bone.
    pub parents: Vec<Option<usize>>,
    /// Rest joint positions.
    pub joints: Vec<Vector3<f64>>,
}

impl RestRig {
    /// Rest frames from the shaped joints of `model`.
    pub fn new(model: &BodyModel, joints: &[[f32; 3]]) -> RestRig {
        let joints: Vec<Vector3<f64>> = joints.iter().map(|&j| v3(j)).collect();
        let frames = model
            .bones
            .iter()
            .map(|b| {
                let head = joints[b.head];
                let rot = if b.parent.is_none() {
                    Rotation3::identity()
                } else {
                    bone_rest_rotation(head, joints[b.tail], b.roll as f64)
                };
                Isometry3::from_parts(
                    Translation3::from(head),
                    UnitQuaternion::from_rotation_matrix(&rot),
                )
            })
            .collect();
        RestRig {
            frames,
            parents: model.bones.iter().map(|b| b.parent).collect(),
            joints,
        }
    }

    /// World (body-frame) transforms `W_b` of every bone for `pose`.
    pub fn forward(&self, pose: &Pose) -> Vec<Isometry3<f64>> {
        let mut w: Vec<Isometry3<f64>> = Vec::with_capacity(self.frames.len());
        for (b, p) in self.frames.iter().enumerate() {
            let d = UnitQuaternion::from_rotation_matrix(&pose.rotation(b));
            let local = match self.parents[b] {
                Some(par) => w[par] * self.frames[par].inverse() * p,
                None => {
                    let t = pose.root_translation;
                    *p * Translation3::new(t[0] as f64, t[1] as f64, t[2] as f64)
                }
            };
            w.push(local * d);
        }
        w
    }

    /// Skinning transforms `T_b = W_b · P_b⁻¹`.
    pub fn skinning(&self, world: &[Isometry3<f64>]) -> Vec<Isometry3<f64>> {
        world
            .iter()
            .zip(&self.frames)
            .map(|(w, p)| w * p.inverse())
            .collect()
    }
}

/// Posed joints: each joint moves with a bone whose head it is, else with a bone whose tail it is.
fn posed_joints(model: &BodyModel, rig: &RestRig, t: &[Isometry3<f64>]) -> Vec<[f32; 3]> {
    (0..rig.joints.len())
        .map(|j| {
            let b = model
                .bones
                .iter()
                .position(|b| b.head == j)
                .or_else(|| model.bones.iter().position(|b| b.tail == j))
                .unwrap_or(0);
            let p = t[b] * Point3::from(rig.joints[j]);
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .collect()
}

/// Linear blend skinning of `model` with `shape` and `pose` (see the module docs).
pub fn pose_body<'m>(model: &'m BodyModel, shape: &Shape, pose: &Pose) -> PosedBody<'m> {
    let rest = model.rest_vertices(shape);
    let rest_joints = model.rest_joints(shape);
    let rig = RestRig::new(model, &rest_joints);
    let world = rig.forward(pose);
    let t = rig.skinning(&world);
    // Affine parts in f64 matrices: 9 mul-adds per influence.
    let mats: Vec<(nalgebra::Matrix3<f64>, Vector3<f64>)> = t
        .iter()
        .map(|x| (x.rotation.to_rotation_matrix().into_inner(), x.translation.vector))
        .collect();
    let vertices: Vec<[f32; 3]> = rest
        .iter()
        .zip(&model.skin)
        .map(|(v, inf)| {
            let p = v3(*v);
            let mut acc = Vector3::zeros();
            for &(b, w) in inf {
                let (r, tr) = &mats[b as usize];
                acc += (r * p + tr) * w as f64;
            }
            [acc.x as f32, acc.y as f32, acc.z as f32]
        })
        .collect();
    let joints = posed_joints(model, &rig, &t);
    let j = |name: &str| {
        model
            .joint_index(name)
            .map(|i| joints[i])
            .unwrap_or([f32::NAN; 3])
    };
    let mid = |a: [f32; 3], b: [f32; 3]| [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2])];
    let salient_points = SalientPoint::ALL.map(|p| match p {
        SalientPoint::Head => mid(j("joint-neck"), j("joint-head")),
        SalientPoint::LeftShoulder => j("joint-l-shoulder"),
        SalientPoint::RightShoulder => j("joint-r-shoulder"),
        SalientPoint::Belly => vertices[NAVEL_VERTEX as usize],
        SalientPoint::LeftHip => j("joint-l-upper-leg"),
        SalientPoint::RightHip => j("joint-r-upper-leg"),
    });
    PosedBody {
        vertices,
        triangles: Cow::Borrowed(&model.triangles),
        part_of_vertex: Cow::Borrowed(&model.part_of_vertex),
        salient_points,
        joints,
    }
}

/// The local rotation (as Euler XYZ) that makes the segment from joint `from` to joint `to` of bone `bone`'s
/// chain point along `dir` (body frame), given the rotations already in `pose` for the bone's ancestors. The
/// rotation is the minimal one (no twist about the segment).
pub fn aim_segment(
    rig: &RestRig,
    pose: &Pose,
    bone: usize,
    from: usize,
    to: usize,
    dir: Vector3<f64>,
) -> [f32; 3] {
    let world = rig.forward(pose);
    // Orientation the bone would have with D = I: A = W_p · P_p⁻¹ · P_c.
    let a = match rig.parents[bone] {
        Some(p) => world[p] * rig.frames[p].inverse() * rig.frames[bone],
        None => rig.frames[bone],
    };
    let seg_local = rig.frames[bone].rotation.inverse() * (rig.joints[to] - rig.joints[from]);
    let target_local = a.rotation.inverse() * dir;
    let d = Rotation3::rotation_between(&seg_local, &target_local).unwrap_or_else(Rotation3::identity);
    let (x, y, z) = d.euler_angles();
    [x as f32, y as f32, z as f32]
}
