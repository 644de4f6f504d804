//! The guess-free start of a calibration: find the probe tip without any extrinsic guess, from what moves and
//! where "down" is, and pair it with the arm's tip for a first, rough Kabsch whose result then serves as the prior
//! of the precise detector ([`super::tip`]).
//!
//! With the bed empty or the patient still, the arm is the only thing that moves: the per-pixel median depth
//! over one still frame of each pose ([`median_background`]) is the scene without the arm wherever the arm was
//! elsewhere in most poses. In each pose's frame, the foreground (nearer than that background) above
//! the floor or mattress (of the largest planes, [`background_planes`], one under which the arm's heights
//! agree; both are horizontal) is the moving part of the arm. Every plane under which at least four poses agree
//! is tried as up, and the rough solve that fits the most poses decides (the height vote alone could prefer a
//! raised head section or a wall where the heights agree by chance).
//! The probe points down, so its tip is a local lowest point of the foreground: points are taken in rising height
//! and each joins a lower neighbour's component or starts its own; components with enough points are the
//! candidates ([`low_points`]). Which candidate is the tip is decided across poses ([`choose_tips`]): the arm's tip
//! height above its base and the candidate's height above the plane differ by the same constant at every pose
//! (the base stands level, `robot_base` z up), so the offset most poses agree on picks one candidate per pose
//! (elbow, forearm and arm parts cut by the image border give offsets that agree with nothing).
//!
//! The rough solve uses "up" on both sides too: the camera is turned so that the plane's up is the base's z, and
//! only yaw and translation are fitted (two pairs fix them), in RANSAC over pairs of candidates from different
//! poses, each pose scoring with its best candidate.
//!
//! Accuracy: the lowest seen point is a corner of the head's end face, up to ~1.5 cm across the axis from the tip
//! (its height is corrected from the arm's orientation, its sideways offset is not known before the extrinsic),
//! so the rough solve takes a 4 cm inlier threshold ([`rough_solve_options`]) and its result a 6 cm prior.
//!
//! Cost: once per pose, one pass over the frame (at most `N` foreground points kept, the stride grows until they
//! fit), a sort of those points by height and a neighbour search within a 2.5 cm height band (~5 ms); the
//! background is one max per pixel per pose; the vote is quadratic in the candidates (a few hundred at most).
//! Nothing allocates: the caller lends the background image and [`StartScratch`].

use core::fmt;

use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::{Isometry3, Plane, Point3, Translation3, UnitQuaternion, Vector3};
use crate::planes::{PlaneConfig, largest_planes};

use super::pairing::ArmSample;
use super::solve::{Pair, Solution, SolveError, SolveOptions, condition_number};
use super::tip::ProbeShape;

/// Settings of the guess-free detection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartOptions {
    /// A pixel is foreground when it is at least this much nearer than the background, metres (the background is
    /// a maximum over noisy frames, so it lies up to ~2 sd beyond the surface).
    pub foreground_m: f32,
    /// Foreground points lower than this above the plane are ignored (a hand resting on the bed, noise), metres.
    pub min_height_m: f32,
    /// Nor higher than this (the arm's base and whatever stands tall beside the bed), metres.
    pub max_height_m: f32,
    /// Two foreground points are neighbours within this distance, metres.
    pub neighbour_m: f32,
    /// Fewest points of a component for it to be a candidate.
    pub min_support: u32,
    /// Tip heights of the candidates and the arm agree within this, metres.
    pub vote_tolerance_m: f32,
    /// The probe (its head box locates the tip from its lowest corner).
    pub shape: ProbeShape,
}

impl Default for StartOptions {
    /// 4 cm foreground margin, 5 cm–1.2 m above the plane, 2.5 cm neighbours, 60 points, 3 cm vote tolerance,
    /// the synthetic probe.
    fn default() -> Self {
        StartOptions {
            foreground_m: 0.04,
            min_height_m: 0.05,
            max_height_m: 1.2,
            neighbour_m: 0.025,
            min_support: 60,
            vote_tolerance_m: 0.03,
            shape: ProbeShape::SYNTHETIC,
        }
    }
}

/// Options of the rough solve over guess-free pairs: a 4 cm inlier threshold (the pairs are ~1.5 cm apart from
/// the truth across the probe axis) and no residual limit; the condition and count limits stay.
pub fn rough_solve_options() -> SolveOptions {
    SolveOptions {
        inlier_threshold_m: 0.04,
        ..SolveOptions::lenient()
    }
}

/// Fold a frame into the background: the farthest depth seen at each pixel (0, no depth, never wins). False (and
/// nothing done) when the sizes differ.
pub fn accumulate_background(background: &mut [u16], frame: &DepthFrame<'_>) -> bool {
    let d = frame.depth_mm();
    if background.len() != d.len() {
        return false;
    }
    for (b, &v) in background.iter_mut().zip(d) {
        *b = (*b).max(v);
    }
    true
}

/// The background as the per-pixel median of the frames' depths (no depth left out; 0 where no frame has depth):
/// the arm covers a pixel in a few of the poses at most, and unlike the farthest depth the median does not pick
/// up the sensor's far outliers. At most [`MAX_POSES`] frames; false (nothing done) when sizes differ or there are
/// more frames.
pub fn median_background<'f>(
    background: &mut [u16],
    frames: usize,
    frame: impl Fn(usize) -> DepthFrame<'f>,
) -> bool {
    if frames == 0 || frames > MAX_POSES || (0..frames).any(|i| frame(i).depth_mm().len() != background.len())
    {
        return false;
    }
    let mut values = [0u16; MAX_POSES];
    for (p, b) in background.iter_mut().enumerate() {
        let mut m = 0;
        for i in 0..frames {
            let d = frame(i).depth_mm()[p];
            if d != 0 {
                values[m] = d;
                m += 1;
            }
        }
        *b = if m == 0 {
            0
        } else {
            let (_, v, _) = values[..m].select_nth_unstable(m / 2);
            *v
        };
    }
    true
}

/// Height of the band at a component's bottom whose centre locates the tip across the probe axis, metres.
const END_BAND_M: f32 = 0.03;

/// Most poses the guess-free start takes.
pub const MAX_POSES: usize = 64;

/// Candidates for "up" in the camera: the largest planes of the background (mattress, floor, a raised head
/// section, a wall), largest first, normals toward the camera, height measured from them; which one is up is
/// decided by the arm ([`rough_extrinsic`] keeps the one under which most poses agree on the tip height).
/// `points` and `labels` are scratch of at least [`crate::planes::scratch_points`]`(width, height, 6)` entries;
/// returns how many planes went to `out`.
pub fn background_planes(
    background: &[u16],
    width: u16,
    height: u16,
    k: &Intrinsics,
    points: &mut [Point3],
    labels: &mut [u8],
    out: &mut [Plane],
) -> usize {
    let (w, h) = (width as usize, height as usize);
    if background.len() != w * h {
        return 0;
    }
    let cfg = PlaneConfig::default();
    let stride = cfg.stride.max(1) as usize;
    let mut n = 0;
    for v in (0..h).step_by(stride) {
        for u in (0..w).step_by(stride) {
            let d = background[v * w + u];
            if d == 0 || n == points.len() {
                continue;
            }
            points[n] = k.unproject(u as f32, v as f32, d as f32 * 0.001);
            n += 1;
        }
    }
    largest_planes(&points[..n], labels, &cfg, out)
}

/// Planes tried as "up".
pub const UP_CANDIDATES: usize = 3;

/// A local lowest point of the foreground: a candidate for the probe tip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LowPoint {
    /// The point, `camera` frame, metres: at the height of the `min_support / 4`-th lowest point of its
    /// component (so that a stray pixel below it does not decide), below the centre of the component's lowest
    /// 3 cm.
    pub point: Point3,
    /// Its height above the plane, metres.
    pub height_m: f32,
    /// Points of its component.
    pub support: u32,
}

/// Working memory of [`low_points`]: up to `N` foreground points, their component and the components' sizes.
#[derive(Debug, Clone)]
pub struct StartScratch<const N: usize> {
    points: [Point3; N],
    component: [u16; N],
    size: [u32; N],
    low: [u16; N],
}

impl<const N: usize> Default for StartScratch<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> StartScratch<N> {
    /// Empty scratch (`N` at most 65 535).
    pub const fn new() -> Self {
        StartScratch {
            points: [Point3::new(0.0, 0.0, 0.0); N],
            component: [0; N],
            size: [0; N],
            low: [0; N],
        }
    }
}

/// The local lowest points of the foreground of `frame` (nearer than `background` by
/// [`StartOptions::foreground_m`], within the height range above `up`), lowest first, into `out`; returns how many.
pub fn low_points<const N: usize>(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    background: &[u16],
    up: &Plane,
    options: &StartOptions,
    scratch: &mut StartScratch<N>,
    out: &mut [LowPoint],
) -> usize {
    let depth = frame.depth_mm();
    if background.len() != depth.len() || out.is_empty() || N == 0 || N > u16::MAX as usize {
        return 0;
    }
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let margin_mm = (options.foreground_m * 1000.0) as i32;
    // Gather the foreground, growing the stride until it fits the scratch.
    let mut stride = 1usize;
    let n = 'gather: loop {
        let mut n = 0usize;
        for v in (0..h).step_by(stride) {
            for u in (0..w).step_by(stride) {
                let i = v * w + u;
                let (d, b) = (depth[i], background[i]);
                if d == 0 || b == 0 || (b as i32 - d as i32) < margin_mm {
                    continue;
                }
                let p = k.unproject(u as f32, v as f32, d as f32 * 0.001);
                let hgt = up.signed_distance(&p);
                if hgt < options.min_height_m || hgt > options.max_height_m {
                    continue;
                }
                if n == N {
                    stride += 1;
                    continue 'gather;
                }
                scratch.points[n] = p;
                n += 1;
            }
        }
        break n;
    };
    let points = &mut scratch.points[..n];
    points.sort_unstable_by(|a, b| up.signed_distance(a).total_cmp(&up.signed_distance(b)));
    // Components in rising height: a point joins the component of the nearest lower neighbour within reach
    // (lower points lie in the height band just below it, found from the sorted order), else starts its own.
    let reach = options.neighbour_m * stride as f32;
    let reach2 = reach * reach;
    let mut components = 0usize;
    let mut band_start = 0usize;
    for i in 0..n {
        let p = scratch.points[i];
        let hi = up.signed_distance(&p);
        while up.signed_distance(&scratch.points[band_start]) < hi - reach {
            band_start += 1;
        }
        let mut best: Option<(f32, u16)> = None;
        for j in band_start..i {
            let d2 = (scratch.points[j] - p).norm_squared();
            if d2 <= reach2 && best.is_none_or(|(b, _)| d2 < b) {
                best = Some((d2, scratch.component[j]));
            }
        }
        let c = match best {
            Some((_, c)) => c as usize,
            None => {
                let c = components;
                components += 1;
                scratch.size[c] = 0;
                scratch.low[c] = i as u16;
                c
            }
        };
        scratch.component[i] = c as u16;
        scratch.size[c] += 1;
        // The representative point: the (min_support / 4)-th lowest of the component, so a stray pixel just below
        // the probe does not set its height.
        if scratch.size[c] == (options.min_support / 4).max(1) {
            scratch.low[c] = i as u16;
        }
    }
    // Candidates: components with enough points, lowest first (their representative points are in rising order
    // only roughly, so sort what is kept).
    let mut m = 0usize;
    for c in 0..components {
        if scratch.size[c] < options.min_support {
            continue;
        }
        // Across the axis, the centre of the component's lowest 3 cm (the head's end) rather than its lowest
        // point (a corner of the end face, or its rim); along up, the lowest point.
        let p = scratch.points[scratch.low[c] as usize];
        let h_low = up.signed_distance(&p);
        let (mut sum, mut cnt) = (Vector3::zeros(), 0u32);
        for i in 0..n {
            let q = scratch.points[i];
            if scratch.component[i] as usize == c && up.signed_distance(&q) <= h_low + END_BAND_M {
                sum += q.coords;
                cnt += 1;
            }
        }
        let centre = Point3::from(sum / cnt.max(1) as f32);
        let lp = LowPoint {
            point: centre - up.normal() * (up.signed_distance(&centre) - h_low),
            height_m: h_low,
            support: scratch.size[c],
        };
        if m < out.len() {
            out[m] = lp;
            m += 1;
        } else if let Some(worst) = (0..m).max_by(|&a, &b| out[a].height_m.total_cmp(&out[b].height_m))
            && out[worst].height_m > lp.height_m
        {
            out[worst] = lp;
        }
    }
    out[..m].sort_unstable_by(|a, b| a.height_m.total_cmp(&b.height_m));
    m
}

/// How far the probe tip lies above the lowest corner of the probe head, metres, for a probe held at
/// `robot_base_from_probe` in a base whose z is up: the head is the box `|x| <= hx, |y| <= hy`, from the tip back
/// `head_length_m` along probe z.
pub fn tip_above_lowest_corner(robot_base_from_probe: &UnitQuaternion, shape: &ProbeShape) -> f32 {
    let [hx, hy] = shape.head_half_xy_m;
    let mut lowest = 0.0f32;
    for sx in [-hx, hx] {
        for sy in [-hy, hy] {
            for sz in [0.0, -shape.head_length_m] {
                lowest = lowest.min((robot_base_from_probe * Vector3::new(sx, sy, sz)).z);
            }
        }
    }
    -lowest
}

/// A candidate tip of one pose, its height corrected to the tip's (see [`tip_above_lowest_corner`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// Index of the pose it belongs to.
    pub pose: usize,
    /// The estimated tip, `camera` frame, metres.
    pub tip_camera: Point3,
    /// The estimated tip's height above the plane, metres.
    pub tip_height_m: f32,
}

impl Candidate {
    /// The candidate for `low` of pose `pose`, the arm holding the probe at `robot_base_from_probe`.
    pub fn new(
        pose: usize,
        low: &LowPoint,
        up: &Plane,
        robot_base_from_probe: &UnitQuaternion,
        shape: &ProbeShape,
    ) -> Candidate {
        let lift = tip_above_lowest_corner(robot_base_from_probe, shape);
        Candidate {
            pose,
            tip_camera: low.point + up.normal() * lift,
            tip_height_m: low.height_m + lift,
        }
    }
}

/// Pick the tip among the candidates of each pose: the offset between the arm's tip height
/// (`robot_tip_z[pose]`, `robot_base` z) and the candidate's height above the plane that the most poses share
/// (within `tolerance_m`; ties go to the tighter agreement), then per pose the candidate nearest that offset within
/// the tolerance. Writes the chosen candidate's index (into `candidates`) per pose into `chosen`; returns how many
/// poses have one (0 when nothing agrees, or `chosen` is shorter than `robot_tip_z`) and the offset (arm height
/// minus tip height above the plane, metres).
pub fn choose_tips(
    candidates: &[Candidate],
    robot_tip_z: &[f32],
    tolerance_m: f32,
    chosen: &mut [Option<usize>],
) -> (usize, f32) {
    let poses = robot_tip_z.len();
    if chosen.len() < poses {
        return (0, 0.0);
    }
    chosen[..poses].fill(None);
    let offset = |c: &Candidate| robot_tip_z.get(c.pose).map(|z| z - c.tip_height_m);
    // Score an offset: poses with a candidate within tolerance, and their summed deviation.
    let score = |o: f32| {
        let (mut count, mut dev) = (0usize, 0.0f32);
        for p in 0..poses {
            let best = candidates
                .iter()
                .filter(|c| c.pose == p)
                .filter_map(|c| offset(c).map(|x| libm::fabsf(x - o)))
                .fold(f32::INFINITY, f32::min);
            if best <= tolerance_m {
                count += 1;
                dev += best;
            }
        }
        (count, dev)
    };
    let mut best: Option<(f32, usize, f32)> = None;
    for c in candidates {
        let Some(o) = offset(c) else { continue };
        let (count, dev) = score(o);
        if best.is_none_or(|(_, n, d)| count > n || (count == n && dev < d)) {
            best = Some((o, count, dev));
        }
    }
    let Some((o0, _, _)) = best else {
        return (0, 0.0);
    };
    // Re-centre on the mean offset of the agreeing poses' picks, then pick again.
    let pick = |o: f32, chosen: &mut [Option<usize>]| {
        let mut sum = 0.0f32;
        let mut n = 0usize;
        for (p, slot) in chosen.iter_mut().enumerate().take(poses) {
            *slot = None;
            let mut best_dev = tolerance_m;
            for (i, c) in candidates.iter().enumerate() {
                if c.pose != p {
                    continue;
                }
                if let Some(x) = offset(c)
                    && libm::fabsf(x - o) <= best_dev
                {
                    best_dev = libm::fabsf(x - o);
                    *slot = Some(i);
                }
            }
            if let Some(i) = *slot
                && let Some(x) = offset(&candidates[i])
            {
                sum += x;
                n += 1;
            }
        }
        (n, if n > 0 { sum / n as f32 } else { o })
    };
    let (_, o1) = pick(o0, chosen);
    (pick(o1, chosen).0, o1)
}

/// Why the guess-free start gave no extrinsic.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum StartError {
    /// No plane (mattress or floor) in the background: "down" is unknown.
    NoPlane,
    /// Too few poses with a tip candidate that agrees with the arm's heights.
    TooFewTips {
        /// Poses with a chosen tip.
        found: usize,
        /// Poses given.
        poses: usize,
    },
    /// The rough solve refused the pairs.
    Solve(SolveError),
    /// A buffer is shorter than the frames need, or the frames differ in size.
    BufferTooShort,
}

impl fmt::Display for StartError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StartError::NoPlane => f.write_str(
                "no bed or floor plane in view: cannot tell down without an extrinsic guess (give --guess)",
            ),
            StartError::TooFewTips { found, poses } => write!(
                f,
                "no probe visible without a guess: a probe tip below the arm found in only {found} of {poses} poses                  (the bed must be empty or the patient still, the probe pointing down into free space; or give                  --guess)"
            ),
            StartError::Solve(e) => write!(f, "guess-free start: {e}"),
            StartError::BufferTooShort => f.write_str("guess-free start: buffers shorter than the frames"),
        }
    }
}

impl core::error::Error for StartError {}

/// Buffers of [`rough_extrinsic`], lent by the caller: `background` one entry per pixel, `plane_points` and
/// `plane_labels` [`crate::planes::scratch_points`]`(width, height, 6)`, `candidates`, `pairs`, `residuals` and
/// `inliers` room for [`CANDIDATES_PER_POSE`] per pose, `chosen` one per pose.
#[derive(Debug)]
pub struct StartBuffers<'a> {
    /// Per-pixel background.
    pub background: &'a mut [u16],
    /// Plane search points.
    pub plane_points: &'a mut [Point3],
    /// Plane search labels.
    pub plane_labels: &'a mut [u8],
    /// Tip candidates.
    pub candidates: &'a mut [Candidate],
    /// Chosen candidate per pose.
    pub chosen: &'a mut [Option<usize>],
    /// Rough pairs.
    pub pairs: &'a mut [Pair],
    /// Residual per pair.
    pub residuals: &'a mut [f32],
    /// Inlier flag per pair.
    pub inliers: &'a mut [bool],
}

/// Candidates kept per pose (the lowest ones). 8 lost the tip on validation sequences where the mattress's
/// edge, the arm's shadow rim and the like gave 8 lower components (s514 at 6 poses: the tip among the
/// candidates in 3 of 6 poses with 8, in 6 of 6 with 16).
pub const CANDIDATES_PER_POSE: usize = 16;

/// The rough extrinsic from one still frame per pose (`frame(i)`, the arm state at it `arms[i]`) and no guess:
/// background, up, candidates, the vote, then Kabsch in RANSAC with [`rough_solve_options`]. Returns the solution
/// and how many poses gave a tip.
pub fn rough_extrinsic<'f, const N: usize>(
    frame: impl Fn(usize) -> DepthFrame<'f>,
    arms: &[ArmSample],
    k: &Intrinsics,
    options: &StartOptions,
    scratch: &mut StartScratch<N>,
    buffers: StartBuffers<'_>,
) -> Result<(Solution, usize), StartError> {
    let poses = arms.len();
    let b = buffers;
    if b.candidates.len() < poses * CANDIDATES_PER_POSE
        || b.chosen.len() < poses
        || b.pairs.len() < poses * CANDIDATES_PER_POSE
        || b.residuals.len() < poses * CANDIDATES_PER_POSE
        || b.inliers.len() < poses * CANDIDATES_PER_POSE
    {
        return Err(StartError::BufferTooShort);
    }
    if poses == 0 {
        return Err(StartError::TooFewTips { found: 0, poses });
    }
    let (w, h) = (frame(0).width(), frame(0).height());
    if (0..poses).any(|i| frame(i).width() != w || frame(i).height() != h)
        || !median_background(b.background, poses, &frame)
    {
        return Err(StartError::BufferTooShort);
    }
    let mut planes = [Plane::through(Vector3::zeros(), Vector3::z()); UP_CANDIDATES];
    let n_planes = background_planes(b.background, w, h, k, b.plane_points, b.plane_labels, &mut planes);
    if n_planes == 0 {
        return Err(StartError::NoPlane);
    }
    let mut robot_z = [0.0f32; MAX_POSES];
    if poses > robot_z.len() {
        return Err(StartError::BufferTooShort);
    }
    for (i, arm) in arms.iter().enumerate() {
        robot_z[i] = arm.tip_robot_base.z;
    }
    // Candidates under a plane taken as up.
    let candidates_under = |up: &Plane, candidates: &mut [Candidate], scratch: &mut StartScratch<N>| {
        let mut nc = 0usize;
        for (i, arm) in arms.iter().enumerate() {
            let mut low = [LowPoint {
                point: Point3::origin(),
                height_m: 0.0,
                support: 0,
            }; CANDIDATES_PER_POSE];
            let m = low_points(&frame(i), k, b.background, up, options, scratch, &mut low);
            for lp in &low[..m] {
                candidates[nc] = Candidate::new(i, lp, up, &arm.robot_base_from_probe, &options.shape);
                nc += 1;
            }
        }
        nc
    };
    // Up is a plane under which the poses agree on the tip height (a head section or a wall is tilted, so the
    // arm's heights do not follow the heights above it). The vote alone can prefer a tilted plane when the tips
    // agree under it by chance (a raised head section under most poses), so every plane whose vote finds enough
    // tips is solved under, and the solve with the most poses within the threshold (then the smaller RMS) wins.
    // Without any, the plane with the most agreeing tips gives the error.
    let mut best_vote = (0usize, 0usize);
    let mut best: Option<(Solution, usize)> = None;
    let mut last_err: Option<StartError> = None;
    for (p, plane) in planes[..n_planes].iter().enumerate() {
        let nc = candidates_under(plane, b.candidates, scratch);
        let (found, _) = choose_tips(
            &b.candidates[..nc],
            &robot_z[..poses],
            options.vote_tolerance_m,
            b.chosen,
        );
        if found > best_vote.1 {
            best_vote = (p, found);
        }
        if found < 4 {
            continue;
        }
        let under = Under {
            up: plane,
            arms,
            robot_z: &robot_z[..poses],
            options,
        };
        match solve_under(&under, &b.candidates[..nc], b.pairs, b.residuals, b.inliers) {
            Ok(sol) => {
                if best.as_ref().is_none_or(|(bs, _)| {
                    sol.inliers > bs.inliers
                        || (sol.inliers == bs.inliers && sol.rms_residual_m < bs.rms_residual_m)
                }) {
                    best = Some((sol, found));
                }
            }
            Err(e) => {
                if p == best_vote.0 || last_err.is_none() {
                    last_err = Some(e);
                }
            }
        }
    }
    // Without a plane of four agreeing poses nothing was solved, so there is no solve error either.
    best.ok_or_else(|| {
        last_err.unwrap_or(StartError::TooFewTips {
            found: best_vote.1,
            poses,
        })
    })
}

/// The rough solve under `up`: every candidate of every pose is a pair, and the levelled RANSAC draws its
/// hypotheses from two pairs whose height offsets (arm tip z minus height above the plane) agree within twice
/// the vote tolerance. The vote's single offset is not imposed: with 6 poses and up to 8 candidates each
/// spread over a metre of height, a wrong offset (wrist and forearm parts) drew 6 of 6 votes on validation
/// s513 and the start came out 191 mm off, while the tips agreed on a transform; the rigid fit tells them apart,
/// a height alone does not.
fn solve_under(
    u: &Under<'_>,
    candidates: &[Candidate],
    pairs: &mut [Pair],
    residuals: &mut [f32],
    inliers: &mut [bool],
) -> Result<Solution, StartError> {
    let Under {
        up,
        arms,
        robot_z,
        options,
    } = *u;
    let poses = robot_z.len();
    let mut pose_of = [0u8; MAX_POSES * CANDIDATES_PER_POSE];
    let mut offset_of = [0.0f32; MAX_POSES * CANDIDATES_PER_POSE];
    let mut np = 0usize;
    for c in candidates {
        if np < pairs.len() && np < pose_of.len() {
            pairs[np] = Pair {
                robot_base: arms[c.pose].tip_robot_base,
                camera: c.tip_camera,
            };
            pose_of[np] = c.pose as u8;
            offset_of[np] = robot_z[c.pose] - c.tip_height_m;
            np += 1;
        }
    }
    level_solve(
        &LevelPairs {
            pairs: &pairs[..np],
            pose_of: &pose_of[..np],
            offset_of: &offset_of[..np],
            offset_tolerance_m: 2.0 * options.vote_tolerance_m,
        },
        poses,
        up,
        &rough_solve_options(),
        residuals,
        inliers,
    )
}

/// What the rough solve under one plane needs besides the buffers.
#[derive(Clone, Copy)]
struct Under<'a> {
    up: &'a Plane,
    arms: &'a [ArmSample],
    robot_z: &'a [f32],
    options: &'a StartOptions,
}

/// The levelled solve's pairs: each pair's pose and height offset, and how far two offsets may differ for the
/// two pairs to seed a hypothesis.
struct LevelPairs<'a> {
    pairs: &'a [Pair],
    pose_of: &'a [u8],
    offset_of: &'a [f32],
    offset_tolerance_m: f32,
}

/// The rough solve with up known on both sides: the camera is first turned so that the plane's up is the base's
/// z, leaving yaw and translation (4 degrees of freedom) to fit, which two pairs fix. RANSAC over all pairs of
/// pairs from different poses (each pose scores with its best candidate), then three rounds of least squares
/// over the inlier poses' best candidates. Writes each pair's residual and whether it was used.
fn level_solve(
    lp: &LevelPairs<'_>,
    poses: usize,
    up: &Plane,
    options: &SolveOptions,
    residuals: &mut [f32],
    used: &mut [bool],
) -> Result<Solution, StartError> {
    let (pairs, pose_of) = (lp.pairs, lp.pose_of);
    let n = pairs.len();
    if pose_of.len() < n || lp.offset_of.len() < n {
        return Err(StartError::BufferTooShort);
    }
    if residuals.len() < n || used.len() < n {
        return Err(StartError::BufferTooShort);
    }
    let level = UnitQuaternion::rotation_between(&up.normal(), &Vector3::z()).unwrap_or_else(|| {
        // Up pointing straight down the base's -z: a half turn about x.
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), core::f32::consts::PI)
    });
    let thr = options.inlier_threshold_m;
    // Yaw and translation from the pairs `use_pair` selects (least squares in the horizontal plane).
    let fit = |use_pair: &dyn Fn(usize) -> bool| -> Option<Isometry3> {
        let (mut cq, mut cr, mut m) = (Vector3::zeros(), Vector3::zeros(), 0.0f32);
        for (i, p) in pairs.iter().enumerate() {
            if use_pair(i) {
                cq += (level * p.camera).coords;
                cr += p.robot_base.coords;
                m += 1.0;
            }
        }
        if m < 2.0 {
            return None;
        }
        cq /= m;
        cr /= m;
        let (mut sxx, mut sxy) = (0.0f32, 0.0f32);
        for (i, p) in pairs.iter().enumerate() {
            if use_pair(i) {
                let q = (level * p.camera).coords - cq;
                let r = p.robot_base.coords - cr;
                sxx += q.x * r.x + q.y * r.y;
                sxy += q.x * r.y - q.y * r.x;
            }
        }
        if sxx == 0.0 && sxy == 0.0 {
            return None;
        }
        let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), libm::atan2f(sxy, sxx));
        let rotation = yaw * level;
        let t = cr - rotation * (cq_camera(&level, &cq));
        Some(Isometry3::from_parts(Translation3::from(t), rotation))
    };
    // Per pose, the best candidate's residual under `t`; the count of poses within the threshold and the
    // truncated cost.
    let score = |t: &Isometry3, best: &mut [Option<(usize, f32)>; MAX_POSES]| {
        best[..poses].fill(None);
        for (i, p) in pairs.iter().enumerate() {
            let r = (p.robot_base - t * p.camera).norm();
            let slot = &mut best[pose_of[i] as usize];
            if slot.is_none_or(|(_, b)| r < b) {
                *slot = Some((i, r));
            }
        }
        let (mut count, mut cost) = (0usize, 0.0f32);
        for b in best[..poses].iter().flatten() {
            if b.1 < thr {
                count += 1;
                cost += b.1 * b.1;
            } else {
                cost += thr * thr;
            }
        }
        (count, cost)
    };
    let mut best_slots = [None; MAX_POSES];
    let mut best: Option<(Isometry3, usize, f32)> = None;
    for a in 0..n {
        for c in a + 1..n {
            // Two pairs whose height offsets differ cannot both hold under a level camera (the offset is the
            // plane's height in the base); skipping them keeps the hypotheses few with many candidates.
            if pose_of[a] == pose_of[c]
                || libm::fabsf(lp.offset_of[a] - lp.offset_of[c]) > lp.offset_tolerance_m
            {
                continue;
            }
            let Some(t) = fit(&|i| i == a || i == c) else {
                continue;
            };
            let (count, cost) = score(&t, &mut best_slots);
            if best.is_none_or(|(_, k, e)| count > k || (count == k && cost < e)) {
                best = Some((t, count, cost));
            }
        }
    }
    let Some((mut t, _, _)) = best else {
        return Err(StartError::Solve(SolveError::TooFewInliers {
            inliers: 0,
            needed: options.min_pairs,
        }));
    };
    for _ in 0..3 {
        score(&t, &mut best_slots);
        let chosen = best_slots;
        let take = |i: usize| chosen[pose_of[i] as usize].is_some_and(|(j, r)| j == i && r < thr);
        if let Some(next) = fit(&take) {
            t = next;
        }
    }
    score(&t, &mut best_slots);
    let (mut count, mut sq, mut max_r) = (0usize, 0.0f32, 0.0f32);
    for (i, p) in pairs.iter().enumerate() {
        residuals[i] = (p.robot_base - t * p.camera).norm();
        used[i] = best_slots[pose_of[i] as usize].is_some_and(|(j, r)| j == i && r < thr);
        if used[i] {
            count += 1;
            sq += residuals[i] * residuals[i];
            max_r = max_r.max(residuals[i]);
        }
    }
    let needed = options.min_pairs.max(3);
    if count < needed {
        return Err(StartError::Solve(SolveError::TooFewInliers {
            inliers: count,
            needed,
        }));
    }
    let condition = condition_number(
        pairs
            .iter()
            .zip(used.iter())
            .filter(|(_, u)| **u)
            .map(|(p, _)| p.robot_base),
    )
    .unwrap_or(f32::INFINITY);
    if condition > options.max_condition {
        return Err(StartError::Solve(SolveError::Coplanar {
            condition,
            limit: options.max_condition,
        }));
    }
    Ok(Solution {
        robot_base_from_camera: t,
        inliers: count,
        rms_residual_m: libm::sqrtf(sq / count as f32),
        max_residual_m: max_r,
        condition,
        // The rough solve's pairs are centimetres off by construction; its uncertainty would say nothing useful.
        uncertainty: None,
    })
}

/// The camera-frame point whose levelled image is `levelled` (the inverse of the levelling turn).
fn cq_camera(level: &UnitQuaternion, levelled: &Vector3) -> Vector3 {
    level.inverse() * levelled
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::solve::{rotation_error_deg, translation_error_m};
    use crate::time::Timestamp;

    const W: u16 = 160;
    const H: u16 = 120;

    fn k() -> Intrinsics {
        Intrinsics {
            fx: 150.0,
            fy: 150.0,
            cx: 80.0,
            cy: 60.0,
            width: W,
            height: H,
        }
    }

    /// A floor 2 m straight ahead (up = toward the camera), a 4 x 4 cm "probe" plate `tip_h` above it at (x, y),
    /// and a second plate (an "elbow") 0.1 m above the floor when `elbow`.
    fn scene(x: f32, y: f32, tip_h: f32, elbow: bool) -> [u16; W as usize * H as usize] {
        let k = k();
        let mut d = [0u16; W as usize * H as usize];
        for v in 0..H as usize {
            for u in 0..W as usize {
                let ray = k.unproject(u as f32, v as f32, 1.0).coords;
                let mut z = 2.0f32;
                // The plate faces the camera `tip_h` above the floor (depth along the optical axis is height down).
                let plate = 2.0 - tip_h;
                let (px, py) = (ray.x * plate, ray.y * plate);
                if (px - x).abs() < 0.02 && (py - y).abs() < 0.02 {
                    z = plate;
                }
                if elbow {
                    let e = 1.9f32;
                    let (ex, ey) = (ray.x * e, ray.y * e);
                    if (ex + 0.2).abs() < 0.03 && (ey + 0.1).abs() < 0.03 {
                        z = e;
                    }
                }
                d[v * W as usize + u] = (z * 1000.0) as u16;
            }
        }
        d
    }

    fn up_plane() -> Plane {
        Plane::through(Vector3::new(0.0, 0.0, 2.0), Vector3::new(0.0, 0.0, -1.0))
    }

    #[test]
    fn the_background_is_the_farthest_depth_and_the_floor_is_up() {
        let a = scene(-0.2, 0.0, 0.3, false);
        let b = scene(0.2, 0.1, 0.3, false);
        let mut bg = [0u16; W as usize * H as usize];
        for d in [&a, &b] {
            let f = DepthFrame::new(d, W, H, Timestamp::from_us(0).unwrap(), 0).unwrap();
            assert!(accumulate_background(&mut bg, &f));
        }
        assert!(bg.iter().all(|&v| v == 2000), "the bar never stays put");
        let n = crate::planes::scratch_points(W as usize, H as usize, 6);
        let (mut pts, mut labels) = ([Point3::origin(); 600], [0u8; 600]);
        assert!(n <= 600);
        let mut planes = [up_plane(); 3];
        assert_eq!(
            background_planes(&bg, W, H, &k(), &mut pts, &mut labels, &mut planes),
            1,
            "one plane"
        );
        let up = planes[0];
        assert!(
            (up.normal() - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-3,
            "{up:?}"
        );
        assert!((up.signed_distance(&Point3::new(0.0, 0.0, 1.5)) - 0.5).abs() < 1e-3);
    }

    #[test]
    fn the_lowest_foreground_points_are_found_and_the_vote_picks_the_tip() {
        let up = Plane::through(Vector3::new(0.0, 0.0, 2.0), Vector3::new(0.0, 0.0, -1.0));
        let bg = [2000u16; W as usize * H as usize];
        let opts = StartOptions {
            min_support: 4,
            ..StartOptions::default()
        };
        let mut scratch = StartScratch::<4096>::new();
        // Three poses at different heights, each with the elbow blob (0.1 m above the floor) lower than the tip.
        let poses = [(-0.2f32, 0.1f32, 0.3f32), (0.15, -0.1, 0.45), (0.0, 0.2, 0.6)];
        let mut candidates = [Candidate {
            pose: 0,
            tip_camera: Point3::origin(),
            tip_height_m: 0.0,
        }; 12];
        let mut nc = 0;
        let level = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), core::f32::consts::PI);
        let lift = tip_above_lowest_corner(&level, &opts.shape);
        assert!(
            lift.abs() < 1e-5,
            "pointing straight down: the end face is the lowest, {lift}"
        );
        for (i, &(x, y, h)) in poses.iter().enumerate() {
            let d = scene(x, y, h, true);
            let f = DepthFrame::new(&d, W, H, Timestamp::from_us(0).unwrap(), 0).unwrap();
            let mut out = [LowPoint {
                point: Point3::origin(),
                height_m: 0.0,
                support: 0,
            }; 4];
            let m = low_points(&f, &k(), &bg, &up, &opts, &mut scratch, &mut out);
            assert_eq!(m, 2, "the bar and the elbow");
            assert!(
                (out[0].height_m - 0.1).abs() < 0.01,
                "the elbow is lowest: {:?}",
                out[0]
            );
            assert!((out[1].height_m - h).abs() < 0.01, "{:?}", out[1]);
            for lp in &out[..m] {
                candidates[nc] = Candidate::new(i, lp, &up, &level, &opts.shape);
                nc += 1;
            }
        }
        // The arm's base 0.8 m below the floor: only the offset's constancy matters.
        let robot_z: [f32; 3] = poses.map(|(_, _, h)| h + 0.8);
        let mut chosen = [None; 3];
        let (found, offset) = choose_tips(&candidates[..nc], &robot_z, 0.03, &mut chosen);
        assert_eq!(found, 3);
        assert!((offset - 0.8).abs() < 0.01, "{offset}");
        for (p, c) in chosen.iter().enumerate() {
            let c = candidates[c.unwrap()];
            assert!((c.tip_height_m - poses[p].2).abs() < 0.01, "pose {p}: {c:?}");
        }
        // Heights that agree with no candidate choose nothing.
        assert_eq!(
            choose_tips(&candidates[..nc], &[0.0, 5.0, 9.0], 0.03, &mut chosen).0,
            1
        );
    }

    #[test]
    fn the_solve_under_a_tilted_plane_fits_fewer_poses() {
        // Camera 2 m above the floor looking straight down (camera z = -base z); the floor is up's plane.
        let truth = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 2.0),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), core::f32::consts::PI),
        );
        let tips: [Point3; 8] = core::array::from_fn(|i| {
            let f = i as f32;
            Point3::new(
                0.3 * libm::cosf(1.7 * f),
                0.3 * libm::sinf(1.7 * f),
                0.3 + 0.05 * f,
            )
        });
        let arms: [ArmSample; 8] = core::array::from_fn(|i| ArmSample {
            time: Timestamp::from_us(i as u64 * 1000).unwrap(),
            tip_robot_base: tips[i],
            robot_base_from_probe: UnitQuaternion::identity(),
        });
        let robot_z = tips.map(|t| t.z);
        let floor = up_plane();
        // A head section tilted 15° about the camera's x axis, through the same point.
        let tilted = Plane::through(
            Vector3::new(0.0, 0.0, 2.0),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 15f32.to_radians())
                * Vector3::new(0.0, 0.0, -1.0),
        );
        let opts = StartOptions::default();
        let blank = Pair {
            robot_base: Point3::origin(),
            camera: Point3::origin(),
        };
        let mut solved = [0usize; 2];
        for (slot, up) in [floor, tilted].iter().enumerate() {
            let candidates: [Candidate; 8] = core::array::from_fn(|i| {
                let c = truth.inverse() * tips[i];
                Candidate {
                    pose: i,
                    tip_camera: c,
                    tip_height_m: up.signed_distance(&c),
                }
            });
            let mut chosen = [None; 8];
            let (found, _) = choose_tips(&candidates, &robot_z, opts.vote_tolerance_m, &mut chosen);
            let under = Under {
                up,
                arms: &arms,
                robot_z: &robot_z,
                options: &opts,
            };
            let (mut pairs, mut res, mut inl) = ([blank; 8], [0.0f32; 8], [false; 8]);
            solved[slot] = match solve_under(&under, &candidates, &mut pairs, &mut res, &mut inl) {
                Ok(s) if found >= 4 => {
                    if slot == 0 {
                        assert!(rotation_error_deg(&s.robot_base_from_camera, &truth) < 0.01);
                    }
                    s.inliers
                }
                _ => 0,
            };
        }
        assert_eq!(solved[0], 8, "under the floor every pose fits");
        assert!(solved[1] < 8, "under the tilted plane {} poses fit", solved[1]);
    }

    #[test]
    fn distractors_that_agree_in_height_do_not_win_over_tips_that_agree_rigidly() {
        // Six poses; each has its true tip (heights off by up to 2 cm, as the corner correction leaves them) and
        // one distractor (a wrist part) whose height agrees exactly with a wrong offset, 0.3 m from the truth's,
        // at a place that fits no rigid transform with the others. The height vote prefers the distractors.
        let truth = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 2.0),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), core::f32::consts::PI),
        );
        const P: usize = 6;
        let tips: [Point3; P] = core::array::from_fn(|i| {
            let f = i as f32;
            Point3::new(
                0.3 * libm::cosf(1.7 * f),
                0.3 * libm::sinf(1.7 * f),
                0.3 + 0.07 * f,
            )
        });
        let arms: [ArmSample; P] = core::array::from_fn(|i| ArmSample {
            time: Timestamp::from_us(i as u64 * 1000).unwrap(),
            tip_robot_base: tips[i],
            robot_base_from_probe: UnitQuaternion::identity(),
        });
        let robot_z = tips.map(|t| t.z);
        let floor = up_plane();
        let opts = StartOptions::default();
        let mut candidates = [Candidate {
            pose: 0,
            tip_camera: Point3::origin(),
            tip_height_m: 0.0,
        }; 2 * P];
        for i in 0..P {
            let c = truth.inverse() * tips[i];
            let h_err = if i % 2 == 0 { 0.02 } else { -0.015 };
            candidates[2 * i] = Candidate {
                pose: i,
                tip_camera: c,
                tip_height_m: floor.signed_distance(&c) + h_err,
            };
            // The distractor: 0.3 m lower than the tip's height would say, scattered sideways.
            let d = Point3::new(0.5 * libm::sinf(2.9 * i as f32), -0.4 + 0.13 * i as f32, 1.5);
            candidates[2 * i + 1] = Candidate {
                pose: i,
                tip_camera: d,
                tip_height_m: tips[i].z + 0.3,
            };
        }
        let mut chosen = [None; P];
        let (found, offset) = choose_tips(&candidates, &robot_z, opts.vote_tolerance_m, &mut chosen);
        assert_eq!(found, P);
        assert!(
            (offset + 0.3).abs() < 0.01,
            "the vote picks the distractors' offset: {offset}"
        );
        let under = Under {
            up: &floor,
            arms: &arms,
            robot_z: &robot_z,
            options: &opts,
        };
        let blank = Pair {
            robot_base: Point3::origin(),
            camera: Point3::origin(),
        };
        let (mut pairs, mut res, mut inl) = ([blank; 2 * P], [0.0f32; 2 * P], [false; 2 * P]);
        let s = solve_under(&under, &candidates, &mut pairs, &mut res, &mut inl).unwrap();
        assert_eq!(s.inliers, P);
        assert!(rotation_error_deg(&s.robot_base_from_camera, &truth) < 0.5);
        assert!(translation_error_m(&s.robot_base_from_camera, &truth) < 0.01);
        for i in 0..P {
            assert!(inl[2 * i] && !inl[2 * i + 1], "pose {i}");
        }
    }
}
