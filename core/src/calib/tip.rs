//! Probe-tip detection in a depth frame: with the bed empty or the patient still, the probe is the arm's end
//! segment in free space. Given a prior (where the tip and the probe axis should be in the camera frame, from the
//! arm state and the current extrinsic guess), gather the depth points in a cylinder around the prior axis, cut
//! off whatever lies beyond a gap ahead of the probe (the bed, the patient), take the tip's position along the axis
//! from the far end of the points and its position across the axis from the centroid of the probe head pushed by
//! the head's half-width away from the camera (the camera only sees the near side).
//!
//! Cost: one pass over a window of about (0.3 m · f / z)² pixels (e.g. 200x200 at 1 m, subsampled to at most `N`
//! points), then three passes over the gathered points; about 0.2 ms. Nothing allocates: points live in a
//! caller-owned [`TipScratch`].

use core::fmt;

use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::{Plane, Point3, Vector3};

/// Where the tip should be: the arm's reported tip and probe axis mapped into the camera by the current guess.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipPrior {
    /// Expected tip, `camera` frame, metres.
    pub tip_camera: Point3,
    /// Expected probe axis (unit, from the wrist toward the tip), `camera` frame.
    pub axis_camera: Vector3,
    /// How far the true tip may be from the expected one, metres (the guess's uncertainty).
    pub uncertainty_m: f32,
}

/// The probe's shape as far as detection needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeShape {
    /// Length of the probe head whose centroid fixes the axis, measured back from the tip, metres.
    pub head_length_m: f32,
    /// Length of the free end segment (probe head and handle) searched behind the tip, metres.
    pub segment_length_m: f32,
    /// Distance from the probe axis to the head surface the camera sees, metres (half the head's width).
    pub surface_offset_m: f32,
    /// Largest distance of a probe surface point from the axis, metres.
    pub max_radius_m: f32,
}

impl ProbeShape {
    /// The probe of the synthetic scene (`supine_models::scene::arm`): a 60 x 24 x 70 mm head on a 40 mm handle.
    pub const SYNTHETIC: ProbeShape = ProbeShape {
        head_length_m: 0.05,
        segment_length_m: 0.12,
        surface_offset_m: 0.03,
        max_radius_m: 0.045,
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
    let a = prior.axis_camera.try_normalize(1e-6).ok_or(TipError::Ambiguous {
        reason: "the prior probe axis is zero",
    })?;
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
    let u_lo = (p0.x.min(p1.x) - pad).floor().max(0.0);
    let u_hi = (p0.x.max(p1.x) + pad).ceil().min(w - 1.0);
    let v_lo = (p0.y.min(p1.y) - pad).floor().max(0.0);
    let v_hi = (p0.y.max(p1.y) + pad).ceil().min(h - 1.0);
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
    let beyond: u32 = hist[end + 1..used_bins].iter().sum();
    if beyond as usize > 10.max(n / 10) {
        return Err(TipError::Ambiguous {
            reason: "another surface lies just ahead of the probe (patient, bed or hand)",
        });
    }
    let s_end = s_lo + (end + 1) as f32 * BIN_M;

    // Three rounds: tip along the axis from the far end of the points, across it from the head centroid.
    let min_scale = 1.0 / stride as f32;
    let mut tip = t0;
    let mut head_points = 0usize;
    let mut limit = s_end - (t0 - tip).dot(&a);
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
        let mut c = Vector3::zeros();
        head_points = 0;
        for i in 0..n {
            let rel = scratch.points[i] - tip;
            let s = rel.dot(&a);
            if s <= s_far && s >= s_far - shape.head_length_m && (rel - a * s).norm() <= lateral {
                c += scratch.points[i].coords;
                head_points += 1;
            }
        }
        if head_points < options.min_head_points {
            return Err(TipError::NoProbe { points: head_points });
        }
        let c_head = Point3::from(c / head_points as f32);
        let view = c_head.coords.normalize();
        let across = view - a * a.dot(&view);
        let Some(across) = across.try_normalize(0.2) else {
            return Err(TipError::Ambiguous {
                reason: "the camera looks along the probe",
            });
        };
        let on_axis = c_head + across * shape.surface_offset_m;
        let s_axis = (on_axis - tip).dot(&a);
        let new_tip = on_axis + a * (s_far - s_axis);
        // Keep the cut-off in the new tip's coordinates.
        limit += (tip - new_tip).dot(&a);
        tip = new_tip;
        limit = limit.min(0.015);
    }

    // Expected head points: the head's visible area (head length x its width) at this distance, subsampled.
    let px_per_m = k.fx / tip.z.max(0.1);
    let expected =
        shape.head_length_m * 2.0 * shape.surface_offset_m * px_per_m * px_per_m * min_scale * min_scale;
    let c_count = (head_points as f32 / (0.3 * expected).max(1.0)).min(1.0);
    let c_clean = 1.0 - beyond as f32 / n as f32;
    let confidence = (c_count * c_clean).clamp(0.0, 1.0);
    if confidence < options.min_confidence {
        return Err(TipError::LowConfidence { confidence });
    }
    Ok(TipDetection {
        tip_camera: tip,
        confidence,
        head_points,
    })
}
