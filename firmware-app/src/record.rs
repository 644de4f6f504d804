//! `supine record --source SOURCE --out FILE.oni [--frames N]`: record a depth stream to an .oni file that
//! libOpenNI2 and `supine replay` play back.
//!
//! Live sources record until `--frames` frames are written (or forever); file sources stop at their end.
//! Consecutive timeouts for longer than `--timeout-ms` end the recording with an error. The recording is written
//! to a temporary file beside `--out` (`.NAME.PID.partial`, readable up to the last whole frame if the process is
//! killed) and renamed over `--out` only when it is complete, so a failed run leaves an old file intact; a failed
//! run's partial recording is kept and named in the error. `--out` may not be the `file:` source.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use supine_drivers::kinect_raw::DisparityCalibration;
use supine_drivers::oni::{Codec, OniWriter, OniWriterConfig};
use supine_drivers::source::{self, DepthSource, OpenOptions, SourceErrorKind, SourceSpec};

use crate::failure::Failure;
use crate::note_raw;
use crate::output::{self, Output};

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
    #[arg(long, value_parser = crate::numbers::positive_u32)]
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
    let options = OpenOptions {
        v4l2_calibration: args.v4l2_calibration,
    };
    let inputs: Vec<(&str, &std::path::Path)> =
        spec.file_path().map(|p| ("--source", p)).into_iter().collect();
    if let Some(path) = spec.file_path()
        && std::fs::metadata(path).is_ok_and(|m| !m.is_file())
    {
        return Err(anyhow::anyhow!("--source {}: not a regular file", path.display()).into());
    }
    // Checked and created before the source is opened: an unwritable --out fails at start.
    let mut out = Output::create("--out", &args.out, &inputs)?;
    // A file source's error already names its path; other sources are named by their spec.
    let mut src = source::open_with(&spec, &options).map_err(|e| match spec.file_path() {
        Some(_) => anyhow::anyhow!("--source: {e}"),
        None => anyhow::anyhow!("opening {spec}: {e}"),
    })?;
    let k = src.intrinsics();
    let file = std::io::BufWriter::with_capacity(1 << 20, out.take_file());
    let mut writer = match OniWriter::new(file, OniWriterConfig::new(&k, args.codec)) {
        Ok(w) => w,
        Err(e) => {
            let kept = out.abandon();
            let err = anyhow::anyhow!("creating {}: {e}", args.out.display());
            return Err(output::with_partial(err, kept).into());
        }
    };
    let result = record(&args, &spec, &mut *src, &mut writer);
    let n = writer.frames_written();
    let finished = result.and_then(|()| {
        writer
            .finish()
            .map(drop)
            .map_err(|e| anyhow::anyhow!("finishing {}: {e}", args.out.display()).into())
    });
    if let Err(e) = finished {
        let kept = out.abandon();
        return Err(match e {
            Failure::Runtime(err) => output::with_partial(err, kept).into(),
            other => other,
        });
    }
    if n == 0 {
        drop(out.abandon());
        return Err(anyhow::anyhow!("{spec} delivered no frames").into());
    }
    out.commit()?;
    let bytes = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(0);
    crate::note!("\rrecorded {n} frames ({bytes} bytes) to {}", args.out.display());
    Ok(())
}

/// The recording loop: frames from `src` into `writer` until `--frames`, the source's end, or a failure.
fn record(
    args: &RecordArgs,
    spec: &SourceSpec,
    src: &mut dyn DepthSource,
    writer: &mut OniWriter<std::io::BufWriter<std::fs::File>>,
) -> Result<(), Failure> {
    let k = src.intrinsics();
    crate::note!(
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
            Err(e) => {
                return Err(match spec.file_path() {
                    Some(_) => anyhow::anyhow!("--source: {e}"),
                    None => anyhow::anyhow!("reading {spec}: {e}"),
                }
                .into());
            }
        }
        if last_report.elapsed() >= Duration::from_secs(2) {
            let total = args.frames.map_or(String::new(), |n| format!("/{n}"));
            note_raw!(
                "\r{}{total} frames, {:.0} s",
                writer.frames_written(),
                started.elapsed().as_secs_f64()
            );
            last_report = Instant::now();
        }
    }
    Ok(())
}
