//! The evaluation episodes of a tracking sequence: the full occlusion (the arm moves in, parks between the head and
//! the torso so that almost none of the torso stays visible, holds for about 1 s, then leaves) and the patient's
//! motion (a 15–20° roll onto one side or a 10 cm shift on the mattress, eased in over about 1.5 s and then held).
//!
//! Timeline (frame indices, half-open ranges): the full occlusion's approach starts at 30 % of the sequence, the arm
//! reaches the park pose after `transit` frames, stays `full_occlusion` frames, and is back on its path (the sweep,
//! or its home pose above the robot's shoulder when there is no sweep) `transit` frames later. The motion starts at
//! 60 % of the sequence when there is a full occlusion (30 % otherwise) and never before the arm has left.
//!
//! The park pose is searched once, on the scene at the approach's first frame: a few hundred reachable arm poses
//! with the wrist and probe along the line of sight from the head to the torso centre, 0.25–0.9 m in front of the
//! camera and clear of the head and of the patient; each is rendered alone against the scene's torso pixels and the
//! one hiding most of them wins (past 95 %, the one farthest from the camera), then up to 200 local moves refine it
//! while it hides less than 95 %. Cost: ~2 ms per candidate, about a second per sequence; nothing per frame but the
//! episode transforms.
//!
//! All draws come from their own generators (seeded from the sequence seed), so sequences without episodes are the
//! same bytes as before the episodes existed.

use crate::dataset::{contact_at, elbow_hint, mix_seed};
use crate::render::{Label, Renderer};
use crate::scene::Scene;
use crate::scene::arm::{ArmState, FORE_LINK_M, PROBE_REACH_M, UPPER_LINK_M};
use crate::scene::shapes::vertex_normals;
use anyhow::{Result, ensure};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;

/// What the patient does in the motion episode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum MotionKind {
    /// A roll of 15–20° onto one side about a line along the bed under that side.
    Roll,
    /// A 10 cm shift on the mattress in a random direction.
    Shift,
}

impl MotionKind {
    /// The kind a bare `--motion` picks for `seed`.
    pub fn for_seed(seed: u64) -> MotionKind {
        if mix_seed(seed, 0x307) & 1 == 0 {
            MotionKind::Roll
        } else {
            MotionKind::Shift
        }
    }
}

/// Episode lengths in frames.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpisodeFrames {
    /// Frames of arm motion into and out of the park pose.
    pub transit: u32,
    /// Frames the arm stays parked over the torso.
    pub full_occlusion: u32,
    /// Frames over which the roll or shift eases in.
    pub motion: u32,
}

impl Default for EpisodeFrames {
    /// At 30 Hz: 0.33 s transits, a 1 s park, a 1.5 s motion.
    fn default() -> Self {
        EpisodeFrames {
            transit: 10,
            full_occlusion: 30,
            motion: 45,
        }
    }
}

/// The full-occlusion episode as `sequence.json` records it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FullOcclusion {
    /// First frame with the arm parked.
    pub start: u32,
    /// One past the last parked frame: recovery is counted from here.
    pub end: u32,
    /// First frame of the approach (the arm leaves its path).
    pub approach_start: u32,
    /// One past the last frame of the arm's way back.
    pub leave_end: u32,
    /// Distance of the probe's wrist from the camera in the park pose, metres.
    pub park_distance_m: f32,
    /// Fraction of the torso pixels the park pose hid when it was chosen.
    pub planned_torso_occluded_fraction: f32,
    /// Smallest torso occluded fraction over the parked frames (measured on every frame).
    pub torso_occluded_fraction_min: f32,
}

/// The motion episode as `sequence.json` records it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Motion {
    /// Roll or shift.
    pub kind: MotionKind,
    /// First frame of the motion.
    pub start: u32,
    /// One past its last frame; the patient stays where the motion left them.
    pub end: u32,
    /// Roll angle, degrees, positive toward the patient's left (0 for a shift).
    pub roll_deg: f32,
    /// Shift in the mattress plane (bed frame x across, y along the bed), metres (zeros for a roll).
    pub shift_m: [f32; 2],
    /// A point of the roll axis (along the bed's y), bed frame, metres.
    pub pivot_bed: [f32; 3],
}

impl Motion {
    /// Fraction of the motion done at frame `f` (smoothstep from `start` to `end`, then 1).
    pub fn progress(&self, f: u32) -> f32 {
        if f < self.start {
            return 0.0;
        }
        let len = (self.end - self.start).max(1) as f32;
        smoothstep((f - self.start) as f32 / len)
    }

    /// The patient's displacement at frame `f`, applied in the bed frame after breathing and drift.
    pub fn bed_transform(&self, f: u32) -> Isometry3<f32> {
        let s = self.progress(f);
        match self.kind {
            MotionKind::Roll => {
                let pivot = Vector3::from(self.pivot_bed);
                // +y is the patient's long axis toward the head: turning about it by +a lifts the right side (−x)
                // about a pivot under the left edge.
                let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), (self.roll_deg * s).to_radians());
                Isometry3::from_parts(Translation3::from(pivot - r * pivot), r)
            }
            MotionKind::Shift => Isometry3::translation(self.shift_m[0] * s, self.shift_m[1] * s, 0.0),
        }
    }
}

/// Both episodes of a sequence (absent ones are `None`).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Episodes {
    /// The full occlusion.
    pub full_occlusion: Option<FullOcclusion>,
    /// The roll or shift.
    pub motion: Option<Motion>,
}

/// Where the arm is in the full-occlusion episode at a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArmPhase {
    /// On its own path (the sweep, or absent).
    Path,
    /// Moving from its path toward the park pose; the blend toward the park pose.
    Approach(f32),
    /// Parked.
    Parked,
    /// Moving back; the blend back toward its path.
    Leave(f32),
}

impl FullOcclusion {
    /// The arm's phase at frame `f`.
    pub fn phase(&self, f: u32) -> ArmPhase {
        let blend = |from: u32, to: u32| smoothstep((f - from + 1) as f32 / (to - from + 1) as f32);
        if f < self.approach_start || f >= self.leave_end {
            ArmPhase::Path
        } else if f < self.start {
            ArmPhase::Approach(blend(self.approach_start, self.start))
        } else if f < self.end {
            ArmPhase::Parked
        } else {
            ArmPhase::Leave(blend(self.end, self.leave_end))
        }
    }
}

/// Plan the episodes of a sequence of `frames` frames: ranges and the motion's parameters. `hips_bed` is the hip
/// centre and `half_width` the half shoulder width of the patient at frame 0 (bed frame), for the roll's pivot.
pub fn plan(
    frames: u32,
    seed: u64,
    full_occlusion: bool,
    motion: Option<MotionKind>,
    lengths: &EpisodeFrames,
    hips_bed: Vector3<f32>,
    half_width: f32,
) -> Result<Episodes> {
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, 0xE915));
    let mut out = Episodes::default();
    let mut free_from = 0;
    if full_occlusion {
        ensure!(
            lengths.full_occlusion > 0 && lengths.transit > 0,
            "the full occlusion needs a park and a transit of at least one frame"
        );
        let approach_start = (frames as f32 * 0.3).round() as u32;
        let start = approach_start + lengths.transit;
        let end = start + lengths.full_occlusion;
        let leave_end = end + lengths.transit;
        ensure!(
            leave_end < frames,
            "--full-occlusion needs more than {} frames ({} of them before the approach)",
            (leave_end as f32 / 0.7).ceil() as u32,
            approach_start
        );
        out.full_occlusion = Some(FullOcclusion {
            start,
            end,
            approach_start,
            leave_end,
            park_distance_m: 0.0,
            planned_torso_occluded_fraction: 0.0,
            torso_occluded_fraction_min: 1.0,
        });
        free_from = leave_end;
    }
    if let Some(kind) = motion {
        ensure!(lengths.motion > 0, "the motion needs at least one frame");
        let at = if full_occlusion { 0.6 } else { 0.3 };
        let start = ((frames as f32 * at).round() as u32).max(free_from);
        let end = start + lengths.motion;
        ensure!(
            end <= frames,
            "--motion needs at least {} frames here (it runs frames {start}..{end})",
            end
        );
        let side = if rng.gen_bool(0.5) { 1.0f32 } else { -1.0 };
        let (roll_deg, shift_m) = match kind {
            MotionKind::Roll => (side * rng.gen_range(15.0..20.0f32), [0.0, 0.0]),
            MotionKind::Shift => {
                let a = rng.gen_range(0.0..std::f32::consts::TAU);
                (0.0, [0.1 * a.cos(), 0.1 * a.sin()])
            }
        };
        // Rolling onto the left side pivots about the left edge of the back on the mattress, and vice versa.
        let pivot = [hips_bed.x + side * half_width, hips_bed.y, 0.0];
        out.motion = Some(Motion {
            kind,
            start,
            end,
            roll_deg,
            shift_m,
            pivot_bed: pivot,
        });
    }
    Ok(out)
}

/// An arm pose before inverse kinematics: the probe tip, the probe axis (into the body) and the elbow hint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmTarget {
    /// Probe tip, world.
    pub tip: Vector3<f32>,
    /// Unit probe axis, pointing away from the wrist.
    pub axis: Vector3<f32>,
    /// Where the elbow should bend.
    pub hint: Vector3<f32>,
}

impl ArmTarget {
    /// The blend `s` of the way from `self` to `other`.
    pub fn lerp(&self, other: &ArmTarget, s: f32) -> ArmTarget {
        ArmTarget {
            tip: self.tip.lerp(&other.tip, s),
            axis: self
                .axis
                .lerp(&other.axis, s)
                .try_normalize(1e-6)
                .unwrap_or(other.axis),
            hint: self.hint.lerp(&other.hint, s),
        }
    }

    /// The posed arm.
    pub fn reach(&self, shoulder: Vector3<f32>) -> ArmState {
        ArmState::reach(shoulder, self.tip, self.axis, self.hint)
    }

    /// Where the arm rests when it has no sweep to follow: the probe hanging 0.6 m above the robot's shoulder.
    pub fn home(shoulder: Vector3<f32>, eye: Vector3<f32>) -> ArmTarget {
        let tip = shoulder + Vector3::new(0.0, -0.1, 0.6);
        ArmTarget {
            tip,
            axis: -Vector3::z(),
            hint: elbow_hint(shoulder, tip, eye),
        }
    }
}

fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Where the arm's shoulder is in a sequence with a full occlusion: on the robot beside the bed (0.2–0.5 m outside
/// its near edge, within 0.5 m of the head along the bed, between 0.1 m above the mattress and 0.3 m below the
/// head), where the wrist still reaches every corner of the sweep over the torso with 5 cm to spare, as near as
/// possible to the head's line of sight 0.35 m in front of the camera. From the usual shoulder
/// ([`crate::dataset::sample_shoulder`], 0.3–0.7 m along the bed from the torso centre and low) the wrist cannot
/// come nearer the camera than about 0.6 m, where the arm hides only a third of the torso. `None` when no candidate
/// reaches the whole sweep (the caller keeps the usual shoulder).
pub fn shoulder_for_full_occlusion(scene: &Scene, eye: Vector3<f32>, seed: u64) -> Option<Vector3<f32>> {
    shoulders_for_full_occlusion(scene, eye, seed, 1).first().copied()
}

/// The `n` best shoulders of [`shoulder_for_full_occlusion`]'s search, best first (fewer when fewer reach).
pub fn shoulders_for_full_occlusion(
    scene: &Scene,
    eye: Vector3<f32>,
    seed: u64,
    n: usize,
) -> Vec<Vector3<f32>> {
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, 0x540));
    let b = &scene.bed;
    let normals = vertex_normals(&scene.body_vertices, &scene.body_triangles);
    let wrists: Vec<Vector3<f32>> = [(0.35, 0.15), (0.65, 0.15), (0.35, 0.9), (0.65, 0.9), (0.5, 0.5)]
        .iter()
        .map(|&(u, v)| {
            let (c, n) = contact_at(scene, &normals, u, v);
            c + n * PROBE_REACH_M
        })
        .collect();
    let park_zone = eye + (Vector3::from(scene.torso_centre()) - eye).normalize() * 0.35;
    let reach = UPPER_LINK_M + FORE_LINK_M - 0.05;
    let (z_lo, z_hi) = (b.mattress_top + 0.1, (eye.z - 0.3).max(b.mattress_top + 0.15));
    let mut found: Vec<(f32, Vector3<f32>)> = Vec::new();
    for _ in 0..400 {
        let s = Vector3::new(
            eye.x + rng.gen_range(-0.5..0.5),
            b.near_edge_y - rng.gen_range(0.2..0.5),
            rng.gen_range(z_lo..z_hi),
        );
        if wrists.iter().any(|w| (w - s).norm() > reach) {
            continue;
        }
        found.push(((park_zone - s).norm(), s));
    }
    // A stable sort keeps the earlier of equal candidates first, as the single-best search did.
    found.sort_by(|a, b| a.0.total_cmp(&b.0));
    found.into_iter().take(n).map(|(_, s)| s).collect()
}

/// Number of random park candidates tried.
pub const PARK_CANDIDATES: usize = 300;
/// Number of local refinements of the best candidate (stopping once it hides 95 %).
pub const PARK_REFINEMENTS: usize = 200;

/// Find the park pose for `scene` seen from `camera_from_world`: the reachable arm pose that hides the most torso
/// pixels (parts `is_torso`). Returns the pose, the fraction it hides and its wrist's distance from the camera.
pub fn find_park_pose(
    scene: &Scene,
    camera_from_world: &Isometry3<f32>,
    renderer: &mut Renderer,
    shoulder: Vector3<f32>,
    is_torso: &dyn Fn(u8) -> bool,
    seed: u64,
) -> Result<(ArmTarget, f32, f32)> {
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, 0x9A4C));
    scene.render(renderer, camera_from_world, false);
    let torso: Vec<(usize, f32)> = {
        let b = renderer.buffers();
        (0..b.label.len())
            .filter(|&i| b.label[i] == Label::Body as u8 && is_torso(b.part[i]))
            .map(|i| (i, b.inv_z[i]))
            .collect()
    };
    ensure!(!torso.is_empty(), "no torso pixel in view to hide");
    let eye = camera_from_world.inverse().translation.vector;
    let s = scene.salient_world.map(Vector3::from);
    let centre = Vector3::from(scene.torso_centre());
    let ray = (centre - eye).normalize();
    let ortho = |v: Vector3<f32>| (v - ray * ray.dot(&v)).try_normalize(1e-6);
    let along = ortho((s[1] + s[2]) - (s[4] + s[5])).unwrap_or_else(Vector3::x);
    let across = ortho((s[1] + s[4]) - (s[2] + s[5])).unwrap_or_else(|| ray.cross(&along));
    // Arm points that must stay clear of the head and the patient (the column and shoulder stand beside the bed).
    let clear = |arm: &ArmState| {
        let pts = [
            Vector3::from(arm.shoulder),
            Vector3::from(arm.elbow),
            Vector3::from(arm.wrist),
            arm.world_from_probe.translation.vector,
        ];
        for w in pts.windows(2) {
            for k in 1..=8 {
                let p = w[0].lerp(&w[1], k as f32 / 8.0);
                if (p - eye).norm() < 0.15 {
                    return false;
                }
                let near_body = scene
                    .body_vertices
                    .iter()
                    .any(|v| (Vector3::from(*v) - p).norm_squared() < 0.08 * 0.08);
                if near_body {
                    return false;
                }
            }
        }
        true
    };
    // Score of a target: the fraction of torso pixels it hides and its wrist's distance from the camera.
    let mut evaluate = |target: &ArmTarget| {
        let arm = target.reach(shoulder);
        if !arm.reached || !clear(&arm) {
            return None;
        }
        renderer.clear();
        renderer.draw(&crate::scene::arm_draw(&arm.mesh), camera_from_world);
        let b = renderer.buffers();
        let hidden = torso.iter().filter(|(i, iz)| b.inv_z[*i] > *iz).count();
        let fraction = hidden as f32 / torso.len() as f32;
        let wrist_distance = (Vector3::from(arm.wrist) - eye).norm();
        // Past 95 % hidden, prefer poses farther from the head.
        Some((
            fraction.min(0.95) + 0.01 * wrist_distance,
            fraction,
            wrist_distance,
        ))
    };
    let mut best: Option<(f32, ArmTarget, f32, f32)> = None;
    for _ in 0..PARK_CANDIDATES {
        let d = rng.gen_range(0.25..0.9f32);
        let jitter = along * rng.gen_range(-0.06..0.06) + across * rng.gen_range(-0.06..0.06);
        let sign = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        let axis = match rng.gen_range(0..3) {
            0 => along * sign,
            1 => across * sign,
            _ => Vector3::new(
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
            )
            .try_normalize(1e-3)
            .unwrap_or(along),
        };
        let wrist_mid = eye + ray * d + jitter;
        let tip = wrist_mid + axis * 0.1;
        let hint = if rng.gen_bool(0.5) {
            elbow_hint(shoulder, tip, eye)
        } else {
            Vector3::new(
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
                rng.gen_range(0.0..1.0),
            )
        };
        let target = ArmTarget { tip, axis, hint };
        if let Some((score, fraction, distance)) = evaluate(&target)
            && best.is_none_or(|(b, ..)| score > b)
        {
            best = Some((score, target, fraction, distance));
        }
    }
    // Then local moves around the best (tip up to 4 cm, axis and elbow turned a little), kept when they improve.
    for k in 0..PARK_REFINEMENTS {
        let Some((best_score, base, ..)) = best else { break };
        if best_score >= 0.95 + 0.01 * 0.9 {
            break;
        }
        let scale = 1.0 - k as f32 / PARK_REFINEMENTS as f32;
        let mut v = |m: f32| Vector3::new(rng.gen_range(-m..m), rng.gen_range(-m..m), rng.gen_range(-m..m));
        let target = ArmTarget {
            tip: base.tip + v(0.04 * scale),
            axis: (base.axis + v(0.3 * scale))
                .try_normalize(1e-3)
                .unwrap_or(base.axis),
            hint: base.hint + v(0.5 * scale),
        };
        if let Some((score, fraction, distance)) = evaluate(&target)
            && score > best_score
        {
            best = Some((score, target, fraction, distance));
        }
    }
    let (_, target, fraction, distance) =
        best.ok_or_else(|| {
            anyhow::anyhow!(
                "no reachable arm pose between the head and the torso for the full occlusion (seed {seed}: another \
                 seed places the patient, the bed and the arm differently)"
            )
        })?;
    Ok((target, fraction, distance))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn the_timeline_orders_the_episodes_and_refuses_short_sequences() {
        let lengths = EpisodeFrames::default();
        let hips = Vector3::new(0.0, 0.0, 0.1);
        let e = plan(300, 3, true, Some(MotionKind::Roll), &lengths, hips, 0.18).unwrap();
        let o = e.full_occlusion.unwrap();
        assert_eq!(
            (o.approach_start, o.start, o.end, o.leave_end),
            (90, 100, 130, 140)
        );
        let m = e.motion.unwrap();
        assert_eq!((m.start, m.end), (180, 225));
        assert!((15.0..20.0).contains(&m.roll_deg.abs()));
        assert!(plan(100, 3, true, Some(MotionKind::Shift), &lengths, hips, 0.18).is_err());
        assert_eq!(o.phase(89), ArmPhase::Path);
        assert!(matches!(o.phase(90), ArmPhase::Approach(s) if s > 0.0 && s < 0.1));
        assert_eq!(o.phase(129), ArmPhase::Parked);
        assert!(matches!(o.phase(139), ArmPhase::Leave(s) if s > 0.9));
        assert_eq!(o.phase(140), ArmPhase::Path);
    }

    #[test]
    fn roll_turns_about_the_pivot_and_shift_moves_ten_cm() {
        let lengths = EpisodeFrames::default();
        let hips = Vector3::new(0.0, 0.0, 0.1);
        for seed in 0..6 {
            let e = plan(200, seed, false, Some(MotionKind::Roll), &lengths, hips, 0.18).unwrap();
            let m = e.motion.unwrap();
            let t = m.bed_transform(m.end);
            let pivot = Point3::from(m.pivot_bed);
            assert!((t * pivot - pivot).norm() < 1e-5);
            let angle = t.rotation.angle().to_degrees();
            assert!(
                (angle - m.roll_deg.abs()).abs() < 1e-3,
                "{angle} vs {}",
                m.roll_deg
            );
            // The side away from the pivot lifts off the mattress.
            let far = Point3::new(hips.x - m.pivot_bed[0].signum() * 0.18, 0.0, 0.0);
            assert!((t * far).z > 0.05, "{:?}", t * far);
            assert_eq!(m.bed_transform(m.start), Isometry3::identity());
            let e = plan(200, seed, false, Some(MotionKind::Shift), &lengths, hips, 0.18).unwrap();
            let m = e.motion.unwrap();
            assert!((m.bed_transform(m.end + 5).translation.vector.norm() - 0.1).abs() < 1e-5);
        }
    }
}
