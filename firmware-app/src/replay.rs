//! `supine replay FILE`: a recording (.oni, or a ROS 2 MCAP depth bag) through the service's per-frame path, as
//! fast as possible or `--realtime`, with `--record OUT.mcap` (Foxglove channels) and `--view PORT` (live Foxglove).
//!
//! Today the per-frame path is the depth frame alone: the tracker (the tracker issue) goes in [`process`], the one
//! place where a frame becomes a [`FrameRecord`]; `--truth`, `--arm` and `--sink` land with it. Corrupt frames are
//! counted and skipped, as the service does. Cost per frame: the source's decode plus, when recording or viewing,
//! the Foxglove encoding (see [`crate::foxglove`]).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_drivers::oni::OniReader;
use supine_drivers::ros_bag::{self, McapSource};
use supine_drivers::source::{DepthSource, SourceErrorKind};

use crate::failure::Failure;
use crate::foxglove::FrameRecord;
use crate::foxglove::live::{self, LiveView};
use crate::foxglove::outputs::{FoxgloveOutputs, Pace};
use crate::output::{self, Output};
use crate::{note, numbers};

/// Arguments of `supine replay`.
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// The recording: an .oni file or a ROS 2 MCAP bag (.mcap) with sensor_msgs/Image 16UC1 or 32FC1 depth.
    pub file: PathBuf,
    /// The bag's depth topic (default: its only image topic, or the only one named *depth*). MCAP only.
    #[arg(long, value_name = "TOPIC")]
    pub topic: Option<String>,
    /// Write the frames as Foxglove channels (depth, scene, transforms, packets) to this MCAP file.
    #[arg(long, value_name = "OUT.mcap")]
    pub record: Option<PathBuf>,
    /// Serve the same channels live over the Foxglove WebSocket protocol on PORT (all interfaces) or HOST:PORT.
    #[arg(long, value_name = "PORT", value_parser = live::parse_addr)]
    pub view: Option<std::net::SocketAddr>,
    /// With --view: wait up to this many seconds for a viewer to subscribe before the first frame.
    #[arg(long, value_name = "SECONDS", requires = "view", value_parser = numbers::positive_u32)]
    pub view_wait: Option<u32>,
    /// Play at the recorded rate (capture timestamps) instead of as fast as possible.
    #[arg(long)]
    pub realtime: bool,
    /// Stop after this many frames.
    #[arg(long, value_parser = numbers::positive_u32)]
    pub frames: Option<u32>,
    /// Also write the summary as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// One frame through the per-frame path. The tracker goes here: it turns the depth frame into salient points,
/// the shaped torso, the probe mapping and the packets of a [`FrameRecord`]; today only the depth is passed on.
fn process<'a>(frame: DepthFrame<'a>, intrinsics: Intrinsics) -> FrameRecord<'a> {
    FrameRecord::depth_only(frame, intrinsics)
}

/// Open the recording by its extension; returns the source and its frame count when the file says.
fn open(args: &ReplayArgs) -> Result<(Box<dyn DepthSource>, Option<u64>), Failure> {
    let path = &args.file;
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        return Err(anyhow::anyhow!("{}: not a regular file", path.display()).into());
    }
    if ros_bag::is_mcap_path(path) {
        let src = McapSource::open(path, args.topic.as_deref()).map_err(|e| match e.kind() {
            SourceErrorKind::InvalidArgument => Failure::usage(e.to_string()),
            _ => anyhow::anyhow!("{e}").into(),
        })?;
        let n = src.frame_count();
        return Ok((Box::new(src), n));
    }
    if args.topic.is_some() {
        return Err(Failure::usage(format!(
            "--topic is for ROS 2 bags (.mcap); {} is not one",
            path.display()
        )));
    }
    let src = OniReader::open(path).map_err(|e| anyhow::anyhow!("{e}"))?;
    let n = src.info().frames.map(u64::from);
    Ok((Box::new(src), n))
}

fn progress(total: Option<u64>) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(total, ProgressDrawTarget::stderr());
    let template = if total.is_some() {
        "{elapsed_precise} [{bar:40}] {pos}/{len} frames  {per_sec}  eta {eta}"
    } else {
        "{elapsed_precise} {pos} frames  {per_sec}"
    };
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

fn percentile_ms(sorted: &[Duration], p: f64) -> Option<f64> {
    let last = sorted.len().checked_sub(1)?;
    let rank = ((p / 100.0) * last as f64).round() as usize;
    Some(sorted[rank.min(last)].as_secs_f64() * 1e3)
}

/// Run `supine replay`.
pub fn run(args: ReplayArgs) -> Result<(), Failure> {
    let inputs = [("FILE", args.file.as_path())];
    let mut record_out = match &args.record {
        Some(p) => Some(Output::create("--record", p, &inputs)?),
        None => None,
    };
    let json_out = match &args.json {
        Some(p) => {
            if args.record.as_deref() == Some(p.as_path()) {
                return Err(Failure::usage(format!(
                    "--record and --json are both {}; give them different files",
                    p.display()
                )));
            }
            Some(Output::create("--json", p, &inputs)?)
        }
        None => None,
    };
    let (mut src, total) = open(&args)?;
    let intrinsics = src.intrinsics();
    note!("supine replay: {}", src.describe());
    let live = match args.view {
        Some(addr) => {
            let v = LiveView::bind(addr).map_err(|e| anyhow::anyhow!("--view {addr}: {e}"))?;
            note!(
                "supine replay: live view on ws://{} (Foxglove: open connection)",
                v.local_addr()
            );
            Some(v)
        }
        None => None,
    };
    let record_file = record_out.as_mut().map(Output::take_file);
    // Replay records every frame (the loop waits for the writer); the service drops frames instead.
    let mut outputs = FoxgloveOutputs::new(record_file, live, None, Pace::Lossless)
        .map_err(|e| anyhow::anyhow!("--record: {e}"))?;
    if let (Some(v), Some(secs)) = (outputs.live(), args.view_wait)
        && !v.wait_for_subscriber(Duration::from_secs(secs as u64))
    {
        note!("supine replay: no viewer subscribed within {secs} s; playing anyway");
    }

    let limit = args.frames.map_or(u64::MAX, u64::from);
    let bar = progress(total.map(|t| t.min(limit)));
    let mut latencies = Vec::new();
    let mut corrupt = 0u64;
    let started = Instant::now();
    let mut first_capture = None;
    while (latencies.len() as u64) < limit {
        let t0 = Instant::now();
        let frame = match src.next_frame(Duration::from_millis(500)) {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e)
                if matches!(
                    e.kind(),
                    SourceErrorKind::CorruptData | SourceErrorKind::Unsupported
                ) =>
            {
                corrupt += 1;
                bar.suspend(|| tracing::warn!("skipping a frame: {e}"));
                // A damaged file repeats its error forever only if the reader cannot move on; bound that.
                if corrupt > 1000 && latencies.is_empty() {
                    return Err(anyhow::anyhow!(
                        "{}: no readable frame in the first 1000",
                        args.file.display()
                    )
                    .into());
                }
                continue;
            }
            Err(e) => return Err(anyhow::anyhow!("reading {}: {e}", args.file.display()).into()),
        };
        if args.realtime {
            let first = *first_capture.get_or_insert(frame.capture);
            let due = Duration::from_micros(frame.capture.since(first).max(0) as u64);
            if let Some(wait) = due.checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        let t0 = if args.realtime { Instant::now() } else { t0 };
        let record = process(frame, intrinsics);
        outputs.frame(&record);
        latencies.push(t0.elapsed());
        bar.inc(1);
    }
    bar.finish_and_clear();
    let frames = latencies.len();
    let report = match outputs.finish() {
        Ok(r) => r,
        Err(e) => {
            let kept = record_out.map(Output::abandon).unwrap_or(None);
            return Err(output::with_partial(anyhow::anyhow!("--record: {e}"), kept).into());
        }
    };
    if frames == 0 {
        return Err(anyhow::anyhow!("{} holds no readable frame", args.file.display()).into());
    }
    if let Some(out) = record_out {
        out.commit()?;
    }
    latencies.sort();
    let (p50, p99) = (percentile_ms(&latencies, 50.0), percentile_ms(&latencies, 99.0));
    let wall = started.elapsed().as_secs_f64();
    let mut table = String::new();
    let mut row = |name: &str, value: String| table.push_str(&format!("  {name:<28} {value}\n"));
    row("recording", args.file.display().to_string());
    row("frames", format!("{frames} ({corrupt} corrupt, skipped)"));
    row("throughput (frames/s)", format!("{:.1}", frames as f64 / wall));
    row(
        "latency p50 / p99 (ms)",
        format!("{:.3} / {:.3}", p50.unwrap_or(f64::NAN), p99.unwrap_or(f64::NAN)),
    );
    if let Some(p) = &args.record {
        row(
            "recorded",
            format!("{} frames to {}", report.recorded, p.display()),
        );
    }
    if let Some(s) = &report.live {
        row(
            "live view",
            format!(
                "{} clients, {} frames queued, {} dropped for slow clients",
                s.connections, s.queued, s.dropped
            ),
        );
    }
    row("tracker", "not wired into replay yet: depth only".to_owned());
    crate::console::out(&format!("supine replay summary\n{table}"))?;
    if let Some(out) = json_out {
        let report = serde_json::json!({
            "frames": frames,
            "corrupt_frames": corrupt,
            "latency_ms_p50": p50,
            "latency_ms_p99": p99,
            "tracked_fraction": serde_json::Value::Null,
            "recorded_frames": args.record.as_ref().map(|_| report.recorded),
            "live_view": report.live.map(|s| serde_json::json!({
                "connections": s.connections, "queued": s.queued, "dropped": s.dropped
            })),
            "recording": args.file.display().to_string(),
        });
        let text = serde_json::to_string_pretty(&report).map_err(anyhow::Error::from)?;
        output::write_all(out, text.as_bytes())?;
    }
    Ok(())
}
