//! `supine-models eval tracking --data DIR [--json FILE] [--png DIR]`: run the real-time tracker
//! (`supine_core::tracker`) over generated sequences (`supine-models sequence`) in each of its three variants and
//! score it against the ground truth, frame by frame.
//!
//! Figures (JSON keys in shared/design/cli.md):
//! - torso surface error: mean distance from each vertex of the tracked torso model to the true posed torso
//!   surface of the frame (`torso.bin`), mm; salient-point error; probe mapping: the arm's own state stream
//!   (`arm.cobs`: latency, encoder noise) mapped through the tracked pose onto the tracked model, against the
//!   probe truth of the frame (nearest point and signed distance), where the tip is near the body.
//! - rigid floor (`torso_floor_mm_mean`): the same torso error for the tracked model at its best rigid pose (Kabsch
//!   to the true posed torso): what the model's shape and the true body's posture leave; the torso error above it
//!   is the tracked pose's.
//! - Sequences without `torso.bin` (the committed demo, older ones) are scored as `supine_core::tracker::accuracy`
//!   does: vertex to vertex against the body model shaped with the true coefficients at the true torso pose.
//! - recovery: frames from the end of the full occlusion to the first frame tracked within 20 mm; counted also over
//!   the sequences tracked within 20 mm as the arm began its approach (`tracked_before_occlusion`), since a track
//!   already off before it has no pose to recover.
//! - motion followed: the torso error's median over the [`MOTION_WINDOW`] frames after the patient's roll or shift
//!   ends is at most [`MOTION_FOLLOWED_MM`] above its median over the frames before it began (not counted without a
//!   pose before it; not followed without one after it).
//! - tracked fraction: frames after the init phase whose state carries a pose.
//! - latency: per-frame processing time on this machine (one thread), p50 and p99. The frames are scored against
//!   the full truth after the sequence (each tracked surface kept once), so the scoring's queries do not empty the
//!   caches between the tracker's frames; `--oracle-start`'s fits still run between them.
//!
//! Cost: one .oni decode and one tracker frame per frame and variant, plus the scoring (~1250 vertices).

use anyhow::{Context, Result, bail, ensure};
use clap::ValueEnum;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use supine_core::body_model::SHAPE_COMPONENTS;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::{Isometry3, Point3, Vector3};
use supine_core::probe::ProbeMapping;
use supine_core::salient::SalientPoint;
use supine_core::shape::combine::{MAX_SHAPE_FRAMES, ShapeCombine};
use supine_core::torso::TorsoSurface;
use supine_core::tracker::accuracy::{self, TrackedFrame, TruthFrame};
use supine_core::tracker::budget::{Stage, Stopwatch};
use supine_core::tracker::torso_icp;
use supine_core::tracker::{ArmSample, FrameReport, Models, ScratchSizes, Tracker, TrackerConfig, Variant};
use supine_core::wire::{ShapeMode, TrackerState};
use supine_drivers::SourceErrorKind;
use supine_drivers::clock::MonotonicClock;
use supine_drivers::oni::OniReader;
use supine_drivers::tracker_host::{ModelFiles, OwnedTorso, TrackerScratch};

use super::tracking_truth::TrackingTruth;
use crate::sequence::episodes::{FullOcclusion, Motion, MotionKind};
use crate::sequence::{FrameTruth, SWEEP_MAX_OCCLUDED, SequenceMeta};

/// Arguments of `supine-models eval tracking`.
#[derive(Debug, clap::Args)]
pub struct TrackingEvalArgs {
    /// A sequence directory, or a folder of them.
    #[arg(long)]
    pub data: PathBuf,
    /// Write the report here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write plots over time (error, state, occluded fraction) here as PNG, one per sequence.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Directory of the model files body.sbm, joints.jfor, shape.ssm (default: the committed models/artifacts).
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Variants to run (default: all three).
    #[arg(long, value_delimiter = ',')]
    pub variants: Vec<String>,
    /// Diagnostic: give the tracker the patient's true shape (the init phase then finds only the bed), to separate
    /// tracking error from shape error.
    #[arg(long)]
    pub true_shape: bool,
    /// Diagnostic: on every fifth frame with a pose, also fit the torso from the tracked model's best rigid pose
    /// against the truth and report it per frame (`oracle_fit`), to tell a missed basin from a shape that cannot
    /// hold the right pose.
    #[arg(long)]
    pub oracle_start: bool,
    /// Diagnostic: the tracker's `forest_every_frame` (off by default): the forest runs on every tracked frame, so
    /// `forest_point_mm` is reported on every frame; the poses are the same.
    #[arg(long)]
    pub forest_every_frame: bool,
    /// The tracker's `search_shape_start` (off by default): the shape refinement starts from a rigid registration
    /// of the estimated torso instead of the forest's points.
    #[arg(long)]
    pub search_shape_start: bool,
    /// The tracker's `acquire_from_init` (default: the tracker's, on since 2026-12-04): the init phase's fitted
    /// torso pose starts the first acquisition and counts as its first consistent frame.
    #[arg(long, value_name = "true|false")]
    pub acquire_from_init: Option<bool>,
    /// The tracker's `seed` (default: the tracker's): its RANSAC and forest pixel draws. Another seed re-draws what
    /// depends on them, which measures how much of a difference between two runs is the draw's.
    #[arg(long, value_name = "S")]
    pub tracker_seed: Option<u64>,
    /// The tracker's `bed_frames` (default: the tracker's): frames whose bed estimates the init phase votes on.
    #[arg(long, value_name = "N")]
    pub bed_frames: Option<u8>,
    /// The tracker's `follow_occluded` (default: the tracker's, on since 2026-12-03's seventh round): while the
    /// torso is mostly hidden, the pose follows fits from the temporal start that pass the acquisition's floors
    /// instead of coasting.
    #[arg(long, value_name = "true|false")]
    pub follow_occluded: Option<bool>,
    /// The tracker's `shape_point_features` (off by default): the init phase's shape estimate reads the salient
    /// points' spacing (the shape model's `LINP` regression).
    #[arg(long)]
    pub shape_point_features: bool,
    /// The tracker's `near_confirm` (default: the tracker's, 4 since 2026-12-07; 0: off, as before): consecutive
    /// acquisition frames whose best fit is good but for a residual up to `--near-max-rms-mm`, at the same pose,
    /// that acquire it.
    #[arg(long, value_name = "N")]
    pub near_confirm: Option<u8>,
    /// The tracker's `near_max_rms_m` in mm (default: the tracker's, 20).
    #[arg(long, value_name = "MM", value_parser = parse_weight)]
    pub near_max_rms_mm: Option<f32>,
    /// The tracker's `occluded_hold_rotation` (default: the tracker's, 0.3): while occluded, the temporal fit's
    /// rotation held at the last pose's, weight per data pair (0: off).
    #[arg(long, value_parser = parse_weight)]
    pub hold_rotation: Option<f32>,
    /// The lock refits with the bed contact (the tracker's `refit_bed_contact`, off by default: the torso's lowest
    /// point held on the mattress).
    #[arg(long)]
    pub refit_bed_contact: bool,
    /// The tracker's `refit_lambda`: Eq. 7's pull toward the mean body in the lock refits (default: the tracker's,
    /// 0.01; 0.1 before 2026-12-03's sixth round).
    #[arg(long, value_parser = parse_weight)]
    pub refit_lambda: Option<f32>,
    /// The tracker's `refit_stride`: the lock refits use every N-th vertex of the body model's subset (default: the
    /// tracker's).
    #[arg(long)]
    pub refit_stride: Option<u16>,
    /// The tracker's `doubt_frames`: good tracked frames in a row with a residual over 7.5 mm, once the first lock
    /// refits are in, that drop the lock once (default: the tracker's, 8 since 2026-12-06; 0: off, as before)
    #[arg(long)]
    pub doubt_frames: Option<u16>,
    /// The tracker's `screen_stride`: the screening of the bed grid's starts (acquisitions, the init phase's shape
    /// fit) uses every N-th torso vertex (default: the tracker's, 4; 1 gives the tracker before 2026-12-05's
    /// nineteenth round).
    #[arg(long)]
    pub screen_stride: Option<u16>,
    /// The tracker's `bed_pitch_weight` (default: the tracker's, 0: off; 3 was measured): the back-on-the-bed prior
    /// in fits from every start but the temporal one.
    #[arg(long, value_parser = parse_weight)]
    pub bed_pitch_weight: Option<f32>,
    /// The tracker's `lock_refits`: shape refits on the first tracked frames (default: the tracker's, 3; 0: off).
    #[arg(long)]
    pub lock_refits: Option<u8>,
    /// The tracker's `refit_rounds`: further rounds of lock refits once the tracker has settled with a round's
    /// shape (default: the tracker's, 2; 0: one round).
    #[arg(long)]
    pub refit_rounds: Option<u8>,
    /// The tracker's `refit_settle_frames`: consecutive good tracked frames a further round waits for (default:
    /// the tracker's, 10).
    #[arg(long)]
    pub refit_settle_frames: Option<u16>,
    /// The tracker's shape mode from the first frame, as the arm controller's command sets it: `once` (the
    /// default), `frozen` (no refits after the init phase) or `continuous` (a round of lock refits every
    /// `--continuous-refit-frames` good tracked frames after the configured rounds).
    #[arg(long, value_parser = parse_shape_mode)]
    pub shape_mode: Option<ShapeMode>,
    /// The tracker's `continuous_refit_frames` (default: the tracker's, 90).
    #[arg(long)]
    pub continuous_refit_frames: Option<u16>,
    /// The tracker's surface adaptation: tracked frames averaged per round (default: the tracker's, 8; 0: off).
    #[arg(long)]
    pub surface_frames: Option<u16>,
    /// The tracker's surface adaptation rounds (default: the tracker's, 2).
    #[arg(long)]
    pub surface_rounds: Option<u8>,
    /// The tracker's surface adaptation: good tracked frames with the current torso model before a frame counts
    /// (default: the tracker's, 3).
    #[arg(long)]
    pub surface_settle_frames: Option<u16>,
    /// The tracker's `refit_min_visible`: a lock refit waits for a fit that sees this share of the torso.
    #[arg(long, value_parser = parse_visible_share)]
    pub refit_min_visible: Option<f32>,
    /// The tracker's `refit_late_frames`: frames with a pose after which waiting lock refits take the late gate
    /// (default: the tracker's, 30; 0: never).
    #[arg(long)]
    pub refit_late_frames: Option<u16>,
    /// The tracker's `refit_late_min_visible`: the lock refits' visibility gate after `refit_late_frames` (default:
    /// the tracker's, 0.4).
    #[arg(long, value_parser = parse_visible_share)]
    pub refit_late_min_visible: Option<f32>,
    /// The tracker's `shape_frames`: init frames whose shape estimates are combined (default: the tracker's; at
    /// most 64).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=MAX_SHAPE_FRAMES as i64))]
    pub shape_frames: Option<u16>,
    /// The tracker's `shape_combine`: how the init frames' shape estimates are combined, `mean` or `median`
    /// (default: the tracker's).
    #[arg(long, value_parser = parse_shape_combine)]
    pub shape_combine: Option<ShapeCombine>,
    /// The tracker's `icp.acquire_min_visible`: the share of the torso model a fit made without a pose must see
    /// (default: the tracker's).
    #[arg(long, value_parser = parse_visible_share)]
    pub acquire_min_visible: Option<f32>,
    /// The tracker's `icp.body_max_height_m`: observed points in front of the torso model but lower than this
    /// above the bed are the patient, not the arm (default: the tracker's; 0: off, as before 2026-12-05)
    #[arg(long, value_parser = parse_body_height)]
    pub body_max_height: Option<f32>,
    /// The tracker's `icp.switch_margin`: while the pose's own fit is not good, a far fit that sees this much more
    /// of the torso replaces the pose on its second frame (default: the tracker's, 0.1; 0: off, as before
    /// 2026-12-05's twenty-second round).
    #[arg(long, value_parser = parse_visible_share)]
    pub switch_margin: Option<f32>,
    /// The tracker's `icp.clear_view_min_support`: a pose whose own fit sees enough of the torso with less support
    /// than this gets a second look from the forest without the prior (default: the tracker's, 0.6; 0: off, as
    /// before 2026-12-05's twenty-fifth round).
    #[arg(long, value_parser = parse_visible_share)]
    pub clear_view_support: Option<f32>,
    /// The tracker's `icp.look_support_margin`: the support a second look's fit needs above the pose's own.
    #[arg(long, value_parser = parse_visible_share)]
    pub look_support_margin: Option<f32>,
    /// The tracker's frame budget, ms (the product's 33 by default). On a loaded machine the budget cuts ICP and
    /// acquisition starts, so the figures depend on the load; a large budget gives those of an idle head computer.
    #[arg(long, default_value_t = 33.0, value_parser = parse_budget_ms)]
    pub budget_ms: f32,
}

fn parse_budget_ms(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && (1.0..=60_000.0).contains(&v) => Ok(v),
        _ => Err(format!("`{s}` is not a budget in ms (1 to 60000)")),
    }
}

fn parse_weight(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a weight (a finite number, 0 or more)")),
    }
}

fn parse_shape_mode(s: &str) -> std::result::Result<ShapeMode, String> {
    ShapeMode::from_name(s).ok_or_else(|| format!("`{s}` is not a shape mode (frozen, once or continuous)"))
}

/// `s` as a number from 0 to 1, or an error naming `what` it should have been.
fn parse_unit(s: &str, what: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("`{s}` is not {what} (0 to 1)")),
    }
}

fn parse_visible_share(s: &str) -> std::result::Result<f32, String> {
    parse_unit(s, "a share of the torso")
}

fn parse_body_height(s: &str) -> std::result::Result<f32, String> {
    parse_unit(s, "a height above the bed in metres")
}

fn parse_shape_combine(s: &str) -> std::result::Result<ShapeCombine, String> {
    match s {
        "mean" => Ok(ShapeCombine::Mean),
        "median" => Ok(ShapeCombine::Median),
        _ => Err(format!(
            "`{s}` is not a combination of shape estimates (mean or median)"
        )),
    }
}

/// A 4x4 row-major rigid transform as an isometry.
pub use supine_core::geometry::isometry_from_rows as isometry_of;

/// One generated sequence as the evaluation reads it.
pub struct SequenceData {
    /// Directory.
    pub dir: PathBuf,
    /// sequence.json.
    pub meta: SequenceMeta,
    /// truth.jsonl, one per frame.
    pub truth: Vec<FrameTruth>,
}

impl SequenceData {
    /// Read `dir`'s sequence.json and truth.jsonl.
    pub fn load(dir: &Path) -> Result<Self> {
        let meta_path = dir.join("sequence.json");
        let meta: SequenceMeta = serde_json::from_slice(
            &std::fs::read(&meta_path).with_context(|| format!("reading {}", meta_path.display()))?,
        )
        .with_context(|| format!("parsing {}", meta_path.display()))?;
        let truth_path = dir.join("truth.jsonl");
        let text = std::fs::read_to_string(&truth_path)
            .with_context(|| format!("reading {}", truth_path.display()))?;
        let truth = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
            .map(|(i, l)| {
                serde_json::from_str::<FrameTruth>(l)
                    .with_context(|| format!("{} line {}", truth_path.display(), i + 1))
            })
            .collect::<Result<Vec<_>>>()?;
        ensure!(!truth.is_empty(), "{} holds no frames", truth_path.display());
        Ok(SequenceData {
            dir: dir.to_path_buf(),
            meta,
            truth,
        })
    }

    /// `robot_base_from_camera` (the sequence's world frame is `robot_base`).
    pub fn robot_base_from_camera(&self) -> Isometry3 {
        isometry_of(&self.meta.camera_from_world).inverse()
    }
}

pub use super::tracking_truth::{incomplete_sequence_dirs, sequence_dirs};

/// Per-frame scores of one variant.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FrameScore {
    /// Frame index.
    pub frame: u32,
    /// State after the frame.
    pub state: String,
    /// Torso surface error, mm (frames with a pose).
    pub torso_mm: Option<f32>,
    /// Torso surface error of the same model at its best rigid pose, mm (frames with a pose): what no pose of this
    /// shape, rigid and in the rest posture, can beat ([`TrackingTruth::rigid_floor_mm`]).
    pub torso_floor_mm: Option<f32>,
    /// Salient-point error, mm.
    pub point_mm: Option<f32>,
    /// Probe nearest-point error, mm.
    pub probe_mm: Option<f32>,
    /// Probe signed-distance error, mm.
    pub probe_distance_mm: Option<f32>,
    /// The probe tip's true signed distance from the skin, mm (frames whose probe is scored).
    pub probe_true_distance_mm: Option<f32>,
    /// Processing time, ms.
    pub ms: f32,
    /// Processing time per stage (init, forest, ICP, output: [`Stage::ALL`]'s order), ms.
    pub stage_ms: [f32; 4],
    /// True occluded fraction of the torso.
    pub occluded: f32,
    /// True share of the torso the arm hides from the sensor, its projector shadow included (sequences of
    /// 2026-12-06 on: `torso_unseen_fraction` in the truth).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unseen: Option<f32>,
    /// RMS point-to-plane residual of the frame's torso fit, mm (frames where a fit ran).
    pub fit_rms_mm: Option<f32>,
    /// Share of the front-facing torso model seen by the fit, 0..1.
    pub fit_visible: Option<f32>,
    /// Pairs, inlier pairs, occluded, see-through and no-depth points of the fit's last association.
    pub fit_counts: Option<[usize; 5]>,
    /// The forest's raw points against the truth, mean mm over the points it found.
    pub forest_point_mm: Option<f32>,
    /// Translation error of the frame's best fit (accepted or not) against the true torso frame, mm.
    pub fit_pose_mm: Option<f32>,
    /// Rotation error of the frame's best fit against the true torso frame, degrees.
    pub fit_pose_deg: Option<f32>,
    /// With `--oracle-start`, on every [`ORACLE_EVERY`]th frame with a pose: the torso fit from the tracked model's
    /// best rigid pose against the truth.
    pub oracle_fit: Option<OracleFit>,
}

/// Frames between two oracle-start fits (`--oracle-start`).
pub const ORACLE_EVERY: usize = 5;

/// A diagnostic torso fit started at the tracked model's best rigid pose against the true torso
/// ([`TrackingTruth::rigid_best`]), run as an acquisition's fit (the tracker's ICP settings, the acquisition's
/// association): whether a better fit than the tracker's lies where the truth is. When its support is clearly
/// above the tracker's own fit's, the tracker's search missed that basin; when ICP walks away from the truth, the
/// shape does not let the data hold the right pose.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct OracleFit {
    /// Inlier pairs over pairs plus see-through points (the tracker's `support`).
    pub support: f32,
    /// The same for the tracker's own fit of the frame.
    pub own_support: f32,
    /// RMS point-to-plane residual, mm.
    pub rms_mm: f32,
    /// Pairs of the last association.
    pub pairs: usize,
    /// Share of the front-facing torso seen.
    pub visible: f32,
    /// Torso surface error at the fit's pose, mm.
    pub torso_mm: f32,
}

/// A probe tip at most this far from the skin (true signed distance, mm) is in contact range:
/// `probe_error_mm_mean_contact` scores those frames alone.
const CONTACT_MM: f32 = 30.0;

fn mean(v: impl Iterator<Item = f32>) -> Option<f32> {
    let (s, n) = v.fold((0.0f64, 0usize), |(s, n), x| (s + x as f64, n + 1));
    (n > 0).then(|| (s / n as f64) as f32)
}

fn percentile(v: &mut [f32], q: f32) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f32::total_cmp);
    let i = ((v.len() - 1) as f32 * q).round() as usize;
    Some(v[i])
}

/// Run `variant` over one sequence, scoring each frame.
pub fn run_variant(
    models: &Models<'_>,
    seq: &SequenceData,
    variant: Variant,
    truth_torso: &OwnedTorso,
    args: &TrackingEvalArgs,
) -> Result<(Vec<FrameScore>, Value)> {
    let k = Intrinsics::KINECT_V1;
    let mut cfg = TrackerConfig {
        variant,
        robot_base_from_camera: seq.robot_base_from_camera(),
        ..TrackerConfig::default()
    };
    cfg.up_camera = Some(cfg.robot_base_from_camera.inverse().rotation * Vector3::z());
    cfg.budget.frame_us = (args.budget_ms * 1000.0) as u32;
    cfg.search_shape_start = args.search_shape_start;
    cfg.forest_every_frame = args.forest_every_frame;
    if let Some(a) = args.acquire_from_init {
        cfg.acquire_from_init = a;
    }
    if let Some(n) = args.bed_frames {
        cfg.bed_frames = n;
    }
    if let Some(seed) = args.tracker_seed {
        cfg.seed = seed;
    }
    if let Some(f) = args.follow_occluded {
        cfg.icp.follow_occluded = f;
    }
    if args.refit_bed_contact {
        cfg.refit_bed_contact = Some(supine_core::fit::BedContact::default());
    }
    if let Some(w) = args.bed_pitch_weight {
        cfg.icp.bed_pitch_weight = w;
    }
    cfg.shape_point_features = args.shape_point_features;
    if let Some(n) = args.near_confirm {
        cfg.icp.near_confirm = n;
    }
    if let Some(mm) = args.near_max_rms_mm {
        cfg.icp.near_max_rms_m = mm * 0.001;
    }
    if let Some(w) = args.hold_rotation {
        cfg.occluded_hold_rotation = w;
    }
    if let Some(n) = args.lock_refits {
        cfg.lock_refits = n;
    }
    if let Some(v) = args.acquire_min_visible {
        cfg.icp.acquire_min_visible = v;
    }
    if let Some(h) = args.body_max_height {
        cfg.icp.body_max_height_m = h;
    }
    if let Some(m) = args.switch_margin {
        cfg.icp.switch_margin = m;
    }
    if let Some(m) = args.clear_view_support {
        cfg.icp.clear_view_min_support = m;
    }
    if let Some(m) = args.look_support_margin {
        cfg.icp.look_support_margin = m;
    }
    if let Some(n) = args.shape_frames {
        cfg.shape_frames = n;
    }
    if let Some(c) = args.shape_combine {
        cfg.shape_combine = c;
    }
    if let Some(l) = args.refit_lambda {
        cfg.refit_lambda = l;
    }
    if let Some(n) = args.refit_stride {
        cfg.refit_stride = n;
    }
    if let Some(n) = args.doubt_frames {
        cfg.doubt_frames = n;
    }
    if let Some(n) = args.screen_stride {
        cfg.screen_stride = n;
    }
    if let Some(v) = args.refit_min_visible {
        cfg.refit_min_visible = v;
    }
    if let Some(n) = args.refit_rounds {
        cfg.refit_rounds = n;
    }
    if let Some(n) = args.refit_settle_frames {
        cfg.refit_settle_frames = n;
    }
    if let Some(m) = args.shape_mode {
        cfg.shape_mode = m;
    }
    if let Some(n) = args.continuous_refit_frames {
        cfg.continuous_refit_frames = n;
    }
    if let Some(n) = args.refit_late_frames {
        cfg.refit_late_frames = n;
    }
    if let Some(v) = args.refit_late_min_visible {
        cfg.refit_late_min_visible = v;
    }
    if let Some(n) = args.surface_frames {
        cfg.surface.frames = n;
    }
    if let Some(n) = args.surface_rounds {
        cfg.surface.rounds = n;
    }
    if let Some(n) = args.surface_settle_frames {
        cfg.surface.settle_frames = n;
    }
    if args.true_shape {
        let mut z = [0.0; SHAPE_COMPONENTS];
        for (o, s) in z.iter_mut().zip(&seq.meta.shape) {
            *o = *s;
        }
        cfg.known_shape = Some(z);
    }
    let sizes = ScratchSizes::of(models, &k, &cfg.planes);
    let mut store = TrackerScratch::new(&sizes);
    let mut tracker = Tracker::new(*models, k, cfg, store.scratch())?;
    let oni = seq.dir.join("sequence.oni");
    let mut reader = OniReader::open(&oni).with_context(|| format!("opening {}", oni.display()))?;
    let clock = MonotonicClock;
    let true_surface = truth_torso
        .surface(&models.body)
        .context("true torso surface has the wrong size")?;
    // Sequences written since the tracking episodes landed carry the true posed torso (torso.bin), probe truth and
    // the arm's own state stream: scored against those. Older ones (the committed demo) against the shaped model.
    let full = if seq.dir.join("torso.bin").is_file() {
        Some(TrackingTruth::load(&seq.dir)?)
    } else {
        None
    };
    let arm_stream = full.as_ref().and_then(|f| f.arm.as_deref()).unwrap_or(&[]);
    let mut next_arm = 0usize;
    let mut newest_arm: Option<ArmSample> = None;
    let mut scores = Vec::with_capacity(seq.truth.len());
    // Frames scored against the full truth after the sequence (the scoring's nearest-surface queries would
    // otherwise empty the caches between the tracker's frames and inflate its timings), and the distinct torso
    // surfaces they were tracked with.
    let mut deferred: Vec<Deferred> = Vec::new();
    let mut surfaces: Vec<Vec<Point3>> = Vec::new();
    let mut i = 0usize;
    let mut init_frames = None;
    loop {
        let frame = match reader.read_frame() {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) => bail!("reading {}: {e}", oni.display()),
        };
        let Some(t) = seq.truth.get(i) else {
            bail!("{} has more frames than truth.jsonl", oni.display());
        };
        let arm = if full.is_some() {
            // The newest arm state sent before the frame was captured, as a live link would deliver it.
            while next_arm < arm_stream.len() && arm_stream[next_arm].time <= frame.capture {
                newest_arm = Some(arm_stream[next_arm]);
                next_arm += 1;
            }
            newest_arm.filter(|_| t.world_from_probe.is_some())
        } else {
            t.world_from_probe.as_ref().map(|m| ArmSample {
                time: frame.capture,
                tip_robot_base: Point3::from(isometry_of(m).translation.vector),
                robot_base_from_probe: isometry_of(m).rotation,
            })
        };
        let r: FrameReport = tracker.process(&frame, arm.as_ref(), &clock);
        if init_frames.is_none() && tracker.state() != TrackerState::Initialising {
            init_frames = Some(i as u32 + 1);
        }
        let mut s = FrameScore {
            frame: i as u32,
            state: r.state.name().to_string(),
            ms: r.times.total() as f32 / 1000.0,
            stage_ms: Stage::ALL.map(|st| r.times.of(st) as f32 / 1000.0),
            occluded: t.torso_occluded_fraction,
            unseen: t.torso_unseen_fraction,
            ..FrameScore::default()
        };
        if r.fit.iterations > 0 {
            s.fit_rms_mm = Some(r.fit.association.rms_m() * 1000.0);
            s.fit_visible = Some(r.fit.visible);
            let a = &r.fit.association;
            s.fit_counts = Some([a.pairs, a.inliers, a.occluded, a.see_through, a.no_depth]);
        }
        if let Some(p) = r.fit_pose {
            let d = isometry_of(&t.camera_from_torso).inverse() * p;
            s.fit_pose_mm = Some(d.translation.vector.norm() * 1000.0);
            s.fit_pose_deg = Some(d.rotation.angle().to_degrees());
        }
        s.forest_point_mm = mean(
            r.forest_points
                .iter()
                .zip(&t.salient_camera)
                .filter_map(|(e, t)| e.map(|e| (e.position.coords - Vector3::from(*t)).norm() * 1000.0)),
        );
        if let (Some(pose), Some(surface), Some(tt)) = (r.camera_from_torso, tracker.surface(), full.as_ref())
        {
            if args.oracle_start && i.is_multiple_of(ORACLE_EVERY) {
                s.oracle_fit = oracle_fit(&tracker, &frame, &k, tt, &surface, &r, i as u32)?;
            }
            if surfaces.last().is_none_or(|v| v.as_slice() != surface.vertices()) {
                surfaces.push(surface.vertices().to_vec());
            }
            deferred.push(Deferred {
                index: scores.len(),
                surface: surfaces.len() - 1,
                pose,
                salient_camera: r.salient_camera,
                probe: r.probe,
            });
        } else if let (Some(pose), Some(surface)) = (r.camera_from_torso, tracker.surface()) {
            let truth = TruthFrame {
                surface: &true_surface,
                camera_from_torso: isometry_of(&t.camera_from_torso),
                salient_camera: t.salient_camera.map(Point3::from),
            };
            let tracked = TrackedFrame {
                surface: &surface,
                camera_from_torso: pose,
                salient_camera: r.salient_camera,
            };
            let tip = arm
                .as_ref()
                .map(|a| (&a.tip_robot_base, &cfg.robot_base_from_camera));
            let a = accuracy::score(&tracked, &truth, tip);
            s.torso_mm = Some(a.torso_m * 1000.0);
            s.point_mm = a.point_m.map(|e| e * 1000.0);
            s.probe_mm = a.probe_m.map(|e| e * 1000.0);
            s.probe_distance_mm = a.probe_distance_m.map(|e| e * 1000.0);
        }
        scores.push(s);
        i += 1;
    }
    if let Some(tt) = full.as_ref() {
        for d in &deferred {
            score_against_truth(tt, &surfaces[d.surface], d, &mut scores[d.index])?;
        }
    }
    let after_init = frames_after_init(&scores, init_frames);
    let tracked = after_init.iter().filter(|s| s.torso_mm.is_some()).count();
    let mut states = serde_json::Map::new();
    for s in &scores {
        let e = states.entry(s.state.clone()).or_insert(json!(0));
        *e = json!(e.as_u64().unwrap_or(0) + 1);
    }
    let mut ms: Vec<f32> = after_init.iter().map(|s| s.ms).collect();
    // Each stage's own percentiles over the same frames: where the frame's time goes (the per-stage latency).
    let stage_percentile = |q: f32| {
        let mut m = serde_json::Map::new();
        for (i, st) in Stage::ALL.iter().enumerate() {
            let mut v: Vec<f32> = after_init.iter().map(|s| s.stage_ms[i]).collect();
            m.insert(st.name().to_string(), json!(percentile(&mut v, q)));
        }
        Value::Object(m)
    };
    let occlusion = full.as_ref().and_then(|f| f.episodes().full_occlusion.as_ref());
    let recovery = occlusion.map(|o| recovery_frames(o.end, &scores));
    let held = occlusion.map(|o| tracked_before(o, &scores));
    let motion = full
        .as_ref()
        .and_then(|f| f.episodes().motion.as_ref())
        .map(|m| motion_score(m, &scores));
    let sweep_unseen = sweep_unseen_max(&scores, occlusion);
    let c = tracker.counters();
    let summary = json!({
        "frames": scores.len(),
        "init_frames": init_frames,
        "tracked_fraction": if after_init.is_empty() { 0.0 } else { tracked as f32 / after_init.len() as f32 },
        "torso_surface_error_mm_mean": mean(scores.iter().filter_map(|s| s.torso_mm)),
        "torso_floor_mm_mean": mean(scores.iter().filter_map(|s| s.torso_floor_mm)),
        "point_error_mm_mean": mean(scores.iter().filter_map(|s| s.point_mm)),
        "probe_error_mm_mean": mean(scores.iter().filter_map(|s| s.probe_mm)),
        "probe_distance_error_mm_mean": mean(scores.iter().filter_map(|s| s.probe_distance_mm)),
        // Where the mapping steers the probe: the tip within CONTACT_MM of the skin. Farther out the nearest point
        // jumps between chest, neck and arm for millimetres of shape.
        "probe_error_mm_mean_contact": mean(scores.iter().filter_map(|s| {
            s.probe_true_distance_mm.filter(|d| d.abs() <= CONTACT_MM).and(s.probe_mm)
        })),
        "recovery_frames": recovery,
        // Whether the track was within the recovery's 20 mm as the arm began its approach: a track already off
        // has nothing to recover to, and its recovery counts a different failure.
        "tracked_before_occlusion": held,
        "motion": motion,
        // The condition on the sequence: the most of the torso the sensor loses on a frame of the arm's
        // sweep (the full occlusion's approach, park and way back left out); null without the per-frame truth.
        "torso_unseen_max_sweep": sweep_unseen,
        "states": states,
        "latency_ms_p50": percentile(&mut ms, 0.5),
        "latency_ms_p99": percentile(&mut ms, 0.99),
        "stage_ms_p50": stage_percentile(0.5),
        "stage_ms_p99": stage_percentile(0.99),
        "budget_overruns": c.overruns,
        "icp_cuts": c.icp_cuts,
        // The init phase's shape (σ units) beside the truth: the largest term of the torso error.
        "shape_estimate": tracker.shape().map(|z| z.to_vec()),
        "shape_true": &seq.meta.shape,
        // The raised head section the init phase found (degrees from the mattress; null when none): acquisition
        // depends on it where the bed is raised.
        "head_section_deg": tracker.bed().and_then(|b| b
            .head_section
            .map(|h| h.normal().angle(&b.mattress.normal()).to_degrees())),
    });
    Ok((scores, summary))
}

/// The frames after the init phase (`init_frames` long; none when it never ended): what the sequence's figures
/// count.
fn frames_after_init(scores: &[FrameScore], init_frames: Option<u32>) -> &[FrameScore] {
    &scores[init_frames.map_or(scores.len(), |n| (n as usize).min(scores.len()))..]
}

/// The largest share of the torso the sensor loses on a frame outside `occlusion`'s approach, park and way back (the
/// whole sequence without one); `None` when a frame's truth lacks it (sequences generated before 2026-12-06).
fn sweep_unseen_max(scores: &[FrameScore], occlusion: Option<&FullOcclusion>) -> Option<f32> {
    scores
        .iter()
        .filter(|s| occlusion.is_none_or(|o| s.frame < o.approach_start || s.frame >= o.leave_end))
        .try_fold(0.0f32, |m, s| s.unseen.map(|u| m.max(u)))
}

/// [`combine`] over the sequences whose sweep stayed within [`SWEEP_MAX_OCCLUDED`] (`within`) or went beyond it, by
/// their `torso_unseen_max_sweep` (sequences without it in neither), with their count as `sequences`; `None` when
/// there are none. `frame_ms` holds each sequence's frame times, in `summaries`' order.
fn sweep_split(summaries: &[Value], frame_ms: &[Vec<f32>], within: bool) -> Option<Value> {
    let (picked, ms): (Vec<Value>, Vec<Vec<f32>>) = summaries
        .iter()
        .zip(frame_ms)
        .filter(|(s, _)| {
            s["torso_unseen_max_sweep"]
                .as_f64()
                .is_some_and(|u| (u <= f64::from(SWEEP_MAX_OCCLUDED)) == within)
        })
        .map(|(s, m)| (s.clone(), m.clone()))
        .unzip();
    if picked.is_empty() {
        return None;
    }
    let mut c = combine(&picked, &mut ms.concat());
    c["sequences"] = json!(picked.len());
    Some(c)
}

/// A tracked frame waiting for [`score_against_truth`]: where its score is, and what the tracker reported.
struct Deferred {
    /// Index into the sequence's scores (= the frame index).
    index: usize,
    /// Index of the torso surface the frame was tracked with.
    surface: usize,
    /// The tracked torso pose.
    pose: Isometry3,
    /// The tracked salient points.
    salient_camera: Option<[Point3; SalientPoint::COUNT]>,
    /// The probe mapping.
    probe: Option<ProbeMapping>,
}

/// Score frame `d` (tracked with torso vertices `surface`) against the sequence's full truth `tt` into `s`.
fn score_against_truth(
    tt: &TrackingTruth,
    surface: &[Point3],
    d: &Deferred,
    s: &mut FrameScore,
) -> Result<()> {
    let f = s.frame;
    s.torso_mm = Some(tt.torso_error_at_mm(surface, &d.pose, f)?);
    s.torso_floor_mm = tt.rigid_floor_mm(surface, f)?;
    if let Some(p) = d.salient_camera {
        s.point_mm = Some(tt.point_error_mm(&p.map(|q| q.coords.into()), f)?.mean_mm);
    }
    if let Some(m) = d.probe
        && let Some(e) = tt.probe_error_of_mapping(&m, &d.pose, f)?
    {
        s.probe_mm = Some(e.position_mm);
        s.probe_distance_mm = Some(e.signed_distance_mm);
        s.probe_true_distance_mm = Some(e.true_distance_mm);
    }
    Ok(())
}

/// The [`OracleFit`] of frame `f`, when the tracker has a bed and the truth a torso of the model's size.
fn oracle_fit(
    tracker: &Tracker<'_, '_>,
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    tt: &TrackingTruth,
    surface: &TorsoSurface<'_>,
    r: &FrameReport,
    f: u32,
) -> Result<Option<OracleFit>> {
    let (Some(best), Some(bed)) = (tt.rigid_best(surface.vertices(), f)?, tracker.bed()) else {
        return Ok(None);
    };
    let cfg = tracker.config();
    let clock = MonotonicClock;
    let (pose, fit) = torso_icp::fit_torso(
        frame,
        k,
        surface.vertices(),
        surface.normals(),
        best,
        &cfg.icp,
        &torso_icp::icp_params(&cfg.icp, bed),
        &cfg.budget,
        cfg.icp.acquire_min_iterations,
        &clock,
        &Stopwatch::start(&clock),
    );
    Ok(Some(OracleFit {
        support: fit.support(),
        own_support: r.fit.support(),
        rms_mm: fit.association.rms_m() * 1000.0,
        pairs: fit.association.pairs,
        visible: fit.visible,
        torso_mm: tt.torso_error_at_mm(surface.vertices(), &pose, f)?,
    }))
}

/// The torso surface error under which a frame counts as tracked again after the full occlusion, mm.
const RECOVERED_MM: f32 = 20.0;

/// Whether at least half of the [`MOTION_WINDOW`] frames before the arm's approach to the full occlusion had a pose
/// within [`RECOVERED_MM`].
fn tracked_before(o: &FullOcclusion, scores: &[FrameScore]) -> bool {
    let (within, n) = scores
        .iter()
        .take(o.approach_start as usize)
        .skip(o.approach_start.saturating_sub(MOTION_WINDOW) as usize)
        .fold((0, 0), |(within, n), s| {
            (
                within + usize::from(s.torso_mm.is_some_and(|e| e < RECOVERED_MM)),
                n + 1,
            )
        });
    n > 0 && 2 * within >= n
}

/// Frames from the end of the full-occlusion episode (the first unparked frame) to the first frame tracked again
/// (a state with a pose and a torso surface error under 20 mm); the frames left when it never recovers.
fn recovery_frames(end: u32, scores: &[FrameScore]) -> u32 {
    scores
        .iter()
        .skip(end as usize)
        .position(|s| s.torso_mm.is_some_and(|e| e < RECOVERED_MM))
        .map(|p| p as u32)
        .unwrap_or(scores.len().saturating_sub(end as usize) as u32)
}

fn variants(names: &[String]) -> Result<Vec<Variant>> {
    if names.is_empty() {
        return Ok(Variant::ALL.to_vec());
    }
    names
        .iter()
        .map(|n| {
            Variant::ALL
                .into_iter()
                .find(|v| v.name() == n)
                .with_context(|| format!("unknown variant `{n}` (forest, forest_icp, forest_icp_feedback)"))
        })
        .collect()
}

/// Frames before the patient's motion begins, and after it ends, whose torso errors [`motion_score`] compares (a
/// third of a second at 30 Hz).
pub const MOTION_WINDOW: u32 = 10;
/// The tracker followed a motion when the torso error after it is at most this much above the error before it, mm.
pub const MOTION_FOLLOWED_MM: f32 = 10.0;

/// The torso error's median over the [`MOTION_WINDOW`] frames with a pose before motion `m` begins and after it
/// ends, and whether the tracker followed it (null when it had no pose before: nothing to follow; false when it has
/// none after).
fn motion_score(m: &Motion, scores: &[FrameScore]) -> Value {
    let median = |from: u32, to: u32| {
        let mut v: Vec<f32> = scores
            .iter()
            .take(to as usize)
            .skip(from as usize)
            .filter_map(|s| s.torso_mm)
            .collect();
        percentile(&mut v, 0.5)
    };
    let before = median(m.start.saturating_sub(MOTION_WINDOW), m.start);
    let after = median(m.end, m.end + MOTION_WINDOW);
    let followed = before.map(|b| after.is_some_and(|a| a <= b + MOTION_FOLLOWED_MM));
    json!({
        "kind": m.kind,
        "torso_mm_before": before,
        "torso_mm_after": after,
        "followed": followed,
    })
}

/// Per motion kind, how many sequences' motions the tracker followed of those it had a pose before (`null`s left
/// out): `{"roll": {"followed": n, "of": m}, "shift": ...}`.
fn motions_followed(summaries: &[Value]) -> Value {
    let per_kind = MotionKind::value_variants().iter().map(|kind| {
        // The kind as the per-sequence `motion` names it.
        let name = json!(kind);
        let verdicts: Vec<bool> = summaries
            .iter()
            .filter(|s| s["motion"]["kind"] == name)
            .filter_map(|s| s["motion"]["followed"].as_bool())
            .collect();
        let counts = json!({"followed": verdicts.iter().filter(|&&f| f).count(), "of": verdicts.len()});
        (name.as_str().unwrap_or_default().to_string(), counts)
    });
    Value::Object(per_kind.collect())
}

/// The recovery target: tracked again within this many frames after the full occlusion.
const RECOVERY_TARGET_FRAMES: u32 = 5;

/// Average the per-sequence summaries of one variant (frame-weighted for rates, mean for errors); `frame_ms` holds
/// the processing time of every frame after the init phase of all its sequences, for the pooled percentiles.
fn combine(summaries: &[Value], frame_ms: &mut [f32]) -> Value {
    // `k` is a path: "latency_ms_p50", "stage_ms_p50/icp".
    let at = |s: &Value, k: &str| {
        s.pointer(&format!("/{k}"))
            .and_then(Value::as_f64)
            .map(|x| x as f32)
    };
    let num = |k: &str| -> Option<f32> { mean(summaries.iter().filter_map(|s| at(s, k))) };
    let max = |k: &str| -> Option<f32> { summaries.iter().filter_map(|s| at(s, k)).reduce(f32::max) };
    // Per stage as the totals: the mean of the sequences' p50s, the largest p99.
    let per_stage = |k: &str, f: &dyn Fn(&str) -> Option<f32>| {
        let mut m = serde_json::Map::new();
        for st in Stage::ALL {
            let key = format!("{k}/{}", st.name());
            m.insert(st.name().to_string(), json!(f(&key)));
        }
        Value::Object(m)
    };
    let recoveries: Vec<u64> = summaries
        .iter()
        .filter_map(|s| s["recovery_frames"].as_u64())
        .collect();
    let held_recoveries: Vec<u64> = summaries
        .iter()
        .filter(|s| s["tracked_before_occlusion"] == json!(true))
        .filter_map(|s| s["recovery_frames"].as_u64())
        .collect();
    let within_target = |r: &[u64]| r.iter().filter(|&&r| r <= RECOVERY_TARGET_FRAMES as u64).count();
    let mut states = serde_json::Map::new();
    for s in summaries {
        if let Some(m) = s["states"].as_object() {
            for (k, v) in m {
                let e = states.entry(k.clone()).or_insert(json!(0));
                *e = json!(e.as_u64().unwrap_or(0) + v.as_u64().unwrap_or(0));
            }
        }
    }
    json!({
        "frames": summaries.iter().map(|s| s["frames"].as_u64().unwrap_or(0)).sum::<u64>(),
        "tracked_fraction": num("tracked_fraction"),
        "torso_surface_error_mm_mean": num("torso_surface_error_mm_mean"),
        "torso_floor_mm_mean": num("torso_floor_mm_mean"),
        "point_error_mm_mean": num("point_error_mm_mean"),
        "probe_error_mm_mean": num("probe_error_mm_mean"),
        "probe_distance_error_mm_mean": num("probe_distance_error_mm_mean"),
        "probe_error_mm_mean_contact": num("probe_error_mm_mean_contact"),
        "recovery_frames": max("recovery_frames"),
        // How many of the sequences with a full occlusion met the recovery target, and how many had one.
        "recovered_within_target": within_target(&recoveries),
        "full_occlusions": recoveries.len(),
        // The same of the sequences tracked within 20 mm as the arm began its approach (`tracked_before_occlusion`).
        "recovered_within_target_tracked_before": within_target(&held_recoveries),
        "full_occlusions_tracked_before": held_recoveries.len(),
        "motions_followed": motions_followed(summaries),
        "states": states,
        "latency_ms_p50": num("latency_ms_p50"),
        "latency_ms_p99": max("latency_ms_p99"),
        // Over every frame after the init phase of all sequences together (the per-sequence figures above are the
        // mean of the sequences' p50s and the largest p99).
        "latency_ms_p50_pooled": percentile(frame_ms, 0.5),
        "latency_ms_p99_pooled": percentile(frame_ms, 0.99),
        "stage_ms_p50": per_stage("stage_ms_p50", &num),
        "stage_ms_p99": per_stage("stage_ms_p99", &max),
        "budget_overruns": summaries.iter().map(|s| s["budget_overruns"].as_u64().unwrap_or(0)).sum::<u64>(),
    })
}

/// Run the command.
pub fn run(args: &TrackingEvalArgs) -> ExitCode {
    match evaluate(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

fn evaluate(args: &TrackingEvalArgs) -> Result<()> {
    let dirs = sequence_dirs(&args.data)?;
    let incomplete = incomplete_sequence_dirs(&args.data);
    for d in &incomplete {
        eprintln!(
            "warning: {} left out: frames without a sequence.json (a generation that did not finish)",
            d.display()
        );
    }
    let wanted = variants(&args.variants)?;
    let model_dir = args
        .models
        .clone()
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("artifacts"));
    let bytes = ModelFiles::load(&model_dir)?;
    let models = bytes.views()?;
    // Per variant: the sequences' summaries and every frame's processing time after the init phase.
    let mut per_variant: Vec<(Variant, Vec<Value>, Vec<Vec<f32>>)> =
        wanted.iter().map(|v| (*v, Vec::new(), Vec::new())).collect();
    let mut sequences = Vec::new();
    for dir in &dirs {
        let seq = SequenceData::load(dir)?;
        let truth_torso = OwnedTorso::new(&models.body, &seq.meta.shape)?;
        let mut per_seq = serde_json::Map::new();
        let mut plots = Vec::new();
        for (variant, acc, frame_ms) in per_variant.iter_mut() {
            let (scores, summary) = run_variant(&models, &seq, *variant, &truth_torso, args)?;
            eprintln!(
                "{}  {:<20} tracked {:.3}  torso {:>6.1} mm (rigid floor {:.1})  points {:>6.1} mm  probe {:>6.1} mm  \
                 p50 {:.2} ms",
                dir.file_name().unwrap_or_default().to_string_lossy(),
                variant.name(),
                summary["tracked_fraction"].as_f64().unwrap_or(0.0),
                summary["torso_surface_error_mm_mean"]
                    .as_f64()
                    .unwrap_or(f64::NAN),
                summary["torso_floor_mm_mean"].as_f64().unwrap_or(f64::NAN),
                summary["point_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
                summary["probe_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
                summary["latency_ms_p50"].as_f64().unwrap_or(f64::NAN),
            );
            let mut with_frames = summary.clone();
            with_frames["per_frame"] = json!(scores);
            per_seq.insert(variant.name().to_string(), with_frames);
            let init_frames = summary["init_frames"].as_u64().map(|n| n as u32);
            frame_ms.push(
                frames_after_init(&scores, init_frames)
                    .iter()
                    .map(|s| s.ms)
                    .collect(),
            );
            acc.push(summary);
            plots.push((*variant, scores));
        }
        if let Some(png) = &args.png {
            std::fs::create_dir_all(png).with_context(|| format!("creating {}", png.display()))?;
            let name = dir.file_name().unwrap_or_default().to_string_lossy().to_string();
            let path = png.join(format!("tracking-{name}.png"));
            super::tracking_plot::write_png(&path, &name, &plots)?;
        }
        sequences.push(json!({"sequence": dir.display().to_string(), "variants": per_seq}));
    }
    let mut report = serde_json::Map::new();
    for (variant, acc, frame_ms) in &per_variant {
        let mut r = combine(acc, &mut frame_ms.concat());
        // The targets are stated for sweeps over up to half the torso: the sequences that stayed within it
        // on every frame of the sweep (by the truth's per-frame loss) and those that did not, apart.
        for (key, within) in [("sweep_within_half", true), ("sweep_beyond_half", false)] {
            if let Some(c) = sweep_split(acc, frame_ms, within) {
                r[key] = c;
            }
        }
        report.insert(variant.name().to_string(), r);
    }
    report.insert("sequences".into(), json!(sequences));
    // What --data held that was not evaluated, so a count short of the folder's says why.
    report.insert(
        "incomplete_sequences".into(),
        json!(
            incomplete
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
        ),
    );
    report.insert("commit".into(), json!(crate::provenance::commit()));
    let report = Value::Object(report);
    for (variant, _, _) in &per_variant {
        let r = &report[variant.name()];
        println!(
            "{:<20} tracked {:.3}  torso {:>6.1} mm (rigid floor {:.1} mm)  points {:>6.1} mm  probe {:>6.1} mm \
             ({:.1} mm distance, {:.1} mm in contact range)  recovery <= {} frames on {} of {} \
             ({} of the {} tracked before it)  frames p50 {:.2} ms  p99 {:.2} ms",
            variant.name(),
            r["tracked_fraction"].as_f64().unwrap_or(0.0),
            r["torso_surface_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
            r["torso_floor_mm_mean"].as_f64().unwrap_or(f64::NAN),
            r["point_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
            r["probe_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
            r["probe_distance_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
            r["probe_error_mm_mean_contact"].as_f64().unwrap_or(f64::NAN),
            RECOVERY_TARGET_FRAMES,
            r["recovered_within_target"],
            r["full_occlusions"],
            r["recovered_within_target_tracked_before"],
            r["full_occlusions_tracked_before"],
            r["latency_ms_p50_pooled"].as_f64().unwrap_or(f64::NAN),
            r["latency_ms_p99_pooled"].as_f64().unwrap_or(f64::NAN),
        );
        let stages: Vec<String> = Stage::ALL
            .iter()
            .map(|st| {
                let ms = |k: &str| r[k][st.name()].as_f64().unwrap_or(f64::NAN);
                format!(
                    "{} {:.2} / {:.2}",
                    st.name(),
                    ms("stage_ms_p50"),
                    ms("stage_ms_p99")
                )
            })
            .collect();
        println!("{:<20} stage ms p50 / p99: {}", "", stages.join(", "));
        for (key, what) in [("sweep_within_half", "within"), ("sweep_beyond_half", "beyond")] {
            let w = &r[key];
            if w.is_object() {
                println!(
                    "{:<20} sweep {what} half the torso: {} sequences, tracked {:.3}  torso {:.1} mm  probe {:.1} mm  \
                     recovery <= {} frames on {} of {}",
                    "",
                    w["sequences"],
                    w["tracked_fraction"].as_f64().unwrap_or(0.0),
                    w["torso_surface_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
                    w["probe_error_mm_mean"].as_f64().unwrap_or(f64::NAN),
                    RECOVERY_TARGET_FRAMES,
                    w["recovered_within_target"],
                    w["full_occlusions"],
                );
            }
        }
        let m = &r["motions_followed"];
        println!(
            "{:<20} motion followed (torso error up by at most {} mm, medians of {} frames): roll {} of {}, shift {} of {}",
            "",
            MOTION_FOLLOWED_MM,
            MOTION_WINDOW,
            m["roll"]["followed"],
            m["roll"]["of"],
            m["shift"]["followed"],
            m["shift"]["of"]
        );
    }
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_vec_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_errors(errors: &[Option<f32>]) -> Vec<FrameScore> {
        errors
            .iter()
            .enumerate()
            .map(|(i, e)| FrameScore {
                frame: i as u32,
                torso_mm: *e,
                ..FrameScore::default()
            })
            .collect()
    }

    #[test]
    fn the_sweeps_loss_leaves_out_the_full_occlusion_and_needs_every_frames_truth() {
        let scores: Vec<FrameScore> = [0.1, 0.45, 0.2, 0.9, 1.0, 0.8, 0.3, 0.5, 0.05]
            .iter()
            .enumerate()
            .map(|(i, &u)| FrameScore {
                frame: i as u32,
                unseen: Some(u),
                ..FrameScore::default()
            })
            .collect();
        let park = FullOcclusion {
            start: 4,
            end: 5,
            approach_start: 3,
            leave_end: 6,
            park_distance_m: 0.5,
            planned_torso_occluded_fraction: 0.95,
            torso_occluded_fraction_min: 0.95,
        };
        assert_eq!(sweep_unseen_max(&scores, Some(&park)), Some(0.5));
        assert_eq!(sweep_unseen_max(&scores, None), Some(1.0));
        let mut old = scores.clone();
        old[7].unseen = None;
        assert_eq!(
            sweep_unseen_max(&old, Some(&park)),
            None,
            "a frame without the truth's loss"
        );
        // The split: one sequence within half, one beyond, one without the figure (in neither).
        let summary = |u: Value, tracked: f32| json!({"torso_unseen_max_sweep": u, "tracked_fraction": tracked, "frames": 10});
        let sums = [
            summary(json!(0.5), 1.0),
            summary(json!(0.7), 0.5),
            summary(Value::Null, 0.0),
        ];
        let ms = [vec![1.0f32, 2.0], vec![3.0], vec![4.0]];
        let within = sweep_split(&sums, &ms, true).unwrap();
        assert_eq!(
            (within["sequences"].as_u64(), within["tracked_fraction"].as_f64()),
            (Some(1), Some(1.0))
        );
        assert_eq!(
            within["latency_ms_p99_pooled"].as_f64(),
            Some(2.0),
            "its own frames only"
        );
        let beyond = sweep_split(&sums, &ms, false).unwrap();
        assert_eq!(
            (beyond["sequences"].as_u64(), beyond["tracked_fraction"].as_f64()),
            (Some(1), Some(0.5))
        );
        assert!(sweep_split(&sums[2..], &ms[2..], true).is_none());
    }

    fn roll(start: u32, end: u32) -> Motion {
        Motion {
            kind: MotionKind::Roll,
            start,
            end,
            roll_deg: 18.0,
            shift_m: [0.0; 2],
            pivot_bed: [0.0; 3],
        }
    }

    #[test]
    fn a_motion_is_followed_when_the_error_after_it_stays_within_the_margin_of_the_error_before() {
        // 5 mm before frame 20; errors during the motion do not count; after frame 30: 12 mm (within 10 mm of 5),
        // then 16 mm (not), then no pose at all.
        let mut e = vec![Some(5.0); 20];
        e.extend([Some(90.0); 10]);
        let after = |x: Option<f32>| {
            let mut v = e.clone();
            v.extend([x; 10]);
            motion_score(&roll(20, 30), &with_errors(&v))
        };
        let ok = after(Some(12.0));
        assert_eq!(ok["kind"], "roll");
        assert_eq!(ok["torso_mm_before"], 5.0);
        assert_eq!(ok["torso_mm_after"], 12.0);
        assert_eq!(ok["followed"], true);
        assert_eq!(after(Some(16.0))["followed"], false);
        let lost = after(None);
        assert!(lost["torso_mm_after"].is_null());
        assert_eq!(lost["followed"], false);
        // Without a pose before the motion there is nothing to follow: left out of the counts.
        let mut v = vec![None; 30];
        v.extend([Some(5.0); 10]);
        let untracked = motion_score(&roll(20, 30), &with_errors(&v));
        assert!(untracked["followed"].is_null());
        let summaries: Vec<Value> = [ok, after(Some(16.0)), untracked]
            .into_iter()
            .map(|m| json!({ "motion": m }))
            .chain([json!({ "motion": null })])
            .collect();
        let counts = motions_followed(&summaries);
        assert_eq!(counts["roll"], json!({"followed": 1, "of": 2}));
        assert_eq!(counts["shift"], json!({"followed": 0, "of": 0}));
    }

    #[test]
    fn a_recovery_is_counted_apart_for_the_tracks_within_20_mm_as_the_approach_began() {
        let park = FullOcclusion {
            start: 30,
            end: 40,
            approach_start: 20,
            leave_end: 45,
            park_distance_m: 0.7,
            planned_torso_occluded_fraction: 0.95,
            torso_occluded_fraction_min: 0.95,
        };
        // The ten frames before the approach: half of them within 20 mm is tracked, fewer is not; frames without
        // a pose count as off.
        let before = |within: usize| {
            let mut e = vec![Some(50.0); 10];
            for x in e.iter_mut().take(within) {
                *x = Some(5.0);
            }
            e[9] = if within == 10 { Some(5.0) } else { None };
            let mut v = vec![Some(5.0); 10];
            v.extend(e);
            v.extend([Some(5.0); 30]);
            tracked_before(&park, &with_errors(&v))
        };
        assert!(before(10));
        assert!(before(5));
        assert!(!before(4));
        assert!(!before(0));
        // Pooled: of two recoveries within the target one was tracked before; the one that was not, and a late one
        // that was, count in their own totals.
        let seq = |rec: u64, held: bool| json!({"recovery_frames": rec, "tracked_before_occlusion": held, "frames": 1});
        let c = combine(&[seq(0, true), seq(2, false), seq(9, true)], &mut [1.0]);
        assert_eq!(
            (
                c["recovered_within_target"].as_u64(),
                c["full_occlusions"].as_u64()
            ),
            (Some(2), Some(3))
        );
        assert_eq!(
            (
                c["recovered_within_target_tracked_before"].as_u64(),
                c["full_occlusions_tracked_before"].as_u64()
            ),
            (Some(1), Some(2))
        );
    }
}
