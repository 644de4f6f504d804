//! The init phase's bed from the estimates of its first frames: one frame's RANSAC can take another plane for the
//! mattress (the bed's base under a raised section, 0.16 m low) or miss a raised section, while the next frame's,
//! drawn afresh, finds them (s42086: the mattress 163 mm low on frame 0, within 5 mm on five of the next six). The
//! mattress most estimates agree on is kept, and with it a raised section when at least two of those estimates
//! place it alike (one frame can miss a section, or more rarely invent one on a flat bed). The tracker votes over
//! its first five frames (`TrackerConfig::bed_frames`).
//!
//! Cost: a few plane comparisons per pair of estimates, once per init phase; nothing allocates.

use super::bed_search;
use crate::geometry::{Plane, Point3};
use crate::planes::BedScene;

/// Two mattress (or section) planes agree when their normals lie within this angle, degrees.
pub const AGREE_DEG: f32 = 2.0;
/// ... and each estimate's mattress centre lies this close to the other's plane, metres.
pub const AGREE_M: f32 = 0.02;

/// Two raised sections agree when their normals lie within this angle, degrees (one frame's estimate of a section
/// varies by a degree or two: s29002 41-42°, once 46°).
pub const SECTION_AGREE_DEG: f32 = 3.0;
/// ... and their hinges within this distance along the bed, metres.
pub const HINGE_AGREE_M: f32 = 0.05;

/// Estimates that must place a raised section alike for it to be kept: one frame's RANSAC can also invent one on a
/// flat bed (s43086 under seed 1: on one frame of five; keeping any section put it 32 mm off instead of 5).
pub const MIN_SECTION_VOTES: usize = 2;

/// The point the bed frame starts from: on the mattress, at the centre of its visible part.
fn centre(b: &BedScene) -> Point3 {
    b.volume.bed_from_camera.inverse() * Point3::origin()
}

/// Whether planes `p` and `q` agree as seen from the points `a` and `b` (each estimate's mattress centre).
fn planes_agree(p: &Plane, q: &Plane, a: &Point3, b: &Point3) -> bool {
    let cos = libm::cosf(AGREE_DEG.to_radians());
    let along = |x: &Point3| libm::fabsf(p.signed_distance(x) - q.signed_distance(x)) <= AGREE_M;
    p.normal().dot(&q.normal()) >= cos && along(a) && along(b)
}

/// Whether two estimates place the mattress alike.
pub fn mattresses_agree(a: &BedScene, b: &BedScene) -> bool {
    planes_agree(&a.mattress, &b.mattress, &centre(a), &centre(b))
}

/// Whether two estimates that both found a raised section place it alike: its slope within [`SECTION_AGREE_DEG`]
/// and its hinge within [`HINGE_AGREE_M`] along the bed (measured from one point: a section's plane, compared far
/// from the section, turns a degree's difference into centimetres).
fn sections_agree(a: &BedScene, b: &BedScene) -> bool {
    let (Some(p), Some(q)) = (a.head_section, b.head_section) else {
        return false;
    };
    let c = centre(a);
    let hinges = bed_search::hinge_offset_m(&c, a).zip(bed_search::hinge_offset_m(&c, b));
    p.normal().dot(&q.normal()) >= libm::cosf(SECTION_AGREE_DEG.to_radians())
        && hinges.is_some_and(|(x, y)| libm::fabsf(x - y) <= HINGE_AGREE_M)
}

/// Whether two estimates are the same bed: the mattress alike, and either no raised section in both or one placed
/// alike.
pub fn same_bed(a: &BedScene, b: &BedScene) -> bool {
    mattresses_agree(a, b)
        && match (a.head_section, b.head_section) {
            (None, None) => true,
            _ => sections_agree(a, b),
        }
}

/// How many of `beds` satisfy `agree` with `beds[i]` (itself included).
fn votes(beds: &[BedScene], i: usize, agree: impl Fn(&BedScene, &BedScene) -> bool) -> usize {
    beds.iter().filter(|b| agree(&beds[i], b)).count()
}

/// The index of the estimate to keep (`None` when `beds` is empty): the mattress most estimates agree with (the
/// earliest among equals); then, of the estimates that agree with it, the one with the raised section most of them
/// place alike when at least [`MIN_SECTION_VOTES`] do (then the most mattress votes, then the earliest), or else the
/// one without a section with the most mattress votes (the mattress's own estimate when all found one).
pub fn vote(beds: &[BedScene]) -> Option<usize> {
    let mattress_votes = |i: usize| votes(beds, i, mattresses_agree);
    let best = (0..beds.len()).rev().max_by_key(|&i| mattress_votes(i))?;
    let agreeing = |i: &usize| mattresses_agree(&beds[best], &beds[*i]);
    let with_section = |i: &usize| agreeing(i) && beds[*i].head_section.is_some();
    // Only estimates with a section can agree on one.
    let section_votes = |i: usize| {
        votes(beds, i, |a, b| {
            mattresses_agree(&beds[best], b) && sections_agree(a, b)
        })
    };
    let section = (0..beds.len())
        .rev()
        .filter(with_section)
        .max_by_key(|&i| (section_votes(i), mattress_votes(i)))
        .filter(|&i| section_votes(i) >= MIN_SECTION_VOTES);
    let plain = (0..beds.len())
        .rev()
        .filter(|i| agreeing(i) && beds[*i].head_section.is_none())
        .max_by_key(|&i| mattress_votes(i));
    Some(section.or(plain).unwrap_or(best))
}

/// The bed the vote over `beds` puts in place of `used` (the first one found), or `None` when the vote's is the same
/// bed.
pub fn replacement(beds: &[BedScene], used: &BedScene) -> Option<BedScene> {
    let i = vote(beds)?;
    (!same_bed(&beds[i], used)).then_some(beds[i])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Isometry3, Translation3, UnitQuaternion, Vector3};
    use crate::planes::VolumeOfInterest;

    /// A bed seen from above: the mattress `dz` metres off the true one (1.5 m from the camera, normal toward it),
    /// with a section tilted `section_deg` when given.
    fn bed(dz: f32, section_deg: Option<f32>) -> BedScene {
        let up = Vector3::new(0.0, 0.0, -1.0);
        let mattress = Plane::through(Vector3::new(0.0, 0.0, 1.5 - dz), up);
        let head_section = section_deg.map(|deg| {
            let r = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), deg.to_radians());
            Plane::through(Vector3::new(0.0, 0.3, 1.5), r * up)
        });
        let camera_from_bed = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5 - dz),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), core::f32::consts::PI),
        );
        BedScene {
            mattress,
            floor: None,
            head_section,
            volume: VolumeOfInterest {
                bed_from_camera: camera_from_bed.inverse(),
                min: [-0.5, -1.0, 0.0],
                max: [0.5, 1.0, 0.6],
                head_section,
            },
            mattress_inliers: 900,
            floor_inliers: 0,
            patient_points: 500,
        }
    }

    #[test]
    fn a_mattress_placed_low_on_one_frame_is_outvoted() {
        let beds = [
            bed(-0.163, None),
            bed(-0.001, None),
            bed(0.003, Some(43.0)),
            bed(0.001, Some(42.0)),
        ];
        assert_eq!(
            vote(&beds),
            Some(2),
            "the mattress of frames 1-3, with the section two of them place alike"
        );
        assert!(!same_bed(&beds[0], &beds[2]) && !same_bed(&beds[1], &beds[2]));
        assert!(same_bed(&beds[2], &beds[3]));
        assert_eq!(replacement(&beds, &beds[0]), Some(beds[2]));
        assert_eq!(replacement(&beds[1..2], &beds[1]), None);
        assert_eq!(vote(&beds[..1]), Some(0));
        assert_eq!(vote(&[]), None);
    }

    #[test]
    fn the_section_most_of_the_agreeing_estimates_place_alike_is_kept() {
        let beds = [
            bed(0.0, Some(30.0)),
            bed(0.005, Some(43.0)),
            bed(-0.004, Some(43.5)),
            bed(0.16, Some(43.0)),
        ];
        assert_eq!(vote(&beds), Some(1));
        // A section found only with a mattress the others do not share is not taken.
        let beds = [bed(0.0, None), bed(0.002, None), bed(0.15, Some(40.0))];
        assert_eq!(vote(&beds), Some(0));
        // Nor one that a single estimate found, whichever estimate leads the mattress vote.
        let beds = [
            bed(0.0, Some(33.0)),
            bed(0.002, None),
            bed(0.001, None),
            bed(0.0, None),
        ];
        assert_eq!(vote(&beds), Some(1));
    }

    #[test]
    fn planes_within_the_tolerances_agree_and_beyond_them_do_not() {
        let a = bed(0.0, None);
        assert!(mattresses_agree(&a, &bed(AGREE_M * 0.9, None)));
        assert!(!mattresses_agree(&a, &bed(AGREE_M * 1.1, None)));
        let mut tilted = a;
        let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), (AGREE_DEG * 1.2).to_radians());
        tilted.mattress = Plane::through(Vector3::new(0.0, 0.0, 1.5), r * a.mattress.normal());
        assert!(!mattresses_agree(&a, &tilted));
    }
}
