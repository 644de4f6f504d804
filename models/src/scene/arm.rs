//! The robot arm holding the ultrasound probe: a column, two links (capsules, elbow-up two-link IK) and a probe whose
//! tip touches the patient's skin. The probe tip pose (`world_from_probe`: origin at the tip, z along the probe into
//! the body) is ground truth for the probe mapping.
//!
//! Building the arm for one probe pose costs ~1.5k vertices.

use super::shapes::TriMesh;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Upper arm length, metres.
pub const UPPER_LINK_M: f32 = 0.5;
/// Forearm length (elbow to wrist flange), metres.
pub const FORE_LINK_M: f32 = 0.45;
/// Wrist flange to probe tip, metres.
pub const PROBE_REACH_M: f32 = 0.19;

/// The posed arm in the world frame.
#[derive(Debug, Clone)]
pub struct ArmState {
    /// Arm and probe mesh in the world frame.
    pub mesh: TriMesh,
    /// Shoulder joint (top of the column).
    pub shoulder: [f32; 3],
    /// Elbow joint.
    pub elbow: [f32; 3],
    /// Wrist flange.
    pub wrist: [f32; 3],
    /// Probe tip pose: origin at the tip, z along the probe pointing into the body.
    pub world_from_probe: Isometry3<f32>,
    /// False if the tip was out of reach and the arm stopped short (the probe then hovers).
    pub reached: bool,
}

impl ArmState {
    /// Pose the arm so the probe tip is at `tip` with the probe axis `into_body` (unit, pointing into the skin); the
    /// elbow bends toward `elbow_hint` (e.g. up and away from the camera), as far as the geometry allows.
    pub fn reach(
        shoulder: Vector3<f32>,
        tip: Vector3<f32>,
        into_body: Vector3<f32>,
        elbow_hint: Vector3<f32>,
    ) -> ArmState {
        let a = into_body.normalize();
        let wrist_goal = tip - a * PROBE_REACH_M;
        let sw = wrist_goal - shoulder;
        let d_goal = sw.norm().max(1e-4);
        let max_reach = UPPER_LINK_M + FORE_LINK_M - 1e-3;
        let min_reach = (UPPER_LINK_M - FORE_LINK_M).abs() + 1e-3;
        let d = d_goal.clamp(min_reach, max_reach);
        let u = sw / d_goal;
        let wrist = shoulder + u * d;
        // Elbow on the circle of points at L1 from the shoulder and L2 from the wrist; pick the one toward the hint.
        let along = (UPPER_LINK_M * UPPER_LINK_M - FORE_LINK_M * FORE_LINK_M + d * d) / (2.0 * d);
        let radius = (UPPER_LINK_M * UPPER_LINK_M - along * along).max(0.0).sqrt();
        let side = elbow_hint - u * u.dot(&elbow_hint);
        let side = if side.norm() > 1e-4 {
            side.normalize()
        } else {
            let up = Vector3::z() - u * u.z;
            if up.norm() > 1e-4 {
                up.normalize()
            } else {
                Vector3::x()
            }
        };
        let elbow = shoulder + u * along + side * radius;
        let tip_actual = wrist + a * PROBE_REACH_M;

        let mut mesh = TriMesh::default();
        mesh.add_capsule([shoulder.x, shoulder.y, 0.0], shoulder.into(), 0.08, 16); // column
        mesh.add_capsule(shoulder.into(), elbow.into(), 0.06, 16);
        mesh.add_capsule(elbow.into(), wrist.into(), 0.05, 16);
        // Wrist body, probe handle, probe head with a rounded tip just touching the skin.
        mesh.add_capsule(wrist.into(), (wrist + a * 0.05).into(), 0.045, 14);
        mesh.add_capsule(
            (wrist + a * 0.06).into(),
            (tip_actual - a * 0.06).into(),
            0.02,
            12,
        );
        let helper = if a.z.abs() < 0.9 {
            Vector3::z()
        } else {
            Vector3::x()
        };
        let px = helper.cross(&a).normalize();
        let py = a.cross(&px);
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
            Matrix3::from_columns(&[px, py, a]),
        ));
        let head_centre = tip_actual - a * 0.035;
        mesh.add_box(
            &Isometry3::from_parts(Translation3::from(head_centre), rot),
            [0.03, 0.012, 0.035],
        );
        ArmState {
            mesh,
            shoulder: shoulder.into(),
            elbow: elbow.into(),
            wrist: wrist.into(),
            world_from_probe: Isometry3::from_parts(Translation3::from(tip_actual), rot),
            reached: (d - d_goal).abs() < 1e-3,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_keep_their_lengths_and_the_tip_lands() {
        let s = Vector3::new(0.0, 0.2, 1.1);
        let tip = Vector3::new(0.1, 0.8, 0.75);
        let arm = ArmState::reach(s, tip, -Vector3::z(), Vector3::z());
        assert!(arm.reached);
        let (e, w) = (Vector3::from(arm.elbow), Vector3::from(arm.wrist));
        assert!(((e - s).norm() - UPPER_LINK_M).abs() < 1e-4);
        assert!(((w - e).norm() - FORE_LINK_M).abs() < 1e-4);
        assert!((arm.world_from_probe.translation.vector - tip).norm() < 1e-4);
        assert!(e.z > s.z.min(w.z), "elbow up");
        let z = arm.world_from_probe.rotation * Vector3::z();
        assert!(
            (z + Vector3::z()).norm() < 1e-5,
            "probe points down into the body"
        );
        let far = ArmState::reach(s, Vector3::new(3.0, 0.2, 1.1), Vector3::x(), Vector3::z());
        assert!(!far.reached);
    }
}
