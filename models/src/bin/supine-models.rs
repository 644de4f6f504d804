//! `supine-models`: the host-only toolchain (body model, synthetic data, training, evaluation). See `--help`.

use clap::{Parser, Subcommand};

/// supine's model toolchain: body model, synthetic Kinect data, training and evaluation (host only).
#[derive(Parser)]
#[command(name = "supine-models", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match cli.command {}
}
