//! `supine`: the service on the robot's head computer and the tools an integrator uses to bring it up.
//!
//! Commands follow the contract in the README (`supine --help`): exit 0 on success, 1 on a runtime failure,
//! 2 on bad usage; errors name the bad argument or file. A closed stdout pipe (`| head`) ends quietly with 141, the
//! status of a program killed by SIGPIPE; a failure to write stderr turns a success into exit 1.

mod allocs;
mod arm_track;
mod calibrate;
mod config;
mod console;
mod demo;
mod failure;
mod faults;
mod foxglove;
mod frame_bench;
mod info;
mod links;
mod model_dirs;
mod models;
mod notify;
mod numbers;
mod output;
mod overlay_png;
mod pipeline;
mod record;
mod replay;
mod run;
mod service;
mod truth;
mod watchdog;
mod wire;

use clap::{Parser, Subcommand};

use crate::failure::Failure;

/// supine: upper-body tracking of a patient on a bed from a Kinect v1, with pose and probe packets to the arm controller.
#[derive(Parser)]
#[command(name = "supine", version, about, propagate_version = true)]
struct Cli {
    /// More log output on stderr (-v info, -vv debug, -vvv trace); `SUPINE_LOG` takes a tracing filter too.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The main job on the committed synthetic recording: the whole pipeline as far as it is built, then a table.
    Demo(demo::DemoArgs),
    /// The service: the real-time tracker from the configured source to the configured link (`--check-config`
    /// validates a configuration and exits).
    Run(run::RunArgs),
    /// Camera-to-robot extrinsic from arm states paired with the probe tip seen in depth (or from recorded pairs).
    Calibrate(calibrate::CalibrateArgs),
    /// Play a recording (.oni or a ROS 2 MCAP depth bag) through the per-frame path; record or view it in Foxglove.
    Replay(replay::ReplayArgs),
    /// Record a depth stream to an .oni file (plays in libOpenNI2 and `supine replay`).
    Record(record::RecordArgs),
    /// Show the models, depth devices and links this build and machine offer.
    Info(info::InfoArgs),
    /// Wire protocol tools: print samples, decode captures, bring up a link to the arm controller.
    #[command(subcommand)]
    Wire(wire::WireCommand),
    /// The tracker's steady-state frame on the demo recording decoded into memory first: latency per frame (and,
    /// under cross/count-instructions, instructions per frame) without the recording's decompression.
    FrameBench(frame_bench::FrameBenchArgs),
}

/// Logging to stderr: `SUPINE_LOG` when set, else `-v`'s level, else `config_filter` (`supine run`'s `[log]
/// filter`), else warnings only.
pub fn init_tracing(verbose: u8, config_filter: Option<&str>) {
    use std::io::IsTerminal;
    use tracing_subscriber::EnvFilter;
    let default = match (verbose, config_filter) {
        (0, Some(f)) => f,
        (0, None) => "warn",
        (1, _) => "info",
        (2, _) => "debug",
        _ => "trace",
    };
    let (filter, bad) = match std::env::var("SUPINE_LOG") {
        Ok(spec) if !spec.trim().is_empty() => match EnvFilter::try_new(&spec) {
            Ok(f) => (f, None),
            Err(e) => (
                EnvFilter::new(default),
                Some(format!("SUPINE_LOG={spec:?} is not a valid filter ({e})")),
            ),
        },
        Ok(_) => (EnvFilter::new(default), None),
        Err(std::env::VarError::NotPresent) => (EnvFilter::new(default), None),
        Err(std::env::VarError::NotUnicode(v)) => (
            EnvFilter::new(default),
            Some(format!("SUPINE_LOG={v:?} is not valid UTF-8")),
        ),
    };
    // Logs go to stderr so that stdout stays machine-readable (JSON lines, candump, ...); colour only on a terminal.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
    if let Some(msg) = bad {
        note!("supine: warning: {msg}; using the default level `{default}`");
    }
}

/// `--help`, `--version` or a usage error from clap, written without panics: help to stdout (a closed pipe is 141,
/// a full disk exit 1 like every other command), usage errors to stderr with exit 2.
fn clap_exit(e: &clap::Error) -> std::process::ExitCode {
    use clap::error::ErrorKind;
    match e.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => match console::out(&e.render().to_string()) {
            Ok(()) => std::process::ExitCode::SUCCESS,
            Err(Failure::BrokenPipe) => std::process::ExitCode::from(Failure::BrokenPipe.exit_code()),
            Err(f) => {
                note!("supine: error: {f}");
                std::process::ExitCode::from(f.exit_code())
            }
        },
        _ => {
            // Coloured like clap does when stderr is a terminal.
            let text = if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
                e.render().ansi().to_string()
            } else {
                e.render().to_string()
            };
            note_raw!("{text}");
            std::process::ExitCode::from(2)
        }
    }
}

fn main() -> std::process::ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return clap_exit(&e),
    };
    // `supine run` starts logging once its config (and its `[log] filter`) is read.
    if !matches!(cli.command, Command::Run(_)) {
        init_tracing(cli.verbose, None);
    }
    let result = match cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Calibrate(args) => calibrate::run(args),
        Command::Record(args) => record::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Run(args) => run::run(args, cli.verbose),
        Command::Info(args) => info::run(args),
        Command::Wire(cmd) => wire::run(cmd),
        Command::FrameBench(args) => frame_bench::run(args),
    };
    match result {
        Ok(()) if console::stderr_failed() => std::process::ExitCode::FAILURE,
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(Failure::BrokenPipe) => std::process::ExitCode::from(Failure::BrokenPipe.exit_code()),
        Err(failure) => {
            note!("supine: error: {failure}");
            std::process::ExitCode::from(failure.exit_code())
        }
    }
}
