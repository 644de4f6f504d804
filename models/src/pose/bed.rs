//! Bed poses from sub-poses, like the paper's HumanVP set (§4.1): upper body (bending, torsion) × left arm × right
//! arm × legs = 6 × 5 × 5 × 5 = 750 combinations, each jittered per sample, plus a lying variation.
//!
//! Split between pose and scene: everything articulated is in the [`Pose`] (spine, arms, legs, and the hip flexion
//! a raised head end forces); the [`Lying`] variation is rigid and maps the posed body frame to the **bed frame**
//! (x = the patient's left when supine, y toward the head end, z up from the mattress) with
//! [`Lying::bed_from_body`]: supine (front up), then raised by `head_raise_rad` about the bed's x axis (the
//! raised head section's hinge line passes through the hip joints, bed y = 0), then rolled by `tilt_rad` about the
//! bed's long axis (> 0 rolls the patient onto their left side), then translated so the hip-joint midpoint lies on
//! x = y = 0 and the lowest skin point on z = 0. The scene draws the mattress (and a raised head section) to match.
//!
//! Limb sub-poses are defined as segment directions or wrist targets in the frame of the chest (arms) or pelvis
//! (legs) of the mean body and applied with [`aim_segment`] and a two-bone IK, so they stay meaningful for every
//! body shape and every trunk pose.

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};

use super::{Pose, RestRig, aim_segment};
use crate::body::{BodyModel, BodyPart, PosedBody, SalientPoint, Shape};

/// Upper-body sub-pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum TrunkPose {
    /// Straight.
    Neutral,
    /// Lateral bend to the patient's left (15° over the spine).
    BendLeft,
    /// Lateral bend to the right.
    BendRight,
    /// Torsion turning the chest to the left (15°).
    TwistLeft,
    /// Torsion to the right.
    TwistRight,
    /// Forward flexion (15°: shoulders lifted off the mattress).
    Flexed,
}

/// Arm sub-pose (one arm).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum ArmPose {
    /// Straight along the side of the body.
    AtSide,
    /// Abducted 45° with the elbow bent 90° toward the head.
    Angled,
    /// Hand resting on the chest.
    HandOnChest,
    /// Hand under the back of the head (supporting it).
    SupportingHead,
    /// Raised toward the ceiling, elbow slightly bent.
    Raised,
}

/// Leg sub-pose (both legs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum LegPose {
    /// Both legs straight.
    Straight,
    /// Left knee up (hip and knee flexed, foot on the mattress).
    LeftKneeUp,
    /// Right knee up.
    RightKneeUp,
    /// Both knees up.
    BothKneesUp,
    /// Both legs straight and spread.
    Apart,
}

const TRUNKS: [TrunkPose; 6] = [
    TrunkPose::Neutral,
    TrunkPose::BendLeft,
    TrunkPose::BendRight,
    TrunkPose::TwistLeft,
    TrunkPose::TwistRight,
    TrunkPose::Flexed,
];
const ARMS: [ArmPose; 5] = [
    ArmPose::AtSide,
    ArmPose::Angled,
    ArmPose::HandOnChest,
    ArmPose::SupportingHead,
    ArmPose::Raised,
];
const LEGS: [LegPose; 5] = [
    LegPose::Straight,
    LegPose::LeftKneeUp,
    LegPose::RightKneeUp,
    LegPose::BothKneesUp,
    LegPose::Apart,
];

/// Number of sub-pose combinations.
pub const COMBINATIONS: usize = TRUNKS.len() * ARMS.len() * ARMS.len() * LEGS.len();

/// What a lying body rests on: where the bed's mattress meets it.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum Rest {
    /// The lowest skin point of the head, trunk and legs ([`Lying::bed_from_trunk`]): a hand under the head or
    /// beside the back sinks into the mattress.
    Trunk,
    /// The lowest skin point of the whole body, hands included ([`Lying::bed_from_body`]): one patient in seven to
    /// nine then lies on a hand, the torso 2-5 cm above the mattress (every dataset before this option).
    #[default]
    LowestPoint,
}

impl Rest {
    /// Whether this is the placement of the datasets before the option (the manifest then leaves `rest` out).
    pub(crate) fn is_lowest_point(&self) -> bool {
        *self == Rest::LowestPoint
    }
}

/// Rigid lying variation (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Lying {
    /// Roll about the bed's long axis, radians (> 0: onto the left side).
    pub tilt_rad: f32,
    /// Raised head end, radians (the pose carries the matching hip flexion).
    pub head_raise_rad: f32,
}

impl Lying {
    /// Flat supine.
    pub const SUPINE: Lying = Lying {
        tilt_rad: 0.0,
        head_raise_rad: 0.0,
    };

    /// Rotation part of body → bed.
    pub fn rotation(&self) -> Rotation3<f32> {
        // Supine: body z (head) → bed +y, body -y (front) → bed +z, x unchanged.
        let supine = Rotation3::from_axis_angle(&Vector3::x_axis(), -std::f32::consts::FRAC_PI_2);
        let raise = Rotation3::from_axis_angle(&Vector3::x_axis(), self.head_raise_rad);
        let tilt = Rotation3::from_axis_angle(&Vector3::y_axis(), self.tilt_rad);
        tilt * raise * supine
    }

    /// The rigid transform taking `posed` (body frame) onto the bed frame.
    pub fn bed_from_body(&self, posed: &PosedBody<'_>) -> Isometry3<f32> {
        self.resting_on(posed, |_| true)
    }

    /// [`Lying::bed_from_trunk`] or [`Lying::bed_from_body`], as `rest` says.
    pub fn bed_from(&self, posed: &PosedBody<'_>, rest: Rest) -> Isometry3<f32> {
        match rest {
            Rest::Trunk => self.bed_from_trunk(posed),
            Rest::LowestPoint => self.bed_from_body(posed),
        }
    }

    /// [`Lying::bed_from_body`] with the body resting on the lowest skin point of its head, trunk and legs, the arms
    /// left out: a hand under the head, or beside a back on a raised head section, lies lower than the back and
    /// would hold the torso 2-7 cm off the mattress (and, as the arms move in a sequence, lift and drop it); here
    /// the hand sinks into the mattress instead.
    pub fn bed_from_trunk(&self, posed: &PosedBody<'_>) -> Isometry3<f32> {
        self.resting_on(posed, |part| {
            !BodyPart::from_u8(part).is_some_and(BodyPart::is_arm)
        })
    }

    /// The placement of the module docs, resting on the lowest vertex whose part `rests` accepts.
    fn resting_on(&self, posed: &PosedBody<'_>, rests: impl Fn(u8) -> bool) -> Isometry3<f32> {
        let r = self.rotation();
        let hl = posed.salient_points[SalientPoint::LeftHip as usize];
        let hr = posed.salient_points[SalientPoint::RightHip as usize];
        let hip = r * Vector3::new(
            0.5 * (hl[0] + hr[0]),
            0.5 * (hl[1] + hr[1]),
            0.5 * (hl[2] + hr[2]),
        );
        let min_z = posed
            .vertices
            .iter()
            .zip(posed.part_of_vertex.iter())
            .filter(|&(_, &part)| rests(part))
            .map(|(v, _)| (r * Vector3::new(v[0], v[1], v[2])).z)
            .fold(f32::INFINITY, f32::min);
        Isometry3::from_parts(
            Translation3::new(-hip.x, -hip.y, -min_z),
            UnitQuaternion::from_rotation_matrix(&r),
        )
    }
}

/// One sampled bed pose.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BedPose {
    /// Index of the sub-pose combination, 0..750.
    pub combination: usize,
    /// Upper-body sub-pose.
    pub trunk: TrunkPose,
    /// Left-arm sub-pose.
    pub left_arm: ArmPose,
    /// Right-arm sub-pose.
    pub right_arm: ArmPose,
    /// Legs sub-pose.
    pub legs: LegPose,
    /// Lying variation.
    pub lying: Lying,
    /// The articulated pose.
    pub pose: Pose,
}

/// Bone and joint indices the generator needs.
#[derive(Clone, Debug)]
struct Limb {
    upper: usize,
    lower: usize,
    root_joint: usize,
    mid_joint: usize,
    end_joint: usize,
}

/// Samples bed poses for one model (sub-poses are laid out on its mean body).
#[derive(Clone, Debug)]
pub struct BedPoseSampler {
    n_bones: usize,
    rig: RestRig,
    spine: [usize; 5],
    neck: usize,
    head: usize,
    chest_bone: usize,
    arms: [Limb; 2],
    legs: [Limb; 2],
    sternum: Vector3<f64>,
    head_back: Vector3<f64>,
}

fn deg(x: f64) -> f64 {
    x.to_radians()
}

fn unit(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z).normalize()
}

impl BedPoseSampler {
    /// Prepare the sampler for `model`. Panics only when the model lacks the default rig's bones (every model
    /// built by this crate has them).
    pub fn new(model: &BodyModel) -> BedPoseSampler {
        let bone = |n: &str| {
            model
                .bone_index(n)
                .unwrap_or_else(|| panic!("body model lacks bone {n}"))
        };
        let rig = RestRig::new(model, &model.rest_joints(&Shape::MEAN));
        let limb = |upper: &str, upper2: &str, lower: &str, lower2: &str| {
            let (u, u2, l, l2) = (bone(upper), bone(upper2), bone(lower), bone(lower2));
            Limb {
                upper: u,
                lower: l,
                root_joint: model.bones[u].head,
                mid_joint: model.bones[u2].tail,
                end_joint: model.bones[l2].tail,
            }
        };
        let rest = model.rest_vertices(&Shape::MEAN);
        let sternum = {
            let p = rest[crate::body::rig::STERNUM_VERTEX as usize];
            Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
        };
        let hj = rig.joints[model.bones[bone("head")].head];
        BedPoseSampler {
            n_bones: model.bones.len(),
            spine: [
                bone("spine05"),
                bone("spine04"),
                bone("spine03"),
                bone("spine02"),
                bone("spine01"),
            ],
            neck: bone("neck01"),
            head: bone("head"),
            chest_bone: bone("spine01"),
            arms: [
                limb("upperarm01.L", "upperarm02.L", "lowerarm01.L", "lowerarm02.L"),
                limb("upperarm01.R", "upperarm02.R", "lowerarm01.R", "lowerarm02.R"),
            ],
            legs: [
                limb("upperleg01.L", "upperleg02.L", "lowerleg01.L", "lowerleg02.L"),
                limb("upperleg01.R", "upperleg02.R", "lowerleg01.R", "lowerleg02.R"),
            ],
            sternum,
            // Behind the skull base: where a supporting hand lies.
            head_back: hj + Vector3::new(0.0, 0.12, 0.05),
            rig,
        }
    }

    /// The sub-poses of combination `i` (0..[`COMBINATIONS`]).
    pub fn combination(i: usize) -> (TrunkPose, ArmPose, ArmPose, LegPose) {
        let i = i % COMBINATIONS;
        (
            TRUNKS[i / 125],
            ARMS[(i / 25) % 5],
            ARMS[(i / 5) % 5],
            LEGS[i % 5],
        )
    }

    /// A random bed pose: uniform combination, jittered angles, lying variation (50 % flat supine, 25 % tilted
    /// 8–20° to either side, 25 % head end raised 15–45°).
    pub fn sample<R: Rng>(&self, rng: &mut R) -> BedPose {
        let combination = rng.gen_range(0..COMBINATIONS);
        let small = Normal::new(0.0, deg(2.0)).expect("finite");
        let lying = match rng.gen_range(0..4) {
            0 | 1 => Lying {
                tilt_rad: small.sample(rng) as f32,
                head_raise_rad: 0.0,
            },
            2 => {
                let side = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
                Lying {
                    tilt_rad: (side * deg(rng.gen_range(8.0..20.0))) as f32,
                    head_raise_rad: 0.0,
                }
            }
            _ => Lying {
                tilt_rad: small.sample(rng) as f32,
                head_raise_rad: deg(rng.gen_range(15.0..45.0)) as f32,
            },
        };
        self.build(combination, lying, Some(rng))
    }

    /// The pose of `combination` with `lying`, without jitter (the canonical sub-pose).
    pub fn canonical(&self, combination: usize, lying: Lying) -> BedPose {
        self.build::<rand_chacha::ChaCha8Rng>(combination, lying, None)
    }

    fn build<R: Rng>(&self, combination: usize, lying: Lying, mut rng: Option<&mut R>) -> BedPose {
        let (trunk, left_arm, right_arm, legs) = Self::combination(combination);
        let mut jitter = |sd_deg: f64| -> f64 {
            match rng.as_deref_mut() {
                Some(r) => Normal::new(0.0, deg(sd_deg)).expect("finite").sample(r),
                None => 0.0,
            }
        };
        let mut pose = Pose::rest(self.n_bones);

        // Trunk: (flexion +x, twist +y, lateral bend +z toward the right), spread evenly over 5 spine bones.
        let (fx, ty, bz) = match trunk {
            TrunkPose::Neutral => (0.0, 0.0, 0.0),
            TrunkPose::BendLeft => (0.0, 0.0, -15.0),
            TrunkPose::BendRight => (0.0, 0.0, 15.0),
            TrunkPose::TwistLeft => (0.0, 15.0, 0.0),
            TrunkPose::TwistRight => (0.0, -15.0, 0.0),
            TrunkPose::Flexed => (15.0, 0.0, 0.0),
        };
        let (fx, ty, bz) = (
            deg(fx) + jitter(3.0),
            deg(ty) + jitter(3.0),
            deg(bz) + jitter(3.0),
        );
        for &b in &self.spine {
            pose.rotations[b] = [(fx / 5.0) as f32, (ty / 5.0) as f32, (bz / 5.0) as f32];
        }
        pose.rotations[self.neck] = [jitter(5.0) as f32, jitter(5.0) as f32, jitter(4.0) as f32];
        pose.rotations[self.head] = [jitter(5.0) as f32, jitter(8.0) as f32, jitter(4.0) as f32];

        // Legs, in the pelvis (= body) frame; a raised head end flexes both hips by the same angle so the legs
        // stay on the flat part of the mattress.
        let hip_flex = Rotation3::from_axis_angle(&Vector3::x_axis(), -(lying.head_raise_rad as f64));
        for (side, limb) in self.legs.iter().enumerate() {
            let sx = if side == 0 { 1.0 } else { -1.0 };
            let knee_up = match legs {
                LegPose::LeftKneeUp => side == 0,
                LegPose::RightKneeUp => side == 1,
                LegPose::BothKneesUp => true,
                _ => false,
            };
            let (thigh, shank) = if knee_up {
                let a = deg(45.0) + jitter(6.0);
                let k = deg(45.0) + jitter(6.0);
                (
                    unit(sx * 0.05, -a.sin(), -a.cos()),
                    unit(sx * 0.03, k.sin(), -k.cos()),
                )
            } else {
                let spread = if legs == LegPose::Apart {
                    deg(12.0)
                } else {
                    deg(2.0)
                } + jitter(2.0);
                let flex = jitter(3.0).abs();
                let d = unit(sx * spread.sin(), -flex.sin(), -spread.cos());
                (d, d)
            };
            self.aim_limb(&mut pose, limb, hip_flex * thigh, hip_flex * shank, &mut jitter);
        }

        // Arms, in the chest frame (they follow trunk bending and torsion).
        let chest = {
            let w = self.rig.forward(&pose);
            w[self.chest_bone] * self.rig.frames[self.chest_bone].inverse()
        };
        for (side, (limb, arm)) in self.arms.iter().zip([left_arm, right_arm]).enumerate() {
            let sx = if side == 0 { 1.0 } else { -1.0 };
            let (upper, fore) = match arm {
                ArmPose::AtSide => (unit(sx * 0.12, 0.0, -1.0), unit(sx * 0.10, -0.05, -1.0)),
                ArmPose::Angled => (unit(sx, 0.0, -1.0), unit(sx, -0.15, 1.0)),
                ArmPose::Raised => (unit(sx * 0.15, -0.9, 0.4), unit(sx * 0.1, -0.75, 0.65)),
                ArmPose::HandOnChest => {
                    let target = self.sternum + Vector3::new(sx * 0.09, -0.07, -0.06);
                    self.two_bone(limb, target, unit(sx, 0.3, -0.6), &mut jitter)
                }
                ArmPose::SupportingHead => {
                    let target = self.head_back + Vector3::new(sx * 0.09, 0.0, 0.0);
                    self.two_bone(limb, target, unit(sx, 0.0, 0.5), &mut jitter)
                }
            };
            let r = chest.rotation.to_rotation_matrix();
            self.aim_limb(&mut pose, limb, r * upper, r * fore, &mut jitter);
        }
        BedPose {
            combination,
            trunk,
            left_arm,
            right_arm,
            legs,
            lying,
            pose,
        }
    }

    /// Upper and lower segment directions that put the limb's end joint at `target` (mean body, body frame), the
    /// middle joint bending toward `pole`.
    fn two_bone(
        &self,
        limb: &Limb,
        target: Vector3<f64>,
        pole: Vector3<f64>,
        jitter: &mut impl FnMut(f64) -> f64,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let j = &self.rig.joints;
        let s = j[limb.root_joint];
        let l1 = (j[limb.mid_joint] - s).norm();
        let l2 = (j[limb.end_joint] - j[limb.mid_joint]).norm();
        // Jitter the target by ~2 cm (jitter takes degrees; 1.15° of a 1 m lever ≈ 2 cm).
        let t = target + Vector3::new(jitter(1.15), jitter(1.15), jitter(1.15));
        let to = t - s;
        let d = to.norm().clamp((l1 - l2).abs() + 1e-3, l1 + l2 - 1e-3);
        let e = to.normalize();
        let a = (l1 * l1 - l2 * l2 + d * d) / (2.0 * d);
        let h = (l1 * l1 - a * a).max(0.0).sqrt();
        let perp = (pole - e * pole.dot(&e)).normalize();
        let elbow = s + e * a + perp * h;
        let hand = s + e * d;
        ((elbow - s).normalize(), (hand - elbow).normalize())
    }

    fn aim_limb(
        &self,
        pose: &mut Pose,
        limb: &Limb,
        upper: Vector3<f64>,
        lower: Vector3<f64>,
        jitter: &mut impl FnMut(f64) -> f64,
    ) {
        let wobble = |v: Vector3<f64>, j: &mut dyn FnMut(f64) -> f64| {
            let r = Rotation3::from_euler_angles(j(4.0), j(4.0), j(4.0));
            r * v
        };
        let upper = wobble(upper, jitter);
        let lower = wobble(lower, jitter);
        pose.rotations[limb.upper] = aim_segment(
            &self.rig,
            pose,
            limb.upper,
            limb.root_joint,
            limb.mid_joint,
            upper,
        );
        pose.rotations[limb.lower] =
            aim_segment(&self.rig, pose, limb.lower, limb.mid_joint, limb.end_joint, lower);
    }
}

/// Posed bodies are in the body frame; this helper poses and places one on the bed, resting on `rest`, in a
/// single call.
pub fn pose_on_bed<'m>(model: &'m BodyModel, shape: &Shape, bed: &BedPose, rest: Rest) -> PosedBody<'m> {
    let posed = model.pose(shape, &bed.pose);
    let t = bed.lying.bed_from(&posed, rest);
    posed.transformed(&t)
}
