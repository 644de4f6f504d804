//! `supine demo`: the README's main job. The committed synthetic recording (4 s, a patient on a bed: the init
//! phase, the robot arm sweeping its probe over the torso, then parking over the whole torso for 1 s and leaving)
//! runs through the whole pipeline with the committed default models: the same `DepthSource` a live Kinect uses, the
//! real-time tracker (init phase, joint forest, torso ICP with feedback, probe mapping from the recorded arm states,
//! arm.cobs beside the recording), packets encoded and sent through the chosen link. A live status line, then a
//! table: latency, the states, and accuracy against the recording's ground truth (truth.jsonl beside it), measured,
//! never assumed. `--png FILE` draws one frame's overlay (`crate::overlay_png`).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use supine_drivers::link::{self, Link, LinkOptions, LinkSpec};
use supine_drivers::source::{self, DepthSource, SourceSpec};
use supine_drivers::tracker_host::{MODEL_FILES, ModelFiles};

use crate::arm_track::ArmTrack;
use crate::failure::Failure;
use crate::foxglove::outputs::{FoxgloveOutputs, Pace};
use crate::foxglove::record_of;
use crate::output::{self, Output};
use crate::overlay_png;
use crate::pipeline::{self, PlayOptions};
use crate::truth::Truth;
use crate::{note, note_raw};
use supine_core::wire::TrackerState;

/// Where the committed demo recording lives, relative to the repository root or the installed model directory
/// (`demo/sequence.oni`, 2 s without the full occlusion, is the tests' fixture).
const DEMO_RECORDING: &str = "demo/occlusion/sequence.oni";

/// Arguments of `supine demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Process at most this many frames (default: the whole recording).
    #[arg(long, value_parser = crate::numbers::positive_u32)]
    pub frames: Option<u32>,
    /// Where the packets go: `stdout`, `serial:PATH[@BAUD]`, `slcan:PATH[@BAUD]`, `can:IFACE`, `file:PATH`
    /// (default: encoded and counted, sent nowhere).
    #[arg(long)]
    pub sink: Option<String>,
    /// The recording to play (default: the committed synthetic sequence, models/artifacts/demo/sequence.oni).
    #[arg(long)]
    pub recording: Option<PathBuf>,
    /// Also write the summary as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Draw one frame (depth, fitted torso, salient points, probe) to this PNG file.
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
    /// With --png: the frame to draw, counted from 0 (default: the last one played).
    #[arg(long, value_name = "N", requires = "png")]
    pub png_frame: Option<u32>,
    /// Write every frame as Foxglove channels (depth, scene, transforms, packets) to this MCAP file.
    #[arg(long, value_name = "OUT.mcap")]
    pub record: Option<PathBuf>,
}

fn find_recording(args: &DemoArgs) -> Result<PathBuf, Failure> {
    match &args.recording {
        Some(path) => Ok(path.clone()),
        None => find_recording_path(),
    }
}

/// The committed demo recording in the first model directory that has it.
pub fn find_recording_path() -> Result<PathBuf, Failure> {
    let dirs = crate::model_dirs::model_dirs();
    dirs.iter().map(|d| d.join(DEMO_RECORDING)).find(|p| p.is_file()).ok_or_else(|| {
        let tried: Vec<String> = dirs.iter().map(|d| d.join(DEMO_RECORDING).display().to_string()).collect();
        anyhow::anyhow!(
            "no demo recording found (tried {}); run from the repository root, set SUPINE_MODELS, or pass --recording",
            tried.join(", ")
        )
        .into()
    })
}

/// The first model directory holding all three default models.
pub fn find_models() -> Result<PathBuf, Failure> {
    let dirs = crate::model_dirs::model_dirs();
    dirs.iter()
        .find(|d| MODEL_FILES.iter().all(|f| d.join(f).is_file()))
        .cloned()
        .ok_or_else(|| {
            let tried: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
            anyhow::anyhow!(
                "no directory with the model files {} found (tried {}); run from the repository root or set \
                 SUPINE_MODELS",
                MODEL_FILES.join(", "),
                tried.join(", ")
            )
            .into()
        })
}

/// Run `supine demo`.
pub fn run(args: DemoArgs) -> Result<(), Failure> {
    let path = find_recording(&args)?;
    // A FIFO or device would block the open until a peer appears; a recording is a regular file.
    if std::fs::metadata(&path).is_ok_and(|m| !m.is_file()) {
        return Err(anyhow::anyhow!("--recording {}: not a regular file", path.display()).into());
    }
    let sink_spec = match &args.sink {
        None => None,
        Some(s) => Some(
            s.parse::<LinkSpec>()
                .map_err(|e| Failure::usage(format!("--sink: {e}")))?,
        ),
    };
    // Outputs are checked (and their temporary files created) before any work: no input is written over, and an
    // unwritable --json fails now rather than after the whole recording.
    let inputs = [("--recording", path.as_path())];
    let json_out = match &args.json {
        Some(p) => Some(Output::create("--json", p, &inputs)?),
        None => None,
    };
    let mut record_out = match &args.record {
        Some(p) => {
            output::refuse_same_output("--record", p, "--json", args.json.as_deref())?;
            output::refuse_same_output("--record", p, "--png", args.png.as_deref())?;
            Some(Output::create("--record", p, &inputs)?)
        }
        None => None,
    };
    let png_out = match &args.png {
        Some(p) => {
            output::refuse_same_output("--png", p, "--json", args.json.as_deref())?;
            Some(Output::create("--png", p, &inputs)?)
        }
        None => None,
    };
    if let Some(LinkSpec::File { path: sink_path }) = &sink_spec {
        let mut others = inputs.to_vec();
        if let Some(j) = &args.json {
            others.push(("--json", j.as_path()));
        }
        output::refuse_overwriting("--sink", sink_path, &others)?;
        output::refuse_same_output("--sink", sink_path, "--json", args.json.as_deref())?;
    }
    let spec = SourceSpec::File { path: path.clone() };
    let mut src = source::open(&spec).map_err(|e| anyhow::anyhow!("opening the demo recording: {e}"))?;
    let mut sink = match &sink_spec {
        None => None,
        Some(spec) => Some(link::open(spec, &LinkOptions::default()).map_err(|e| anyhow::anyhow!("{e}"))?),
    };
    note!("supine demo: {}", src.describe());
    let model_dir = find_models()?;
    let files = ModelFiles::load(&model_dir).map_err(|e| anyhow::anyhow!("{e}"))?;
    let truth_path = path.with_file_name("truth.jsonl");
    let truth = if truth_path.is_file() {
        Some(Truth::load(&truth_path).map_err(|e| anyhow::anyhow!("{e:#}"))?)
    } else {
        note!("supine demo: no truth.jsonl beside the recording; accuracy is not measured");
        None
    };
    let arm_path = path.with_file_name("arm.cobs");
    let arm = if arm_path.is_file() {
        Some(ArmTrack::load(&arm_path).map_err(|e| anyhow::anyhow!("{e:#}"))?)
    } else {
        None
    };
    let opts = PlayOptions {
        arm: arm.as_ref(),
        count_allocations: record_out.is_none(),
        ..PlayOptions::new(args.frames.unwrap_or(u32::MAX), truth.as_ref())
    };
    // The demo records every frame (the loop waits for the writer), as replay does.
    let mut outputs = FoxgloveOutputs::new(
        record_out.as_mut().map(Output::take_file),
        None,
        truth.as_ref().map(|t| t.robot_base_from_camera),
        Pace::Lossless,
    )
    .map_err(|e| anyhow::anyhow!("--record: {e}"))?;
    let intrinsics = src.intrinsics();
    let mut picture = None;
    let mut states = Vec::new();
    let started = Instant::now();
    let link: Option<&mut dyn Link> = match sink.as_mut() {
        Some(l) => Some(l.as_mut()),
        None => None,
    };
    let stats = pipeline::play(src.as_mut(), &files, &opts, link, |v, s| {
        let wanted = match args.png_frame {
            Some(n) => s.frames == n + 1,
            None => true,
        };
        states.push(v.report.state);
        if png_out.is_some() && wanted {
            picture = Some(overlay_png::render(&record_of(v, intrinsics)));
        }
        if record_out.is_some() {
            outputs.frame(&record_of(v, intrinsics));
        }
        if s.frames % 10 == 0 || s.frames == 1 {
            let err = s
                .torso_mm
                .last()
                .map(|e| format!("{e:5.1} mm"))
                .unwrap_or_else(|| "   -    ".into());
            note_raw!(
                "\rsupine demo: frame {:>4}  {:<12}  {:>5.2} ms  torso vs truth {err}   ",
                s.frames,
                v.report.state.name(),
                v.report.times.total() as f64 / 1000.0,
            );
        }
    })
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    note!();
    // Messages a full link queue evicted (newest wins): a replay runs faster than a slow line can carry.
    let mut dropped = 0u64;
    let mut sink_failure = None;
    if let Some(link) = sink.as_mut() {
        let closed = link.close(Duration::from_secs(2));
        let c = link.counters();
        dropped = c.dropped;
        // A sink that failed its writes makes the run fail (after the table), naming the OS error once.
        if let Some(e) = link.last_io_error() {
            if link.describe() == "stdout" && e.contains("(os error 32)") {
                return Err(Failure::BrokenPipe);
            }
            sink_failure = Some(format!(
                "--sink {}: {e} ({} write error(s), {} of {} packets not delivered)",
                link.describe(),
                c.io_errors,
                c.queued.saturating_sub(c.sent),
                c.queued
            ));
        } else if let Err(e) = closed {
            sink_failure = Some(format!("--sink {}: {e}", link.describe()));
        }
    }
    let recorded = match outputs.finish() {
        Ok(r) => r.recorded,
        Err(e) => {
            let kept = record_out.map(Output::abandon).unwrap_or(None);
            return Err(output::with_partial(anyhow::anyhow!("--record: {e}"), kept).into());
        }
    };
    if stats.frames == 0 {
        return Err(anyhow::anyhow!("{} holds no frames", path.display()).into());
    }
    if let Some(out) = record_out {
        out.commit()?;
    }
    let wall = started.elapsed().as_secs_f64();
    let p50 = pipeline::percentile(&stats.latency_us, 50.0) / 1000.0;
    let p99 = pipeline::percentile(&stats.latency_us, 99.0) / 1000.0;
    let mm = |v: &[f32]| {
        let m = pipeline::mean(v);
        if m.is_finite() {
            format!("{m:.1} mm (over {} frames)", v.len())
        } else {
            "n/a".to_owned()
        }
    };

    // With `--sink stdout` the packets own stdout; the table goes to stderr so neither corrupts the other.
    let mut table = String::new();
    let mut row = |name: &str, value: String| table.push_str(&format!("  {name:<34} {value}\n"));
    row("recording", path.display().to_string());
    row("models", model_dir.display().to_string());
    row("frames", stats.frames.to_string());
    row(
        "throughput (frames/s)",
        format!("{:.1}", stats.frames as f64 / wall),
    );
    row("latency p50 / p99 (ms)", format!("{p50:.3} / {p99:.3}"));
    row(
        "init phase",
        match stats.init_frames {
            Some(n) => format!("{n} frames ({:.2} s of sensor time)", n as f64 / 30.0),
            None => "not finished".to_owned(),
        },
    );
    row("states (frames)", stats.states_line());
    if let Some(p) = &args.record {
        row("recorded", format!("{recorded} frames to {}", p.display()));
    }
    let recovery = truth.as_ref().and_then(|t| t.full_occlusion).map(|e| {
        // Frames from the end of the park until the tracker tracks (not coasts) again.
        let back = states
            .iter()
            .enumerate()
            .skip(e.end as usize)
            .find(|(_, s)| matches!(s, TrackerState::Tracking | TrackerState::Degraded))
            .map(|(i, _)| i as u32 - e.end);
        let during = states
            .get(e.start as usize..(e.end as usize).min(states.len()))
            .unwrap_or(&[]);
        let coasted = during.iter().filter(|s| **s == TrackerState::Occluded).count();
        (e, back, coasted)
    });
    if let Some((e, back, coasted)) = recovery {
        row(
            "full occlusion",
            format!(
                "frames {}..{} (arm parked over the torso): {coasted} of {} frames coasted as occluded, {}",
                e.start,
                e.end,
                e.end - e.start,
                match back {
                    Some(n) => format!("tracking again {n} frames after it"),
                    None => "not tracking again by the end".to_owned(),
                }
            ),
        );
    }
    row(
        "tracked after init",
        format!("{:.1} %", stats.tracked_fraction() * 100.0),
    );
    row("torso surface error", mm(&stats.torso_mm));
    row("salient-point error", mm(&stats.point_mm));
    row("probe mapping error", mm(&stats.probe_mm));
    row("probe distance error", mm(&stats.probe_distance_mm));
    row("budget overruns", stats.budget_overruns.to_string());
    row("heap allocations after init", stats.allocations_summary());
    row(
        "packets",
        format!("{} ({} B on a serial line)", stats.packets, stats.serial_bytes),
    );
    if let Some(s) = &args.sink {
        row(
            "sent to",
            format!(
                "{s} ({} send errors, {dropped} dropped by the link queue)",
                stats.send_errors
            ),
        );
    }
    if args.sink.as_deref() == Some("stdout") {
        note_raw!("supine demo summary\n{table}");
    } else {
        crate::console::out(&format!("supine demo summary\n{table}"))?;
    }

    // A failed run leaves an old --json file as it was (the dropped output removes its empty temporary file).
    if let Some(msg) = sink_failure {
        return Err(anyhow::anyhow!(msg).into());
    }
    if let Some(mut out) = png_out {
        let pic = picture.ok_or_else(|| {
            anyhow::anyhow!(
                "--png-frame {}: the recording has only {} frames",
                args.png_frame.unwrap_or(0),
                stats.frames
            )
        })?;
        let target = out.target().display().to_string();
        let mut w = std::io::BufWriter::new(out.file());
        pic.write_png(&mut w)
            .map_err(anyhow::Error::from)
            .and_then(|()| std::io::Write::flush(&mut w).map_err(anyhow::Error::from))
            .map_err(|e| anyhow::anyhow!("--png {target}: {e}"))?;
        drop(w);
        out.commit()?;
    }
    if let Some(out) = json_out {
        let mut report = stats.json();
        if let Some((_, back, _)) = recovery {
            report["recovery_frames"] = serde_json::json!(back);
        }
        report["packets_dropped"] = dropped.into();
        report["recording"] = path.display().to_string().into();
        let text = serde_json::to_string_pretty(&report).map_err(anyhow::Error::from)?;
        output::write_all(out, text.as_bytes())?;
    }
    Ok(())
}
