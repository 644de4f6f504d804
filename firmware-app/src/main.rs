//! `supine`: the service on the robot's head computer and the tools an integrator uses to bring it up.
//!
//! Commands follow the contract in the README (`supine --help`): exit 0 on success, 1 on a runtime failure,
//! 2 on bad usage; errors name the bad argument or file.

mod calibrate;
mod demo;
mod failure;
mod info;
mod links;
mod notify;
mod record;
mod wire;

use clap::{Parser, Subcommand};

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
    /// Camera-to-robot extrinsic from arm states paired with the probe tip seen in depth (or from recorded pairs).
    Calibrate(calibrate::CalibrateArgs),
    /// Record a depth stream to an .oni file (plays in libOpenNI2 and `supine replay`).
    Record(record::RecordArgs),
    /// Show the models, depth devices and links this build and machine offer.
    Info(info::InfoArgs),
    /// Wire protocol tools: print samples, decode captures, bring up a link to the arm controller.
    #[command(subcommand)]
    Wire(wire::WireCommand),
}

fn init_tracing(verbose: u8) {
    use tracing_subscriber::EnvFilter;
    let default = match verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    let filter = EnvFilter::try_from_env("SUPINE_LOG").unwrap_or_else(|_| EnvFilter::new(default));
    // Logs go to stderr so that stdout stays machine-readable (JSON lines, candump, ...).
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    init_tracing(cli.verbose);
    let result = match cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Calibrate(args) => calibrate::run(args),
        Command::Record(args) => record::run(args),
        Command::Info(args) => info::run(args),
        Command::Wire(cmd) => wire::run(cmd),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(failure) => {
            eprintln!("supine: error: {failure}");
            std::process::ExitCode::from(failure.exit_code())
        }
    }
}
