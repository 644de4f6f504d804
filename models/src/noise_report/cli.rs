//! `supine-models noise-report`: argument parsing, the Markdown table on stdout, `--json` and `--png`.

use super::stats::Window;
use super::{compare, side, sources};
use std::path::PathBuf;
use std::process::ExitCode;
use supine_core::camera::Intrinsics;

/// Arguments of `supine-models noise-report`.
#[derive(Debug, clap::Args)]
pub struct NoiseReportArgs {
    /// Real frames: a depth PNG (16-bit mm), .oni or .mcap file, or a directory of them.
    #[arg(long)]
    pub real: PathBuf,
    /// Synthetic frames: a dataset or sequence directory from `supine-models`, or files as for --real.
    #[arg(long)]
    pub synthetic: PathBuf,
    /// Intrinsics of PNGs and of bags without camera info: fx,fy,cx,cy in pixels (the PCL five_people frame's).
    #[arg(long, default_value = "525,525,319.5,239.5")]
    pub intrinsics: String,
    /// Nearest depth counted, mm.
    #[arg(long, default_value_t = 1000)]
    pub min_mm: u16,
    /// Farthest depth counted, mm.
    #[arg(long, default_value_t = 3500)]
    pub max_mm: u16,
    /// Frames read per side at most.
    #[arg(long, default_value_t = 200)]
    pub max_frames: usize,
    /// Write the full report (counts, histograms, judged rows) as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Draw the histograms side by side into this PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

fn usage(msg: &str) -> ExitCode {
    eprintln!("error: {msg}");
    ExitCode::from(2)
}

/// Run the command; exit 0 on success, 1 on a runtime failure, 2 on bad arguments.
pub fn run(args: NoiseReportArgs) -> ExitCode {
    let k: Vec<f32> = match args
        .intrinsics
        .split(',')
        .map(|s| s.trim().parse::<f32>())
        .collect()
    {
        Ok(k) => k,
        Err(_) => return usage("--intrinsics must be four numbers fx,fy,cx,cy"),
    };
    if k.len() != 4 || k[0] <= 0.0 || k[1] <= 0.0 || k.iter().any(|v| !v.is_finite()) {
        return usage("--intrinsics must be four numbers fx,fy,cx,cy with positive focal lengths");
    }
    if args.min_mm >= args.max_mm {
        return usage("--min-mm must be below --max-mm");
    }
    if args.max_frames == 0 {
        return usage("--max-frames must be at least 1");
    }
    let camera = Intrinsics {
        fx: k[0],
        fy: k[1],
        cx: k[2],
        cy: k[3],
        width: 640,
        height: 480,
    };
    match run_inner(&args, camera) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

fn run_inner(args: &NoiseReportArgs, camera: Intrinsics) -> anyhow::Result<()> {
    let window = Window {
        min_mm: args.min_mm,
        max_mm: args.max_mm,
    };
    sources::check_kind(&args.real)?;
    sources::check_kind(&args.synthetic)?;
    let real = sources::measure_source(&args.real, camera, window, args.max_frames)?;
    let synthetic = sources::measure_source(&args.synthetic, camera, window, args.max_frames)?;
    let report = compare(
        [args.min_mm, args.max_mm],
        side(real.description, &real.frames),
        side(synthetic.description, &synthetic.frames),
    );
    print!("{}", report.markdown());
    if let Some(path) = &args.json {
        let mut v = serde_json::to_value(&report)?;
        v["command"] = "noise-report".into();
        std::fs::write(path, serde_json::to_vec_pretty(&v)?)
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    if let Some(path) = &args.png {
        super::plot::write_png(&report, path)?;
    }
    Ok(())
}
