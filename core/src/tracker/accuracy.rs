//! Scoring one tracked frame against ground truth (synthetic sequences and recordings with a truth file): the
//! figures `supine-models eval tracking`, `supine replay --truth` and `supine demo` report, computed one way.
//!
//! - Torso surface error: mean distance between each vertex of the tracked torso model and the same vertex of the
//!   true torso surface, both in the camera frame (vertex to vertex: stricter than point to surface, it also counts
//!   sliding along the skin), metres.
//! - Salient-point error: mean distance of the six reported points from the true ones, metres.
//! - Probe mapping: the same arm tip mapped through the tracked pose onto the tracked model and through the true
//!   pose onto the true surface: distance of the two nearest points (camera frame) and the difference of the signed
//!   distances, metres; scored only where the true tip is within [`PROBE_NEAR_M`] of the skin.
//!
//! Cost: one pass over the torso vertices and two probe mappings (tens of µs); not part of the tracking loop.

use crate::geometry::{Isometry3, Point3};
use crate::probe;
use crate::salient::SalientPoint;
use crate::torso::TorsoSurface;

/// Probe mapping is scored while the true tip is at most this far from the true skin, metres.
pub const PROBE_NEAR_M: f32 = 0.05;

/// What the truth says about one frame.
#[derive(Debug, Clone, Copy)]
pub struct TruthFrame<'a> {
    /// The true torso surface (torso frame) and where it is (`camera_from_torso`).
    pub surface: &'a TorsoSurface<'a>,
    /// The true torso pose.
    pub camera_from_torso: Isometry3,
    /// The true salient points, camera frame.
    pub salient_camera: [Point3; SalientPoint::COUNT],
}

/// What the tracker reported for the frame.
#[derive(Debug, Clone, Copy)]
pub struct TrackedFrame<'a> {
    /// The tracked torso model (torso frame) and its pose.
    pub surface: &'a TorsoSurface<'a>,
    /// The tracked torso pose.
    pub camera_from_torso: Isometry3,
    /// The reported salient points, camera frame.
    pub salient_camera: Option<[Point3; SalientPoint::COUNT]>,
}

/// One frame's errors, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameAccuracy {
    /// Torso surface error.
    pub torso_m: f32,
    /// Salient-point error (`None` without reported points).
    pub point_m: Option<f32>,
    /// Probe nearest-point error (`None` without a tip near the skin).
    pub probe_m: Option<f32>,
    /// Probe signed-distance error.
    pub probe_distance_m: Option<f32>,
}

/// Score `tracked` against `truth`; `tip_robot_base` with `robot_base_from_camera` is the arm tip to map.
pub fn score(
    tracked: &TrackedFrame<'_>,
    truth: &TruthFrame<'_>,
    tip: Option<(&Point3, &Isometry3)>,
) -> FrameAccuracy {
    let (mut sum, mut n) = (0.0f32, 0usize);
    for (e, g) in tracked.surface.vertices().iter().zip(truth.surface.vertices()) {
        sum += (tracked.camera_from_torso * e - truth.camera_from_torso * g).norm();
        n += 1;
    }
    let point_m = tracked.salient_camera.map(|p| {
        p.iter()
            .zip(&truth.salient_camera)
            .map(|(a, b)| (a - b).norm())
            .sum::<f32>()
            / SalientPoint::COUNT as f32
    });
    let mut out = FrameAccuracy {
        torso_m: if n == 0 { f32::NAN } else { sum / n as f32 },
        point_m,
        ..FrameAccuracy::default()
    };
    if let Some((tip_rb, rb_from_camera)) = tip {
        let tracked_tip = probe::tip_in_torso(tip_rb, rb_from_camera, &tracked.camera_from_torso);
        let true_tip = probe::tip_in_torso(tip_rb, rb_from_camera, &truth.camera_from_torso);
        if let (Some(m), Some(g)) = (
            probe::map_tip(tracked.surface, &tracked_tip),
            probe::map_tip(truth.surface, &true_tip),
        ) && libm::fabsf(g.signed_distance) < PROBE_NEAR_M
        {
            out.probe_m =
                Some((tracked.camera_from_torso * m.nearest - truth.camera_from_torso * g.nearest).norm());
            out.probe_distance_m = Some(libm::fabsf(m.signed_distance - g.signed_distance));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body_model::BodyModelView;
    use crate::geometry::{Translation3, UnitQuaternion, Vector3};
    use crate::torso::TorsoBuffers;
    use crate::wire::BodyRegion;

    #[test]
    fn a_shifted_pose_scores_its_shift() {
        extern crate std;
        use std::vec;
        let mut buf = vec![0u8; 1 << 16];
        let len = crate::fixture::tiny_body_model(&mut buf).unwrap();
        let view = BodyModelView::parse(&buf[..len]).unwrap();
        let n = view.counts().subset;
        let (mut v, mut nr, mut r) = (
            vec![Point3::origin(); n],
            vec![Vector3::zeros(); n],
            vec![BodyRegion::OffBody; n],
        );
        let surface = TorsoSurface::build(
            &view,
            &[0.0; 20],
            TorsoBuffers {
                vertices: &mut v,
                normals: &mut nr,
                regions: &mut r,
            },
        )
        .unwrap();
        let truth_pose = Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.5), UnitQuaternion::identity());
        let shifted = Isometry3::from_parts(Translation3::new(0.0, 0.01, 1.5), UnitQuaternion::identity());
        let points = [Point3::new(0.0, 0.0, 1.5); SalientPoint::COUNT];
        let truth = TruthFrame {
            surface: &surface,
            camera_from_torso: truth_pose,
            salient_camera: points,
        };
        let tracked = TrackedFrame {
            surface: &surface,
            camera_from_torso: shifted,
            salient_camera: Some(points.map(|p| p + Vector3::new(0.0, 0.0, 0.02))),
        };
        let a = score(&tracked, &truth, None);
        assert!((a.torso_m - 0.01).abs() < 1e-5, "{a:?}");
        assert!((a.point_m.unwrap() - 0.02).abs() < 1e-5);
        assert_eq!(a.probe_m, None);
        let same = score(
            &TrackedFrame {
                camera_from_torso: truth_pose,
                ..tracked
            },
            &truth,
            None,
        );
        assert!(same.torso_m < 1e-6);
    }
}
