//! `supine run`: the service on the head computer. `--check-config` validates its configuration: every key, the
//! source and link strings, and the model files it names (present, of the right kind, and valid as core loads
//! them). `--config` validates the same way, starts logging with the config's `[log] filter` (unless `SUPINE_LOG` or
//! `-v` say otherwise), then runs the service loop (`crate::service`), with `--record OUT.mcap` and `--view PORT`
//! writing and serving the Foxglove channels `supine replay` has (frames are dropped, never waited for, when the
//! outputs fall behind the sensor).

use std::path::PathBuf;

use std::time::Duration;

use crate::config;
use crate::failure::Failure;
use crate::foxglove::live::{self, LiveView};
use crate::foxglove::outputs::{FoxgloveOutputs, Pace};
use crate::numbers;
use crate::output::{self, Output};
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
    /// Also write the Foxglove channels (depth, scene, transforms, packets) to this MCAP file.
    #[arg(long, value_name = "OUT.mcap", conflicts_with = "check_config")]
    pub record: Option<PathBuf>,
    /// Serve the same channels live over the Foxglove WebSocket protocol on PORT (all interfaces) or HOST:PORT.
    #[arg(long, value_name = "PORT", value_parser = live::parse_addr, conflicts_with = "check_config")]
    pub view: Option<std::net::SocketAddr>,
    /// With --view: wait up to this many seconds for a viewer to subscribe before the first frame.
    #[arg(long, value_name = "SECONDS", requires = "view", value_parser = numbers::positive_u32)]
    pub view_wait: Option<u32>,
}

/// Run `supine run` (`verbose`: the count of `-v`).
pub fn run(args: RunArgs, verbose: u8) -> Result<(), Failure> {
    if let Some(path) = args.check_config {
        let checked = check(&path)?;
        crate::console::out(&summary(&path, &checked))?;
        return Ok(());
    }
    let path = args.config.unwrap_or_default();
    let checked = check(&path)?;
    crate::init_tracing(verbose, Some(&checked.log_filter));
    let inputs = [("--config", path.as_path())];
    let mut record_out = match &args.record {
        Some(p) => Some(Output::create("--record", p, &inputs)?),
        None => None,
    };
    let live = match args.view {
        Some(addr) => {
            let v = LiveView::bind(addr).map_err(|e| anyhow::anyhow!("--view {addr}: {e}"))?;
            crate::note!(
                "supine run: live view on ws://{} (Foxglove: open connection)",
                v.local_addr()
            );
            Some(v)
        }
        None => None,
    };
    let mut outputs = if record_out.is_some() || live.is_some() {
        let file = record_out.as_mut().map(Output::take_file);
        let o = FoxgloveOutputs::new(file, live, checked.robot_base_from_camera, Pace::DropWhenBusy)
            .map_err(|e| anyhow::anyhow!("--record: {e}"))?;
        if let (Some(v), Some(secs)) = (o.live(), args.view_wait)
            && !v.wait_for_subscriber(Duration::from_secs(secs as u64))
        {
            crate::note!("supine run: no viewer subscribed within {secs} s; starting anyway");
        }
        Some(o)
    } else {
        None
    };
    let served = crate::service::serve(&checked, outputs.as_mut());
    let report = match outputs.map(FoxgloveOutputs::finish) {
        None => None,
        Some(Ok(r)) => Some(r),
        Some(Err(e)) => {
            let kept = record_out.map(Output::abandon).unwrap_or(None);
            return Err(output::with_partial(anyhow::anyhow!("--record: {e}"), kept).into());
        }
    };
    let stats = served?;
    if let Some(out) = record_out {
        out.commit()?;
    }
    let l = &stats.link;
    crate::note!(
        "supine run: {} frames, {} corrupt frames skipped, {} sensor faults ({} reopens), {} arm states, {} \
         commands, {} send errors; link: {} sent, {} dropped, {} garbage units received, {} reconnects",
        stats.frames,
        stats.corrupt,
        stats.source_faults,
        stats.reopens,
        stats.arm_states,
        stats.commands,
        stats.send_errors,
        l.sent,
        l.dropped,
        l.rx_errors.total(),
        l.reconnects
    );
    if let Some(r) = report {
        let live = r.live.map(|s| {
            format!(
                "; live view: {} clients, {} frames queued, {} dropped for slow clients",
                s.connections, s.queued, s.dropped
            )
        });
        crate::note!(
            "supine run: Foxglove outputs: {} frames recorded{}, {} frames dropped (outputs busy){}",
            r.recorded,
            args.record
                .as_ref()
                .map(|p| format!(" to {}", p.display()))
                .unwrap_or_default(),
            r.dropped,
            live.unwrap_or_default()
        );
    }
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
    let at = |n: Option<u64>| n.map_or_else(|| "never".to_owned(), |n| format!("frame {n}"));
    let faults = match &c.faults {
        Some(f) => format!(
            "  faults                 INJECTED, test only (seed {}, corrupt-frame probability {}, unplug at {}, \
             link stall at {} for {} frames)\n",
            f.seed,
            f.corrupt_frames,
            at(f.unplug_at_frame),
            at(f.link_stall_at_frame),
            f.link_stall_frames
        ),
        None => String::new(),
    };
    format!(
        "{}: valid\n  source                 {}{}\n  link                   {}\n  body model             {}\n  \
         joint forest           {}\n  shape model            {}\n  frame budget           {:.1} ms, {} ICP \
         iterations\n  init                   {} shape frames, {:.0} s timeout\n  log filter             {}\n  \
         robot_base_from_camera {extrinsic}\n{faults}",
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
