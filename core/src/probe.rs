//! Probe mapping: where the ultrasound probe's tip is relative to the patient's torso surface. From the newest arm
//! state (tip in `robot_base`), the calibration (`robot_base_from_camera`) and the tracked torso pose
//! (`camera_from_torso`), the tip in the `torso` frame; then the nearest point of the shaped torso surface, its
//! outward normal, the signed distance along it, and the body region there; and the wire's [`ProbeReport`].
//!
//! Cost: an exact closest-point test against every triangle of the torso surface (Ericson, "Real-Time Collision
//! Detection" §5.1.5; about 60 flops each, some 0.15 M flops per frame for the default model's 2400 triangles,
//! tens of µs). Nothing allocates.

use crate::geometry::{Isometry3, Point3, Vector3};
use crate::torso::TorsoSurface;
use crate::wire::{BodyRegion, NormalQ14, ProbeReport};

/// The probe tip against the torso surface, `torso` frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeMapping {
    /// The tip.
    pub tip: Point3,
    /// The nearest point of the torso surface.
    pub nearest: Point3,
    /// Unit outward surface normal at `nearest` (the vertex normals interpolated there).
    pub normal: Vector3,
    /// Distance from the surface to the tip along the normal: positive outside, negative pressed in.
    pub signed_distance: f32,
    /// Body region of the nearest point ([`BodyRegion::OffBody`] when the tip is farther than the off-body distance
    /// from the surface, or beyond its rim).
    pub region: BodyRegion,
}

/// Farther than this from the surface, a tip is off the body whatever lies nearest, metres.
pub const OFF_BODY_M: f32 = 0.15;

/// The tip in the `torso` frame from an arm-state tip in `robot_base`.
pub fn tip_in_torso(
    tip_robot_base: &Point3,
    robot_base_from_camera: &Isometry3,
    camera_from_torso: &Isometry3,
) -> Point3 {
    (robot_base_from_camera * camera_from_torso).inverse_transform_point(tip_robot_base)
}

/// Map `tip` (`torso` frame) onto `surface`; `None` for a surface without triangles.
pub fn map_tip(surface: &TorsoSurface<'_>, tip: &Point3) -> Option<ProbeMapping> {
    let v = surface.vertices();
    let mut best: Option<(f32, usize, [f32; 3], Point3)> = None;
    for t in 0..surface.triangle_count() {
        let idx = surface.triangle(t);
        let (q, bary) = closest_on_triangle(tip, &v[idx[0]], &v[idx[1]], &v[idx[2]]);
        let d2 = (tip - q).norm_squared();
        if best.is_none_or(|(b, ..)| d2 < b) {
            best = Some((d2, t, bary, q));
        }
    }
    let (d2, t, bary, nearest) = best?;
    let idx = surface.triangle(t);
    let n = surface.normals();
    let normal = (n[idx[0]] * bary[0] + n[idx[1]] * bary[1] + n[idx[2]] * bary[2])
        .try_normalize(1e-9)
        .unwrap_or_else(|| {
            let face = (v[idx[1]] - v[idx[0]]).cross(&(v[idx[2]] - v[idx[0]]));
            face.try_normalize(1e-12).unwrap_or_else(Vector3::z)
        });
    let signed_distance = (tip - nearest).dot(&normal);
    // The region of the triangle's vertex with the largest weight: regions are per vertex.
    let k = (0..3).max_by(|&a, &b| bary[a].total_cmp(&bary[b])).unwrap_or(0);
    // On the rim (an edge or corner nearest) with the tip off to the side, the tip is not over the torso.
    let on_rim = bary.iter().any(|&w| w <= 1e-6) && libm::fabsf(signed_distance) < 0.5 * libm::sqrtf(d2);
    let region = if d2 > OFF_BODY_M * OFF_BODY_M || on_rim {
        BodyRegion::OffBody
    } else {
        surface.regions()[idx[k]]
    };
    Some(ProbeMapping {
        tip: *tip,
        nearest,
        normal,
        signed_distance,
        region,
    })
}

impl ProbeMapping {
    /// The wire's probe report (millimetres, Q14 normal, saturating at the i32 range).
    pub fn report(&self) -> ProbeReport {
        let mm = |p: &Point3| [p.x, p.y, p.z].map(|c| libm::roundf(c * 1000.0) as i32);
        ProbeReport {
            tip_mm: mm(&self.tip),
            nearest_mm: mm(&self.nearest),
            normal: NormalQ14::from_f32(self.normal.into()).unwrap_or(NormalQ14::NONE),
            signed_distance_mm: libm::roundf(self.signed_distance * 1000.0) as i32,
            region: self.region,
        }
    }
}

/// The point of triangle `abc` nearest `p`, with its barycentric weights (Ericson §5.1.5).
pub fn closest_on_triangle(p: &Point3, a: &Point3, b: &Point3, c: &Point3) -> (Point3, [f32; 3]) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let w = d1 / (d1 - d3);
        return (a + ab * w, [1.0 - w, w, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body_model::BodyModelView;
    use crate::fixture::{self, TINY_BODY_LEN};
    use crate::torso::TorsoBuffers;

    #[test]
    fn closest_point_regions_of_a_triangle() {
        let (a, b, c) = (
            Point3::origin(),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        );
        let (q, w) = closest_on_triangle(&Point3::new(0.25, 0.25, 0.3), &a, &b, &c);
        assert!((q - Point3::new(0.25, 0.25, 0.0)).norm() < 1e-6 && (w[0] - 0.5).abs() < 1e-6);
        assert_eq!(
            closest_on_triangle(&Point3::new(-1.0, -1.0, 0.0), &a, &b, &c).0,
            a
        );
        assert_eq!(closest_on_triangle(&Point3::new(2.0, -0.1, 0.0), &a, &b, &c).0, b);
        let (q, _) = closest_on_triangle(&Point3::new(0.5, -1.0, 0.2), &a, &b, &c);
        assert!((q - Point3::new(0.5, 0.0, 0.0)).norm() < 1e-6, "edge ab: {q:?}");
        let (q, _) = closest_on_triangle(&Point3::new(1.0, 1.0, 0.0), &a, &b, &c);
        assert!((q - Point3::new(0.5, 0.5, 0.0)).norm() < 1e-6, "edge bc: {q:?}");
    }

    #[test]
    fn maps_a_tip_over_the_fixture_surface() {
        let mut bytes = [0u8; TINY_BODY_LEN];
        let n = fixture::tiny_body_model(&mut bytes).unwrap();
        let view = BodyModelView::parse(&bytes[..n]).unwrap();
        let mut vertices = [Point3::origin(); 3];
        let mut normals = [Vector3::zeros(); 3];
        let mut regions = [BodyRegion::OffBody; 3];
        let s = [0.2, -0.4];
        let surface = TorsoSurface::build(
            &view,
            &s,
            TorsoBuffers {
                vertices: &mut vertices,
                normals: &mut normals,
                regions: &mut regions,
            },
        )
        .unwrap();
        // The one subset triangle: a tip 2 cm out along its normal over its centroid maps back onto the centroid.
        let v = surface.vertices();
        let centroid = Point3::from((v[0].coords + v[1].coords + v[2].coords) / 3.0);
        let normal = (v[1] - v[0]).cross(&(v[2] - v[0])).normalize();
        let m = map_tip(&surface, &(centroid + normal * 0.02)).unwrap();
        assert!(
            (m.nearest - centroid).norm() < 1e-5,
            "{:?} vs {centroid:?}",
            m.nearest
        );
        assert!((m.signed_distance - 0.02).abs() < 1e-5);
        assert!((m.normal - normal).norm() < 1e-4);
        assert_ne!(m.region, BodyRegion::OffBody);
        // Pressed 5 mm in: negative.
        let m = map_tip(&surface, &(centroid - normal * 0.005)).unwrap();
        assert!((m.signed_distance + 0.005).abs() < 1e-5);
        // Far above: off body.
        assert_eq!(
            map_tip(&surface, &(centroid + normal * 0.5)).unwrap().region,
            BodyRegion::OffBody
        );
        let r = map_tip(&surface, &(centroid + normal * 0.02)).unwrap().report();
        assert_eq!(r.signed_distance_mm, 20);
        // Buffers of the wrong length are refused.
        let mut short = [Point3::origin(); 2];
        let mut n2 = [Vector3::zeros(); 3];
        let mut r2 = [BodyRegion::OffBody; 3];
        let buf = TorsoBuffers {
            vertices: &mut short,
            normals: &mut n2,
            regions: &mut r2,
        };
        assert!(TorsoSurface::build(&view, &s, buf).is_err());
    }

    #[test]
    fn the_tip_goes_through_calibration_and_pose() {
        let base_from_camera = Isometry3::new(Vector3::new(0.3, 0.0, 1.5), Vector3::new(2.0, 0.0, 0.0));
        let camera_from_torso = Isometry3::new(Vector3::new(0.0, 0.1, 1.2), Vector3::new(0.0, 0.3, 0.0));
        let tip_torso = Point3::new(0.05, 0.2, 0.12);
        let tip_base = base_from_camera * camera_from_torso * tip_torso;
        let back = tip_in_torso(&tip_base, &base_from_camera, &camera_from_torso);
        assert!((back - tip_torso).norm() < 1e-5);
    }
}
