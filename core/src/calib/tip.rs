//! Probe-tip detection in a depth frame: with the bed empty or the patient still, the probe is the arm's end
//! segment in free space. Given a prior (where the tip and the probe axis should be in the camera frame, from the
//! arm state and the current extrinsic guess), gather the depth points in a cylinder around the prior axis, cut
//! off whatever lies beyond a gap ahead of the probe (the bed, the patient), take the tip's position along the axis
//! from the far end of the points and its position across the axis by fitting the probe head's box (its size known,
//! its orientation from the arm) to the faces the camera sees: the camera only sees the near side of the head, so
//! a centroid would sit off the axis by an amount that depends on how the probe is turned.
//!
//! Cost: one pass over a window of about (0.3 m · f / z)² pixels (e.g. 200x200 at 1 m, subsampled to at most `N`
//! points), then three passes over the gathered points; about 0.2 ms. Nothing allocates: points live in a
//! caller-owned [`TipScratch`].

use core::fmt;

use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::{Plane, Point3, UnitQuaternion, Vector3};

/// Where the tip should be: the arm's reported tip and probe axis mapped into the camera by the current guess.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipPrior {
    /// Expected tip, `camera` frame, metres.
    pub tip_camera: Point3,
    /// Expected probe orientation `camera_from_probe` (probe z along the probe from the wrist toward the tip, x
    /// and y along the head's width and thickness).
    pub camera_from_probe: UnitQuaternion,
    /// How far the true tip may be from the expected one, metres (the guess's uncertainty).
    pub uncertainty_m: f32,
}

/// The probe's shape as far as detection needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeShape {
    /// Length of the probe head used for the fit, measured back from the tip, metres (at most the head's length).
    pub head_length_m: f32,
    /// Length of the free end segment (probe head and handle) searched behind the tip, metres.
    pub segment_length_m: f32,
    /// Half width and half thickness of the probe head along probe x and y, metres (its cross-section is the box
    /// `|x| <= hx, |y| <= hy`, centred on the axis).
    pub head_half_xy_m: [f32; 2],
    /// Largest distance of a probe surface point from the axis, metres.
    pub max_radius_m: f32,
    /// How far the far end of the seen points falls short of the tip along the axis, metres: the head's end face
    /// looks away from the camera and its rim is seen at a grazing angle, where the sensor loses points.
    pub axial_shortfall_m: f32,
    /// Distance from the tip back to the head's back face, metres: the face across the axis where the narrower
    /// handle begins (0: the probe has no such face and the tip is taken from the far end of the points alone).
    pub head_back_m: f32,
    /// Radius of the handle behind the head, metres (the back face is the head's cross-section outside it).
    pub handle_radius_m: f32,
}

impl ProbeShape {
    /// The probe of the synthetic scene (`supine_models::scene::arm`): a 60 x 24 x 70 mm head on a 40 mm handle.
    /// The shortfall (4 mm) was measured with the true extrinsic on the validation sequences (seeds 1 and 2 of
    /// `sequence --calibration`); the evaluation uses other seeds.
    pub const SYNTHETIC: ProbeShape = ProbeShape {
        head_length_m: 0.05,
        segment_length_m: 0.12,
        head_half_xy_m: [0.03, 0.012],
        max_radius_m: 0.045,
        axial_shortfall_m: 0.004,
        head_back_m: 0.07,
        handle_radius_m: 0.02,
    };
}

/// Detection settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipOptions {
    /// The probe.
    pub shape: ProbeShape,
    /// Points on or below this plane (plus the margin) are background (the mattress), `camera` frame.
    pub background: Option<Plane>,
    /// Margin above the background plane, metres.
    pub background_margin_m: f32,
    /// Fewest points on the probe head for a detection.
    pub min_head_points: usize,
    /// Detections below this confidence are refused.
    pub min_confidence: f32,
}

impl Default for TipOptions {
    /// The synthetic probe, no background plane, 20 head points, confidence 0.5.
    fn default() -> Self {
        TipOptions {
            shape: ProbeShape::SYNTHETIC,
            background: None,
            background_margin_m: 0.02,
            min_head_points: 20,
            min_confidence: 0.5,
        }
    }
}

/// A detected tip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipDetection {
    /// The tip, `camera` frame, metres.
    pub tip_camera: Point3,
    /// Confidence 0..1 (enough head points, nothing else near the tip).
    pub confidence: f32,
    /// Points on the probe head.
    pub head_points: usize,
}

/// Why a frame gave no tip.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum TipError {
    /// The expected tip projects outside the image or lies behind the camera.
    OutOfView,
    /// Too few depth points where the probe should be.
    NoProbe {
        /// Head points found.
        points: usize,
    },
    /// Something else lies just ahead of the probe (the patient, the bed, a hand), or the camera looks along the
    /// probe: the tip cannot be told apart.
    Ambiguous {
        /// What made it ambiguous.
        reason: &'static str,
    },
    /// The tip found lies farther from the expected tip than the prior's uncertainty allows: the detector took
    /// something else (the wrist, the head's other end) for it.
    FarFromPrior {
        /// Distance from the expected tip, metres.
        distance_m: f32,
    },
    /// A tip was found but with too little confidence.
    LowConfidence {
        /// The confidence reached.
        confidence: f32,
    },
}

impl fmt::Display for TipError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TipError::OutOfView => f.write_str("the probe tip should be outside the camera's view"),
            TipError::NoProbe { points } => write!(
                f,
                "no probe visible where the arm says it is ({points} depth points on the probe head)"
            ),
            TipError::Ambiguous { reason } => write!(f, "ambiguous probe tip: {reason}"),
            TipError::FarFromPrior { distance_m } => write!(
                f,
                "the probe tip found lies {:.0} mm from where the arm says it is, farther than the guess allows",
                distance_m * 1000.0
            ),
            TipError::LowConfidence { confidence } => {
                write!(f, "probe tip found with low confidence {confidence:.2}")
            }
        }
    }
}

impl core::error::Error for TipError {}

/// Working memory of the detector: up to `N` gathered points and their axial coordinates.
#[derive(Debug, Clone)]
pub struct TipScratch<const N: usize> {
    points: [Point3; N],
    axial: [f32; N],
    len: usize,
}

impl<const N: usize> Default for TipScratch<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> TipScratch<N> {
    /// Empty scratch.
    pub const fn new() -> Self {
        TipScratch {
            points: [Point3::new(0.0, 0.0, 0.0); N],
            axial: [0.0; N],
            len: 0,
        }
    }
}

/// Bins of the histogram along the axis (1 cm each).
const BINS: usize = 48;
const BIN_M: f32 = 0.01;

/// Detect the probe tip in `frame` near `prior`.
pub fn detect_tip<const N: usize>(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    prior: &TipPrior,
    options: &TipOptions,
    scratch: &mut TipScratch<N>,
) -> Result<TipDetection, TipError> {
    let shape = &options.shape;
    let a = prior.camera_from_probe * Vector3::z();
    let ex = prior.camera_from_probe * Vector3::x();
    let ey = prior.camera_from_probe * Vector3::y();
    let t0 = prior.tip_camera;
    let err = prior.uncertainty_m.max(0.005);
    let back = shape.segment_length_m + err;
    let lateral_max = shape.max_radius_m + err;

    // Window: the projections of both ends of the searched cylinder, widened by its radius.
    let far_end = t0 - a * back;
    let z_near = t0.z.min(far_end.z) - lateral_max;
    if z_near <= 0.1 {
        return Err(TipError::OutOfView);
    }
    let (Some(p0), Some(p1)) = (k.project(&(t0 + a * err)), k.project(&far_end)) else {
        return Err(TipError::OutOfView);
    };
    let pad = lateral_max * k.fx.max(k.fy) / z_near;
    let (w, h) = (frame.width() as f32, frame.height() as f32);
    // libm, not the f32 methods: those need std (or a newer core) on some targets.
    let u_lo = libm::floorf(p0.x.min(p1.x) - pad).max(0.0);
    let u_hi = libm::ceilf(p0.x.max(p1.x) + pad).min(w - 1.0);
    let v_lo = libm::floorf(p0.y.min(p1.y) - pad).max(0.0);
    let v_hi = libm::ceilf(p0.y.max(p1.y) + pad).min(h - 1.0);
    let tip_px = k.project(&t0).ok_or(TipError::OutOfView)?;
    if tip_px.x < 0.0
        || tip_px.y < 0.0
        || tip_px.x > w - 1.0
        || tip_px.y > h - 1.0
        || u_lo > u_hi
        || v_lo > v_hi
    {
        return Err(TipError::OutOfView);
    }
    let (u_lo, u_hi, v_lo, v_hi) = (u_lo as usize, u_hi as usize, v_lo as usize, v_hi as usize);
    let area = (u_hi - u_lo + 1) * (v_hi - v_lo + 1);
    // Subsample so that even a full window fits the scratch (square stride).
    let mut stride = 1usize;
    while area / (stride * stride) > N {
        stride += 1;
    }

    // Gather the cylinder around the prior axis, above the background.
    scratch.len = 0;
    let depth = frame.depth_mm();
    let width = frame.width() as usize;
    let mut hist = [0u32; BINS];
    let s_lo = -back;
    'rows: for v in (v_lo..=v_hi).step_by(stride) {
        for u in (u_lo..=u_hi).step_by(stride) {
            let d = depth[v * width + u];
            if d == 0 {
                continue;
            }
            let p = k.unproject(u as f32, v as f32, d as f32 * 0.001);
            if let Some(bg) = &options.background
                && bg.signed_distance(&p) < options.background_margin_m
            {
                continue;
            }
            let rel = p - t0;
            let s = rel.dot(&a);
            if s < s_lo || s > err {
                continue;
            }
            if (rel - a * s).norm() > lateral_max {
                continue;
            }
            if scratch.len == N {
                break 'rows;
            }
            scratch.points[scratch.len] = p;
            scratch.len += 1;
            let bin = ((s - s_lo) / BIN_M) as usize;
            hist[bin.min(BINS - 1)] += 1;
        }
    }
    let n = scratch.len;
    if n < options.min_head_points {
        return Err(TipError::NoProbe { points: n });
    }

    // The probe is the run of occupied bins holding the most points; a second mass after a gap of two empty bins
    // ahead of it is something else near the tip.
    let used_bins = (((back + err) / BIN_M) as usize + 1).min(BINS);
    let peak = (0..used_bins).max_by_key(|&b| hist[b]).unwrap_or(0);
    let mut end = peak;
    while end + 1 < used_bins && (hist[end + 1] > 0 || (end + 2 < used_bins && hist[end + 2] > 0)) {
        end += 1;
    }
    // Mass beyond the run is cut off; it is only ambiguous when it starts within 3 cm of the run's end, too close
    // to tell the tip from what it nearly touches.
    let beyond: u32 = hist[end + 1..used_bins].iter().sum();
    let near: u32 = hist[end + 1..(end + 4).min(used_bins)].iter().sum();
    if near > 0 && beyond as usize > 10.max(n / 10) {
        return Err(TipError::Ambiguous {
            reason: "another surface lies just ahead of the probe (patient, bed or hand)",
        });
    }
    let beyond = if near > 0 { beyond } else { 0 };
    let s_end = s_lo + (end + 1) as f32 * BIN_M;

    // Three rounds: tip along the axis from the far end of the points, across it from the box fit of the head.
    let min_scale = 1.0 / stride as f32;
    let mut tip = t0;
    let mut head_points = 0usize;
    let mut fit_rms = 0.0f32;
    let mut limit = s_end;
    for round in 0..3 {
        let lateral = if round == 0 {
            lateral_max
        } else {
            shape.max_radius_m
        };
        let mut m = 0usize;
        for i in 0..n {
            let rel = scratch.points[i] - tip;
            let s = rel.dot(&a);
            if s <= limit && (rel - a * s).norm() <= lateral {
                scratch.axial[m] = s;
                m += 1;
            }
        }
        if m < options.min_head_points {
            return Err(TipError::NoProbe { points: m });
        }
        // 97th percentile: the far end without the few noisiest points.
        let q = ((m - 1) as f32 * 0.97) as usize;
        let (_, s_far, _) = scratch.axial[..m].select_nth_unstable_by(q, |x, y| x.total_cmp(y));
        let s_far = *s_far;
        let fit = fit_head(scratch, n, tip, s_far, lateral, [a, ex, ey], shape)?;
        head_points = fit.points;
        fit_rms = fit.rms_m;
        if head_points < options.min_head_points {
            return Err(TipError::NoProbe { points: head_points });
        }
        let new_tip = tip + a * s_far + ex * fit.dx + ey * fit.dy;
        // Keep the cut-off in the new tip's coordinates, at most 1.5 cm ahead of it.
        limit = (limit + (tip - new_tip).dot(&a)).min(0.015);
        tip = new_tip;
    }

    // Free space: the probe head stands in front of whatever is behind it, so a little beyond its width on some
    // side the depth jumps back (or is missing). A patch of bed or skin taken for the head has no such edge.
    let mut free = 0usize;
    let mut tested = 0usize;
    for i in (0..n).step_by((n / 64).max(1)) {
        let p = scratch.points[i];
        let rel = p - tip;
        let s = rel.dot(&a);
        if s < -shape.head_length_m || s > 0.0 {
            continue;
        }
        tested += 1;
        let Some(px) = k.project(&p) else { continue };
        let r = (shape.max_radius_m + 0.02) * k.fx / p.z.max(0.1);
        let behind = |du: f32, dv: f32| match frame
            .at(libm::roundf(px.x + du) as i32, libm::roundf(px.y + dv) as i32)
        {
            Some(0) | None => true,
            Some(d) => d as f32 * 0.001 > p.z + 0.05,
        };
        if behind(r, 0.0) || behind(-r, 0.0) || behind(0.0, r) || behind(0.0, -r) {
            free += 1;
        }
    }
    let c_free = if tested == 0 {
        0.0
    } else {
        (2.0 * free as f32 / tested as f32).min(1.0)
    };
    if c_free < 0.5 {
        return Err(TipError::NoProbe { points: 0 });
    }
    // Along the axis, the head's back face is the better reference where the camera sees it: the far end of the
    // points is cut short where the arm shadows the head's end from the projector (1-2 cm on validation poses)
    // and its percentile moves with how many points lie behind it.
    let tip = match back_face(scratch, n, tip, [a, ex, ey], shape) {
        Some(s_back) => tip + a * (s_back + shape.head_back_m),
        None => tip + a * shape.axial_shortfall_m,
    };
    // The tip can only be as far from the expected one as the prior allows (plus the head's half width, which
    // the box fit may move it by when the prior's orientation is a little off).
    let distance_m = (tip - t0).norm();
    if distance_m > err + shape.head_half_xy_m[0] {
        return Err(TipError::FarFromPrior { distance_m });
    }
    // Expected head points: the head's visible area (head length x its width) at this distance, subsampled.
    let px_per_m = k.fx / tip.z.max(0.1);
    let expected =
        shape.head_length_m * 2.0 * shape.head_half_xy_m[1] * px_per_m * px_per_m * min_scale * min_scale;
    let c_count = (head_points as f32 / (0.5 * expected).max(1.0)).min(1.0);
    let c_clean = 1.0 - beyond as f32 / n as f32;
    // Points should lie on the box faces to within the sensor noise (a few mm); 15 mm means it is not the head.
    let c_fit = (1.0 - (fit_rms - 0.005).max(0.0) / 0.010).clamp(0.0, 1.0);
    let confidence = (c_count * c_clean * c_fit * c_free).clamp(0.0, 1.0);
    if confidence < options.min_confidence {
        return Err(TipError::LowConfidence { confidence });
    }
    Ok(TipDetection {
        tip_camera: tip,
        confidence,
        head_points,
    })
}

/// Fewest points on the head's back face for it to place the tip.
const MIN_BACK_FACE_POINTS: usize = 8;

/// Where the head's back face lies along the axis relative to `tip` (the far end of the points, fitted across the
/// axis), metres; `None` when the camera does not see it well enough. Its points are those inside the head's
/// cross-section (2 mm in from its faces) and outside the handle (3 mm out), in a window from just behind where
/// the face would be if the far end were complete to 3 cm ahead of it (the far end can only fall short); the
/// face is the densest 1 cm of them (side-face points that jitter inward spread over the window), placed at their
/// median.
fn back_face<const N: usize>(
    scratch: &mut TipScratch<N>,
    n: usize,
    tip: Point3,
    [a, ex, ey]: [Vector3; 3],
    shape: &ProbeShape,
) -> Option<f32> {
    if shape.head_back_m <= 0.0 {
        return None;
    }
    // The camera must look at the face from the handle's side, not along it edge-on.
    let view = (tip - a * shape.head_back_m).coords;
    if view.dot(&a) < 0.1 * view.norm() {
        return None;
    }
    let [hx, hy] = shape.head_half_xy_m;
    let (in_x, in_y, out_r) = (hx - 0.002, hy - 0.002, shape.handle_radius_m + 0.003);
    let (lo, hi) = (-shape.head_back_m - 0.008, -shape.head_back_m + 0.03);
    let mut m = 0usize;
    for i in 0..n {
        let rel = scratch.points[i] - tip;
        let s = rel.dot(&a);
        let (x, y) = (rel.dot(&ex), rel.dot(&ey));
        if s >= lo && s <= hi && x.abs() < in_x && y.abs() < in_y && x * x + y * y > out_r * out_r {
            scratch.axial[m] = s;
            m += 1;
        }
    }
    if m < MIN_BACK_FACE_POINTS {
        return None;
    }
    let v = &mut scratch.axial[..m];
    v.sort_unstable_by(|x, y| x.total_cmp(y));
    let (mut best, mut best_len, mut j) = (0usize, 0usize, 0usize);
    for i in 0..m {
        while j < m && v[j] <= v[i] + 0.01 {
            j += 1;
        }
        if j - i > best_len {
            best = i;
            best_len = j - i;
        }
    }
    (best_len >= MIN_BACK_FACE_POINTS).then(|| v[best + best_len / 2])
}

/// The lateral correction of the head box fit, in probe x and y, and how well the points sit on the faces.
struct HeadFit {
    dx: f32,
    dy: f32,
    points: usize,
    rms_m: f32,
}

/// Fit the head's cross-section box to the points of the head (axial range `s_far - head_length ..= s_far` around
/// the axis through `tip`): each point belongs to the visible x face or the visible y face, whichever it lies
/// nearer; a face with points fixes the offset across it, a direction without its face is centred on the span of
/// the other face's points (the box is symmetric). Three assignment rounds.
fn fit_head<const N: usize>(
    scratch: &TipScratch<N>,
    n: usize,
    tip: Point3,
    s_far: f32,
    lateral: f32,
    [a, ex, ey]: [Vector3; 3],
    shape: &ProbeShape,
) -> Result<HeadFit, TipError> {
    let [hx, hy] = shape.head_half_xy_m;
    // The faces facing the camera: their outward normal points against the view ray to the head.
    let view = (tip - a * (0.5 * shape.head_length_m)).coords;
    let (vx, vy) = (view.dot(&ex), view.dot(&ey));
    if libm::sqrtf(vx * vx + vy * vy) < 0.2 * view.norm() {
        return Err(TipError::Ambiguous {
            reason: "the camera looks along the probe",
        });
    }
    let fx = if vx > 0.0 { -hx } else { hx };
    let fy = if vy > 0.0 { -hy } else { hy };
    let (mut dx, mut dy) = (0.0f32, 0.0f32);
    let mut result = HeadFit {
        dx,
        dy,
        points: 0,
        rms_m: 0.0,
    };
    for _ in 0..3 {
        let (mut sx, mut nx, mut sy, mut ny) = (0.0f32, 0usize, 0.0f32, 0usize);
        let (mut lo_x, mut hi_x, mut lo_y, mut hi_y) =
            (f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY);
        let mut sq = 0.0f32;
        for i in 0..n {
            let rel = scratch.points[i] - tip;
            let s = rel.dot(&a);
            if s > s_far || s < s_far - shape.head_length_m {
                continue;
            }
            let (x, y) = (rel.dot(&ex) - dx, rel.dot(&ey) - dy);
            if libm::sqrtf(x * x + y * y) > lateral {
                continue;
            }
            let (rx, ry) = (fx - x, fy - y);
            if rx.abs() <= ry.abs() {
                sx += rx;
                nx += 1;
                lo_y = lo_y.min(y);
                hi_y = hi_y.max(y);
                sq += rx * rx;
            } else {
                sy += ry;
                ny += 1;
                lo_x = lo_x.min(x);
                hi_x = hi_x.max(x);
                sq += ry * ry;
            }
        }
        let total = nx + ny;
        if total == 0 {
            return Err(TipError::NoProbe { points: 0 });
        }
        // A face seen edge-on has few points: trust it only with a tenth of the points.
        let enough = (total / 10).max(5);
        let step_x = if nx >= enough {
            -sx / nx as f32
        } else if ny > 0 {
            (lo_x + hi_x) * 0.5
        } else {
            0.0
        };
        let step_y = if ny >= enough {
            -sy / ny as f32
        } else if nx > 0 {
            (lo_y + hi_y) * 0.5
        } else {
            0.0
        };
        dx += step_x;
        dy += step_y;
        result = HeadFit {
            dx,
            dy,
            points: total,
            rms_m: libm::sqrtf(sq / total as f32),
        };
    }
    Ok(result)
}
