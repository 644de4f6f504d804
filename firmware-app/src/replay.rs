//! `supine replay FILE`: a recording (.oni, or a ROS 2 MCAP depth bag) through the service's per-frame path, as
//! fast as possible or `--realtime`, with `--record OUT.mcap` (Foxglove channels) and `--view PORT` (live Foxglove).
//!
//! Each frame goes through the tracker (`crate::pipeline::play`, the same loop as `supine demo`); [`record_of`] turns
//! its report into the `FrameRecord` the Foxglove outputs write. With `--truth FILE` (a sequence's truth.jsonl,
//! sequence.json beside it) the tracker gets the calibration and arm states synthesised from the truth's probe pose
//! (`crate::arm_track`), and the summary reports accuracy. `--arm FILE` (a sequence's arm.cobs, or any capture of
//! arm-state messages in the serial framing) gives it the recorded arm states instead. `--sink` sends the packets. Corrupt frames are counted and skipped, as the service
//! does. Cost per frame: the source's decode, the tracker, and when recording or viewing the Foxglove encoding.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use supine_drivers::oni::OniReader;
use supine_drivers::ros_bag::{self, McapSource};
use supine_drivers::source::{DepthSource, SourceErrorKind};

use crate::arm_track::ArmTrack;
use crate::failure::Failure;
use crate::foxglove::live::{self, LiveView};
use crate::foxglove::outputs::{FoxgloveOutputs, Pace};
use crate::foxglove::record_of;
use crate::output::{self, Output};
use crate::pipeline::{self, PlayOptions};
use crate::truth::Truth;
use crate::{note, numbers};
use supine_drivers::link::{self, Link, LinkOptions, LinkSpec};
use supine_drivers::tracker_host::ModelFiles;

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
    /// Ground truth (a sequence's truth.jsonl, with sequence.json beside it): calibration, arm states from the true
    /// probe pose, and accuracy in the summary.
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    /// Arm states from this capture (a sequence's arm.cobs: arm-state messages in the serial framing), instead of
    /// ones synthesised from --truth.
    #[arg(long, value_name = "FILE")]
    pub arm: Option<PathBuf>,
    /// Where the packets go: `stdout`, `serial:PATH[@BAUD]`, `slcan:PATH[@BAUD]`, `can:IFACE`, `file:PATH`.
    #[arg(long)]
    pub sink: Option<String>,
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

/// Run `supine replay`.
pub fn run(args: ReplayArgs) -> Result<(), Failure> {
    let inputs = [("FILE", args.file.as_path())];
    let mut record_out = match &args.record {
        Some(p) => Some(Output::create("--record", p, &inputs)?),
        None => None,
    };
    let json_out = match &args.json {
        Some(p) => {
            output::refuse_same_output("--record", p, "--json", args.record.as_deref())?;
            Some(Output::create("--json", p, &inputs)?)
        }
        None => None,
    };
    let truth = match &args.truth {
        Some(p) => Some(Truth::load(p).map_err(|e| anyhow::anyhow!("--truth: {e:#}"))?),
        None => None,
    };
    let arm = match &args.arm {
        Some(p) => {
            let track = ArmTrack::load(p).map_err(|e| anyhow::anyhow!("--arm: {e:#}"))?;
            note!(
                "supine replay: {} arm states from {} ({} undecodable frames skipped)",
                track.len(),
                p.display(),
                track.bad_frames
            );
            Some(track)
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
    let rb_known = truth.as_ref().map(|t| t.robot_base_from_camera);
    let mut outputs = FoxgloveOutputs::new(record_file, live, rb_known, Pace::Lossless)
        .map_err(|e| anyhow::anyhow!("--record: {e}"))?;
    if let (Some(v), Some(secs)) = (outputs.live(), args.view_wait)
        && !v.wait_for_subscriber(Duration::from_secs(secs as u64))
    {
        note!("supine replay: no viewer subscribed within {secs} s; playing anyway");
    }

    let mut sink = match &args.sink {
        None => None,
        Some(s) => {
            let spec = s
                .parse::<LinkSpec>()
                .map_err(|e| Failure::usage(format!("--sink: {e}")))?;
            Some(link::open(&spec, &LinkOptions::default()).map_err(|e| anyhow::anyhow!("--sink: {e}"))?)
        }
    };
    let model_dir = crate::demo::find_models()?;
    let files = ModelFiles::load(&model_dir).map_err(|e| anyhow::anyhow!("{e}"))?;
    let opts = PlayOptions {
        realtime: args.realtime,
        skip_corrupt: true,
        count_allocations: args.record.is_none() && args.view.is_none(),
        arm: arm.as_ref(),
        ..PlayOptions::new(args.frames.unwrap_or(u32::MAX), truth.as_ref())
    };
    let bar = progress(total.map(|t| t.min(opts.limit as u64)));
    let started = Instant::now();
    let link: Option<&mut dyn Link> = match sink.as_mut() {
        Some(l) => Some(l.as_mut()),
        None => None,
    };
    let stats = pipeline::play(src.as_mut(), &files, &opts, link, |v, _| {
        outputs.frame(&record_of(v, intrinsics));
        bar.inc(1);
    })
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(l) = sink.as_mut() {
        let _ = l.close(Duration::from_secs(2));
    }
    let frames = stats.frames as usize;
    let corrupt = stats.corrupt;
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
    let p50 = pipeline::percentile(&stats.latency_us, 50.0) / 1000.0;
    let p99 = pipeline::percentile(&stats.latency_us, 99.0) / 1000.0;
    let wall = started.elapsed().as_secs_f64();
    let mut table = String::new();
    let mut row = |name: &str, value: String| table.push_str(&format!("  {name:<28} {value}\n"));
    row("recording", args.file.display().to_string());
    row("frames", format!("{frames} ({corrupt} corrupt, skipped)"));
    row("throughput (frames/s)", format!("{:.1}", frames as f64 / wall));
    row("latency p50 / p99 (ms)", format!("{p50:.3} / {p99:.3}"));
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
    row(
        "arm states",
        match (&args.arm, &truth) {
            (Some(p), _) => format!("from {}", p.display()),
            (None, Some(_)) => "synthesised from the truth's probe pose (seeded noise)".into(),
            (None, None) => "none (probe mapping off)".into(),
        },
    );
    row("states (frames)", stats.states_line());
    row(
        "tracked after init",
        format!("{:.1} %", stats.tracked_fraction() * 100.0),
    );
    if truth.is_some() {
        for (name, v) in [
            ("torso surface error (mm)", &stats.torso_mm),
            ("salient-point error (mm)", &stats.point_mm),
            ("probe mapping error (mm)", &stats.probe_mm),
            ("probe distance error (mm)", &stats.probe_distance_mm),
        ] {
            row(name, format!("{:.1} over {} frames", pipeline::mean(v), v.len()));
        }
    }
    row("budget overruns", stats.budget_overruns.to_string());
    row("heap allocations after init", stats.allocations_summary());
    crate::console::out(&format!("supine replay summary\n{table}"))?;
    if let Some(out) = json_out {
        let mut j = stats.json();
        j["recorded_frames"] = serde_json::json!(args.record.as_ref().map(|_| report.recorded));
        j["live_view"] = serde_json::json!(report.live.map(|s| serde_json::json!({
            "connections": s.connections, "queued": s.queued, "dropped": s.dropped
        })));
        j["recording"] = args.file.display().to_string().into();
        let report = j;
        let text = serde_json::to_string_pretty(&report).map_err(anyhow::Error::from)?;
        output::write_all(out, text.as_bytes())?;
    }
    Ok(())
}
