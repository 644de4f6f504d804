//! `supine-bench`: the supine halves of the side-by-side benchmarks (issue 14); `tests/bench/run.sh` runs them with
//! the Python peers and writes docs/BENCHMARKS.md. See `--help`.

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use supine_models::bench::{forest, icp};

/// Benchmarks of supine beside Open3D, small_gicp and scikit-learn (host only).
#[derive(Parser)]
#[command(name = "supine-bench", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// ICP problems from generated held-out patients (views with and without the arm) and supine's registrations
    Icp(IcpArgs),
    /// Forest: train and time supine's joint forest and export the same samples for scikit-learn
    Forest(ForestArgs),
}

#[derive(clap::Args)]
struct IcpArgs {
    /// Output directory (problems.json, supine.json, .npy point sets)
    #[arg(long)]
    out: PathBuf,
    /// Seed of the patients, views and start perturbations
    #[arg(long, default_value_t = 1400)]
    seed: u64,
    /// Patients (held out: generated here, never trained on)
    #[arg(long, default_value_t = 8)]
    bodies: u32,
    /// Views per patient (half with the robot arm)
    #[arg(long, default_value_t = 4)]
    views: u16,
    /// Start perturbation: rotation, degrees
    #[arg(long, default_value_t = 5.0)]
    rotation_deg: f32,
    /// Start perturbation: translation, metres
    #[arg(long, default_value_t = 0.03)]
    translation_m: f32,
    /// Most ICP iterations
    #[arg(long, default_value_t = 10)]
    iterations: usize,
    /// Timed repetitions per problem (median)
    #[arg(long, default_value_t = 21)]
    repeats: usize,
}

#[derive(clap::Args)]
struct ForestArgs {
    /// Output directory (supine.json, supine.jfor, .npy training bank and held-out images)
    #[arg(long)]
    out: PathBuf,
    /// Seed
    #[arg(long, default_value_t = 1414)]
    seed: u64,
    /// Bodies (70 % train, 30 % held out)
    #[arg(long, default_value_t = 30)]
    bodies: u32,
    /// Views per body
    #[arg(long, default_value_t = 8)]
    views: u16,
    /// Trees
    #[arg(long, default_value_t = 3)]
    trees: usize,
    /// Maximum depth
    #[arg(long, default_value_t = 20)]
    depth: usize,
    /// Fewest samples a node needs to split
    #[arg(long, default_value_t = 50)]
    min_split: usize,
    /// Candidate tests per split (scikit-learn: max_features)
    #[arg(long, default_value_t = 128)]
    candidates: usize,
    /// Features in scikit-learn's bank
    #[arg(long, default_value_t = 512)]
    bank: usize,
    /// Samples per image
    #[arg(long, default_value_t = 512)]
    samples: usize,
    /// Refinement epochs of supine's trainer
    #[arg(long, default_value_t = 48)]
    epochs: usize,
    /// Held-out images at most
    #[arg(long, default_value_t = 60)]
    test_images: usize,
    /// Timed passes over the held-out images
    #[arg(long, default_value_t = 5)]
    repeats: usize,
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Icp(a) => {
            let cfg = icp::ProblemConfig {
                seed: a.seed,
                bodies: a.bodies,
                views: a.views,
                rotation_deg: a.rotation_deg,
                translation_m: a.translation_m,
                repeats: a.repeats,
            };
            let stop = icp::StopRule {
                max_iterations: a.iterations,
                ..icp::StopRule::default()
            };
            let r = icp::run(&cfg, &stop, &a.out, true)?;
            let n = r["results"].as_array().map_or(0, |v| v.len());
            println!("supine-bench icp: {n} problems in {}", a.out.display());
        }
        Command::Forest(a) => {
            let cfg = forest::ForestBenchConfig {
                seed: a.seed,
                bodies: a.bodies,
                views: a.views,
                trees: a.trees,
                depth: a.depth,
                min_split: a.min_split,
                candidates: a.candidates,
                bank: a.bank,
                samples: a.samples,
                epochs: a.epochs,
                test_images: a.test_images,
                repeats: a.repeats,
            };
            let r = forest::run(&cfg, &a.out, true)?;
            println!(
                "supine-bench forest: trained in {:.1} s, {} bytes, {:.3} ms/frame, joint error {:.1} mm",
                r["train_s"].as_f64().unwrap_or(f64::NAN),
                r["model_bytes"],
                r["frame_ms_median"].as_f64().unwrap_or(f64::NAN),
                r["joint_error_mm_mean"].as_f64().unwrap_or(f64::NAN)
            );
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("supine-bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}
