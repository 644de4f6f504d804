//! `supine record --source SOURCE --out FILE.oni [--frames N]`: record a depth stream to an .oni file that
//! libOpenNI2 and `supine replay` play back.
//!
//! Live sources record until `--frames` frames are written (or forever: the file is written as it goes and stays
//! readable up to the last whole frame if the process is killed); file sources stop at their end. Consecutive
//! timeouts for longer than `--timeout-ms` end the recording with an error.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use supine_drivers::kinect_raw::DisparityCalibration;
use supine_drivers::oni::{Codec, OniWriter};
use supine_drivers::source::{self, OpenOptions, SourceErrorKind, SourceSpec};

use crate::failure::Failure;

/// Arguments of `supine record`.
#[derive(Args, Debug)]
pub struct RecordArgs {
    /// Depth source: openni2[:URI], freenect[:INDEX], v4l2:/dev/videoN or file:PATH.
    #[arg(long)]
    pub source: String,
    /// Output .oni file (created or truncated).
    #[arg(long)]
    pub out: PathBuf,
    /// Stop after this many frames (default: until the source ends).
    #[arg(long)]
    pub frames: Option<u32>,
    /// Depth codec: 16zT (what OpenNI's Recorder writes, default), 16zP or NONE (raw).
    #[arg(long, default_value = "16zT")]
    pub codec: Codec,
    /// Give up after this long without a frame, milliseconds.
    #[arg(long, default_value_t = 5000)]
    pub timeout_ms: u64,
    /// Raw→mm calibration "a,b" for v4l2 sources (1/z = a·raw + b, see drivers/README.md).
    #[arg(long)]
    pub v4l2_calibration: Option<DisparityCalibration>,
}

/// Run `supine record`.
pub fn run(args: RecordArgs) -> Result<(), Failure> {
    let spec: SourceSpec = args
        .source
        .parse()
        .map_err(|e: source::SourceError| Failure::usage(format!("--source: {e}")))?;
    if args.frames == Some(0) {
        return Err(Failure::usage("--frames must be at least 1"));
    }
    let options = OpenOptions {
        v4l2_calibration: args.v4l2_calibration,
    };
    let mut src = source::open_with(&spec, &options).map_err(|e| anyhow::anyhow!("opening {spec}: {e}"))?;
    let k = src.intrinsics();
    let mut writer = OniWriter::create(&args.out, &k, args.codec)
        .map_err(|e| anyhow::anyhow!("creating {}: {e}", args.out.display()))?;
    eprintln!(
        "recording {} ({}x{}) to {} with {}",
        src.describe(),
        k.width,
        k.height,
        args.out.display(),
        args.codec
    );
    let limit = Duration::from_millis(args.timeout_ms);
    let started = Instant::now();
    let mut last_frame = Instant::now();
    let mut last_report = Instant::now();
    loop {
        if args.frames.is_some_and(|n| writer.frames_written() >= n) {
            break;
        }
        match src.next_frame(Duration::from_millis(200).min(limit)) {
            Ok(frame) => {
                writer
                    .write(&frame)
                    .map_err(|e| anyhow::anyhow!("writing {}: {e}", args.out.display()))?;
                last_frame = Instant::now();
            }
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) if e.kind() == SourceErrorKind::Timeout => {
                if last_frame.elapsed() >= limit {
                    return Err(anyhow::anyhow!("no frame from {spec} for {} ms", args.timeout_ms).into());
                }
            }
            Err(e) => return Err(anyhow::anyhow!("reading {spec}: {e}").into()),
        }
        if last_report.elapsed() >= Duration::from_secs(2) {
            let total = args.frames.map_or(String::new(), |n| format!("/{n}"));
            eprint!(
                "\r{}{total} frames, {:.0} s",
                writer.frames_written(),
                started.elapsed().as_secs_f64()
            );
            last_report = Instant::now();
        }
    }
    let n = writer.frames_written();
    writer
        .finish()
        .map_err(|e| anyhow::anyhow!("finishing {}: {e}", args.out.display()))?;
    let bytes = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(0);
    eprintln!("\rrecorded {n} frames ({bytes} bytes) to {}", args.out.display());
    if n == 0 {
        return Err(anyhow::anyhow!("{spec} delivered no frames").into());
    }
    Ok(())
}
