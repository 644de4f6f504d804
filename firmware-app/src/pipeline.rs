//! The tracking pipeline on a host: depth source → `supine_core::tracker` → packets to a link, with figures
//! (latency, states, accuracy against a truth file) collected as it runs. `supine demo` and `supine replay` play a
//! recording through [`play`]; `supine run` drives the same tracker from its service loop.
//!
//! The tracker's model files are read and validated once and its scratch allocated once before the first frame
//! (`supine_drivers::tracker_host`); per frame the tracker allocates nothing. The figures here (a latency per frame,
//! a score per frame) are host-side bookkeeping, outside the tracker's frame budget.

use crate::allocs;
use std::collections::BTreeMap;
use std::time::Duration;

use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::{Isometry3, Vector3};
use supine_core::torso::TorsoSurface;
use supine_core::tracker::accuracy::{self, TrackedFrame};
use supine_core::tracker::{FrameReport, ScratchSizes, Tracker, TrackerConfig};
use supine_core::wire::{Message, TrackerState};
use supine_drivers::clock::MonotonicClock;
use supine_drivers::link::Link;
use supine_drivers::source::{DepthSource, SourceErrorKind};
use supine_drivers::tracker_host::{ModelFiles, OwnedTorso, TrackerScratch};

use crate::arm_track::{self, ArmTrack};
use crate::truth::Truth;
use supine_core::rng::SplitMix64;

/// The tracker settings for a camera whose pose in `robot_base` is `robot_base_from_camera` (up is `robot_base`'s
/// +z, which the bed search uses).
pub fn tracker_config(robot_base_from_camera: Isometry3) -> TrackerConfig {
    TrackerConfig {
        robot_base_from_camera,
        up_camera: Some(robot_base_from_camera.inverse().rotation * Vector3::z()),
        ..TrackerConfig::default()
    }
}

/// Figures of one run.
#[derive(Debug, Default, Clone)]
pub struct RunStats {
    /// Frames processed.
    pub frames: u32,
    /// Frames the init phase took (until the state left initialising).
    pub init_frames: Option<u32>,
    /// Frames after init whose state carries a pose.
    pub tracked_after_init: u32,
    /// Processing time per frame, µs.
    pub latency_us: Vec<u32>,
    /// Frames per state name.
    pub states: BTreeMap<&'static str, u32>,
    /// Per-frame torso surface error, mm (frames with a pose and a truth).
    pub torso_mm: Vec<f32>,
    /// Per-frame salient-point error, mm.
    pub point_mm: Vec<f32>,
    /// Per-frame probe nearest-point error, mm.
    pub probe_mm: Vec<f32>,
    /// Per-frame probe signed-distance error, mm.
    pub probe_distance_mm: Vec<f32>,
    /// Packets produced.
    pub packets: u64,
    /// Bytes they take on a serial line.
    pub serial_bytes: u64,
    /// Packets the link refused.
    pub send_errors: u64,
    /// Budget overruns the tracker counted.
    pub budget_overruns: u32,
    /// Frames the source could not decode (skipped, as the service does).
    pub corrupt: u64,
    /// Heap allocations made while the tracker processed the frames after init (`None`: not counted).
    pub tracker_allocations_after_init: Option<u64>,
}

impl RunStats {
    /// The allocation figure for the summary tables of `demo` and `replay`.
    pub fn allocations_summary(&self) -> String {
        match self.tracker_allocations_after_init {
            Some(n) => format!(
                "{n} in the tracker over {} frames",
                self.frames
                    .saturating_sub(self.init_frames.map_or(self.frames, |i| i + 1))
            ),
            None => "not counted (--record/--view threads allocate beside the tracker)".to_string(),
        }
    }
}

/// Mean of a list, NaN when empty.
pub fn mean(v: &[f32]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64
    }
}

/// Percentile (0..=100) of a list by nearest rank, NaN when empty.
pub fn percentile(v: &[u32], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_unstable();
    s[(((p / 100.0) * (s.len() - 1) as f64).round() as usize).min(s.len() - 1)] as f64
}

impl RunStats {
    /// Fraction of frames after init that carried a pose (NaN before init ends).
    pub fn tracked_fraction(&self) -> f64 {
        match self.init_frames {
            Some(i) if self.frames > i => self.tracked_after_init as f64 / (self.frames - i) as f64,
            _ => f64::NAN,
        }
    }

    /// The states seen, as `name frames` pairs.
    pub fn states_line(&self) -> String {
        self.states
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The JSON report (keys of cli.md's `replay --json`).
    pub fn json(&self) -> serde_json::Value {
        let num = |x: f64| {
            if x.is_finite() {
                serde_json::json!(x)
            } else {
                serde_json::Value::Null
            }
        };
        serde_json::json!({
            "frames": self.frames,
            "init_frames": self.init_frames,
            "tracked_fraction": num(self.tracked_fraction()),
            "torso_surface_error_mm_mean": num(mean(&self.torso_mm)),
            "point_error_mm_mean": num(mean(&self.point_mm)),
            "probe_error_mm_mean": num(mean(&self.probe_mm)),
            "probe_distance_error_mm_mean": num(mean(&self.probe_distance_mm)),
            "recovery_frames": serde_json::Value::Null,
            "states": self.states,
            "latency_ms_p50": num(percentile(&self.latency_us, 50.0) / 1000.0),
            "latency_ms_p99": num(percentile(&self.latency_us, 99.0) / 1000.0),
            "budget_overruns": self.budget_overruns,
            "tracker_allocations_after_init": self.tracker_allocations_after_init,
            "corrupt_frames": self.corrupt,
            "packets": self.packets,
            "send_errors": self.send_errors,
        })
    }
}

/// How [`play`] runs.
pub struct PlayOptions<'a> {
    /// Stop after this many frames.
    pub limit: u32,
    /// Truth to score against (and to synthesise arm states from when there is no `arm` track).
    pub truth: Option<&'a Truth>,
    /// Arm states from a capture file (`replay --arm`); they replace the ones synthesised from the truth.
    pub arm: Option<&'a ArmTrack>,
    /// The tracker settings.
    pub tracker: TrackerConfig,
    /// Play at the recorded rate (capture timestamps) instead of as fast as possible.
    pub realtime: bool,
    /// Skip frames the source cannot decode (replay of a damaged file) instead of failing the run (the demo).
    pub skip_corrupt: bool,
    /// Count the heap allocations made while the tracker runs (the allocator's counters are process-wide, so this
    /// is off when other threads, the MCAP recorder or the live view, allocate beside it).
    pub count_allocations: bool,
}

impl<'a> PlayOptions<'a> {
    /// Play up to `limit` frames as fast as possible, failing on a corrupt frame; the tracker is calibrated by the
    /// truth's extrinsic when there is one (identity otherwise).
    pub fn new(limit: u32, truth: Option<&'a Truth>) -> Self {
        let rb = truth
            .map(|t| t.robot_base_from_camera)
            .unwrap_or_else(Isometry3::identity);
        PlayOptions {
            limit,
            truth,
            arm: None,
            tracker: tracker_config(rb),
            realtime: false,
            skip_corrupt: false,
            count_allocations: true,
        }
    }
}

/// What [`play`] hands each frame's observer.
pub struct FrameView<'a, 'r> {
    /// The frame.
    pub frame: &'a DepthFrame<'a>,
    /// The tracker's report.
    pub report: &'r FrameReport,
    /// The shaped torso model (torso frame) once the init phase is done.
    pub surface: Option<TorsoSurface<'r>>,
}

/// Why [`play`] stopped early.
#[derive(Debug)]
pub enum PlayError {
    /// The source failed (other than at its end).
    Source(String),
    /// The models or scratch did not fit.
    Setup(String),
}

impl std::fmt::Display for PlayError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlayError::Source(e) | PlayError::Setup(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for PlayError {}

/// Play `src` through the tracker: packets to `sink` (when given), `observe` called per frame; returns the figures.
pub fn play(
    src: &mut dyn DepthSource,
    files: &ModelFiles,
    opts: &PlayOptions<'_>,
    mut sink: Option<&mut (dyn Link + '_)>,
    mut observe: impl FnMut(&FrameView<'_, '_>, &RunStats),
) -> Result<RunStats, PlayError> {
    let models = files
        .views()
        .map_err(|e| PlayError::Setup(format!("model files: {e}")))?;
    let k: Intrinsics = src.intrinsics();
    let mut store = TrackerScratch::new(&ScratchSizes::of(&models, &k, &opts.tracker.planes));
    let mut tracker = Tracker::new(models, k, opts.tracker, store.scratch())
        .map_err(|e| PlayError::Setup(e.to_string()))?;
    let true_torso = match opts.truth {
        Some(t) => {
            Some(OwnedTorso::new(&models.body, &t.shape).map_err(|e| PlayError::Setup(e.to_string()))?)
        }
        None => None,
    };
    let true_surface = true_torso.as_ref().and_then(|t| t.surface(&models.body));
    let clock = MonotonicClock;
    let mut stats = RunStats::default();
    let mut buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
    let started = std::time::Instant::now();
    let mut first_capture = None;
    let mut arm_noise = SplitMix64(arm_track::SYNTH_SEED);
    while stats.frames < opts.limit {
        let frame = match src.next_frame(Duration::from_millis(500)) {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e)
                if opts.skip_corrupt
                    && matches!(
                        e.kind(),
                        SourceErrorKind::CorruptData | SourceErrorKind::Unsupported
                    ) =>
            {
                stats.corrupt += 1;
                tracing::warn!("skipping a frame: {e}");
                // A damaged file that repeats its error without moving on: bound it.
                if stats.corrupt > 1000 && stats.frames == 0 {
                    return Err(PlayError::Source(format!(
                        "{}: no readable frame in the first 1000",
                        src.describe()
                    )));
                }
                continue;
            }
            Err(e) => return Err(PlayError::Source(format!("reading {}: {e}", src.describe()))),
        };
        if opts.realtime {
            let first = *first_capture.get_or_insert(frame.capture);
            let due = Duration::from_micros(frame.capture.since(first).max(0) as u64);
            if let Some(wait) = due.checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        let i = stats.frames as usize;
        // The probe errors are measured against the true probe; the tracker gets what an arm would report.
        let true_arm = opts.truth.and_then(|t| arm_track::from_truth(t, i, &frame));
        let arm = match opts.arm {
            Some(track) => track.at(frame.capture).copied(),
            None => true_arm.map(|a| arm_track::synthesise(&a, &mut arm_noise)),
        };
        let allocs_before = allocs::count();
        let report = tracker.process(&frame, arm.as_ref(), &clock);
        let allocated = allocs::count() - allocs_before;
        stats.frames += 1;
        stats.latency_us.push(report.times.total());
        *stats.states.entry(report.state.name()).or_insert(0) += 1;
        if stats.init_frames.is_none() && report.state != TrackerState::Initialising {
            stats.init_frames = Some(stats.frames - 1);
        }
        if stats.init_frames.is_some() && report.camera_from_torso.is_some() {
            stats.tracked_after_init += 1;
        }
        if opts.count_allocations && stats.init_frames.is_some_and(|n| stats.frames > n + 1) {
            // After the frame that ended init (which builds the torso model into buffers allocated before).
            *stats.tracker_allocations_after_init.get_or_insert(0) += allocated;
        }
        if let (Some(truth), Some(true_surface), Some(pose), Some(surface)) = (
            opts.truth.and_then(|t| t.frame(i)),
            true_surface.as_ref(),
            report.camera_from_torso,
            tracker.surface(),
        ) {
            let a = accuracy::score(
                &TrackedFrame {
                    surface: &surface,
                    camera_from_torso: pose,
                    salient_camera: report.salient_camera,
                },
                &accuracy::TruthFrame {
                    surface: true_surface,
                    camera_from_torso: supine_core::geometry::isometry_from_rows(&truth.camera_from_torso),
                    salient_camera: truth.salient(),
                },
                true_arm
                    .as_ref()
                    .map(|a| (&a.tip_robot_base, &opts.tracker.robot_base_from_camera)),
            );
            stats.torso_mm.push(a.torso_m * 1000.0);
            stats.point_mm.extend(a.point_m.map(|e| e * 1000.0));
            stats.probe_mm.extend(a.probe_m.map(|e| e * 1000.0));
            stats
                .probe_distance_mm
                .extend(a.probe_distance_m.map(|e| e * 1000.0));
        }
        for m in &report.packets {
            send(m, &mut sink, &mut buf, &mut stats);
        }
        stats.budget_overruns = tracker.counters().overruns;
        observe(
            &FrameView {
                frame: &frame,
                report: &report,
                surface: tracker.surface(),
            },
            &stats,
        );
    }
    Ok(stats)
}

fn send(m: &Message, sink: &mut Option<&mut (dyn Link + '_)>, buf: &mut [u8], stats: &mut RunStats) {
    stats.packets += 1;
    if let Ok(n) = m.encode_serial(buf) {
        stats.serial_bytes += n as u64;
    }
    if let Some(link) = sink.as_deref_mut()
        && link.send(m).is_err()
    {
        stats.send_errors += 1;
    }
}
