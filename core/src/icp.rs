//! Rigid ICP of a model point set against a depth frame: projective association, point-to-plane error, one
//! linearised 6-DoF Gauss-Newton step per call (paper §3.4; the shape fit and the tracker both use it).
//!
//! Association: a model point (camera frame) is projected into the depth image; the observed point at that pixel
//! is its partner when it lies above the mattress margin (and above the raised head section's, when the bed has
//! one), within `max_distance_m` (the paper's 0.1 m), and not in front of the model point by more than
//! `occluder_margin_m`: points in front of the model surface belong to whatever occludes the body (the robot arm, a
//! raised hand) and are counted, not fitted, unless they lie lower over the bed than a lying patient's front reaches
//! (`body_max_height_m`): those are the patient, in front of a model that has sunk behind them. The observed normal
//! comes from the depth neighbours `normal_step_px` away.
//!
//! Cost: per model point one projection, three unprojections and a 6x6 outer product (~80 flops): 1.2 k torso
//! points take about 20 µs per step on one desktop core; nothing allocates. A frame that carries a normal memo
//! ([`crate::normal_memo`], the tracker's frames) computes each pixel's normal once however many fits and steps read
//! it, with the same result.

use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::{Isometry3, Plane, Point3, Translation3, UnitQuaternion, Vector3};
use crate::spd::solve_spd;

/// Pixel distance of the depth neighbours that give an observed normal ([`IcpParams::new`]'s).
pub const NORMAL_STEP_PX: u16 = 2;

/// Association and rejection parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpParams {
    /// Largest model-to-observed distance of a pair (metres).
    pub max_distance_m: f32,
    /// An observed point nearer to the camera than its model point by more than this is an occluder (metres).
    pub occluder_margin_m: f32,
    /// The mattress plane in the camera frame (normal up); observed points below `above_mattress_m` are bed.
    pub mattress: Plane,
    /// The bed's raised head section in the camera frame (normal up), when there is one: observed points must lie
    /// `above_mattress_m` above it too, or the raised mattress beside the torso pairs with the model's edges.
    pub head_section: Option<Plane>,
    /// Height above the mattress below which observed points are not body (metres).
    pub above_mattress_m: f32,
    /// Pixel distance of the neighbours that give an observed normal.
    pub normal_step_px: u16,
    /// An observed point farther from the camera than its model point by more than this is not its partner (the
    /// camera sees past the model's edge onto the arms or the bed), metres; infinite keeps such pairs.
    pub behind_margin_m: f32,
    /// An observed point in front of its model point by more than `occluder_margin_m` but lower than this above the
    /// bed is the patient, not an occluder, and is paired (metres; 0: off, every such point is an occluder).
    pub body_max_height_m: f32,
}

impl IcpParams {
    /// The paper's settings (0.1 m correspondences) for a given mattress plane.
    pub fn new(mattress: Plane) -> IcpParams {
        IcpParams {
            max_distance_m: 0.1,
            occluder_margin_m: 0.04,
            mattress,
            head_section: None,
            above_mattress_m: 0.015,
            normal_step_px: NORMAL_STEP_PX,
            behind_margin_m: f32::INFINITY,
            body_max_height_m: 0.0,
        }
    }

    /// Whether an observed point (camera frame) is bed: less than `above_mattress_m` above the bed's surface.
    pub fn is_bed(&self, o: &Point3) -> bool {
        self.above_bed(o).0 < self.above_mattress_m
    }

    /// Whether an observed point `o` (camera frame) in front of the model surface occludes it: it is not the
    /// patient's own front, which lies less than `body_max_height_m` above the bed.
    pub fn occludes(&self, o: &Point3) -> bool {
        self.body_max_height_m <= 0.0 || self.above_bed(o).0 >= self.body_max_height_m
    }

    /// Whether the camera sees the observed point `o` more than `occluder_margin_m` behind the model point `p`
    /// (both camera frame): through the model, where there is no body.
    #[inline(always)]
    pub fn sees_through(&self, p: &Point3, o: &Point3) -> bool {
        o.z > p.z + self.occluder_margin_m
    }

    /// Height of `p` (camera frame) above the bed's surface, the higher of the mattress and the raised head section,
    /// and that surface's normal.
    pub fn above_bed(&self, p: &Point3) -> (f32, Vector3) {
        let m = (self.mattress.signed_distance(p), self.mattress.normal());
        match self.head_section {
            Some(h) if h.signed_distance(p) < m.0 => (h.signed_distance(p), h.normal()),
            _ => m,
        }
    }
}

/// One association pass: pairs found, occluders seen, and the point-to-plane residual.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Association {
    /// Accepted pairs.
    pub pairs: usize,
    /// Model points whose observed partner lay in front of them (occluded).
    pub occluded: usize,
    /// Sum of squared point-to-plane residuals of the pairs (m²).
    pub sum_sq_m2: f32,
    /// Pairs whose point-to-plane residual is under [`INLIER_M`].
    pub inliers: usize,
    /// Model points with the observed surface well behind them (the camera sees through the model: it floats
    /// where there is no body), paired or not.
    pub see_through: usize,
    /// Model points whose pixel has no depth (a shadow, a dropout, an occluder nearer than the sensor's range).
    pub no_depth: usize,
}

/// A pair with a point-to-plane residual under this is an inlier (metres): the shape estimate's typical mismatch.
pub const INLIER_M: f32 = 0.015;

impl Association {
    /// RMS point-to-plane residual (metres), 0 without pairs.
    pub fn rms_m(&self) -> f32 {
        if self.pairs == 0 {
            0.0
        } else {
            libm::sqrtf(self.sum_sq_m2 / self.pairs as f32)
        }
    }
}

/// One extra linearised residual of a rigid step beside the point-to-plane pairs: `r + j·(ω, t)` with the step's
/// rotation `ω` and translation `t` (camera frame), weighted by `w` times the step's pair count (so `w = 1` weighs
/// it like all pairs together at the same residual).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PriorRow {
    /// Jacobian: rotation part then translation part.
    pub j: [f32; 6],
    /// Residual at the current pose (metres).
    pub r: f32,
    /// Weight per pair of the step's data term.
    pub w: f32,
}

/// Why an ICP step could not be taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IcpError {
    /// Fewer pairs than unknowns.
    TooFewPairs {
        /// Pairs found.
        pairs: usize,
    },
    /// The 6x6 system was singular (a degenerate, e.g. planar, point set).
    Singular,
}

impl core::fmt::Display for IcpError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            IcpError::TooFewPairs { pairs } => write!(f, "ICP found only {pairs} correspondences"),
            IcpError::Singular => f.write_str("ICP system is singular"),
        }
    }
}

impl core::error::Error for IcpError {}

fn observed(frame: &DepthFrame<'_>, k: &Intrinsics, u: i32, v: i32) -> Option<Point3> {
    match frame.at(u, v) {
        Some(d) if d != 0 => Some(point_at(k, u, v, d)),
        _ => None,
    }
}

/// The camera-frame point of pixel (`u`, `v`) at depth `d_mm`.
#[inline(always)]
fn point_at(k: &Intrinsics, u: i32, v: i32, d_mm: u16) -> Point3 {
    k.unproject(u as f32, v as f32, d_mm as f32 * 0.001)
}

/// What the observed surface offers a model point: its partner, or why it has none (the counts of
/// [`Association`]).
enum Pairing {
    /// The observed point and its unit normal toward the camera.
    Pair(Point3, Vector3),
    /// The observed point lies in front of the model point and is an occluder.
    Occluded,
    /// Its pixel has no depth.
    NoDepth,
    /// The observed surface lies more than the occluder margin behind it.
    SeeThrough,
    /// Anything else (off the image, bed, too far, no normal).
    Other,
}

/// The [`Pairing`] of `p_cam` (camera frame): one projection and one pixel read, whatever the outcome.
// Inlined into the association loop (with `partner_of`): left to the compiler it stayed a call per model point and
// the tracker's ICP stage ran 7 % slower than before this function existed; inlined, 21 % faster (docs/tracking.md).
#[inline(always)]
fn pairing(frame: &DepthFrame<'_>, k: &Intrinsics, p_cam: &Point3, params: &IcpParams) -> Pairing {
    let Some(uv) = k.project(p_cam) else {
        return Pairing::Other;
    };
    let (u, v) = (libm::roundf(uv.x) as i32, libm::roundf(uv.y) as i32);
    let o = match frame.at(u, v) {
        None => return Pairing::Other,
        Some(0) => return Pairing::NoDepth,
        Some(d) => point_at(k, u, v, d),
    };
    if o.z < p_cam.z - params.occluder_margin_m && params.occludes(&o) {
        return Pairing::Occluded;
    }
    match partner_of(frame, k, p_cam, o, u, v, params) {
        Some(n) => Pairing::Pair(o, n),
        None if params.sees_through(p_cam, &o) => Pairing::SeeThrough,
        None => Pairing::Other,
    }
}

/// The observed partner's unit normal toward the camera, for the observed point `o` at pixel (`u`, `v`) known not to
/// occlude `p_cam`; `None` when it is not a partner.
#[inline(always)]
fn partner_of(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    p_cam: &Point3,
    o: Point3,
    u: i32,
    v: i32,
    params: &IcpParams,
) -> Option<Vector3> {
    if params.is_bed(&o)
        || (o - p_cam).norm() > params.max_distance_m
        || o.z > p_cam.z + params.behind_margin_m
    {
        return None;
    }
    let s = params.normal_step_px.max(1);
    let n = match frame.normal_memo() {
        Some(memo) if memo.step_px() == s => {
            memo.get_or(u, v, || observed_normal(frame, k, &o, u, v, s).map(Into::into))
        }
        _ => observed_normal(frame, k, &o, u, v, s).map(Into::into),
    };
    n.map(Vector3::from)
}

/// The unit normal toward the camera of the surface observed at pixel (`u`, `v`) (point `o`), from its depth
/// neighbours `step` pixels away; `None` where a neighbour is missing or lies across a depth edge.
fn observed_normal(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    o: &Point3,
    u: i32,
    v: i32,
    step: u16,
) -> Option<Vector3> {
    let s = step as i32;
    let near = |q: Option<Point3>| q.filter(|q| (q.z - o.z).abs() < 0.05);
    let (Some(l), Some(r), Some(t), Some(b)) = (
        near(observed(frame, k, u - s, v)),
        near(observed(frame, k, u + s, v)),
        near(observed(frame, k, u, v - s)),
        near(observed(frame, k, u, v + s)),
    ) else {
        return None;
    };
    let n = (r - l).cross(&(b - t));
    let nn = n.norm();
    if nn.is_nan() || nn <= 0.0 {
        return None;
    }
    let mut n = n / nn;
    if n.dot(&o.coords) > 0.0 {
        n = -n;
    }
    Some(n)
}

/// Associate every model point (`points`, model frame, every `stride`-th) moved by `camera_from_model`, calling
/// `on_pair(index, model point in camera frame, observed point, observed normal)` for each accepted pair. With
/// `normals` (outward model normals, model frame, one per point), points facing away from the camera are skipped:
/// the camera cannot see them, and their projective partner would be the near surface.
#[allow(clippy::too_many_arguments)] // the frame, its camera, the model points and the pose are all needed
pub fn associate<P: Copy + Into<Point3>, N: Copy + Into<Vector3>>(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    points: &[P],
    normals: Option<&[N]>,
    stride: usize,
    camera_from_model: &Isometry3,
    params: &IcpParams,
    mut on_pair: impl FnMut(usize, &Point3, &Point3, &Vector3),
) -> Association {
    let mut a = Association::default();
    for (i, q) in points.iter().enumerate().step_by(stride.max(1)) {
        let p = camera_from_model * (*q).into();
        if let Some(nm) = normals.and_then(|n| n.get(i))
            && (camera_from_model.rotation * (*nm).into()).dot(&p.coords) >= 0.0
        {
            continue;
        }
        match pairing(frame, k, &p, params) {
            Pairing::Pair(o, n) => {
                let r = n.dot(&(p - o));
                a.pairs += 1;
                a.sum_sq_m2 += r * r;
                a.inliers += (r.abs() < INLIER_M) as usize;
                a.see_through += params.sees_through(&p, &o) as usize;
                on_pair(i, &p, &o, &n);
            }
            Pairing::NoDepth => a.no_depth += 1,
            Pairing::SeeThrough => a.see_through += 1,
            Pairing::Occluded => a.occluded += 1,
            Pairing::Other => {}
        }
    }
    a
}

/// Add residual `r` with Jacobian `j` and weight `w` to the normal equations `a` (lower triangle) and `b`.
#[inline(always)]
fn accumulate(a: &mut [[f32; 6]; 6], b: &mut [f32; 6], j: &[f32; 6], r: f32, w: f32) {
    for x in 0..6 {
        b[x] -= w * j[x] * r;
        for y in 0..=x {
            a[x][y] += w * j[x] * j[y];
        }
    }
}

/// One point-to-plane Gauss-Newton step: the updated `camera_from_model` and the association it was computed from.
#[allow(clippy::too_many_arguments)] // as `associate`
pub fn point_to_plane_step<P: Copy + Into<Point3>, N: Copy + Into<Vector3>>(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    points: &[P],
    normals: Option<&[N]>,
    stride: usize,
    camera_from_model: &Isometry3,
    params: &IcpParams,
) -> Result<(Isometry3, Association), IcpError> {
    robust_point_to_plane_step(
        frame,
        k,
        points,
        normals,
        stride,
        camera_from_model,
        params,
        f32::INFINITY,
        &[],
    )
}

/// [`point_to_plane_step`] with Huber weights: a pair whose point-to-plane residual exceeds `huber_m` counts with
/// weight `huber_m / |r|` (one IRLS step), so the few wrong pairs at the occluder's rim or a raised hand do not drag
/// the pose. `f32::INFINITY` gives plain least squares. `rows` are prior residuals added to the same system.
#[allow(clippy::too_many_arguments)] // as `associate`
pub fn robust_point_to_plane_step<P: Copy + Into<Point3>, N: Copy + Into<Vector3>>(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    points: &[P],
    normals: Option<&[N]>,
    stride: usize,
    camera_from_model: &Isometry3,
    params: &IcpParams,
    huber_m: f32,
    rows: &[PriorRow],
) -> Result<(Isometry3, Association), IcpError> {
    let mut a = [[0.0f32; 6]; 6];
    let mut b = [0.0f32; 6];
    // Linearise about the centroid-free camera frame: p' = p + ω × p + t, r' = r + (p × n)·ω + n·t.
    let assoc = associate(
        frame,
        k,
        points,
        normals,
        stride,
        camera_from_model,
        params,
        |_, p, o, n| {
            let r = n.dot(&(p - o));
            let w = if libm::fabsf(r) > huber_m {
                huber_m / libm::fabsf(r)
            } else {
                1.0
            };
            let c = p.coords.cross(n);
            accumulate(&mut a, &mut b, &[c.x, c.y, c.z, n.x, n.y, n.z], r, w);
        },
    );
    if assoc.pairs < 6 {
        return Err(IcpError::TooFewPairs { pairs: assoc.pairs });
    }
    for row in rows {
        accumulate(&mut a, &mut b, &row.j, row.r, row.w * assoc.pairs as f32);
    }
    // A whisper of damping keeps a nearly planar patch from sliding without bound.
    for (i, row) in a.iter_mut().enumerate() {
        row[i] += 1e-6 * assoc.pairs as f32;
    }
    if !solve_spd(&mut a, &mut b) {
        return Err(IcpError::Singular);
    }
    let delta = Isometry3::from_parts(
        Translation3::new(b[3], b[4], b[5]),
        UnitQuaternion::new(Vector3::new(b[0], b[1], b[2])),
    );
    Ok((delta * camera_from_model, assoc))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_raised_head_section_is_bed_like_the_mattress() {
        // Bed frame as camera frame for the test: mattress z = 0 (normal up), head section raised 30° about the
        // hinge line x at y = 0, toward +y.
        let mut params = IcpParams::new(Plane::through(Vector3::zeros(), Vector3::z()));
        let (s, c) = (libm::sinf(30f32.to_radians()), libm::cosf(30f32.to_radians()));
        let on_section = Point3::new(0.1, 0.5 * c, 0.5 * s + 0.005);
        let on_body = Point3::new(0.1, 0.5 * c, 0.5 * s + 0.1);
        let on_flat = Point3::new(0.1, -0.5, 0.005);
        // Without the section, its surface is 25 cm above the mattress: body.
        assert!(!params.is_bed(&on_section));
        params.head_section = Some(Plane::through(Vector3::zeros(), Vector3::new(0.0, -s, c)));
        assert!(params.is_bed(&on_section));
        assert!(!params.is_bed(&on_body));
        // The flat part stays bed, and a body lying on it stays body (the extended section plane is far below).
        assert!(params.is_bed(&on_flat));
        assert!(!params.is_bed(&Point3::new(0.1, -0.5, 0.1)));
    }

    /// A 64x48 camera for frames small enough to write out in a test.
    const SMALL_CAMERA: Intrinsics = Intrinsics {
        fx: 60.0,
        fy: 60.0,
        cx: 31.5,
        cy: 23.5,
        width: 64,
        height: 48,
    };

    /// A flat wall 1 m from [`SMALL_CAMERA`] (depth, mm), and a 5x5 grid of model points 0.1 m apart at depth
    /// `z` with normals toward the camera.
    fn wall_and_grid(z: f32) -> ([u16; 64 * 48], [Point3; 25], [Vector3; 25]) {
        let mut points = [Point3::origin(); 25];
        for (i, p) in points.iter_mut().enumerate() {
            *p = Point3::new(-0.2 + 0.1 * (i % 5) as f32, -0.2 + 0.1 * (i / 5) as f32, z);
        }
        ([1000u16; 64 * 48], points, [Vector3::new(0.0, 0.0, -1.0); 25])
    }

    /// One unweighted (no Huber) step of every point with its normal from the identity pose, [`SMALL_CAMERA`].
    fn step_from_identity(
        frame: &DepthFrame<'_>,
        points: &[Point3],
        normals: &[Vector3],
        params: &IcpParams,
        rows: &[PriorRow],
    ) -> Result<(Isometry3, Association), IcpError> {
        robust_point_to_plane_step(
            frame,
            &SMALL_CAMERA,
            points,
            Some(normals),
            1,
            &Isometry3::identity(),
            params,
            f32::INFINITY,
            rows,
        )
    }

    #[test]
    fn a_prior_row_moves_the_pose_where_the_pairs_leave_it_free() {
        // A flat wall 1 m in front of a small camera: the pairs fix depth, pitch and roll, and leave the slide
        // across the wall free; a row asking for x 1 cm lower takes the step there and changes nothing else.
        let (depth, points, normals) = wall_and_grid(1.0);
        let frame = DepthFrame::new(&depth, 64, 48, crate::time::Timestamp::default(), 0).unwrap();
        let below = Plane::through(Vector3::new(0.0, 0.0, 3.0), Vector3::new(0.0, 0.0, -1.0));
        let params = IcpParams::new(below);
        let row = PriorRow {
            j: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            r: 0.01,
            w: 1.0,
        };
        let step = |rows: &[PriorRow]| {
            let (pose, a) = step_from_identity(&frame, &points, &normals, &params, rows).unwrap();
            assert_eq!(a.pairs, 25);
            pose
        };
        let free = step(&[]);
        assert!(free.translation.vector.norm() < 1e-5 && free.rotation.angle() < 1e-5);
        let held = step(&[row]);
        let t = held.translation.vector;
        assert!(
            (t.x + 0.01).abs() < 1e-4 && t.y.abs() < 1e-5 && t.z.abs() < 1e-5,
            "{t:?}"
        );
        assert!(held.rotation.angle() < 1e-4);
    }

    #[test]
    fn a_front_low_over_the_bed_is_the_patient_and_pulls_a_sunk_model_out() {
        // A flat front 1 m from the camera, 20 cm above a bed whose surface is z = 1.2 (normal toward the camera),
        // and a model sunk 6 cm behind it: past the 4 cm occluder margin.
        let k = SMALL_CAMERA;
        let (depth, points, normals) = wall_and_grid(1.06);
        let frame = DepthFrame::new(&depth, 64, 48, crate::time::Timestamp::default(), 0).unwrap();
        let bed = Plane::through(Vector3::new(0.0, 0.0, 1.2), Vector3::new(0.0, 0.0, -1.0));
        let params = |h: f32| IcpParams {
            body_max_height_m: h,
            ..IcpParams::new(bed)
        };
        let step = |h: f32| step_from_identity(&frame, &points, &normals, &params(h), &[]);
        // Off, or a limit below the front's height: the front is an occluder, nothing pairs.
        for h in [0.0, 0.18] {
            let a = associate(
                &frame,
                &k,
                &points,
                Some(&normals[..]),
                1,
                &Isometry3::identity(),
                &params(h),
                |_, _, _, _| {},
            );
            assert_eq!((a.pairs, a.occluded), (0, 25), "limit {h}");
            assert!(step(h).is_err(), "limit {h}");
        }
        // Over the front's height: it is the patient, every point pairs and the step brings the model onto it.
        let (pose, a) = step(0.22).unwrap();
        assert_eq!((a.pairs, a.occluded), (25, 0));
        let t = pose.translation.vector;
        assert!(
            (t.z + 0.06).abs() < 1e-4 && t.x.abs() < 1e-5 && t.y.abs() < 1e-5,
            "{t:?}"
        );
    }

    #[test]
    fn a_normal_memo_gives_the_same_pairs_as_computing_every_normal() {
        // A bumpy surface with a hole and a depth edge, and model points near it: the pairs found without a memo,
        // with a fresh memo (every normal computed) and with the same memo again (every normal read back) agree
        // to the bit, and a memo of another normal step is bypassed.
        let k = SMALL_CAMERA;
        let mut depth = [0u16; 64 * 48];
        for (i, d) in depth.iter_mut().enumerate() {
            let (u, v) = ((i % 64) as f32, (i / 64) as f32);
            *d = (1000.0 + 40.0 * libm::sinf(0.3 * u) + 25.0 * libm::cosf(0.2 * v)) as u16;
            if (20..26).contains(&(i % 64)) && (10..14).contains(&(i / 64)) {
                *d = 0;
            }
            if i % 64 >= 50 {
                *d += 300;
            }
        }
        let frame = DepthFrame::new(&depth, 64, 48, crate::time::Timestamp::default(), 0).unwrap();
        let mut points = [Point3::origin(); 300];
        for (i, p) in points.iter_mut().enumerate() {
            *p = Point3::new(
                -0.45 + 0.03 * (i % 30) as f32,
                -0.3 + 0.06 * (i / 30) as f32,
                1.01,
            );
        }
        let below = Plane::through(Vector3::new(0.0, 0.0, 3.0), Vector3::new(0.0, 0.0, -1.0));
        let params = IcpParams::new(below);
        let pose = Isometry3::from_parts(
            Translation3::new(0.01, -0.02, 0.0),
            UnitQuaternion::from_euler_angles(0.05, -0.03, 0.02),
        );
        let pairs = |f: &DepthFrame<'_>| {
            let mut seen = [None; 300];
            let a = associate(
                f,
                &k,
                &points,
                None::<&[Vector3]>,
                1,
                &pose,
                &params,
                |i, p, o, n| {
                    seen[i] = Some((*p, *o, *n));
                },
            );
            (a, seen)
        };
        let plain = pairs(&frame);
        assert!(plain.0.pairs > 100 && plain.0.no_depth > 0, "{:?}", plain.0);
        let mut cells = [crate::normal_memo::MemoCell::EMPTY; 64 * 48];
        let cells = core::cell::Cell::from_mut(&mut cells[..]).as_slice_of_cells();
        let mut stamps = crate::normal_memo::MemoStamp::default();
        let memo = frame.with_normal_memo(stamps.next(cells, 64, NORMAL_STEP_PX));
        assert!(memo.normal_memo().is_some());
        assert_eq!(pairs(&memo), plain, "the memo's first pass");
        assert_eq!(pairs(&memo), plain, "the memo read back");
        let other = frame.with_normal_memo(stamps.next(cells, 64, NORMAL_STEP_PX + 1));
        assert_eq!(pairs(&other), plain, "a memo of another step is bypassed");
        let wrong = frame.with_normal_memo(stamps.next(&cells[..64 * 47], 64, NORMAL_STEP_PX));
        assert!(
            wrong.normal_memo().is_none(),
            "a memo of another frame size is not lent"
        );
    }
}
