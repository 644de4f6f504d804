//! `supine frame-bench`: the steady-state cost of the tracker's frame on the head computer, without the recording's
//! decompression (a live sensor lends raw depth). The demo recording is decoded into memory first, the tracker runs
//! its init phase on it, and then `--frames N` calls of `Tracker::process` follow on the recording played forth and
//! back (so the motion stays continuous), each timed alone. The tracker reads a virtual clock set to the frames'
//! times: its decisions never depend on how fast the machine (or an emulator) runs, so instruction counts repeat
//! exactly (`cross/count-instructions`, workload `tracker-frame`: N and 2N frames differenced, init cancels out).
//! Cost per frame: one `Tracker::process` and the serial encoding of its packets; the timing is four clock reads
//! (wall time, and the thread's CPU time, which other processes on a shared machine do not inflate).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use supine_core::depth::DepthFrame;
use supine_core::time::{Timestamp, VirtualClock};
use supine_core::tracker::{ScratchSizes, Tracker};
use supine_core::wire::TrackerState;
use supine_drivers::clock::thread_cpu_ns;
use supine_drivers::source::{self, DepthSource, SourceErrorKind, SourceSpec};
use supine_drivers::tracker_host::{ModelFiles, TrackerScratch};

use crate::arm_track;
use crate::failure::Failure;
use crate::output::{self, Output};
use crate::pipeline::{self, PlayOptions};
use crate::truth::Truth;
use crate::{console, note};

/// Frames the init phase may take before the run gives up (the demo patient is acquired in a few).
const MAX_INIT_FRAMES: u32 = 300;
/// Frame period of the replayed recording, µs (30 frames/s).
const PERIOD_US: u64 = 33_333;

/// Arguments of `supine frame-bench`.
#[derive(Args)]
pub struct FrameBenchArgs {
    /// Measured frames after the init phase (the recording is played forth and back as often as needed).
    #[arg(long, default_value_t = 600, value_parser = crate::numbers::positive_u32)]
    pub frames: u32,
    /// The recording (default: the committed demo sequence); a truth.jsonl beside it gives the arm states and the
    /// camera's pose in `robot_base`.
    #[arg(long)]
    pub recording: Option<PathBuf>,
    /// Also write the figures (and every frame's latency) as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Index into a recording of `len` frames played forth and back, at step `i`.
fn ping_pong(i: u64, len: usize) -> usize {
    if len < 2 {
        return 0;
    }
    let period = 2 * (len as u64 - 1);
    let k = i % period;
    if k < len as u64 {
        k as usize
    } else {
        (period - k) as usize
    }
}

/// Peak resident set of this process so far (VmHWM), KiB; `None` where /proc does not say.
fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Run `supine frame-bench`.
pub fn run(args: FrameBenchArgs) -> Result<(), Failure> {
    let path = match &args.recording {
        Some(p) => p.clone(),
        None => crate::demo::find_recording_path()?,
    };
    let inputs = [("--recording", path.as_path())];
    let json_out = match &args.json {
        Some(p) => Some(Output::create("--json", p, &inputs)?),
        None => None,
    };
    let mut src = source::open(&SourceSpec::File { path: path.clone() })
        .map_err(|e| anyhow::anyhow!("opening {}: {e}", path.display()))?;
    let k = src.intrinsics();
    // Decoded once, outside everything measured.
    let mut frames: Vec<Vec<u16>> = Vec::new();
    loop {
        match src.next_frame(Duration::from_millis(500)) {
            Ok(f) => frames.push(f.depth_mm().to_vec()),
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) => return Err(anyhow::anyhow!("reading {}: {e}", src.describe()).into()),
        }
    }
    if frames.is_empty() {
        return Err(anyhow::anyhow!("{} holds no frames", path.display()).into());
    }
    let truth_path = path.with_file_name("truth.jsonl");
    let truth = if truth_path.is_file() {
        Some(Truth::load(&truth_path).map_err(|e| anyhow::anyhow!("{e:#}"))?)
    } else {
        None
    };
    let model_dir = crate::demo::find_models()?;
    let files = ModelFiles::load(&model_dir).map_err(|e| anyhow::anyhow!("{e}"))?;
    let models = files.views().map_err(|e| anyhow::anyhow!("model files: {e}"))?;
    let cfg = PlayOptions::new(u32::MAX, truth.as_ref()).tracker;
    let mut store = TrackerScratch::new(&ScratchSizes::of(&models, &k, &cfg.planes));
    let mut tracker = Tracker::new(models, k, cfg, store.scratch()).map_err(|e| anyhow::anyhow!("{e}"))?;
    let clock = VirtualClock::new(Timestamp::from_us(1).expect("1 µs is a valid time"));
    let mut buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
    let mut wire_bytes = 0u64;
    let mut step = 0u64;
    let mut process =
        |tracker: &mut Tracker<'_, '_>, wire_bytes: &mut u64| -> Result<TrackerState, Failure> {
            let j = ping_pong(step, frames.len());
            let t = Timestamp::from_us(1 + step * PERIOD_US)
                .ok_or_else(|| anyhow::anyhow!("--frames: too many frames for the timestamp range"))?;
            clock.set(t);
            let f = DepthFrame::new(&frames[j], k.width, k.height, t, step as u32)
                .map_err(|e| anyhow::anyhow!("frame {j}: {e}"))?;
            let arm = truth.as_ref().and_then(|tr| arm_track::from_truth(tr, j, &f));
            let report = tracker.process(&f, arm.as_ref(), &clock);
            for m in &report.packets {
                if let Ok(n) = m.encode_serial(&mut buf) {
                    *wire_bytes += n as u64;
                }
            }
            step += 1;
            Ok(report.state)
        };
    let mut init_frames = 0u32;
    while matches!(
        tracker.state(),
        TrackerState::Initialising | TrackerState::Acquiring
    ) {
        if init_frames == MAX_INIT_FRAMES {
            return Err(anyhow::anyhow!(
                "the tracker did not acquire the patient in {MAX_INIT_FRAMES} frames of {}",
                path.display()
            )
            .into());
        }
        process(&mut tracker, &mut wire_bytes)?;
        init_frames += 1;
    }
    let mut latency_us: Vec<u32> = Vec::with_capacity(args.frames as usize);
    let mut cpu_us: Vec<u32> = Vec::with_capacity(args.frames as usize);
    let mut tracked = 0u32;
    for _ in 0..args.frames {
        let c0 = thread_cpu_ns();
        let t0 = Instant::now();
        let state = process(&mut tracker, &mut wire_bytes)?;
        latency_us.push(t0.elapsed().as_micros().min(u32::MAX as u128) as u32);
        cpu_us.push(((thread_cpu_ns() - c0) / 1000).min(u32::MAX as u64) as u32);
        if matches!(state, TrackerState::Tracking | TrackerState::Degraded) {
            tracked += 1;
        }
    }
    let ms = |v: &[u32], p: f64| pipeline::percentile(v, p) / 1000.0;
    let mean = |v: &[u32]| v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64 / 1000.0;
    let rss = peak_rss_kib();
    let decoded_bytes = frames.iter().map(|f| f.len() * 2).sum::<usize>();
    console::out(&format!(
        "frames {} after {init_frames} init frames ({} decoded frames held, {:.1} MiB)\n\
         thread CPU ms p50 {:.3} p99 {:.3} mean {:.3}\n\
         wall ms       p50 {:.3} p99 {:.3} mean {:.3}\n\
         tracked {tracked} of {}\npeak RSS {} KiB\n",
        args.frames,
        frames.len(),
        decoded_bytes as f64 / (1 << 20) as f64,
        ms(&cpu_us, 50.0),
        ms(&cpu_us, 99.0),
        mean(&cpu_us),
        ms(&latency_us, 50.0),
        ms(&latency_us, 99.0),
        mean(&latency_us),
        args.frames,
        rss.map_or("-".to_owned(), |r| r.to_string()),
    ))?;
    if let Some(out) = json_out {
        let report = serde_json::json!({
            "recording": path.display().to_string(),
            "frames": args.frames,
            "init_frames": init_frames,
            "decoded_frames": frames.len(),
            "decoded_bytes": decoded_bytes,
            "tracked_frames": tracked,
            "frame_ms_p50": ms(&cpu_us, 50.0),
            "frame_ms_p99": ms(&cpu_us, 99.0),
            "frame_ms_mean": mean(&cpu_us),
            "frame_wall_ms_p50": ms(&latency_us, 50.0),
            "frame_wall_ms_p99": ms(&latency_us, 99.0),
            "frame_wall_ms_mean": mean(&latency_us),
            "peak_rss_kib": rss,
            "wire_bytes": wire_bytes,
            "cpu_us": cpu_us,
            "latency_us": latency_us,
        });
        let target = out.target().display().to_string();
        let text = serde_json::to_string_pretty(&report).map_err(anyhow::Error::from)?;
        output::write_all(out, text.as_bytes())?;
        note!("supine frame-bench: wrote {target}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::ping_pong;

    #[test]
    fn ping_pong_plays_forth_and_back() {
        let seq: Vec<usize> = (0..10).map(|i| ping_pong(i, 4)).collect();
        assert_eq!(seq, [0, 1, 2, 3, 2, 1, 0, 1, 2, 3]);
        assert_eq!(ping_pong(7, 1), 0);
    }
}
