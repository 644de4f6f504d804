//! Per-frame rigid registration of the shaped torso model: robust projective point-to-plane ICP for a fixed
//! number of iterations with an early stop and the budget's cut, and the verdict the state machine takes.
//!
//! Cost per iteration: one association of the torso vertices (`stride` apart) and a 6x6 solve; about 20-40 µs for
//! the default model's 1250 vertices on one desktop core. Nothing allocates.

use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::{Isometry3, Point3, Vector3};
use crate::icp::{self, Association, IcpParams};
use crate::time::Clock;
use crate::tracker::budget::{BudgetConfig, Stopwatch, iteration_fits};
use crate::tracker::state::FitQuality;

/// How the torso fit is run and judged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorsoIcpConfig {
    /// Use every `stride`-th torso vertex.
    pub stride: u16,
    /// Huber threshold of the point-to-plane residual, metres.
    pub huber_m: f32,
    /// Stop when an iteration moves the model less than this, metres (translation plus rotation times 0.5 m).
    pub stop_m: f32,
    /// A good fit has at least this many pairs.
    pub min_pairs: u16,
    /// A good fit's RMS point-to-plane residual is at most this while tracking, metres (the estimated shape never
    /// matches the patient exactly: a right fit leaves some residual).
    pub max_rms_m: f32,
    /// The stricter limit when acquiring without a pose, metres: a wrong local minimum (turned or shifted torso) leaves
    /// about 1 cm.
    pub acquire_max_rms_m: f32,
    /// Below this share of the front-facing torso points visible (the rest occluded), the torso is occluded.
    pub min_visible: f32,
    /// A fit that is not good while less than this share is visible counts as occluded rather than failed.
    pub occluded_below: f32,
    /// An occluder is an observed point this much nearer to the camera than the model surface, metres.
    pub occluder_margin_m: f32,
    /// Largest model-to-observed distance of a pair, metres.
    pub max_distance_m: f32,
}

impl Default for TorsoIcpConfig {
    fn default() -> Self {
        TorsoIcpConfig {
            stride: 1,
            huber_m: 0.01,
            stop_m: 1e-4,
            min_pairs: 150,
            max_rms_m: 0.012,
            acquire_max_rms_m: 0.008,
            min_visible: 0.3,
            occluded_below: 0.7,
            occluder_margin_m: 0.04,
            max_distance_m: 0.1,
        }
    }
}

/// What one frame's fit did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TorsoFit {
    /// Iterations run.
    pub iterations: u8,
    /// Whether the budget cut iterations (not an early stop).
    pub cut: bool,
    /// The last association: pairs, occluded points, residual.
    pub association: Association,
    /// Share of the front-facing model points that were seen (pairs over pairs plus occluded), 0..1.
    pub visible: f32,
}

impl TorsoFit {
    /// The verdict for the state machine (`acquiring`: no pose yet, the stricter residual limit applies).
    pub fn quality(&self, cfg: &TorsoIcpConfig, acquiring: bool) -> FitQuality {
        let a = &self.association;
        let max_rms = if acquiring {
            cfg.acquire_max_rms_m
        } else {
            cfg.max_rms_m
        };
        if a.pairs >= cfg.min_pairs as usize && a.rms_m() <= max_rms && self.visible >= cfg.min_visible {
            FitQuality::Good
        } else if self.visible < cfg.occluded_below && a.pairs + a.occluded >= cfg.min_pairs as usize {
            // Too little seen, or a fit spoiled while a good part of the torso is hidden (the arm coming or going):
            // occlusion, not a lost patient.
            FitQuality::Occluded
        } else {
            FitQuality::Failed
        }
    }
}

/// The association parameters of the fit for a mattress plane.
pub fn icp_params(cfg: &TorsoIcpConfig, mattress: crate::geometry::Plane) -> IcpParams {
    IcpParams {
        max_distance_m: cfg.max_distance_m,
        occluder_margin_m: cfg.occluder_margin_m,
        ..IcpParams::new(mattress)
    }
}

/// Register the torso model (`vertices`/`normals`, torso frame) to `frame` from `start`; returns the refined
/// `camera_from_torso` (the start when no step could be taken) and what the fit did.
#[allow(clippy::too_many_arguments)] // the frame, its camera, the model, the start, settings and the clock
pub fn fit_torso(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    vertices: &[Point3],
    normals: &[Vector3],
    start: Isometry3,
    cfg: &TorsoIcpConfig,
    params: &IcpParams,
    budget: &BudgetConfig,
    clock: &(impl Clock + ?Sized),
    watch: &Stopwatch,
) -> (Isometry3, TorsoFit) {
    let mut pose = start;
    let mut fit = TorsoFit::default();
    let mut slowest = 0u32;
    for it in 0..budget.icp_iterations {
        let before = watch.elapsed(clock);
        if it > 0 && !iteration_fits(budget, before, slowest) {
            fit.cut = true;
            break;
        }
        let step = icp::robust_point_to_plane_step(
            frame,
            k,
            vertices,
            Some(normals),
            cfg.stride as usize,
            &pose,
            params,
            cfg.huber_m,
        );
        fit.iterations += 1;
        slowest = slowest.max(watch.elapsed(clock).saturating_sub(before));
        let Ok((next, a)) = step else {
            // Too few pairs for a step: count what was seen so the verdict can tell occlusion from absence.
            fit.association = icp::associate(
                frame,
                k,
                vertices,
                Some(normals),
                cfg.stride as usize,
                &pose,
                params,
                |_, _, _, _| {},
            );
            break;
        };
        fit.association = a;
        let delta = next * pose.inverse();
        pose = next;
        if delta.translation.vector.norm() + 0.5 * delta.rotation.angle() < cfg.stop_m {
            break;
        }
    }
    let a = &fit.association;
    let seen = a.pairs + a.occluded;
    fit.visible = if seen == 0 {
        0.0
    } else {
        a.pairs as f32 / seen as f32
    };
    (pose, fit)
}
