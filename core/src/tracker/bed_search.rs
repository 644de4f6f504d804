//! Acquisition starts laid on the bed: when the tracker has no pose, the forest's torso frame can be 15-25 cm and
//! 40-60° off (a view or a body the forest handles badly), too far for ICP to converge. A patient lying on the bed
//! is constrained though: chest up, the body axis along the bed, the back on the mattress. So besides the forest's
//! own pose, the acquisition tries the model lying flat on the mattress along the bed (toward the end the forest's
//! shoulders point at), on a grid around the forest's hip centre, screens each start with a few ICP iterations and
//! refines the best ones fully. When the bed's head section is raised the grid lies on the section instead, the body
//! axis up its slope: the trunk lies on a raised section with the pelvis at the hinge, and a torso flat on the
//! mattress would be the legs. The same constraint judges fits ([`along_the_bed`]): on a raised head section, whose
//! slope gives the bed's axis exactly, a torso points up it, and its hips lie near the hinge ([`near_the_hinge`]).
//!
//! Cost per acquiring frame: [`STARTS`] screening fits of [`SCREEN_ITERATIONS`] ICP iterations on every fourth torso
//! vertex (the tracker's `screen_stride`; about 0.5-1 ms with the default model); nothing while tracking; nothing
//! allocates.

use crate::geometry::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use crate::planes::BedScene;
use heapless::Vec;

/// Offsets of the grid along the bed from the forest's hip centre, metres (the forest's worst error is along the
/// body: the torso slides along itself).
pub const ALONG_M: [f32; 5] = [-0.16, -0.08, 0.0, 0.08, 0.16];
/// Offsets of the grid across the bed, metres.
pub const ACROSS_M: [f32; 3] = [-0.08, 0.0, 0.08];
/// Number of grid starts per surface the patient may lie on.
pub const STARTS: usize = ALONG_M.len() * ACROSS_M.len();
/// ICP iterations a grid start gets before the best are chosen.
pub const SCREEN_ITERATIONS: u8 = 3;
/// Grid starts refined fully after the screening.
pub const KEEP: usize = 2;

/// How far the torso frame's origin (the hip centre) lies above the lowest point of the torso model: the origin's
/// height over the mattress when the model lies flat on it.
pub fn back_depth_m(torso_vertices: &[Point3]) -> f32 {
    let lowest = torso_vertices.iter().map(|v| v.z).fold(0.0f32, f32::min);
    -lowest
}

/// The grid starts around `forest` (`camera_from_torso`): the model lying on the mattress with its back `back_m`
/// below the hip centre, the body axis along the bed toward the end the forest's shoulders point at; or, when the
/// bed's head section is raised, lying on the section, its body axis up the slope.
pub fn grid_starts(forest: &Isometry3, bed: &BedScene, back_m: f32) -> Vec<Isometry3, STARTS> {
    let camera_from_bed = bed.volume.bed_from_camera.inverse();
    let across = camera_from_bed.rotation * Vector3::x();
    let hip = Point3::from(forest.translation.vector);
    let (plane, toward, hip) = match bed.head_section {
        None => (bed.mattress, forest.rotation * Vector3::y(), hip),
        Some(head) => {
            // The head lies up the raised section: the body axis rises away from the mattress. A forest's hip
            // centre too far toward the foot end for a patient on the section (the legs taken for the torso) moves
            // to the hinge, where the patient's hips are. No start lies flat on the mattress: on the choice sets'
            // 130 raised sections such starts won an acquisition twice, both times a worse one (docs/tracking.md,
            // thirty-first round).
            let on_section = match (hinge_offset_m(&hip, bed), up_the_bed(bed)) {
                (Some(s), Some(u)) if s < -MAX_HIPS_BELOW_HINGE_M => hip - u * s,
                _ => hip,
            };
            (head, bed.mattress.normal(), on_section)
        }
    };
    let mut out = Vec::new();
    let z = plane.normal();
    let Some(x) = (across - z * across.dot(&z)).try_normalize(1e-6) else {
        return out;
    };
    let (x, y) = {
        let y = z.cross(&x);
        if y.dot(&toward) >= 0.0 { (x, y) } else { (-x, -y) }
    };
    let rotation =
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
            x, y, z,
        ])));
    let centre = hip.coords - z * (plane.signed_distance(&hip) - back_m);
    for along in ALONG_M {
        for side in ACROSS_M {
            let at = centre + y * along + x * side;
            let _ = out.push(Isometry3::from_parts(Translation3::from(at), rotation));
        }
    }
    out
}

/// How far toward the foot end of a raised head section's hinge the hip centre of a patient lying on the bed can be,
/// metres. On the choice sets' 78 sections the init phase found, the true hip centre lies at most 0.23 m toward the
/// foot end of the found hinge (a mattress placed up to 0.26 m high moves the hinge up the bed), the tracked poses at
/// most 0.27 m; the legs taken for the torso (held-out s41074) 0.28-0.42 m (docs/tracking.md, twenty-third round).
pub const MAX_HIPS_BELOW_HINGE_M: f32 = 0.3;

/// Where `p` lies along the bed from a raised head section's hinge, metres, measured in the mattress plane: positive
/// up the section (toward the head end); `None` without a raised section.
pub fn hinge_offset_m(p: &Point3, bed: &BedScene) -> Option<f32> {
    let head = bed.head_section?;
    let (m, h) = (bed.mattress.normal(), head.normal());
    let sin = m.cross(&h).norm();
    if sin < 1e-3 {
        return None;
    }
    // In the cut through the bed's axis (u along the bed toward the head, z up from the mattress, the hinge at the
    // origin) the mattress is z = 0 and the section -u sin + z cos = 0, so u = (z cos - distance to the section) / sin.
    let (z, b) = (bed.mattress.signed_distance(p), head.signed_distance(p));
    Some((z * m.dot(&h) - b) / sin)
}

/// The direction along the mattress toward the raised head section (`None` without one).
fn up_the_bed(bed: &BedScene) -> Option<Vector3> {
    let (m, h) = (bed.mattress.normal(), bed.head_section?.normal());
    // The section's normal leans toward the foot end.
    (m * m.dot(&h) - h).try_normalize(1e-6)
}

/// Whether a torso's hip centre lies where a patient on a raised head section's bed can lie it (no farther toward the
/// foot end than [`MAX_HIPS_BELOW_HINGE_M`]); always on a flat bed.
pub fn near_the_hinge(camera_from_torso: &Isometry3, bed: &BedScene) -> bool {
    let hip = Point3::from(camera_from_torso.translation.vector);
    hinge_offset_m(&hip, bed).is_none_or(|s| s >= -MAX_HIPS_BELOW_HINGE_M)
}

/// Most a torso's long axis turns from the bed's, on the mattress plane, when the head section is raised, degrees:
/// the bed's axis then comes from the section's slope, exactly. On validation s402 (raised 29°, the arm over 43 % of
/// the torso) a fit 33° off it, 0.3 m beside the patient, was tracked as the patient at RMS 7 mm (with the true shape
/// too); 20° also turned away s705's right fits.
pub const MAX_YAW_ON_SECTION_DEG: f32 = 30.0;

/// On a raised head section a torso lying on the bed points along it (see [`MAX_YAW_ON_SECTION_DEG`]).
pub fn along_the_bed(camera_from_torso: &Isometry3, bed: &BedScene) -> bool {
    if bed.head_section.is_none() {
        return true;
    }
    let n = bed.mattress.normal();
    let axis = camera_from_torso.rotation * Vector3::y();
    let along = bed.volume.bed_from_camera.inverse().rotation * Vector3::y();
    let Some(a) = (axis - n * axis.dot(&n)).try_normalize(1e-6) else {
        return true;
    };
    libm::fabsf(a.dot(&along)) >= libm::cosf(MAX_YAW_ON_SECTION_DEG.to_radians())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::Plane;
    use crate::planes::VolumeOfInterest;

    /// A flat bed 1.5 m below a camera looking straight down.
    pub(crate) fn bed() -> BedScene {
        // Camera 1.5 m above the mattress looking down; bed frame x = camera x, y = -camera y, z = -camera z.
        let bed_from_camera = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), core::f32::consts::PI),
        );
        BedScene {
            mattress: Plane::through(Vector3::new(0.0, 0.0, 1.5), Vector3::new(0.0, 0.0, -1.0)),
            floor: None,
            head_section: None,
            volume: VolumeOfInterest {
                bed_from_camera,
                min: [-0.5, -1.0, 0.0],
                max: [0.5, 1.0, 0.6],
                head_section: None,
            },
            mattress_inliers: 0,
            floor_inliers: 0,
            patient_points: 0,
        }
    }

    #[test]
    fn starts_lie_flat_on_the_mattress_along_the_bed_toward_the_forests_shoulders() {
        let bed = bed();
        let bed_from_camera = bed.volume.bed_from_camera;
        // The forest's pose: hips 0.3 m along the bed, 40° off the bed axis and rolled, shoulders toward -y.
        let forest_in_bed = Isometry3::from_parts(
            Translation3::new(0.05, 0.3, 0.2),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), core::f32::consts::PI - 0.7)
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.4),
        );
        let forest = bed_from_camera.inverse() * forest_in_bed;
        let starts = grid_starts(&forest, &bed, 0.1);
        for (i, s) in starts.iter().enumerate() {
            let in_bed = bed_from_camera * s;
            let t = in_bed.translation.vector;
            assert!((t.z - 0.1).abs() < 1e-5, "start {i} at height {}", t.z);
            let y = in_bed.rotation * Vector3::y();
            let z = in_bed.rotation * Vector3::z();
            assert!(
                (y - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-5,
                "body axis {y:?}"
            );
            assert!((z - Vector3::z()).norm() < 1e-5, "chest {z:?}");
            // The grid is centred on the forest's hip centre, along the start's own axes.
            let along = ALONG_M[i / ACROSS_M.len()];
            let side = ACROSS_M[i % ACROSS_M.len()];
            let x = in_bed.rotation * Vector3::x();
            let expected = Vector3::new(0.05, 0.3, 0.1) + y * along + x * side;
            assert!(
                (t - expected).norm() < 1e-5,
                "start {i} at {t:?}, expected {expected:?}"
            );
        }
        assert_eq!(starts.len(), STARTS);
    }

    #[test]
    fn with_a_raised_head_section_every_start_lies_on_it_head_up_the_slope() {
        let mut bed = bed();
        let bed_from_camera = bed.volume.bed_from_camera;
        let camera_from_bed = bed_from_camera.inverse();
        // Raised 40° about the bed's x axis at the hinge y = 0, rising toward +y.
        let slope = 40f32.to_radians();
        let normal_bed = Vector3::new(0.0, -libm::sinf(slope), libm::cosf(slope));
        bed.head_section = Some(Plane::through(
            camera_from_bed.translation.vector,
            camera_from_bed.rotation * normal_bed,
        ));
        // The forest's pose points the shoulders toward -y (wrong): the head-section starts ignore it.
        let forest = camera_from_bed
            * Isometry3::from_parts(
                Translation3::new(0.0, 0.2, 0.3),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), core::f32::consts::PI),
            );
        let starts = grid_starts(&forest, &bed, 0.1);
        assert_eq!(starts.len(), STARTS);
        for s in &starts {
            let in_bed = bed_from_camera * s;
            let z = in_bed.rotation * Vector3::z();
            let y = in_bed.rotation * Vector3::y();
            assert!((z - normal_bed).norm() < 1e-4, "chest {z:?}");
            assert!(y.z > 0.5 && y.y > 0.5, "body axis {y:?} should rise along +y");
            let height = normal_bed.dot(&in_bed.translation.vector);
            assert!((height - 0.1).abs() < 1e-4, "back {height} above the section");
        }
    }

    #[test]
    fn a_hip_centre_far_toward_the_foot_end_of_a_raised_sections_hinge_is_not_a_patients() {
        let mut bed = bed();
        let bed_from_camera = bed.volume.bed_from_camera;
        let camera_from_bed = bed_from_camera.inverse();
        let at = |y: f32, z: f32| camera_from_bed * Isometry3::translation(0.0, y, z);
        // A flat bed has no hinge: a torso may lie anywhere along it.
        assert_eq!(
            hinge_offset_m(&Point3::from(at(-0.6, 0.1).translation.vector), &bed),
            None
        );
        assert!(near_the_hinge(&at(-0.6, 0.1), &bed));
        // Raised 20° about the bed's x axis at the hinge y = 0, rising toward +y.
        let slope = 20f32.to_radians();
        let normal_bed = Vector3::new(0.0, -libm::sinf(slope), libm::cosf(slope));
        bed.head_section = Some(Plane::through(
            camera_from_bed.translation.vector,
            camera_from_bed.rotation * normal_bed,
        ));
        // The offset is the distance along the bed from the hinge, at any height over the mattress or the section.
        for (y, z) in [(-0.6, 0.1), (-0.2, 0.25), (0.0, 0.0), (0.3, 0.15), (0.5, 0.3)] {
            let s = hinge_offset_m(&Point3::from(at(y, z).translation.vector), &bed).unwrap();
            assert!((s - y).abs() < 1e-4, "({y}, {z}): {s}");
        }
        assert!(near_the_hinge(&at(-0.25, 0.1), &bed));
        assert!(near_the_hinge(&at(0.4, 0.25), &bed));
        assert!(!near_the_hinge(&at(-0.35, 0.1), &bed));
        // The forest put the hips on the legs, 0.6 m down the bed: the starts move to the hinge.
        let forest = at(-0.6, 0.2);
        let starts = grid_starts(&forest, &bed, 0.1);
        let centre = |starts: &[Isometry3]| {
            let c = starts.iter().fold(Vector3::zeros(), |c, s| {
                c + (bed_from_camera * s).translation.vector
            });
            c / starts.len() as f32
        };
        let on_section = centre(&starts);
        assert!(
            on_section.y.abs() < 0.05,
            "section starts centred at {on_section:?}"
        );
        // Hips near enough the hinge are not moved (only laid on the section's plane, 5 cm up the bed here).
        let starts = grid_starts(&at(-0.2, 0.2), &bed, 0.1);
        let on_section = centre(&starts);
        assert!(
            (on_section.y + 0.147).abs() < 0.01,
            "section starts centred at {on_section:?}"
        );
    }

    #[test]
    fn back_depth_is_the_depth_of_the_lowest_vertex_below_the_origin() {
        let v = [
            Point3::new(0.0, 0.0, 0.05),
            Point3::new(0.1, 0.2, -0.12),
            Point3::new(0.0, 0.1, -0.02),
        ];
        assert!((back_depth_m(&v) - 0.12).abs() < 1e-6);
        assert_eq!(back_depth_m(&[Point3::new(0.0, 0.0, 0.1)]), 0.0);
    }

    #[test]
    fn on_a_raised_section_a_torso_points_up_the_slope() {
        let mut bed = bed();
        let camera_from_bed = bed.volume.bed_from_camera.inverse();
        let turned = |deg: f32| {
            camera_from_bed
                * Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, 0.1),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), deg.to_radians()),
                )
        };
        // Flat bed: the bed's axis is the patient's own, no test.
        assert!(along_the_bed(&turned(60.0), &bed));
        bed.head_section = Some(Plane::through(
            camera_from_bed * Vector3::new(0.0, 0.0, 0.0),
            camera_from_bed.rotation * Vector3::new(0.0, -0.5, 0.866),
        ));
        assert!(along_the_bed(&turned(20.0), &bed));
        assert!(along_the_bed(&turned(180.0 - 20.0), &bed));
        assert!(!along_the_bed(&turned(40.0), &bed));
    }
}
