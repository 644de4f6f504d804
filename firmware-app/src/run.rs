//! `supine run`: the service on the head computer. `--check-config` validates its configuration: every key, the
//! source and link strings, and the model files it names (present, of the right kind, and valid as core loads
//! them). `--config` validates the same way, then runs the service loop (`crate::service`).

use std::path::PathBuf;

use crate::config;
use crate::failure::Failure;
use clap::Args;

/// Arguments of `supine run`.
#[derive(Args, Debug)]
#[command(group = clap::ArgGroup::new("file").required(true))]
pub struct RunArgs {
    /// The service configuration (e.g. /etc/supine/supine.toml).
    #[arg(long, group = "file", value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Validate this configuration and its model files, print a summary, and exit (0 when valid, 2 when not).
    #[arg(long, group = "file", value_name = "FILE")]
    pub check_config: Option<PathBuf>,
}

/// Run `supine run`.
pub fn run(args: RunArgs) -> Result<(), Failure> {
    if let Some(path) = args.check_config {
        let checked = check(&path)?;
        crate::console::out(&summary(&path, &checked))?;
        return Ok(());
    }
    let path = args.config.unwrap_or_default();
    let checked = check(&path)?;
    let stats = crate::service::serve(&checked)?;
    crate::note!(
        "supine run: {} frames, {} sensor faults ({} reopens), {} arm states, {} commands, {} send errors",
        stats.frames,
        stats.source_faults,
        stats.reopens,
        stats.arm_states,
        stats.commands,
        stats.send_errors
    );
    Ok(())
}

/// Parse the file and check the model files it names; a bad file or model is a usage error (exit 2).
fn check(path: &std::path::Path) -> Result<config::Checked, Failure> {
    let c = config::load(path).map_err(|e| Failure::usage(e.to_string()))?;
    use crate::models::ModelCheck;
    use supine_core::{body_model, forest, shape};
    for (key, file, want) in [
        ("models.body", &c.body_model, body_model::KIND),
        ("models.joints", &c.joint_forest, forest::model::KIND),
        ("models.shape", &c.shape_model, shape::KIND),
    ] {
        let bad = |what: String| {
            Failure::usage(format!(
                "{}: `{key}` = {}: {what}",
                path.display(),
                file.display()
            ))
        };
        let bytes = std::fs::read(file).map_err(|e| bad(e.to_string()))?;
        let (kind, valid) = match crate::models::check(&bytes) {
            ModelCheck::Valid { kind, .. } => (kind, Ok(())),
            ModelCheck::Invalid { kind, error } => (kind, Err(error)),
            ModelCheck::NotAModel => return Err(bad("not a supine model file".into())),
            ModelCheck::UnknownKind(k) => return Err(bad(format!("model kind {k:?} unknown to this build"))),
        };
        if kind != want {
            return Err(bad(format!(
                "a {} model file, a {} model expected",
                crate::models::kind_name(kind),
                crate::models::kind_name(want)
            )));
        }
        valid.map_err(bad)?;
    }
    Ok(c)
}

fn summary(path: &std::path::Path, c: &config::Checked) -> String {
    let extrinsic = match &c.robot_base_from_camera {
        Some(t) => format!(
            "translation {:.3?} m, rotation {:.2}°",
            t.translation.vector.as_slice(),
            t.rotation.angle().to_degrees()
        ),
        None => "none (probe mapping off)".into(),
    };
    format!(
        "{}: valid\n  source                 {}{}\n  link                   {}\n  body model             {}\n  \
         joint forest           {}\n  shape model            {}\n  frame budget           {:.1} ms, {} ICP \
         iterations\n  init                   {} shape frames, {:.0} s timeout\n  log filter             {}\n  \
         robot_base_from_camera {extrinsic}\n",
        path.display(),
        c.source,
        if c.loop_source { " (looped)" } else { "" },
        c.link,
        c.body_model.display(),
        c.joint_forest.display(),
        c.shape_model.display(),
        c.frame_budget_us as f64 / 1000.0,
        c.icp_iterations,
        c.shape_frames,
        c.init_timeout_s,
        c.log_filter,
    )
}
