//! The service loop of `supine run --config FILE`: the configured depth source into the real-time tracker, packets
//! out on the configured link, arm states and commands read back from it, systemd told where it stands.
//!
//! Life cycle: models loaded and validated and all tracker memory allocated before the first frame; the init phase
//! (bed, shape) on the first frames, then `READY=1`; `WATCHDOG=1` from the frame loop; SIGTERM or SIGINT ends it
//! cleanly (a final health packet, `STOPPING=1`, exit 0); a file source ends the run at its end (exit 0) unless
//! `loop_source` is set. Faults never end it: a source error is a `sensor_fault` health packet and a reopen with
//! back-off, a corrupt frame is counted and skipped (a run of [`CORRUPT_RUN_FAULT`] of them is a sensor fault), a
//! link that is down keeps tracking and counts drops (the link reconnects itself), garbage from the arm is counted
//! by the decoder and skipped. Only start-up errors (bad model file, source or link that cannot be opened, an init
//! phase that never finds the bed) end the process with an error. Capture times never go backwards across a reopen
//! or a loop of a file source: packets keep their order on the wire.
//!
//! `--record`/`--view` hand each frame to [`FoxgloveOutputs`] (which drops frames rather than wait); `[faults]`
//! (test only, `crate::faults`) wraps the source and link in fault injectors. Tracing spans per stage: `read`,
//! `track`, `send`, `outputs` (inside a `frame` span carrying the frame number).
//!
//! Cost per frame: the tracker's own (see `supine_core::tracker`), one link poll and a few sends; nothing allocates
//! in the loop except the link's queue slots, which are fixed at start-up.

use std::time::{Duration, Instant};

use supine_core::time::Clock;
use supine_core::tracker::{ArmSample, ScratchSizes, Tracker, TrackerConfig};
use supine_core::wire::{Body, Command, TrackerState};
use supine_drivers::clock::MonotonicClock;
use supine_drivers::link::{self, Link, LinkCounters, LinkOptions};
use supine_drivers::source::{self, DepthSource, SourceErrorKind};
use supine_drivers::tracker_host::{ModelFiles, TrackerScratch};
use tracing::{info, info_span, warn};

use crate::config::Checked;
use crate::failure::Failure;
use crate::faults::{Injector, ServiceLink};
use crate::foxglove::outputs::FoxgloveOutputs;
use crate::notify::Notifier;
use crate::pipeline::FrameView;

/// Longest wait for one frame before the sensor counts as silent.
const FRAME_TIMEOUT: Duration = Duration::from_millis(1000);
/// Back-off between reopen attempts of a failed source: first and longest.
const REOPEN_BACKOFF: (Duration, Duration) = (Duration::from_millis(100), Duration::from_secs(5));
/// Corrupt frames in a row that make a sensor fault (1 s at 30 Hz): the sensor delivers only unusable frames.
pub const CORRUPT_RUN_FAULT: u32 = 30;
/// Frame interval assumed where capture times restart (a reopened or looped source), µs.
const NOMINAL_INTERVAL_US: i64 = 33_333;

/// Counters of one service run, logged at the end.
#[derive(Debug, Default, Clone, Copy)]
pub struct ServiceStats {
    /// Frames processed.
    pub frames: u64,
    /// Source faults (errors and silences).
    pub source_faults: u64,
    /// Successful reopens of the source.
    pub reopens: u64,
    /// Arm states received.
    pub arm_states: u64,
    /// Commands received.
    pub commands: u64,
    /// Corrupt frames skipped.
    pub corrupt: u64,
    /// Packets the link refused.
    pub send_errors: u64,
    /// The link's counters at the end (drops, garbage received, reconnects).
    pub link: LinkCounters,
}

fn tracker_config(c: &Checked) -> TrackerConfig {
    let rb = c
        .robot_base_from_camera
        .unwrap_or_else(supine_core::geometry::Isometry3::identity);
    let mut cfg = crate::pipeline::tracker_config(rb);
    if c.robot_base_from_camera.is_none() {
        // Without the calibration, up is unknown: the bed search takes the floor's normal.
        cfg.up_camera = None;
    }
    cfg.budget.frame_us = c.frame_budget_us;
    cfg.budget.icp_iterations = c.icp_iterations.min(u8::MAX as u32) as u8;
    cfg.shape_frames = c.shape_frames.min(u16::MAX as u32) as u16;
    cfg
}

fn send_all(link: &mut dyn Link, msgs: &[supine_core::wire::Message], stats: &mut ServiceStats) {
    for m in msgs {
        if link.send(m).is_err() {
            stats.send_errors += 1;
        }
    }
}

/// Run the service until a signal, the end of a file source, or a start-up error; frames also go to `outputs`
/// (`--record`, `--view`) when given.
pub fn serve(c: &Checked, mut outputs: Option<&mut FoxgloveOutputs>) -> Result<ServiceStats, Failure> {
    let files = ModelFiles::load_files(&c.body_model, &c.joint_forest, &c.shape_model)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let models = files.views().map_err(|e| anyhow::anyhow!("model files: {e}"))?;
    let mut faults = c.faults.clone().map(Injector::new);
    let mut src: Box<dyn DepthSource> =
        source::open(&c.source).map_err(|e| anyhow::anyhow!("opening the source {}: {e}", c.source))?;
    if let Some(f) = faults.as_mut() {
        src = f.source(src, 0);
    }
    let opened = link::open(&c.link, &LinkOptions::default())
        .map_err(|e| anyhow::anyhow!("opening the link {}: {e}", c.link))?;
    let mut link = match &faults {
        Some(f) => f.link(opened),
        None => ServiceLink::Plain(opened),
    };
    let k = src.intrinsics();
    let cfg = tracker_config(c);
    let mut store = TrackerScratch::new(&ScratchSizes::of(&models, &k, &cfg.planes));
    let mut tracker = Tracker::new(models, k, cfg, store.scratch()).map_err(|e| anyhow::anyhow!("{e}"))?;
    crate::links::catch_interrupts().map_err(|e| anyhow::anyhow!("installing the signal handlers: {e}"))?;
    let notifier = Notifier::from_env().map_err(|e| anyhow::anyhow!("$NOTIFY_SOCKET: {e}"))?;
    let watchdog_every = crate::notify::watchdog_interval().map(|d| d / 2);
    let mut last_ping = Instant::now();
    let clock = MonotonicClock;
    let mut stats = ServiceStats::default();
    let mut arm: Option<ArmSample> = None;
    let mut sending = true;
    let mut ready = false;
    let mut last_state = TrackerState::Initialising;
    let mut backoff = REOPEN_BACKOFF.0;
    let mut corrupt_run = 0u32;
    let mut capture_offset = 0i64;
    let mut last_capture = None;
    let init_deadline = Duration::from_secs_f64(c.init_timeout_s.max(0.0));
    let mut init_started = Instant::now();
    info!(source = %c.source, link = %c.link, "supine run: started");
    let stop_reason = loop {
        if crate::links::interrupted() {
            break "signal";
        }
        if let Some(f) = faults.as_mut() {
            f.frame(stats.frames, &mut link);
        }
        let l = link.get();
        l.poll();
        while let Ok(Some(m)) = l.receive() {
            match m.body {
                Body::ArmState(a) => {
                    stats.arm_states += 1;
                    arm = Some(ArmSample::from_wire(m.timestamp, &a));
                }
                Body::Command(cmd) => {
                    stats.commands += 1;
                    info!(?cmd, "command");
                    match cmd {
                        Command::Reinitialise => {
                            // In the frozen shape mode the tracker keeps the shape over the new init phase.
                            tracker.reinitialise();
                            init_started = Instant::now();
                        }
                        Command::Start => sending = true,
                        Command::Stop => sending = false,
                        Command::SetShapeMode(mode) => tracker.set_shape_mode(mode),
                        _ => warn!(?cmd, "command not understood by this build"),
                    }
                }
                _ => {}
            }
        }
        let _frame_span = info_span!("frame", n = stats.frames).entered();
        let read = info_span!("read").entered();
        let frame = match src.next_frame(FRAME_TIMEOUT) {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream && !c.loop_source => {
                break "end of the recording";
            }
            Err(e) => {
                let looping = e.kind() == SourceErrorKind::EndOfStream;
                let corrupt = matches!(
                    e.kind(),
                    SourceErrorKind::CorruptData | SourceErrorKind::Unsupported
                );
                if corrupt {
                    stats.corrupt += 1;
                    corrupt_run += 1;
                    tracker.dropped(1);
                    if corrupt_run < CORRUPT_RUN_FAULT {
                        warn!(error = %e, "skipping a corrupt frame");
                        continue;
                    }
                    corrupt_run = 0;
                }
                if !looping {
                    stats.source_faults += 1;
                    warn!(error = %e, "sensor fault; reopening");
                    if let Some(f) = faults.as_mut() {
                        f.source_failed(stats.frames);
                    }
                    tracker.sensor_fault();
                    let h = tracker.health(clock.now(), 0);
                    send_all(link.get(), &[h], &mut stats);
                    std::thread::sleep(backoff);
                    backoff = (backoff * 2).min(REOPEN_BACKOFF.1);
                }
                match source::open(&c.source) {
                    Ok(s) => {
                        src = match faults.as_mut() {
                            Some(f) => f.source(s, stats.frames),
                            None => s,
                        };
                        stats.reopens += 1;
                        if !looping {
                            info!("source reopened");
                        }
                    }
                    Err(e) => warn!(error = %e, "reopening the source failed"),
                }
                continue;
            }
        };
        drop(read);
        backoff = REOPEN_BACKOFF.0;
        corrupt_run = 0;
        let mut frame = frame;
        // A reopened sensor or a looped recording starts its clock again: continue from the last capture time.
        let t = frame.capture.offset_by(capture_offset);
        if let Some(last) = last_capture
            && t.since(last) <= 0
        {
            capture_offset += last.since(t) + NOMINAL_INTERVAL_US;
        }
        frame.capture = frame.capture.offset_by(capture_offset);
        last_capture = Some(frame.capture);
        let report = {
            let _span = info_span!("track").entered();
            tracker.process(&frame, arm.as_ref(), &clock)
        };
        stats.frames += 1;
        if report.state != last_state {
            info!(from = last_state.name(), to = report.state.name(), "state");
            if let Some(n) = &notifier {
                let _ = n.status(report.state.name());
            }
            last_state = report.state;
        }
        if sending {
            let _span = info_span!("send").entered();
            send_all(link.get(), &report.packets, &mut stats);
        }
        if let Some(out) = outputs.as_deref_mut() {
            let _span = info_span!("outputs").entered();
            let view = FrameView {
                frame: &frame,
                report: &report,
                surface: tracker.surface(),
            };
            out.frame(&crate::foxglove::record_of(&view, k));
        }
        if report.state == TrackerState::Initialising {
            if init_started.elapsed() > init_deadline && !ready {
                return Err(anyhow::anyhow!(
                    "the init phase found no bed and patient within {:.0} s ([init] timeout_s)",
                    c.init_timeout_s
                )
                .into());
            }
        } else if !ready {
            ready = true;
            info!(frames = stats.frames, "init phase done; tracking");
            if let Some(n) = &notifier {
                let _ = n.ready();
            }
        }
        if let (Some(n), Some(every)) = (&notifier, watchdog_every)
            && last_ping.elapsed() >= every
        {
            let _ = n.watchdog();
            last_ping = Instant::now();
        }
    };
    info!(
        reason = stop_reason,
        frames = stats.frames,
        "supine run: stopping"
    );
    let h = tracker.health(clock.now(), 0);
    let l = link.get();
    send_all(l, &[h], &mut stats);
    if let Some(n) = &notifier {
        let _ = n.stopping();
    }
    let _ = l.close(Duration::from_secs(2));
    stats.link = l.counters();
    Ok(stats)
}
