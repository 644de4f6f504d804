//! `supine demo`: the README's main job, on the committed synthetic recording.
//!
//! Today supine has its foundations (depth sources, the wire protocol, the links) but no tracker yet: the joint
//! forest, shape estimation and ICP land with the tracker issues. So the demo runs the stages that exist, end to end
//! and for real: the recording is read through the same `DepthSource` as a live Kinect, each frame is checked
//! (valid-depth fraction inside the Kinect's working range), a health message saying `initialising` is encoded with
//! the frame's capture timestamp and sent through the chosen link, and the table reports the latency of those
//! stages. It says plainly that no pose is estimated; it never prints an accuracy it did not measure.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use supine_core::wire::{Body, Health, Message, TrackerState};
use supine_drivers::link::{self, Link, LinkOptions, LinkSpec};
use supine_drivers::source::{self, DepthSource, SourceErrorKind, SourceSpec};

use crate::failure::Failure;
use crate::output::{self, Output};
use crate::{note, note_raw};

/// Where the committed demo recording lives, relative to the repository root or the installed model directory.
const DEMO_RECORDING: &str = "demo/sequence.oni";

/// Depth range in which a Kinect v1 measures (mm); outside it a pixel carries no usable depth.
const WORKING_RANGE_MM: std::ops::RangeInclusive<u16> = 500..=4500;

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
}

fn find_recording(args: &DemoArgs) -> Result<PathBuf, Failure> {
    if let Some(path) = &args.recording {
        return Ok(path.clone());
    }
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

/// Latency percentile (0..=100) of sorted durations, in milliseconds.
fn percentile_ms(sorted: &[Duration], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((p / 100.0) * (sorted.len() - 1) as f64).round() as usize;
    sorted[rank.min(sorted.len() - 1)].as_secs_f64() * 1e3
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
    if let Some(LinkSpec::File { path: sink_path }) = &sink_spec {
        let mut others = inputs.to_vec();
        if let Some(j) = &args.json {
            others.push(("--json", j.as_path()));
        }
        output::refuse_overwriting("--sink", sink_path, &others)?;
        if args.json.as_deref().is_some_and(|j| j == sink_path.as_path()) {
            return Err(Failure::usage(format!(
                "--sink and --json are both {}; give them different files",
                sink_path.display()
            )));
        }
    }
    let spec = SourceSpec::File { path: path.clone() };
    let mut src = source::open(&spec).map_err(|e| anyhow::anyhow!("opening the demo recording: {e}"))?;
    let mut sink = match &sink_spec {
        None => None,
        Some(spec) => Some(link::open(spec, &LinkOptions::default()).map_err(|e| anyhow::anyhow!("{e}"))?),
    };
    note!("supine demo: {}", src.describe());
    note!(
        "supine demo: the tracker (joint forest, shape estimation, ICP) is not built yet; this run exercises the\n\
         \x20            depth source, frame checks and the wire/link path, and reports the tracker as initialising."
    );

    let limit = args.frames.unwrap_or(u32::MAX);
    let mut latencies = Vec::new();
    let mut valid_fraction_sum = 0.0f64;
    let mut bytes_encoded = 0usize;
    let mut send_errors = 0u64;
    let mut serial_buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
    let mut seq = 0u16;
    let started = Instant::now();
    while (latencies.len() as u32) < limit {
        let t0 = Instant::now();
        let frame = match src.next_frame(Duration::from_millis(500)) {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) => return Err(anyhow::anyhow!("reading {}: {e}", path.display()).into()),
        };
        let depth = frame.depth_mm();
        let valid = depth.iter().filter(|d| WORKING_RANGE_MM.contains(d)).count();
        valid_fraction_sum += valid as f64 / depth.len() as f64;
        let timestamp = frame.capture;
        let msg = Message {
            seq,
            timestamp,
            body: Body::Health(Health {
                state: TrackerState::Initialising,
                frame_rate_chz: 0,
                latency_us: 0,
                budget_overruns: 0,
                dropped_frames: 0,
            }),
        };
        seq = seq.wrapping_add(1);
        match msg.encode_serial(&mut serial_buf) {
            Ok(n) => bytes_encoded += n,
            Err(e) => return Err(anyhow::anyhow!("encoding a health message: {e}").into()),
        }
        if let Some(link) = sink.as_mut()
            && link.send(&msg).is_err()
        {
            send_errors += 1;
        }
        latencies.push(t0.elapsed());
        if latencies.len() % 30 == 0 {
            note_raw!("\rsupine demo: {} frames", latencies.len());
        }
    }
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
    let frames = latencies.len();
    if frames == 0 {
        return Err(anyhow::anyhow!("{} holds no frames", path.display()).into());
    }
    let wall = started.elapsed().as_secs_f64();
    latencies.sort();
    let p50 = percentile_ms(&latencies, 50.0);
    let p99 = percentile_ms(&latencies, 99.0);
    let valid_mean = valid_fraction_sum / frames as f64;

    // With `--sink stdout` the packets own stdout; the table goes to stderr so neither corrupts the other.
    let mut table = String::new();
    let mut row = |name: &str, value: String| table.push_str(&format!("  {name:<34} {value}\n"));
    row("recording", path.display().to_string());
    row("frames", frames.to_string());
    row("throughput (frames/s)", format!("{:.1}", frames as f64 / wall));
    row("latency p50 / p99 (ms)", format!("{p50:.3} / {p99:.3}"));
    row("valid depth in 0.5-4.5 m", format!("{:.1} %", valid_mean * 100.0));
    row("health packets encoded", format!("{frames} ({bytes_encoded} B)"));
    if let Some(s) = &args.sink {
        row(
            "sent to",
            format!("{s} ({send_errors} send errors, {dropped} dropped by the link queue)"),
        );
    }
    row("tracker", "not built yet: no pose is estimated".to_owned());
    row(
        "accuracy vs ground truth",
        "n/a until the tracker lands".to_owned(),
    );
    if args.sink.as_deref() == Some("stdout") {
        note_raw!("supine demo summary\n{table}");
    } else {
        crate::console::out(&format!("supine demo summary\n{table}"))?;
    }

    // A failed run leaves an old --json file as it was (the dropped output removes its empty temporary file).
    if let Some(msg) = sink_failure {
        return Err(anyhow::anyhow!(msg).into());
    }
    if let Some(out) = json_out {
        let report = serde_json::json!({
            "frames": frames,
            "latency_ms_p50": p50,
            "latency_ms_p99": p99,
            "valid_depth_fraction": valid_mean,
            "packets_dropped": dropped,
            "send_errors": send_errors,
            "tracked_fraction": serde_json::Value::Null,
            "tracker": "not built",
            "recording": path.display().to_string(),
        });
        let text = serde_json::to_string_pretty(&report).map_err(anyhow::Error::from)?;
        output::write_all(out, text.as_bytes())?;
    }
    Ok(())
}
