//! The scene part of the init phase (paper §3.1): the floor and mattress planes from one depth frame (RANSAC on a
//! subsampled point cloud, then least squares on the inliers), the bed's long axis and visible extent, and from them
//! the [`VolumeOfInterest`] whose [`VolumeOfInterest::keeps`] is the tracker's per-frame clip: what lies above the
//! mattress inside the bed's footprint (the patient and, where present, the robot arm), not bed or floor.
//!
//! The init phase requires the patient on the bed and no other object in view. The mattress is the plane with the
//! patient on it: when the floor is visible too it is the parallel plane nearer the camera with more lying on it (a
//! plane of the robot arm's links a bed's height above a mattress, or nearer the camera than a mattress can lie, is not
//! a mattress over a floor); when one plane is found alone, it is the mattress if something body-sized lies on it. The
//! long axis is the principal axis of the points lying on the mattress (a patient lies along the bed), which an
//! occluded or image-cropped mattress would not give. A raised head section is the largest plane tilted from up that
//! spans the bed, rises from the mattress at a hinge, ends below the volume's top and is one flat surface (its points'
//! local normals along its own); the clip keeps only what lies above it as well, and the bed's long axis runs up its
//! slope. A patient on a raised section can hide the whole mattress: then a bed-wide tilted plane larger than the
//! chosen mattress whose bottom lies well below it (an arm link's or the legs' flat top was chosen) or, with no floor
//! found under the chosen plane, a bed's height above it (the floor was) places the mattress level through that
//! bottom; a level plane 8-35 cm under that bottom whose points lie under the section is the bed's base bared by it,
//! never the mattress (the mattress then goes a nominal thickness above it), and a level-looking plane more than
//! 2.5° off that base is not the mattress either. A section's bottom leaves out the strip of the floor its plane
//! crosses (5 cm each side: a far floor comes in depth layers) and, when no floor was found, its points below an
//! empty 0.3 m of height, and a few strays (at most 3 % of its points) below an empty 2 cm. Up is the caller's (from
//! `robot_base_from_camera`) or the floor's normal; without either, the largest plane is taken as horizontal, which a
//! steeply raised head section in a close view can defeat.
//!
//! Cost: [`estimate_bed`] back-projects every `stride`-th pixel of each `stride`-th row (8 k points at the default
//! stride of 6) and runs `iterations` hypotheses per plane over them (about 5 M multiply-adds, a few ms, once). Telling
//! floor from mattress counts what lies on each candidate pair (up to ~70 passes over the points, under a million
//! comparisons). The head-section tests add a few passes over the points and up to 256 local normals (four depth reads
//! each) per tilted plane; with a raised section, its bottom takes the local normal of each of the section's points
//! at every height query (about 0.5 ms more, 3.6 -> 4.1 ms median on the choice sets' 78 raised first frames). The
//! clip is one rigid transform and six comparisons per point. Nothing allocates: the caller lends the scratch.

use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::{Isometry3, Matrix3, Plane, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use crate::rng::SplitMix64;

/// Settings of the plane search (the defaults suit a Kinect v1 1-3 m from the bed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneConfig {
    /// Sample every `stride`-th pixel of every `stride`-th row.
    pub stride: u16,
    /// RANSAC hypotheses per plane.
    pub iterations: u32,
    /// A point within this distance of a plane is an inlier, metres (Kinect v1 noise is 5-10 mm at 2 m).
    pub inlier_m: f32,
    /// A plane must hold at least this share of the sampled points.
    pub min_inlier_fraction: f32,
    /// Two planes are parallel (floor and mattress) when their normals agree within this angle, degrees.
    pub parallel_deg: f32,
    /// Points this far above the mattress and no higher than [`PlaneConfig::max_height_m`] are the patient.
    pub min_height_m: f32,
    /// Highest point above the mattress that belongs to the volume of interest, metres.
    pub max_height_m: f32,
    /// Margin added around the visible mattress footprint, metres.
    pub margin_m: f32,
    /// Seed of the hypothesis sampler (the result is deterministic for a seed).
    pub seed: u64,
}

impl Default for PlaneConfig {
    fn default() -> Self {
        PlaneConfig {
            stride: 6,
            iterations: 256,
            inlier_m: 0.012,
            min_inlier_fraction: 0.04,
            parallel_deg: 6.0,
            min_height_m: 0.02,
            max_height_m: 0.8,
            margin_m: 0.05,
            seed: 0x5EED_B0ED,
        }
    }
}

/// Points a scratch buffer must hold for a `width` x `height` frame at `stride`.
pub const fn scratch_points(width: usize, height: usize, stride: usize) -> usize {
    width.div_ceil(stride) * height.div_ceil(stride)
}

/// Why no bed was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum PlaneError {
    /// Too few pixels with depth in range to look for planes.
    TooFewPoints {
        /// Points sampled.
        found: usize,
    },
    /// No plane holds enough points (nothing flat in view, or the view is cluttered).
    NoPlane,
    /// Planes were found but none has a patient-sized object lying on it.
    NoPatientOnBed,
    /// The scratch buffers are smaller than [`scratch_points`] for this frame.
    ScratchTooSmall {
        /// Points needed.
        needed: usize,
    },
}

impl core::fmt::Display for PlaneError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            PlaneError::TooFewPoints { found } => {
                write!(
                    f,
                    "only {found} pixels with depth in range: cannot look for the bed"
                )
            }
            PlaneError::NoPlane => f.write_str("no plane large enough for a mattress or floor in view"),
            PlaneError::NoPatientOnBed => f.write_str("planes found, but no patient lies on any of them"),
            PlaneError::ScratchTooSmall { needed } => {
                write!(f, "plane scratch holds fewer than {needed} points")
            }
        }
    }
}

impl core::error::Error for PlaneError {}

/// The bed as the init phase found it, in the `camera` frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BedScene {
    /// The mattress top, normal toward the camera.
    pub mattress: Plane,
    /// The floor, when it is in view.
    pub floor: Option<Plane>,
    /// The bed's raised head section, when it is raised and in view (normal toward the camera).
    pub head_section: Option<Plane>,
    /// The volume of interest derived from the mattress, its long axis and its visible extent.
    pub volume: VolumeOfInterest,
    /// Sampled points on the mattress plane.
    pub mattress_inliers: u32,
    /// Sampled points on the floor plane (0 without a floor).
    pub floor_inliers: u32,
    /// Sampled points lying on the mattress (the patient).
    pub patient_points: u32,
}

impl BedScene {
    /// The planes the tracker's clip keeps points above (camera frame): the mattress and the raised head section, or
    /// the mattress twice on a flat bed.
    pub fn clip_planes(&self) -> [Plane; 2] {
        [self.mattress, self.head_section.unwrap_or(self.mattress)]
    }
}

/// A box in the bed frame (origin on the mattress at the centre of its visible part, x across, y along the bed,
/// z up from the mattress): the per-frame clip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeOfInterest {
    /// Rigid transform from the camera into the bed frame.
    pub bed_from_camera: Isometry3,
    /// Lower corner, bed frame, metres.
    pub min: [f32; 3],
    /// Upper corner, bed frame, metres.
    pub max: [f32; 3],
    /// A raised head section (`camera` frame): kept points lie at least `min[2]` above it too.
    pub head_section: Option<Plane>,
}

impl VolumeOfInterest {
    /// Whether a `camera`-frame point lies in the volume (above the mattress and the head section, within the bed's
    /// footprint).
    pub fn keeps(&self, p_camera: &Point3) -> bool {
        let q = self.bed_from_camera * p_camera;
        (0..3).all(|i| q[i] >= self.min[i] && q[i] <= self.max[i])
            && self
                .head_section
                .is_none_or(|hs| hs.signed_distance(p_camera) >= self.min[2])
    }

    /// Whether pixel (u, v) with depth `mm` is kept (0 = no depth is never kept).
    pub fn keeps_pixel(&self, k: &Intrinsics, u: u16, v: u16, mm: u16) -> bool {
        mm != 0 && self.keeps(&k.unproject(u as f32, v as f32, mm as f32 * 0.001))
    }
}

/// Depth accepted as a point for the search, metres (the Kinect v1's working range).
const DEPTH_RANGE_M: (f32, f32) = (0.4, 6.0);
/// Label of a sampled point not (yet) on any plane.
const FREE: u8 = 0;
/// A label no point carries (the mattress when it was placed through a head section's bottom, not found as a plane).
const NO_LABEL: u8 = u8::MAX;
/// A found mattress this far above the bottom of a raised head section is not the mattress, metres.
const SECTION_BELOW_MATTRESS_M: f32 = 0.05;
/// A level plane whose points lie mostly this far under a raised head section's plane is the bed's base bared by
/// the section, not the mattress (metres).
const BASE_UNDER_SECTION_M: f32 = 0.03;
/// The bed's base lies at least this far under the lowest visible part of a raised section, metres (a mattress's
/// thickness less the few centimetres the section's bottom can lie below the mattress's top).
const BASE_BELOW_SECTION_M: f32 = 0.08;
/// ... and at most this far (a thick mattress, 20 cm, under a section whose lowest 15 cm the hips hide): farther
/// down is the floor under the section (s4004, s8012 took the floor for the base), metres.
const BASE_MAX_BELOW_SECTION_M: f32 = 0.35;
/// A hospital mattress's thickness (12-20 cm; the synthetic beds 12-18 cm), metres: where the base under a raised
/// section is all that shows of the bed, the mattress is taken this far above it.
const NOMINAL_MATTRESS_THICKNESS_M: f32 = 0.15;
/// How far above the mattress the lowest visible part of a raised head section can lie, metres: the patient's hips
/// hide the hinge, and beside them the arm or the view can hide the section's lower edge too (14 cm on s402; 15-16
/// cm on s34011's 42° section, missed in three of its first five frames at 0.15 m). At 0.20 m the first three frames
/// of 442 stored sequences (329 flat beds) show no false section (docs/tracking.md, seventeenth round).
const SECTION_BOTTOM_HIDDEN_M: f32 = 0.20;
/// Most planes searched for (floor, mattress, head section, the flat top of what lies on it, a wall).
const MAX_PLANES: usize = 5;
/// With the bed's base bared under a raised section, the flat mattress lies parallel to it within this angle,
/// degrees. A level-looking plane farther off is RANSAC's plane through disconnected patches (s21012: the legs'
/// side and the base's far end, 5.2° off the base, taken for the mattress under a section whose hinge the hips
/// hide; the section then refused). On the first 5 frames of the 238 stored sequences, no other bed changed.
const MATTRESS_ON_BASE_DEG: f32 = 2.5;
/// A plane this close to up is horizontal, degrees.
const HORIZONTAL_DEG: f32 = 10.0;
/// Height band above the mattress in which a raised head section meets it (its hinge), metres.
const HINGE_BAND_M: f32 = 0.03;
/// A raised head section has at least this many sampled points within [`HINGE_BAND_M`] of the mattress, and at
/// least one in this many of its points there: the patient's hips hide most of the hinge, leaving the bed's edges
/// beside them (0.9-2.6 % of the section's points on validation views); a flat, tilted body surface has none.
const HINGE_MIN_POINTS: u32 = 8;
/// See [`HINGE_MIN_POINTS`].
const HINGE_SHARE_INV: u32 = 200;
/// A head section's share of local normals along its own: on the first frames of the 154 stored tracking sequences
/// the 32 true sections had 0.81-0.98, the one false section (s11010: a plane through the patient, the arm and a
/// strip of floor) 0.53, and nine tenths of the other tilted planes found under 0.63.
const SURFACE_MIN_SHARE: f32 = 0.7;
/// Fewest points with a local normal for [`one_surface`] to judge.
const SURFACE_MIN_TESTED: usize = 20;

/// Local normals within this angle of a plane's agree with it, degrees (the depth noise over [`SURFACE_STEP_PX`]
/// tilts a flat surface's local normal by up to about 10° at 2 m).
const SURFACE_NORMAL_DEG: f32 = 25.0;
/// Pixels to the neighbours a local normal is taken from.
const SURFACE_STEP_PX: u16 = 6;
/// A neighbour this much nearer or farther than the point is across an edge, metres.
const SURFACE_STEP_JUMP_M: f32 = 0.05;
/// Points a [`surface_agreement`] tests at most.
const SURFACE_SAMPLES: usize = 256;

/// A head section's normal lies within this angle of the plane of up and the bed's long axis, degrees.
const HINGE_AXIS_DEG: f32 = 8.0;
/// A head section's own inliers spread at least this far along its hinge line, as a standard deviation, metres (a
/// uniform strip 0.45 m wide): it spans the bed (0.57-0.91 m between the 5th and 95th percentiles on the raised
/// sections of the validation and diagnostic sequences), while a flat, tilted part of the body (a thigh, the
/// chest) is narrower: s4008's 36° plane 0.37 m above the mattress spanned 0.30 m and was taken for a section.
const SECTION_MIN_SPREAD_M: f32 = 0.13;
/// The steepest head section looked for, degrees from horizontal.
const MAX_HEAD_RAISE_DEG: f32 = 70.0;
/// Height range of a mattress above the floor, metres (hospital and home beds).
const FLOOR_TO_MATTRESS_M: (f32, f32) = (0.4, 1.2);

/// Find the bed in `frame`: planes, long axis, extent, volume of interest. `up_camera` is the direction of up in the
/// camera frame when known (from `robot_base_from_camera`); without it, up is the floor's normal when the floor is in
/// view, else the largest plane's. `points` and `labels` are scratch of at least [`scratch_points`] entries.
pub fn estimate_bed(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    cfg: &PlaneConfig,
    up_camera: Option<&Vector3>,
    points: &mut [Point3],
    labels: &mut [u8],
) -> Result<BedScene, PlaneError> {
    let stride = cfg.stride.max(1) as usize;
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let needed = scratch_points(w, h, stride);
    if points.len() < needed || labels.len() < needed {
        return Err(PlaneError::ScratchTooSmall { needed });
    }
    let mut n = 0;
    let depth = frame.depth_mm();
    for v in (0..h).step_by(stride) {
        for u in (0..w).step_by(stride) {
            let z = depth[v * w + u] as f32 * 0.001;
            if z >= DEPTH_RANGE_M.0 && z <= DEPTH_RANGE_M.1 {
                points[n] = k.unproject(u as f32, v as f32, z);
                n += 1;
            }
        }
    }
    let points = &points[..n];
    let labels = &mut labels[..n];
    labels.fill(FREE);
    let min_inliers = ((n as f32 * cfg.min_inlier_fraction) as usize).max(50);
    if n < 3 * min_inliers.max(100) / 2 {
        return Err(PlaneError::TooFewPoints { found: n });
    }
    let mut rng = SplitMix64::new(cfg.seed);
    // The largest planes, labelled 1, 2, ... in the order found: floor, mattress, a raised head section, the flat top
    // of whatever lies on the mattress, a wall.
    // One slot more than the greedy search fills: the targeted mattress search below may add a plane.
    let mut found = [(Plane::through(Vector3::zeros(), Vector3::z()), 0usize); MAX_PLANES + 1];
    let mut count = 0;
    while count < MAX_PLANES {
        let Some(p) = ransac(points, labels, cfg, &mut rng, &|_| true) else {
            break;
        };
        let m = mark(points, labels, &p, cfg.inlier_m, count as u8 + 1);
        if m < min_inliers {
            // Unmark: these points stay free for the patient test below.
            labels
                .iter_mut()
                .filter(|l| **l == count as u8 + 1)
                .for_each(|l| *l = FREE);
            break;
        }
        found[count] = (p, m);
        count += 1;
    }
    if count == 0 {
        return Err(PlaneError::NoPlane);
    }
    let cos_par = libm::cosf(cfg.parallel_deg.to_radians());
    let parallel = |a: &Plane, b: &Plane| a.normal().dot(&b.normal()) >= cos_par;
    // Offset of `b` above `a` along `a`'s normal (both face the camera, so the nearer plane has the smaller d).
    let above = |a: &Plane, b: &Plane| a.d - b.d;
    // `b` can be the mattress over the floor `f`: parallel, a bed's height above it, and a patient lies on `b`
    // rather than on `f` (more within a lying body's height above it). Without the last test, a low view that
    // hides the floor took the mattress for the floor and the arm's links 0.67 m above it for the mattress (s984 of
    // the 981-986 set, found after its held-out run).
    // Nor can `b` lie nearer the camera than a mattress can (`MIN_MATTRESS_DISTANCE_M`): the flat top of an arm link
    // near the camera, with more of the arm "lying on" it than the patient the arm hides, made the mattress the
    // floor (s22008: a link 0.45 m above the mattress, 0.54 m from the camera; the mattress then placed 153 mm low).
    let bed_height = |f: &Plane, b: &Plane| {
        parallel(f, b)
            && (FLOOR_TO_MATTRESS_M.0..FLOOR_TO_MATTRESS_M.1).contains(&above(f, b))
            && b.d >= MIN_MATTRESS_DISTANCE_M
            && lying_on(points, b) > lying_on(points, f)
    };
    // A patient covers most of the mattress, so its visible band may be too small for the search above: when the
    // largest horizontal-looking plane has no plane a bed's height above it, look for one there with a lower bar.
    let has_bed_above = |f: &Plane, found: &[(Plane, usize)]| found.iter().any(|(b, _)| bed_height(f, b));
    {
        let lowest = found[..count]
            .iter()
            .filter(|(p, _)| up_camera.is_none_or(|u| p.normal().dot(&u.normalize()) >= cos_par))
            .max_by(|a, b| a.0.d.total_cmp(&b.0.d))
            .map(|(p, _)| *p);
        if let Some(f) = lowest.filter(|f| !has_bed_above(f, &found[..count])) {
            // The normal is known (the floor's), so only the height is searched: the densest 1 cm layer of points
            // a bed's height above it, then least squares.
            let p = densest_layer(points, labels, &f, FLOOR_TO_MATTRESS_M)
                .and_then(|p| refine(points, labels, &p, cfg.inlier_m))
                .filter(|p| bed_height(&f, p));
            if let Some(p) = p {
                let m = mark(points, labels, &p, cfg.inlier_m, count as u8 + 1);
                if m >= min_inliers / 4 {
                    found[count] = (p, m);
                    count += 1;
                } else {
                    labels
                        .iter_mut()
                        .filter(|l| **l == count as u8 + 1)
                        .for_each(|l| *l = FREE);
                }
            }
        }
    }
    let found = &found[..count];
    // The floor: the farthest plane with a parallel one a bed's height nearer. Up is its normal, else the caller's,
    // else the largest plane's (a view in which the flat mattress dominates).
    let mut floor = found
        .iter()
        .filter(|(f, _)| has_bed_above(f, found))
        .max_by(|a, b| a.0.d.total_cmp(&b.0.d))
        .copied();
    let up = match (floor, up_camera) {
        (Some((f, _)), _) => f.normal(),
        (None, Some(u)) => u.normalize(),
        (None, None) => found[0].0.normal(),
    };
    let cos_up = libm::cosf(HORIZONTAL_DEG.to_radians());
    let bottom = section_bottom(
        points,
        labels,
        found,
        &up,
        floor.map(|(f, _)| f),
        Some((frame, k)),
    );
    let level_at_bed_height = |p: &Plane| {
        p.normal().dot(&up) >= cos_up
            && floor.is_none_or(|(f, _)| bed_height(&f, p))
            && p.d >= MIN_MATTRESS_DISTANCE_M
    };
    // A raised head section bares the bed's base under it: a level plane a mattress's thickness below the mattress,
    // seen through the wedge between the section and the base, that can be all the camera sees level at a bed's
    // height when the patient and the section hide the flat mattress (s13006, s13022: the base taken for the
    // mattress 12-16 cm low, the section then refused). Its points lie under the section's plane; the flat
    // mattress, on the other side of the hinge, lies above that plane's extension. Only a section larger than the
    // plane, rising from a mattress's thickness above it and one flat surface tells (on a flat bed the arm's links
    // and the patient's own surfaces make tilted planes over the mattress too). Judged once per plane.
    let mut bared = [false; MAX_PLANES + 1];
    if let Some(b) = &bottom {
        let section = &found[b.label as usize - 1].0;
        let mut flat = None;
        for (i, (p, n)) in found.iter().enumerate() {
            bared[i] = level_at_bed_height(p)
                && b.points > *n
                && (BASE_BELOW_SECTION_M..=BASE_MAX_BELOW_SECTION_M)
                    .contains(&b.height_above(p, points, labels))
                && *flat.get_or_insert_with(|| {
                    one_surface(surface_agreement(frame, k, section, points, labels, b.label))
                })
                && mostly_under(section, points, labels, i as u8 + 1);
        }
    }
    let base = found
        .iter()
        .zip(bared)
        .filter(|(_, bared)| *bared)
        .max_by(|a, b| a.0.0.d.total_cmp(&b.0.0.d))
        .map(|((p, _), _)| *p);
    // The mattress: the lowest horizontal plane a bed's height above the floor (far floors come out of the Kinect
    // in depth layers a few centimetres apart, which may be found as planes of their own), and far enough from the
    // camera for a patient lying on it to be seen (an arm link's flat top near the camera is not it); not the base.
    let cos_base = libm::cosf(MATTRESS_ON_BASE_DEG.to_radians());
    let chosen = found
        .iter()
        .zip(bared)
        .filter(|((p, _), bared)| {
            level_at_bed_height(p) && !bared && base.is_none_or(|b| p.normal().dot(&b.normal()) >= cos_base)
        })
        .max_by(|a, b| a.0.0.d.total_cmp(&b.0.0.d))
        .map(|(f, _)| *f);
    // A patient on a raised head section can hide the whole mattress; then the flat top of an arm link, or the
    // floor, is taken for it. The section still shows: its lowest points lie on the mattress (within 1-3 cm on 11 of
    // 12 raised sections of the validation and diagnostic sequences), so a mattress far above or far below them is
    // replaced by the level plane through them; with the base in view, a typical mattress's thickness above the
    // base unless that is above the section's bottom (the hips can hide the hinge).
    let section_level = |b: &SectionBottom<'_>| {
        base.map(|base| Plane {
            normal: base.normal,
            d: base.d - NOMINAL_MATTRESS_THICKNESS_M,
        })
        .filter(|on_base| b.height_above(on_base, points, labels) >= 0.0)
        .unwrap_or_else(|| b.level(points, labels))
    };
    let (mattress, mattress_n) = match (chosen, bottom) {
        (Some((m, n)), Some(b)) => {
            let below = b.height_above(&m, points, labels);
            // Above the section's bottom: an arm link's or the legs' flat top. A bed's height below it: the floor,
            // unless the floor was found under the chosen plane (then a steep section's lower part is hidden: the
            // patient and the arm hid all of a 41° section's lowest 0.43 m in s29002, and the mattress went there).
            // Only a section larger than the chosen plane tells: the arm's links line up into tilted planes too,
            // reaching from beside the bed's base to high above the mattress, but smaller than a visible mattress.
            let chosen_is_floor = floor.is_none() && below > FLOOR_TO_MATTRESS_M.0;
            if b.points > n && (below < -SECTION_BELOW_MATTRESS_M || chosen_is_floor) {
                (section_level(&b), 0)
            } else {
                (m, n)
            }
        }
        (Some(m), None) => m,
        (None, Some(b)) => (section_level(&b), 0),
        // No level plane at a bed's height and no section: a low view without a floor (`bed_height` no longer
        // lets a plane too near the camera make one; only a `parallel_deg` wider than `HORIZONTAL_DEG` can still
        // bring a floor here, which is dropped). The mattress is the farthest level plane.
        (None, None) => {
            floor = None;
            found
                .iter()
                .filter(|(p, _)| p.normal().dot(&up) >= cos_up && p.d >= MIN_MATTRESS_DISTANCE_M)
                .max_by(|a, b| a.0.d.total_cmp(&b.0.d))
                .copied()
                .ok_or(PlaneError::NoPlane)?
        }
    };
    let mattress_label = found
        .iter()
        .position(|(p, _)| *p == mattress)
        .map_or(NO_LABEL, |i| i as u8 + 1);
    // A raised head section: tilted from up about the hinge line, which runs across the bed, so its normal lies in
    // the plane of up and the bed's long axis (taken here from everything lying on the mattress); rising above the
    // mattress from the hinge.
    let coarse_across = {
        let on = |p: &Point3| {
            let h = mattress.signed_distance(p);
            h > cfg.min_height_m && h < cfg.max_height_m
        };
        long_axis(points, &mattress.normal(), &on).cross(&mattress.normal())
    };
    let sin_axis = libm::sinf(HINGE_AXIS_DEG.to_radians());
    // The bed-wide tilted plane larger than the mattress, by its label: evidence enough of a section that two of
    // the tests below are waived for it.
    let larger = bottom
        .filter(|b| b.points > mattress_n)
        .map(|b| (b.label, b.height_above(&mattress, points, labels)));
    let head_section = found
        .iter()
        .enumerate()
        .filter(|(i, (p, _))| {
            // The patient's long axis can be 10-20° off when the arm's links or the section's own points pull it.
            libm::fabsf(p.normal().dot(&coarse_across)) < sin_axis
                || larger.is_some_and(|(l, _)| l == *i as u8 + 1)
        })
        .filter(|(_, (p, _))| {
            let c = p.normal().dot(&up);
            c < cos_up && c > libm::cosf(MAX_HEAD_RAISE_DEG.to_radians())
        })
        .filter(|(i, (p, _))| {
            // The patient's hips and the arm can hide the hinge but for a few points; the larger plane's lowest
            // points near the mattress show it rises from there just as well.
            rises_from_the_hinge(p, points, &mattress, cfg)
                || larger.is_some_and(|(l, h)| l == *i as u8 + 1 && bottom_may_be_hidden(h))
        })
        .filter(|(i, (p, _))| spans_the_bed(p, &mattress.normal(), points, labels, *i as u8 + 1, found))
        .filter(|(i, (p, _))| one_surface(surface_agreement(frame, k, p, points, labels, *i as u8 + 1)))
        .max_by_key(|(_, (_, m))| *m)
        .map(|(_, (p, _))| *p);
    let floor_n = floor.map_or(0, |(_, n)| n);
    let floor = floor.map(|(f, _)| f);
    let patient = |p: &Point3| {
        let hgt = mattress.signed_distance(p);
        hgt > cfg.min_height_m
            && hgt < cfg.max_height_m
            && head_section.is_none_or(|hs| hs.signed_distance(p) > cfg.min_height_m)
    };
    let patient_n = points.iter().filter(|p| patient(p)).count();
    if patient_n < min_inliers / 2 {
        return Err(PlaneError::NoPatientOnBed);
    }
    // A lone plane with a patient on it could still be the floor with the bed standing on it: then most of what is
    // above it is higher than a body lying on a mattress is thick.
    let high = points
        .iter()
        .filter(|p| {
            let hgt = mattress.signed_distance(p);
            hgt >= cfg.max_height_m && hgt < 2.0
        })
        .count();
    if floor.is_none() && high > patient_n {
        return Err(PlaneError::NoPatientOnBed);
    }

    // Bed frame: z the mattress normal, y the patient's principal axis on the mattress, origin at the mattress
    // inliers' centroid projected on the plane.
    let nz = mattress.normal();
    // Along the bed: up the raised head section when there is one (its hinge runs across the bed), else the
    // patient's principal axis.
    let along = head_section
        .and_then(|h| (nz * h.normal().dot(&nz) - h.normal()).try_normalize(1e-6))
        .unwrap_or_else(|| long_axis(points, &nz, &patient));
    let across = along.cross(&nz);
    let mut centroid = Vector3::zeros();
    let mut count = 0.0f32;
    for (p, &l) in points.iter().zip(labels.iter()) {
        if l == mattress_label {
            centroid += p.coords;
            count += 1.0;
        }
    }
    if count == 0.0 {
        // A mattress placed through the section's bottom has no inliers of its own: centre on the patient.
        for p in points.iter().filter(|p| patient(p)) {
            centroid += p.coords;
            count += 1.0;
        }
    }
    let centroid = centroid / count.max(1.0);
    let origin = centroid - nz * mattress.signed_distance(&Point3::from(centroid));
    let camera_from_bed = Isometry3::from_parts(
        Translation3::from(origin),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
            across, along, nz,
        ]))),
    );
    let bed_from_camera = camera_from_bed.inverse();
    let mut lo = [f32::INFINITY; 2];
    let mut hi = [f32::NEG_INFINITY; 2];
    for (p, &l) in points.iter().zip(labels.iter()) {
        if l == mattress_label || patient(p) {
            let q = bed_from_camera * p;
            for i in 0..2 {
                lo[i] = lo[i].min(q[i]);
                hi[i] = hi[i].max(q[i]);
            }
        }
    }
    let volume = VolumeOfInterest {
        bed_from_camera,
        min: [lo[0] - cfg.margin_m, lo[1] - cfg.margin_m, cfg.min_height_m],
        max: [hi[0] + cfg.margin_m, hi[1] + cfg.margin_m, cfg.max_height_m],
        head_section,
    };
    Ok(BedScene {
        mattress,
        floor,
        head_section,
        volume,
        mattress_inliers: mattress_n as u32,
        floor_inliers: floor_n as u32,
        patient_points: patient_n as u32,
    })
}

/// Whether a tilted plane's inliers among `points` are those of a raised head section of the bed on `mattress`: it
/// starts at the mattress (the hinge) and rises, so some of its points lie within a few centimetres of the mattress
/// and almost none far below it (a body surface that happens to be flat and tilted starts higher), and it ends below
/// the volume's top (the robot arm's links, up to a metre above the mattress, can line up with a few bed points into
/// a tilted plane: 80 % of such a plane's points were above 0.75 m on validation views, none of a true section's).
fn rises_from_the_hinge(plane: &Plane, points: &[Point3], mattress: &Plane, cfg: &PlaneConfig) -> bool {
    let (mut n, mut at_hinge, mut below, mut above) = (0u32, 0u32, 0u32, 0u32);
    for q in points {
        if libm::fabsf(plane.signed_distance(q)) < cfg.inlier_m {
            let h = mattress.signed_distance(q);
            n += 1;
            at_hinge += (h < HINGE_BAND_M) as u32;
            // Not below: the floor's strip where the plane crosses it, at least a bed's height down (a far floor
            // comes in depth layers a few centimetres apart, so that strip can hold 5 % of a section's band).
            below += (h < -HINGE_BAND_M && h > -FLOOR_TO_MATTRESS_M.0) as u32;
            above += (h > cfg.max_height_m) as u32;
        }
    }
    n > 0
        && at_hinge >= HINGE_MIN_POINTS
        && at_hinge * HINGE_SHARE_INV >= n
        && below * 20 < n
        && above * 20 < n
}

/// Whether a raised section whose lowest visible points lie `h` metres above the mattress can still rise from it
/// (the hinge and its lowest [`SECTION_BOTTOM_HIDDEN_M`] hidden), rather than start higher up (a body surface).
fn bottom_may_be_hidden(h: f32) -> bool {
    h > -SECTION_BELOW_MATTRESS_M && h < SECTION_BOTTOM_HIDDEN_M
}

/// The lowest part of the largest plane that is tilted like a raised head section (10-70° from `up`) and spans the
/// bed: where the section meets the mattress.
#[derive(Debug, Clone, Copy)]
struct SectionBottom<'a> {
    label: u8,
    points: usize,
    up: Vector3,
    found: &'a [(Plane, usize)],
    floor: Option<Plane>,
    /// The frame the points come from: a point whose local surface faces away from the section is not the
    /// section's (`None`: every inlier counts).
    surface: Option<(&'a DepthFrame<'a>, &'a Intrinsics)>,
}

/// A section inlier whose local surface normal lies farther than this from the section's faces elsewhere and is not
/// its bottom, degrees. The side of the flat mattress lies 90° off: where the section's plane runs on below the hinge
/// through it, its strip put s40058's mattress 127 mm low (the true mattress then refused as lying above the
/// section's bottom). Of 2000 one-frame scenes (seeds 50001-52000) 12 had their mattress 8-125 mm low this way; at
/// 60° 11 end within 4 mm, one at 51 mm, and no mattress moves the other way. 25° (the flatness test's angle) also
/// refuses points at the hinge whose normals the hips bend: mattresses placed through a hidden hinge rose by up to
/// 30 mm (docs/tracking.md, twenty-third round).
const SECTION_FACING_DEG: f32 = 60.0;
/// Share of a section's own points below its bottom (the hinge region beside the hips; the rest hides it).
const SECTION_BOTTOM_SHARE: f32 = 0.01;
/// A section's points below an empty stretch this high are not the section's but the floor's strip where the
/// section's plane crosses it, when the floor was not found as a plane of its own (s20022: 72 points of 1070, the
/// section missed or the mattress placed on the floor), metres. The floor lies at least
/// [`FLOOR_TO_MATTRESS_M`]`.0` below the mattress, and a section's own points run up from the hinge without such a
/// gap: the arm hides at most a band of it a few decimetres long, which at a 20-70° raise is less than this high.
const SECTION_GAP_M: f32 = 0.3;
/// ... and only while they are at most this share of its points.
const SECTION_STRIP_MAX_SHARE: f32 = 0.2;
/// A few of a section's inliers below an empty stretch this high are strays, not its bottom, metres: where another
/// surface crosses the section's plane below the hinge (the bed's frame, an arm link, at the image's edge where no
/// local normal tells them apart), a short line of its points lies in the inlier band. They put s51036's mattress
/// 144-179 mm low on all of its first five frames and s54072's 103-111 mm low on two (the vote then kept that bed):
/// the tracker never acquired either. A section's own points run up from the hinge in 1 cm steps without a gap.
const SECTION_STRAY_GAP_M: f32 = 0.02;
/// ... and only while they are at most this share of its points (s51036: 6 strays of 1211 over a floor strip of 26;
/// 3 % chosen on 2000 one-frame scenes, where 10 % let one mattress sink 141 mm).
const SECTION_STRAY_MAX_SHARE: f32 = 0.03;
/// The (gap, share) rules of what [`low_quantile`] drops below a section's bottom: the floor's strip, then strays.
const SECTION_DROPS: [(f32, f32); 2] = [
    (SECTION_GAP_M, SECTION_STRIP_MAX_SHARE),
    (SECTION_STRAY_GAP_M, SECTION_STRAY_MAX_SHARE),
];

impl SectionBottom<'_> {
    /// The height above `plane` under which [`SECTION_BOTTOM_SHARE`] of the section's points lie, metres.
    fn height_above(&self, plane: &Plane, points: &[Point3], labels: &[u8]) -> f32 {
        // Not the strip of the floor where the section's plane crosses it, half a metre below the section.
        let floor = |h: &Plane| (self.floor == Some(*h)).then_some(FLOOR_STRIP_M);
        // A point in the section's inlier band whose own surface faces elsewhere (the side of the flat mattress or
        // of the bed's frame, where the section's plane runs on below the hinge) is not on the section: it still
        // counts toward the share, so the bottom does not sink when such points leave, but it is never the bottom.
        let normal = self.found[self.label as usize - 1].0.normal();
        let cos_max = libm::cosf(SECTION_FACING_DEG.to_radians());
        let on_section = |p: &Point3| {
            self.surface.is_none_or(|(frame, k)| {
                local_normal(frame, k, p).is_none_or(|n| libm::fabsf(n.dot(&normal)) >= cos_max)
            })
        };
        let own = || {
            section_points(points, labels, self.label, self.found, &floor)
                .map(|p| on_section(p).then(|| plane.signed_distance(p)))
        };
        low_quantile(own, SECTION_BOTTOM_SHARE, &SECTION_DROPS)
    }

    /// The level plane (normal `up`) through the section's bottom.
    fn level(&self, points: &[Point3], labels: &[u8]) -> Plane {
        let reference = Plane {
            normal: self.up.into(),
            d: 0.0,
        };
        let h = self.height_above(&reference, points, labels);
        Plane {
            normal: self.up.into(),
            d: -h,
        }
    }
}

fn section_bottom<'a>(
    points: &[Point3],
    labels: &[u8],
    found: &'a [(Plane, usize)],
    up: &Vector3,
    floor: Option<Plane>,
    surface: Option<(&'a DepthFrame<'a>, &'a Intrinsics)>,
) -> Option<SectionBottom<'a>> {
    let (cos_flat, cos_steep) = (
        libm::cosf(HORIZONTAL_DEG.to_radians()),
        libm::cosf(MAX_HEAD_RAISE_DEG.to_radians()),
    );
    found
        .iter()
        .enumerate()
        .filter(|(_, (p, _))| {
            let c = p.normal().dot(up);
            c < cos_flat && c > cos_steep
        })
        .filter(|(i, (p, _))| spans_the_bed(p, up, points, labels, *i as u8 + 1, found))
        .max_by_key(|(_, (_, m))| *m)
        .map(|(i, (_, m))| SectionBottom {
            label: i as u8 + 1,
            points: *m,
            up: *up,
            found,
            floor,
            surface,
        })
}

/// The points labelled `label` (a tilted plane's inliers) that lie on none of the planes in `found` that `strip`
/// picks, within the half-width it gives: where a tilted plane crosses the floor or the mattress, a strip of their
/// points is within its inlier band too.
fn section_points<'a>(
    points: &'a [Point3],
    labels: &'a [u8],
    label: u8,
    found: &'a [(Plane, usize)],
    strip: &'a dyn Fn(&Plane) -> Option<f32>,
) -> impl Iterator<Item = &'a Point3> + 'a {
    points
        .iter()
        .zip(labels)
        .filter(move |(_, l)| **l == label)
        .map(|(p, _)| p)
        .filter(move |p| {
            !found
                .iter()
                .any(|(h, _)| strip(h).is_some_and(|half| libm::fabsf(h.signed_distance(p)) < half))
        })
}

/// Half-width of the strip of a level plane's points that a tilted plane's inlier band takes in where the two cross,
/// metres (the search's inlier distance and a little).
const LEVEL_STRIP_M: f32 = 0.015;
/// The same for the floor, which lies too far for [`LEVEL_STRIP_M`]: the Kinect returns a far floor in depth layers a
/// few centimetres apart, so the floor points in a section's inlier band lay up to 32 mm off the floor's fitted plane
/// on s19019 (37 points of 1413, more than [`SECTION_BOTTOM_SHARE`]: the bottom, and so the mattress, went to the
/// floor). Narrower than [`BASE_BELOW_SECTION_M`]: the plane taken for the floor can be the bed's base when the
/// floor is out of view (s403: the section's bottom 113 mm above it; a strip of 0.2 m put the mattress 80 mm high).
const FLOOR_STRIP_M: f32 = 0.05;

/// The value under which `share` of the values `own` yields lie (1 cm bins over their range; 0 when none), but
/// above the lowest values when, for one of the `(gap, max_dropped)` pairs of `drops`, an empty stretch at least
/// `gap` long separates them from the rest and they are at most `max_dropped` of all. Those still count toward
/// `share`: [`SECTION_BOTTOM_SHARE`] was set with them in, and counting only the rest put s4004's mattress 16 mm high
/// (few points show near its hinge). A `None` is a value that counts toward `share` but can never be the answer (it
/// lies above all the others).
fn low_quantile<I: Iterator<Item = Option<f32>>>(
    own: impl Fn() -> I,
    share: f32,
    drops: &[(f32, f32)],
) -> f32 {
    const BINS: usize = 256;
    let (lo, hi, n) = own().fold(
        (f32::INFINITY, f32::NEG_INFINITY, 0u32),
        |(lo, hi, n), x| match x {
            Some(x) => (lo.min(x), hi.max(x), n + 1),
            None => (lo, hi, n + 1),
        },
    );
    if lo > hi {
        return 0.0;
    }
    let bin = ((hi - lo) / BINS as f32).max(0.01);
    let mut hist = [0u32; BINS];
    for x in own().flatten() {
        hist[(((x - lo) / bin) as usize).min(BINS - 1)] += 1;
    }
    let (mut dropped, mut below, mut empty) = (0u32, 0u32, 0.0f32);
    for &c in &hist {
        if c == 0 {
            empty += bin;
            continue;
        }
        if drops
            .iter()
            .any(|&(gap, max_dropped)| empty >= gap && below as f32 <= max_dropped * n as f32)
        {
            dropped = below;
        }
        empty = 0.0;
        below += c;
    }
    let want = (libm::ceilf(share * n as f32) as u32).max(dropped + 1);
    let mut seen = 0;
    for (i, c) in hist.iter().enumerate() {
        seen += c;
        if seen >= want {
            return lo + (i as f32 + 0.5) * bin;
        }
    }
    hi
}

/// Whether the points labelled `label` (a tilted plane's own inliers, off the level planes in `found`) spread along
/// the plane's level lines (normal to `up`) as wide as a bed ([`SECTION_MIN_SPREAD_M`]).
fn spans_the_bed(
    plane: &Plane,
    up: &Vector3,
    points: &[Point3],
    labels: &[u8],
    label: u8,
    found: &[(Plane, usize)],
) -> bool {
    let hinge = plane.normal().cross(up);
    let Some(hinge) = hinge.try_normalize(1e-6) else {
        return false;
    };
    let (mut n, mut sum, mut sq) = (0.0f64, 0.0f64, 0.0f64);
    let cos_flat = libm::cosf(HORIZONTAL_DEG.to_radians());
    let level = |h: &Plane| (h.normal().dot(up) >= cos_flat).then_some(LEVEL_STRIP_M);
    for p in section_points(points, labels, label, found, &level) {
        let x = hinge.dot(&p.coords) as f64;
        n += 1.0;
        sum += x;
        sq += x * x;
    }
    if n < 2.0 {
        return false;
    }
    let mean = sum / n;
    let var = (sq / n - mean * mean).max(0.0);
    libm::sqrt(var) >= SECTION_MIN_SPREAD_M as f64
}

/// Whether most of the points labelled `label` lie at least [`BASE_UNDER_SECTION_M`] under `section`.
fn mostly_under(section: &Plane, points: &[Point3], labels: &[u8], label: u8) -> bool {
    let (under, all) =
        points
            .iter()
            .zip(labels)
            .filter(|(_, l)| **l == label)
            .fold((0u32, 0u32), |(u, a), (p, _)| {
                (
                    u + u32::from(section.signed_distance(p) < -BASE_UNDER_SECTION_M),
                    a + 1,
                )
            });
    all > 0 && under * 2 > all
}

/// The unit normal of the depth surface through `p`, from its neighbours [`SURFACE_STEP_PX`] pixels away in `frame`;
/// `None` where a neighbour has no depth or lies more than [`SURFACE_STEP_JUMP_M`] off (an edge).
fn local_normal(frame: &DepthFrame<'_>, k: &Intrinsics, p: &Point3) -> Option<Vector3> {
    let px = k.project(p)?;
    let d = SURFACE_STEP_PX as f32;
    let at = |du: f32, dv: f32| {
        let (u, v) = (libm::roundf(px.x + du), libm::roundf(px.y + dv));
        match frame.at(u as i32, v as i32) {
            Some(z) if z > 0 => {
                let q = k.unproject(u, v, z as f32 * 0.001);
                (libm::fabsf(q.z - p.z) < SURFACE_STEP_JUMP_M).then_some(q)
            }
            _ => None,
        }
    };
    let (r, l, dn, up) = (at(d, 0.0)?, at(-d, 0.0)?, at(0.0, d)?, at(0.0, -d)?);
    (r - l).cross(&(dn - up)).try_normalize(1e-12)
}

/// Of the points labelled `label` (a plane's own inliers), how many had a local surface normal to test and how many
/// of those lie within `SURFACE_NORMAL_DEG` of `plane`'s normal: the normal of the depth surface through each
/// point, from its neighbours `SURFACE_STEP_PX` pixels away in `frame` (skipped where a neighbour has no depth or
/// lies more than `SURFACE_STEP_JUMP_M` off, an edge). A bed's head section is one flat surface; a plane that RANSAC
/// draws through a curved body, an arm and a strip of floor only crosses them. At most `SURFACE_SAMPLES` points.
pub fn surface_agreement(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    plane: &Plane,
    points: &[Point3],
    labels: &[u8],
    label: u8,
) -> (usize, usize) {
    let own = labels.iter().filter(|l| **l == label).count();
    let step = own.div_ceil(SURFACE_SAMPLES).max(1);
    let cos_max = libm::cosf(SURFACE_NORMAL_DEG.to_radians());
    let (mut tested, mut agree) = (0usize, 0usize);
    for p in points
        .iter()
        .zip(labels)
        .filter(|(_, l)| **l == label)
        .map(|(p, _)| p)
        .step_by(step)
    {
        let Some(n) = local_normal(frame, k, p) else {
            continue;
        };
        tested += 1;
        agree += (libm::fabsf(n.dot(&plane.normal())) >= cos_max) as usize;
    }
    (tested, agree)
}

/// Whether a tilted plane's own inliers are one flat surface, as a head section is, from their
/// [`surface_agreement`] `(tested, agree)`: at least [`SURFACE_MIN_SHARE`] of the tested local normals agree with the
/// plane's. With fewer than [`SURFACE_MIN_TESTED`] testable points it cannot tell and does not object.
fn one_surface((tested, agree): (usize, usize)) -> bool {
    tested < SURFACE_MIN_TESTED || agree as f32 >= SURFACE_MIN_SHARE * tested as f32
}

/// The principal direction, in the plane normal to `nz`, of the points `keep` accepts (a lying patient's long axis).
fn long_axis(points: &[Point3], nz: &Vector3, keep: &dyn Fn(&Point3) -> bool) -> Vector3 {
    let ex0 = {
        let a = Vector3::x() - nz * nz.x;
        if a.norm() > 1e-3 {
            a.normalize()
        } else {
            (Vector3::y() - nz * nz.y).normalize()
        }
    };
    let ey0 = nz.cross(&ex0);
    let (mut n, mut mean) = (0.0f64, [0.0f64; 2]);
    for p in points.iter().filter(|p| keep(p)) {
        mean[0] += ex0.dot(&p.coords) as f64;
        mean[1] += ey0.dot(&p.coords) as f64;
        n += 1.0;
    }
    let mean = [mean[0] / n.max(1.0), mean[1] / n.max(1.0)];
    let mut cov = [0.0f64; 3];
    for p in points.iter().filter(|p| keep(p)) {
        let (a, b) = (
            ex0.dot(&p.coords) as f64 - mean[0],
            ey0.dot(&p.coords) as f64 - mean[1],
        );
        cov[0] += a * a;
        cov[1] += a * b;
        cov[2] += b * b;
    }
    // Major axis of the 2x2 covariance [[c0, c1], [c1, c2]].
    let angle = 0.5 * libm::atan2(2.0 * cov[1], cov[0] - cov[2]);
    (ex0 * libm::cos(angle) as f32 + ey0 * libm::sin(angle) as f32).normalize()
}

/// The plane through three points, normal toward the camera (the origin); `None` when they are (nearly) collinear.
fn plane_through(a: &Point3, b: &Point3, c: &Point3) -> Option<Plane> {
    let n = (b - a).cross(&(c - a));
    let len = n.norm();
    if len < 1e-6 {
        return None;
    }
    let mut n = n / len;
    if -n.dot(&a.coords) < 0.0 {
        n = -n;
    }
    Some(Plane::through(a.coords, n))
}

/// The best plane over the free points by RANSAC, refined by least squares; only hypotheses (and a result) that
/// `accept` takes count.
fn ransac(
    points: &[Point3],
    labels: &[u8],
    cfg: &PlaneConfig,
    rng: &mut SplitMix64,
    accept: &dyn Fn(&Plane) -> bool,
) -> Option<Plane> {
    let n = points.len();
    let mut best: Option<(Plane, usize)> = None;
    // Score on a fixed subset of the points: the ranking of hypotheses needs no more, the refinement uses all.
    let step = (n / 2048).max(1);
    for _ in 0..cfg.iterations {
        let pick = |rng: &mut SplitMix64| {
            for _ in 0..16 {
                let i = rng.below(n);
                if labels[i] == FREE {
                    return Some(i);
                }
            }
            None
        };
        let (Some(i), Some(j), Some(l)) = (pick(rng), pick(rng), pick(rng)) else {
            continue;
        };
        let Some(p) = plane_through(&points[i], &points[j], &points[l]) else {
            continue;
        };
        if !accept(&p) {
            continue;
        }
        let score = (0..n)
            .step_by(step)
            .filter(|&i| labels[i] == FREE && libm::fabsf(p.signed_distance(&points[i])) < cfg.inlier_m)
            .count();
        if best.is_none_or(|(_, s)| score > s) {
            best = Some((p, score));
        }
    }
    let (mut plane, _) = best?;
    for _ in 0..2 {
        plane = refine(points, labels, &plane, cfg.inlier_m)?;
    }
    accept(&plane).then_some(plane)
}

/// Height band above a plane in which a patient lying on it is seen, metres.
const LYING_BAND_M: (f32, f32) = (0.03, 0.35);

/// Nearest a mattress can lie to the camera, metres: a patient lying on it must be in the sensor's range. The arm's
/// links a bed's height above the mattress lay 0.47-0.72 m from the camera on the sequences where they were taken
/// for it; true mattresses lie 0.86-1.7 m away (the scene generator puts the camera 1.0-1.6 m above them).
const MIN_MATTRESS_DISTANCE_M: f32 = DEPTH_RANGE_M.0 + LYING_BAND_M.1;

/// How many of `points` lie in [`LYING_BAND_M`] above `plane`: a patient's worth on a mattress, little on a floor.
fn lying_on(points: &[Point3], plane: &Plane) -> usize {
    points
        .iter()
        .filter(|q| (LYING_BAND_M.0..LYING_BAND_M.1).contains(&plane.signed_distance(q)))
        .count()
}

/// The plane parallel to `base` through the densest 1 cm layer of free points between `range` metres above it.
fn densest_layer(points: &[Point3], labels: &[u8], base: &Plane, range: (f32, f32)) -> Option<Plane> {
    const BINS: usize = 128;
    let bin = (range.1 - range.0) / BINS as f32;
    let mut hist = [0u32; BINS];
    for (p, &l) in points.iter().zip(labels) {
        let h = base.signed_distance(p) - range.0;
        if l == FREE && h >= 0.0 && h < range.1 - range.0 {
            hist[((h / bin) as usize).min(BINS - 1)] += 1;
        }
    }
    // Two neighbouring bins: a layer straddling a bin edge still counts whole.
    let best = (0..BINS - 1).max_by_key(|&i| hist[i] + hist[i + 1])?;
    if hist[best] + hist[best + 1] == 0 {
        return None;
    }
    let h = range.0 + (best + 1) as f32 * bin;
    Some(Plane {
        normal: base.normal,
        d: base.d - h,
    })
}

/// Least-squares plane (centroid and the smallest principal direction) of the free points near `plane`.
fn refine(points: &[Point3], labels: &[u8], plane: &Plane, inlier_m: f32) -> Option<Plane> {
    let near = |i: usize| labels[i] == FREE && libm::fabsf(plane.signed_distance(&points[i])) < inlier_m;
    let mut sum = Vector3::zeros();
    let mut count = 0usize;
    for i in (0..points.len()).filter(|&i| near(i)) {
        sum += points[i].coords;
        count += 1;
    }
    if count < 3 {
        return None;
    }
    let c = sum / count as f32;
    let mut cov = Matrix3::zeros();
    for i in (0..points.len()).filter(|&i| near(i)) {
        let d = points[i].coords - c;
        cov += d * d.transpose();
    }
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imin();
    let mut nrm: Vector3 = eig.eigenvectors.column(k).into_owned();
    if nrm.dot(&plane.normal()) < 0.0 {
        nrm = -nrm;
    }
    Some(Plane::through(c, nrm.normalize()))
}

/// Label the free points within `inlier_m` of `plane` with `label`; returns how many.
fn mark(points: &[Point3], labels: &mut [u8], plane: &Plane, inlier_m: f32, label: u8) -> usize {
    let mut m = 0;
    for (p, l) in points.iter().zip(labels.iter_mut()) {
        if *l == FREE && libm::fabsf(plane.signed_distance(p)) < inlier_m {
            *l = label;
            m += 1;
        }
    }
    m
}

/// The largest planes among `points` (RANSAC with `cfg`, then least squares; each found plane's points are set aside
/// before the next search), largest first, normals turned toward the camera, into `out`; returns how many (at most
/// `out.len()`, only planes holding `cfg.min_inlier_fraction` of the points). Where nothing else is known about the
/// scene they are the candidates for "up" (mattress, floor, a raised head section, a wall). Cost: `cfg.iterations`
/// hypotheses scored on at most 2048 points per plane.
pub fn largest_planes(points: &[Point3], labels: &mut [u8], cfg: &PlaneConfig, out: &mut [Plane]) -> usize {
    let n = points.len().min(labels.len());
    if n < 3 {
        return 0;
    }
    let (points, labels) = (&points[..n], &mut labels[..n]);
    labels.fill(FREE);
    let min_inliers = ((n as f32 * cfg.min_inlier_fraction) as usize).max(50);
    let mut rng = SplitMix64::new(cfg.seed);
    let mut found = 0;
    while found < out.len() && found < 250 {
        let Some(p) = ransac(points, labels, cfg, &mut rng, &|_| true) else {
            break;
        };
        if mark(points, labels, &p, cfg.inlier_m, found as u8 + 1) < min_inliers {
            break;
        }
        // The camera sits at the origin, on the side the normal should point to.
        out[found] = if p.d < 0.0 {
            Plane {
                normal: (-p.normal()).into(),
                d: -p.d,
            }
        } else {
            p
        };
        found += 1;
    }
    found
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::depth::{HEIGHT, PIXELS, WIDTH};
    use crate::time::Timestamp;
    use std::boxed::Box;
    use std::vec;

    /// A camera 1.4 m above a mattress looking down at 25° from vertical, the floor 0.55 m below the mattress, a
    /// 0.5 x 1.6 x 0.22 m "patient" box on the mattress along the bed; depth by ray casting, no noise.
    fn scene() -> (vec::Vec<u16>, Isometry3, Plane, Plane) {
        scene_with(0.48, None)
    }

    /// `world_from_camera` of a camera at `eye` looking at `target`, image rows down the world's z (z up).
    fn looking_at(eye: Vector3, target: Vector3) -> Isometry3 {
        let fwd = (target - eye).normalize();
        let right = fwd.cross(&Vector3::z()).normalize();
        let down = fwd.cross(&right);
        Isometry3::from_parts(
            Translation3::from(eye),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(
                &[right, down, fwd],
            ))),
        )
    }

    /// [`scene`] with the mattress `half_width` metres to each side and, with `plate`, a 0.4 x 0.4 m horizontal
    /// plate that high above the mattress beside the box (where the robot arm's links would be).
    fn scene_with(half_width: f32, plate: Option<f32>) -> (vec::Vec<u16>, Isometry3, Plane, Plane) {
        let k = Intrinsics::KINECT_V1;
        // World: z up, mattress top z = 0, floor z = -0.55, bed along world y.
        let tilt = 25f32.to_radians();
        let eye = Vector3::new(0.0, -1.4 * libm::sinf(tilt), 1.4 * libm::cosf(tilt));
        let world_from_camera = looking_at(eye, Vector3::zeros());
        let camera_from_world = world_from_camera.inverse();
        let mut depth = vec![0u16; PIXELS];
        for v in 0..HEIGHT {
            for u in 0..WIDTH {
                let ray_c = k.unproject(u as f32, v as f32, 1.0).coords;
                let ray = world_from_camera.rotation * ray_c;
                let mut best = f32::INFINITY;
                // Horizontal planes: mattress (within its footprint), floor, box top.
                let mut hit = |z: f32, inside: &dyn Fn(Vector3) -> bool| {
                    if ray.z.abs() > 1e-6 {
                        let t = (z - eye.z) / ray.z;
                        let p = eye + ray * t;
                        if t > 0.0 && t < best && inside(p) {
                            best = t;
                        }
                    }
                };
                hit(0.22, &|p| p.x.abs() < 0.25 && p.y.abs() < 0.8);
                hit(0.0, &|p| {
                    p.x.abs() < half_width && p.y.abs() < half_width.max(1.0)
                });
                if let Some(z) = plate {
                    hit(z, &|p| (0.3..0.7).contains(&p.x) && p.y.abs() < 0.2);
                }
                hit(-0.55, &|_| true);
                if best.is_finite() {
                    // Depth is along the optical axis: t along a ray with unit z in the camera frame.
                    depth[v * WIDTH + u] = (best * 1000.0).round() as u16;
                }
            }
        }
        let mattress = Plane::through(Vector3::zeros(), Vector3::z()).transformed(&camera_from_world);
        let floor =
            Plane::through(Vector3::new(0.0, 0.0, -0.55), Vector3::z()).transformed(&camera_from_world);
        (depth, camera_from_world, mattress, floor)
    }

    /// Depth by ray casting in the camera frame: the nearest positive hit of `hit(ray)` (a ray with unit z).
    fn depth_of(hit: impl Fn(Vector3) -> Option<f32>) -> vec::Vec<u16> {
        let k = Intrinsics::KINECT_V1;
        let mut depth = vec![0u16; PIXELS];
        for v in 0..HEIGHT {
            for u in 0..WIDTH {
                if let Some(t) = hit(k.unproject(u as f32, v as f32, 1.0).coords) {
                    depth[v * WIDTH + u] = (t * 1000.0).round() as u16;
                }
            }
        }
        depth
    }

    #[test]
    fn a_flat_surface_agrees_with_its_plane_and_a_plane_through_a_ball_does_not() {
        let k = Intrinsics::KINECT_V1;
        // A plane tilted 40° from facing the camera, through (0, 0, 1.5).
        let n = Vector3::new(0.0, libm::sinf(0.7), -libm::cosf(0.7));
        let plane = Plane::through(Vector3::new(0.0, 0.0, 1.5), n);
        let flat = depth_of(|r| {
            let t = -plane.d / n.dot(&r);
            (t > 0.0).then_some(t)
        });
        // A ball of radius 0.7 m at 2.5 m, and a plane cutting across the face the camera sees.
        let c = Vector3::new(0.0, 0.0, 2.5);
        let ball = depth_of(|r| {
            let (a, b, q) = (r.dot(&r), -2.0 * r.dot(&c), c.dot(&c) - 0.49);
            let disc = b * b - 4.0 * a * q;
            (disc >= 0.0).then(|| (-b - libm::sqrtf(disc)) / (2.0 * a))
        });
        let through_ball = Plane::through(
            c - Vector3::new(0.0, 0.0, 0.3),
            Vector3::new(0.0, 1.0, -0.3).normalize(),
        );
        let judge = |depth: &[u16], plane: &Plane| {
            let frame = DepthFrame::new(depth, WIDTH as u16, HEIGHT as u16, Timestamp::default(), 0).unwrap();
            // The plane's inliers among every 6th pixel, labelled 1, as the search labels them.
            let band = PlaneConfig::default().inlier_m;
            let (mut pts, mut lab) = (vec::Vec::new(), vec::Vec::new());
            for v in (0..HEIGHT).step_by(6) {
                for u in (0..WIDTH).step_by(6) {
                    let z = depth[v * WIDTH + u];
                    if z > 0 {
                        let p = k.unproject(u as f32, v as f32, z as f32 * 0.001);
                        lab.push((libm::fabsf(plane.signed_distance(&p)) < band) as u8);
                        pts.push(p);
                    }
                }
            }
            let (tested, agree) = surface_agreement(&frame, &k, plane, &pts, &lab, 1);
            (tested, agree, one_surface((tested, agree)))
        };
        let (tested, agree, flat_ok) = judge(&flat, &plane);
        assert!(
            tested >= 100 && agree as f32 >= 0.95 * tested as f32,
            "{agree}/{tested}"
        );
        assert!(flat_ok);
        let (tested, agree, ball_ok) = judge(&ball, &through_ball);
        assert!(
            tested >= SURFACE_MIN_TESTED && (agree as f32) < 0.5 * tested as f32,
            "{agree}/{tested}"
        );
        assert!(!ball_ok);
    }

    fn scratch() -> (vec::Vec<Point3>, vec::Vec<u8>) {
        let n = scratch_points(WIDTH, HEIGHT, 6);
        (vec![Point3::origin(); n], vec![0u8; n])
    }

    /// The bed search on a frame of `depth`, up being the world's z.
    fn bed_seen_from(depth: &[u16], camera_from_world: &Isometry3) -> BedScene {
        let frame = DepthFrame::new(depth, WIDTH as u16, HEIGHT as u16, Timestamp::default(), 0).unwrap();
        let (mut pts, mut lab) = scratch();
        let up = camera_from_world.rotation * Vector3::z();
        estimate_bed(
            &frame,
            &Intrinsics::KINECT_V1,
            &PlaneConfig::default(),
            Some(&up),
            &mut pts,
            &mut lab,
        )
        .unwrap()
    }

    /// The found mattress is the world's z = 0 plane within 0.5° and 2 cm.
    fn assert_mattress_at_world_zero(bed: &BedScene, camera_from_world: &Isometry3) {
        let mattress = Plane::through(Vector3::zeros(), Vector3::z()).transformed(camera_from_world);
        assert!(
            bed.mattress.normal().dot(&mattress.normal()) > libm::cosf(0.5f32.to_radians())
                && (bed.mattress.d - mattress.d).abs() < 0.02,
            "mattress {:?} vs {mattress:?}",
            bed.mattress
        );
    }

    #[test]
    fn finds_mattress_floor_axis_and_clips_the_patient() {
        let (depth, camera_from_world, mattress, floor) = scene();
        let frame = DepthFrame::new(&depth, WIDTH as u16, HEIGHT as u16, Timestamp::default(), 0).unwrap();
        let (mut pts, mut lab) = scratch();
        let k = Intrinsics::KINECT_V1;
        let bed = estimate_bed(&frame, &k, &PlaneConfig::default(), None, &mut pts, &mut lab).unwrap();
        let angle = |a: &Plane, b: &Plane| libm::acosf(a.normal().dot(&b.normal()).min(1.0)).to_degrees();
        assert!(
            angle(&bed.mattress, &mattress) < 0.2,
            "mattress normal off by {}°",
            angle(&bed.mattress, &mattress)
        );
        assert!(
            (bed.mattress.d - mattress.d).abs() < 0.003,
            "mattress offset {} vs {}",
            bed.mattress.d,
            mattress.d
        );
        let f = bed.floor.expect("the floor is in view");
        assert!(
            angle(&f, &floor) < 0.3 && (f.d - floor.d).abs() < 0.005,
            "floor {f:?} vs {floor:?}"
        );
        // The long axis is the world y axis (the box's long side), up to sign.
        let world_from_camera = camera_from_world.inverse();
        let along =
            world_from_camera.rotation * (bed.volume.bed_from_camera.inverse().rotation * Vector3::y());
        assert!(along.y.abs() > 0.99, "long axis {along:?}");
        // The clip keeps the box top and rejects the mattress and the floor.
        let world = |p: Vector3| camera_from_world * Point3::from(p);
        assert!(bed.volume.keeps(&world(Vector3::new(0.1, 0.3, 0.22))));
        assert!(!bed.volume.keeps(&world(Vector3::new(0.4, 0.3, 0.0))));
        assert!(!bed.volume.keeps(&world(Vector3::new(0.1, 0.3, -0.55))));
        assert!(!bed.volume.keeps(&world(Vector3::new(0.1, 0.3, 1.0))));
        // Deterministic for the seed.
        let again = estimate_bed(&frame, &k, &PlaneConfig::default(), None, &mut pts, &mut lab).unwrap();
        assert_eq!(again, bed);
    }

    /// World z up. A bed whose flat mattress (top z = 0) is out of sight but for the hinge at y = 0, where the head
    /// section rises 35° toward +y as a thin plate 0.9 m wide; under it the bed's base (top z = -0.15), seen from
    /// the side through the wedge; the floor at z = -0.75; a patient's block on the section. The camera is beside
    /// the bed, above it. With `tilted`, a plate 0.9 x 0.6 m toward the foot end tilted `tilted` degrees about the
    /// bed's long axis, its centre 5 cm under the mattress's top (what RANSAC can fit through the legs' side and the
    /// base's far end). The camera and the depth.
    fn bared_base_scene(tilted: Option<f32>) -> (Isometry3, vec::Vec<u16>) {
        let raise = 35f32.to_radians();
        let (sr, cr) = (libm::sinf(raise), libm::cosf(raise));
        let section_n = Vector3::new(0.0, -sr, cr);
        let up_slope = move |p: Vector3| p.y * cr + p.z * sr;
        let mut plates: vec::Vec<Plate> = vec![
            (
                section_n,
                0.0,
                Box::new(move |p| p.x.abs() < 0.45 && (0.0..=0.9).contains(&up_slope(p))),
            ),
            // The patient's back half lying on the section: a block 0.2 m thick.
            (
                section_n,
                0.2,
                Box::new(move |p| p.x.abs() < 0.2 && (0.1..=0.7).contains(&up_slope(p))),
            ),
            (
                Vector3::z(),
                -0.15,
                Box::new(|p| p.x.abs() < 0.45 && (0.0..1.0).contains(&p.y)),
            ),
            (
                Vector3::z(),
                0.0,
                Box::new(|p| p.x.abs() < 0.45 && (-0.04..0.0).contains(&p.y)),
            ),
            (Vector3::z(), -0.75, Box::new(|_| true)),
        ];
        if let Some(deg) = tilted {
            let (st, ct) = (libm::sinf(deg.to_radians()), libm::cosf(deg.to_radians()));
            plates.push((
                Vector3::new(-st, 0.0, ct),
                -0.05 * ct,
                Box::new(|p| p.x.abs() < 0.45 && (-0.75..-0.15).contains(&p.y)),
            ));
        }
        plates_seen_from(
            Vector3::new(-1.3, 0.2, 1.2),
            Vector3::new(0.0, 0.45, 0.0),
            &plates,
        )
    }

    /// A plate: the plane `n·p = c` (world frame) where `inside(p)`.
    type Plate = (Vector3, f32, Box<dyn Fn(Vector3) -> bool>);

    /// The camera at `eye` looking at `target` (world z up) and the depth of the nearest of `plates` along each ray.
    fn plates_seen_from(eye: Vector3, target: Vector3, plates: &[Plate]) -> (Isometry3, vec::Vec<u16>) {
        let world_from_camera = looking_at(eye, target);
        let depth = depth_of(|ray_c| {
            let ray = world_from_camera.rotation * ray_c;
            let hits = plates.iter().filter_map(|(n, c, inside)| {
                let dn = n.dot(&ray);
                let t = (c - n.dot(&eye)) / dn;
                (dn.abs() > 1e-6 && t > 0.0 && inside(eye + ray * t)).then_some(t)
            });
            hits.min_by(f32::total_cmp)
        });
        (world_from_camera.inverse(), depth)
    }

    /// The bed of [`bared_base_scene`]: its mattress is the true one, flat at z = 0, and its 35° section is found.
    fn assert_bared_base_bed(tilted: Option<f32>) {
        let (camera_from_world, depth) = bared_base_scene(tilted);
        let bed = bed_seen_from(&depth, &camera_from_world);
        let mattress = Plane::through(Vector3::zeros(), Vector3::z()).transformed(&camera_from_world);
        assert!(
            (bed.mattress.d - mattress.d).abs() < 0.02
                && bed.mattress.normal().dot(&mattress.normal()) > 0.999,
            "{tilted:?}: mattress {:?} against {mattress:?} (the base is 0.15 m lower)",
            bed.mattress
        );
        let section = bed.head_section.expect("the raised section is found");
        let deg = libm::acosf(section.normal().dot(&bed.mattress.normal()).min(1.0)).to_degrees();
        assert!((deg - 35.0).abs() < 2.0, "{tilted:?}: section at {deg}°");
    }

    #[test]
    fn the_base_bared_by_a_raised_section_is_not_the_mattress() {
        assert_bared_base_bed(None);
    }

    #[test]
    fn a_level_looking_plane_not_parallel_to_the_bared_base_is_not_the_mattress() {
        assert_bared_base_bed(Some(4.0));
    }

    /// Points every 2 cm on a plate 0.5 m wide standing on the mattress z = 0 and rising `deg` toward +y from
    /// y = `y0`, up to `top` metres; the plate's plane.
    fn plate(deg: f32, y0: f32, top: f32) -> (vec::Vec<Point3>, Plane) {
        let (s, c) = (libm::sinf(deg.to_radians()), libm::cosf(deg.to_radians()));
        let mut pts = vec::Vec::new();
        for i in 0..26 {
            for j in 0..((top / s / 0.02) as usize + 1) {
                let along = j as f32 * 0.02;
                pts.push(Point3::new(-0.25 + i as f32 * 0.02, y0 + along * c, along * s));
            }
        }
        (
            pts,
            Plane::through(Vector3::new(0.0, y0, 0.0), Vector3::new(0.0, -s, c)),
        )
    }

    #[test]
    fn a_head_section_rises_from_the_mattress_and_ends_below_the_volume_top() {
        let cfg = PlaneConfig::default();
        let mattress = Plane::through(Vector3::zeros(), Vector3::z());
        let (section, p) = plate(40.0, 0.0, 0.6);
        assert!(rises_from_the_hinge(&p, &section, &mattress, &cfg));
        // The hips hide the hinge but for the bed's edges: 1 % of the section's points near the mattress suffice.
        let hidden: vec::Vec<Point3> = section
            .iter()
            .copied()
            .filter(|q| q.z > HINGE_BAND_M || q.x.abs() > 0.21)
            .collect();
        assert!(rises_from_the_hinge(&p, &hidden, &mattress, &cfg));
        // A flat, tilted body surface 15 cm above the mattress never reaches it.
        let (body, pb) = plate(40.0, 0.0, 0.45);
        let lifted: vec::Vec<Point3> = body
            .iter()
            .map(|q| q + Vector3::new(0.0, -0.15 / 0.84, 0.15))
            .collect();
        let pb = Plane::through(Vector3::new(0.0, -0.15 / 0.84, 0.15), pb.normal());
        assert!(!rises_from_the_hinge(&pb, &lifted, &mattress, &cfg));
        // The arm's links lined up with the bed edge: the same plate reaching 1.2 m, most of it above the 0.8 m top.
        let (arm, pa) = plate(40.0, 0.0, 1.2);
        assert!(!rises_from_the_hinge(&pa, &arm, &mattress, &cfg));
        // A plane whose points run far below the mattress (the bed's side or the floor) is not a section either.
        let (deep, pd) = plate(40.0, 0.0, 0.6);
        let deep: vec::Vec<Point3> = deep
            .iter()
            .map(|q| q - Vector3::new(0.0, 0.3 * 0.766 / 0.643, 0.3))
            .collect();
        let pd = Plane::through(Vector3::new(0.0, -0.3 * 0.766 / 0.643, -0.3), pd.normal());
        assert!(!rises_from_the_hinge(&pd, &deep, &mattress, &cfg));
        // The section with the floor's strip 0.6 m down in its band (three rows of the plane's extension, 6 % of
        // its points; s33022, s33011): still a section.
        let (mut with_strip, ps) = plate(40.0, 0.0, 0.6);
        let (sn, cs) = (libm::sinf(40f32.to_radians()), libm::cosf(40f32.to_radians()));
        for row in 0..3 {
            let along = -(0.6 + row as f32 * 0.0125) / sn;
            for i in 0..26 {
                with_strip.push(Point3::new(-0.25 + i as f32 * 0.02, along * cs, along * sn));
            }
        }
        assert!(rises_from_the_hinge(&ps, &with_strip, &mattress, &cfg));
    }

    #[test]
    fn a_sections_bottom_is_at_the_hinge_whatever_strip_of_the_floor_its_band_takes_in() {
        // A section raised 30° from the hinge at the mattress (z = 0), and where its plane crosses a level surface
        // `below` the mattress, that surface's points in its inlier band: a far floor comes in depth layers, up to
        // 32 mm off the floor's plane (s19019), here 8 % of the section's points.
        let (section_pts, section) = plate(30.0, 0.0, 0.6);
        let own = section_pts.len();
        let (s, c) = (libm::sinf(30f32.to_radians()), libm::cosf(30f32.to_radians()));
        let with_strip = |below: f32| {
            let mut pts = section_pts.clone();
            for i in 0..26 {
                for dz in [-0.032f32, -0.016, 0.0, 0.016, 0.032] {
                    let z = dz - below;
                    pts.push(Point3::new(-0.25 + i as f32 * 0.02, z / s * c, z));
                }
            }
            pts
        };
        let floor = Plane::through(Vector3::new(0.0, 0.0, -0.6), Vector3::z());
        let mattress = Plane::through(Vector3::zeros(), Vector3::z());
        let found = [(section, own), (floor, 2 * own)];
        let height = |pts: &[Point3], floor| {
            let labels = vec![1u8; pts.len()];
            let bottom = SectionBottom {
                label: 1,
                points: own,
                up: Vector3::z(),
                found: &found,
                floor,
                surface: None,
            };
            bottom.height_above(&mattress, pts, &labels)
        };
        let far = with_strip(0.6);
        // The identified floor's strip is left out; without the floor found, the empty 0.5 m between leaves it out.
        // (Either alone mends this strip; on the stored sequences' first frames each alone mended fewer.)
        for floor in [Some(floor), None] {
            let h = height(&far, floor);
            assert!(h.abs() < 0.02, "{floor:?}: {h}");
        }
        // Points 0.2 m under the hinge (the bed's base, say) are no such gap away: they are the bottom.
        let near = with_strip(0.2);
        let h = height(&near, None);
        assert!((h + 0.2).abs() < 0.04, "{h}");
        // Nor is a fifth of the points or more, whatever the gap: the section may be mostly hidden.
        let mut heavy = far.clone();
        for _ in 0..3 {
            heavy.extend_from_slice(&far[own..]);
        }
        let h = height(&heavy, None);
        assert!((h + 0.6).abs() < 0.04, "{h}");
    }

    /// A bed whose flat part returns no depth (a dark cover), its head section raised 40° from the hinge at world
    /// y = 0 (0.9 m wide, 0.8 m long), the patient's legs a box 0.22 m high (0.36 x 0.65 m) on the flat part, the
    /// arm's link a 0.4 x 0.4 m plate 0.45 m above the mattress, the floor around the bed; the camera and the true
    /// section.
    fn hidden_mattress_scene() -> (vec::Vec<u16>, Isometry3, Plane) {
        section_scene(None)
    }

    /// [`hidden_mattress_scene`], or with `Some(from)` the flat mattress in view beside the legs and the section only
    /// from `from` metres up its slope (the patient and the arm hide its lower part; nothing hides the mattress there,
    /// so rays meet it), 1.2 m long.
    fn section_scene(section_from_m: Option<f32>) -> (vec::Vec<u16>, Isometry3, Plane) {
        let k = Intrinsics::KINECT_V1;
        // From beyond the foot end, looking at the section.
        let eye = Vector3::new(0.1, -1.5, 1.3);
        let world_from_camera = looking_at(eye, Vector3::new(0.0, 0.3, 0.2));
        let raise = 40f32.to_radians();
        let section_n = Vector3::new(0.0, -libm::sinf(raise), libm::cosf(raise));
        let mut depth = vec![0u16; PIXELS];
        for v in 0..HEIGHT {
            for u in 0..WIDTH {
                let ray = world_from_camera.rotation * k.unproject(u as f32, v as f32, 1.0).coords;
                let mut best = f32::INFINITY;
                let mut hit = |n: Vector3, d: f32, inside: &dyn Fn(Vector3) -> bool| {
                    let den = n.dot(&ray);
                    if den.abs() > 1e-6 {
                        let t = -(n.dot(&eye) + d) / den;
                        let p = eye + ray * t;
                        if t > 0.0 && t < best && inside(p) {
                            best = t;
                        }
                    }
                };
                hit(Vector3::z(), -0.22, &|p| {
                    p.x.abs() < 0.18 && (-0.7..-0.05).contains(&p.y)
                });
                let (from, to) = section_from_m.map_or((0.0, 0.8), |from| (from, 1.2));
                hit(section_n, 0.0, &|p| {
                    let up_slope = p.y / libm::cosf(raise);
                    p.x.abs() < 0.45 && p.y >= 0.0 && (from..to).contains(&up_slope)
                });
                if section_from_m.is_some() {
                    hit(Vector3::z(), 0.0, &|p| {
                        p.x.abs() < 0.45 && (-1.0..0.0).contains(&p.y)
                    });
                }
                hit(Vector3::z(), -0.45, &|p| {
                    (0.3..0.7).contains(&p.x) && p.y.abs() < 0.2
                });
                hit(Vector3::z(), 0.55, &|p| p.x.abs() > 0.5 || p.y.abs() > 1.0);
                if best.is_finite() {
                    depth[v * WIDTH + u] = (best * 1000.0).round() as u16;
                }
            }
        }
        let camera_from_world = world_from_camera.inverse();
        let section = Plane::through(Vector3::zeros(), section_n).transformed(&camera_from_world);
        (depth, camera_from_world, section)
    }

    #[test]
    fn a_hidden_mattress_is_placed_through_the_raised_sections_bottom() {
        let (depth, camera_from_world, section) = hidden_mattress_scene();
        let bed = bed_seen_from(&depth, &camera_from_world);
        // Not the legs' top (0.22 m), the arm's plate (0.45 m) or the floor: the level plane through the hinge.
        assert_mattress_at_world_zero(&bed, &camera_from_world);
        let found = bed.head_section.expect("the raised section");
        assert!(found.normal().dot(&section.normal()) > libm::cosf(2f32.to_radians()));
        // Along the bed: up the section, world y.
        let along = camera_from_world.inverse().rotation
            * (bed.volume.bed_from_camera.inverse().rotation * Vector3::y());
        assert!(along.y > 0.99, "long axis {along:?}");
    }

    #[test]
    fn a_steep_sections_hidden_lower_part_does_not_lift_the_mattress_found_over_the_floor() {
        // s29002's case: a 40° section seen only from 0.42 m above the mattress (the patient and the arm hide the
        // rest), larger than the flat mattress's visible strips, which lie a bed's height over the floor as they
        // should.
        let (depth, camera_from_world, _) = section_scene(Some(0.65));
        let bed = bed_seen_from(&depth, &camera_from_world);
        assert!(bed.floor.is_some(), "the floor is in view");
        assert_mattress_at_world_zero(&bed, &camera_from_world);
    }

    /// World z up. s40058's bed seen from beside it: the flat mattress (top z = 0, 0.17 m thick, its side face toward
    /// the camera at x = -0.45) from the foot end to the hinge at y = 0, the head section raised 16° toward +y, a
    /// patient's legs (a block 0.2 m high) on the flat part and back (0.2 m thick) on the section, the floor at z =
    /// -0.75. The section's plane runs on below the hinge through the mattress's side face.
    fn side_face_scene() -> (Isometry3, vec::Vec<u16>) {
        let raise = 16f32.to_radians();
        let (sr, cr) = (libm::sinf(raise), libm::cosf(raise));
        let section_n = Vector3::new(0.0, -sr, cr);
        let up_slope = move |p: Vector3| p.y * cr + p.z * sr;
        let plates: [Plate; 6] = [
            (
                section_n,
                0.0,
                Box::new(move |p| p.x.abs() < 0.45 && (0.0..=0.9).contains(&up_slope(p))),
            ),
            (
                section_n,
                0.2,
                Box::new(move |p| p.x.abs() < 0.22 && (0.05..=0.6).contains(&up_slope(p))),
            ),
            (
                Vector3::z(),
                0.0,
                Box::new(|p| p.x.abs() < 0.45 && (-1.0..0.0).contains(&p.y)),
            ),
            (
                Vector3::z(),
                0.2,
                Box::new(|p| p.x.abs() < 0.22 && (-0.95..0.0).contains(&p.y)),
            ),
            // The mattress's side face and the bed's frame under it, facing the camera.
            (
                -Vector3::x(),
                0.45,
                Box::new(|p| (-1.0..0.0).contains(&p.y) && (-0.29..0.0).contains(&p.z)),
            ),
            (Vector3::z(), -0.75, Box::new(|_| true)),
        ];
        plates_seen_from(Vector3::new(-1.3, 0.1, 1.1), Vector3::new(0.0, 0.1, 0.0), &plates)
    }

    #[test]
    fn the_mattress_side_under_the_sections_plane_is_not_the_sections_bottom() {
        let (camera_from_world, depth) = side_face_scene();
        let bed = bed_seen_from(&depth, &camera_from_world);
        assert_mattress_at_world_zero(&bed, &camera_from_world);
        let section = bed.head_section.expect("the raised section is found");
        let deg = libm::acosf(section.normal().dot(&bed.mattress.normal()).min(1.0)).to_degrees();
        assert!((deg - 16.0).abs() < 2.0, "section at {deg}°");
    }

    #[test]
    fn a_few_strays_below_a_gap_are_not_the_sections_bottom() {
        // s51036's first frame, in shape: 1200 section points rising evenly from the hinge (0 to 0.6 m), six strays
        // 0.10-0.18 m below it (a surface crossing the plane under the hinge) and a floor strip 0.7 m below.
        let section = (0..1200).map(|i| i as f32 * 0.0005);
        let strays = [-0.177, -0.177, -0.135, -0.115, -0.102, -0.102];
        let floor = (0..26).map(|i| -0.75 + i as f32 * 0.002);
        let values: vec::Vec<f32> = section.chain(strays).chain(floor).collect();
        let own = || values.iter().map(|&v| Some(v));
        let bottom = low_quantile(own, SECTION_BOTTOM_SHARE, &SECTION_DROPS);
        assert!(bottom.abs() < 0.01, "bottom {bottom}");
        // With the floor's rule alone the lowest stray was the bottom.
        let floor_only = low_quantile(own, SECTION_BOTTOM_SHARE, &SECTION_DROPS[..1]);
        assert!((floor_only + 0.177).abs() < 0.01, "floor rule alone {floor_only}");
        // Strays more than SECTION_STRAY_MAX_SHARE of the points are the section's own: nothing is dropped.
        let many: vec::Vec<f32> = (0..1200)
            .map(|i| i as f32 * 0.0005)
            .chain((0..60).map(|i| -0.12 + i as f32 * 0.0002))
            .collect();
        let bottom = low_quantile(
            || many.iter().map(|&v| Some(v)),
            SECTION_BOTTOM_SHARE,
            &SECTION_DROPS,
        );
        assert!(bottom < -0.1, "bottom {bottom}");
    }

    #[test]
    fn a_sections_bottom_may_hide_up_to_twenty_centimetres_above_the_mattress() {
        // s402's lowest visible section point (14 cm), s34011's (14.8-16.0 cm in its first frames).
        for h in [0.0, 0.14, 0.148, 0.155, 0.16] {
            assert!(bottom_may_be_hidden(h), "{h}");
        }
        // A tilted body surface lying on a flat bed starts a torso's depth up; a plane running below the mattress
        // is the bed's side or the floor.
        for h in [0.22, 0.3, -0.1] {
            assert!(!bottom_may_be_hidden(h), "{h}");
        }
    }

    #[test]
    fn a_section_spans_the_bed_and_a_tilted_body_part_does_not() {
        let up = Vector3::z();
        let (wide, pw) = plate(40.0, 0.0, 0.6);
        let labels = vec![1u8; wide.len()];
        assert!(spans_the_bed(&pw, &up, &wide, &labels, 1, &[]));
        // A thigh or the chest: the same slope 0.3 m wide.
        let narrow: vec::Vec<Point3> = wide.iter().copied().filter(|q| q.x.abs() < 0.15).collect();
        assert!(!spans_the_bed(&pw, &up, &narrow, &labels[..narrow.len()], 1, &[]));
        // Only the plane's own points count.
        assert!(!spans_the_bed(&pw, &up, &wide, &labels, 2, &[]));
        // Nor the strip of a level plane that its band takes in where the two cross (2 m of mattress along the
        // narrow plate's foot): it is still narrow.
        let mattress = [(Plane::through(Vector3::zeros(), up), 1)];
        let mut standing = narrow.clone();
        standing.extend((0..200).map(|i| Point3::new(-1.0 + i as f32 * 0.01, 0.0, 0.0)));
        assert!(spans_the_bed(
            &pw,
            &up,
            &standing,
            &vec![1u8; standing.len()],
            1,
            &[]
        ));
        let standing_labels = vec![1u8; standing.len()];
        assert!(!spans_the_bed(
            &pw,
            &up,
            &standing,
            &standing_labels,
            1,
            &mattress
        ));
    }

    #[test]
    fn a_plate_above_a_mattress_without_floor_is_not_the_mattress() {
        // The floor out of view (a mattress filling the image) and a horizontal plate 0.67 m above it, off the
        // patient's box: a bed's height apart, like floor and mattress, but the patient lies on the lower plane.
        let (depth, camera_from_world, mattress, _) = scene_with(3.0, Some(0.67));
        assert_mattress_without_floor(&depth, &camera_from_world, &mattress);
    }

    /// The bed search on `depth` finds `mattress` (camera frame) and no floor.
    fn assert_mattress_without_floor(depth: &[u16], camera_from_world: &Isometry3, mattress: &Plane) {
        let bed = bed_seen_from(depth, camera_from_world);
        assert!(
            (bed.mattress.d - mattress.d).abs() < 0.003,
            "mattress {:?} vs {mattress:?}",
            bed.mattress
        );
        assert_eq!(bed.floor, None);
    }

    #[test]
    fn a_plate_too_near_the_camera_is_not_the_mattress_whatever_lies_on_it() {
        // As above, but a sloping slab (the arm's upper links, rising toward the camera) 5-41 cm above the plate
        // fills more of the image than the patient's box: by what lies on it the plate looks like the mattress and
        // the mattress like the floor. A patient lying on the plate, 0.6 m from the camera, could not be seen.
        let (mut depth, camera_from_world, mattress, _) = scene_with(3.0, Some(0.67));
        assert!(add_slab(&mut depth, &camera_from_world) > 15_000);
        assert_mattress_without_floor(&depth, &camera_from_world, &mattress);
    }

    /// Draws the arm's upper links of [`a_plate_too_near_the_camera_is_not_the_mattress_whatever_lies_on_it`] into
    /// `depth`; returns the pixels they cover.
    fn add_slab(depth: &mut [u16], camera_from_world: &Isometry3) -> usize {
        // z = 0.72 + 0.26 (0.2 - y) / 0.8 over y in -0.9..0.2, x in -0.55..-0.15: rising toward the camera, a strip
        // 0.4 m wide across its slope (not a bed-wide head section).
        let slope = 0.26 / 0.8;
        overlay_plane(
            depth,
            camera_from_world,
            (Vector3::new(0.0, slope, 1.0), Vector3::new(0.0, 0.2, 0.72)),
            |p| (-0.9..0.2).contains(&p.y) && (-0.55..-0.15).contains(&p.x),
        )
    }

    /// Draws into `depth` the part of the world plane (normal, point) that `inside` keeps, wherever it is nearer
    /// than what `depth` holds; returns the pixels drawn.
    fn overlay_plane(
        depth: &mut [u16],
        camera_from_world: &Isometry3,
        (n, at): (Vector3, Vector3),
        inside: impl Fn(Vector3) -> bool,
    ) -> usize {
        let world_from_camera = camera_from_world.inverse();
        let k = Intrinsics::KINECT_V1;
        let eye = world_from_camera.translation.vector;
        let mut pixels = 0;
        for v in 0..HEIGHT {
            for u in 0..WIDTH {
                let ray = world_from_camera.rotation * k.unproject(u as f32, v as f32, 1.0).coords;
                let den = n.dot(&ray);
                if den.abs() < 1e-6 {
                    continue;
                }
                let t = n.dot(&(at - eye)) / den;
                let p = eye + ray * t;
                let old = depth[v * WIDTH + u];
                if t > 0.0 && inside(p) && (old == 0 || t * 1000.0 < old as f32) {
                    depth[v * WIDTH + u] = (t * 1000.0).round() as u16;
                    pixels += 1;
                }
            }
        }
        pixels
    }

    /// Draws a ramp 1.2 m wide rising 49° toward the head end from 0.1 m over the mattress at y = 0.3 into `depth`
    /// (a tilted, bed-wide plane: what a head section looks like to the search); returns the pixels it covers.
    fn tilted_ramp(depth: &mut [u16], camera_from_world: &Isometry3) -> usize {
        const RAMP_Y: f32 = 0.3;
        const RAMP_Z: f32 = 0.1;
        let (s, c) = (libm::sinf(49f32.to_radians()), libm::cosf(49f32.to_radians()));
        overlay_plane(
            depth,
            camera_from_world,
            (Vector3::new(0.0, -s, c), Vector3::new(0.0, RAMP_Y, RAMP_Z)),
            |p| p.x.abs() < 0.6 && (0.0..0.8).contains(&((p.y - RAMP_Y) * c + (p.z - RAMP_Z) * s)),
        )
    }

    #[test]
    fn an_arm_links_top_near_the_camera_does_not_make_the_mattress_the_floor() {
        // The slab's scene (more of the arm "lies on" the plate 0.67 m up, 0.6 m from the camera, than of the
        // patient on the mattress) and a ramp whose bottom the search takes for a raised section's. With the plate
        // taken for a mattress over a "floor" (here the patient's top, on s22008 the mattress), no level plane was
        // left for the mattress, and it was placed through the ramp's bottom (s22008: 153 mm low).
        let (mut depth, camera_from_world, mattress, _) = scene_with(3.0, Some(0.67));
        assert!(add_slab(&mut depth, &camera_from_world) > 15_000);
        assert!(tilted_ramp(&mut depth, &camera_from_world) > 20_000);
        assert_mattress_without_floor(&depth, &camera_from_world, &mattress);
    }

    #[test]
    fn empty_or_flat_frames_are_errors() {
        let k = Intrinsics::KINECT_V1;
        let (mut pts, mut lab) = scratch();
        let empty = vec![0u16; PIXELS];
        let frame = DepthFrame::new(&empty, WIDTH as u16, HEIGHT as u16, Timestamp::default(), 0).unwrap();
        assert!(matches!(
            estimate_bed(&frame, &k, &PlaneConfig::default(), None, &mut pts, &mut lab),
            Err(PlaneError::TooFewPoints { .. })
        ));
        // A wall 2 m away: one plane, nothing on it.
        let wall = vec![2000u16; PIXELS];
        let frame = DepthFrame::new(&wall, WIDTH as u16, HEIGHT as u16, Timestamp::default(), 0).unwrap();
        assert_eq!(
            estimate_bed(&frame, &k, &PlaneConfig::default(), None, &mut pts, &mut lab),
            Err(PlaneError::NoPatientOnBed)
        );
        assert!(matches!(
            estimate_bed(
                &frame,
                &k,
                &PlaneConfig::default(),
                None,
                &mut pts[..10],
                &mut lab
            ),
            Err(PlaneError::ScratchTooSmall { .. })
        ));
    }
}
