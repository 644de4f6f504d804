//! `supine wire listen`: link bring-up. Prints every message that arrives (arm state, commands, and any other
//! valid message) as one JSON line on stdout; damaged input is counted, never fatal. Once the link is open, every
//! `REPORT_EVERY` and at the end a JSON object with the link's counters and the sequence accounting (messages lost
//! by gaps) goes to stderr; the last one has `stopped` set to the reason. Stops on `--count` messages, `--idle-timeout` seconds without one, the end of a `file:` capture, or
//! SIGINT/SIGTERM, always cleanly (exit 0).

use std::io::Write;
use std::time::{Duration, Instant};

use supine_drivers::link::{self, FileMode, Link, LinkOptions, LinkSpec, LinkState, SequenceAccounting};

use super::{ListenArgs, json};
use crate::failure::Failure;
use crate::links;
use crate::note;

/// How often the counters are reported on stderr while listening.
const REPORT_EVERY: Duration = Duration::from_secs(5);
/// Longest wait for input before the loop checks the stop conditions again.
const WAIT_SLICE: Duration = Duration::from_millis(50);

/// Run `supine wire listen`.
pub fn run(args: &ListenArgs) -> Result<(), Failure> {
    let spec: LinkSpec = args
        .link
        .parse()
        .map_err(|e| Failure::usage(format!("--link: {e}")))?;
    if !spec.can_receive() {
        return Err(Failure::usage(format!(
            "--link: `{}` can only send; listen on serial:, slcan:, can: or file:",
            args.link
        )));
    }
    let idle_timeout = match args.idle_timeout {
        Some(s) if s > 0.0 && Duration::try_from_secs_f64(s).is_ok() => Some(Duration::from_secs_f64(s)),
        Some(s) => {
            return Err(Failure::usage(format!(
                "--idle-timeout: {s} is not a positive number of seconds"
            )));
        }
        None => None,
    };
    links::catch_interrupts().map_err(|e| anyhow::anyhow!("installing the SIGINT handler: {e}"))?;
    let options = LinkOptions {
        file_mode: FileMode::Read,
        ..LinkOptions::default()
    };
    let mut link = link::open(&spec, &options).map_err(|e| anyhow::anyhow!("{e}"))?;

    let start = Instant::now();
    // A first report as soon as the link is open: tells a human (and a peer script) that listening has begun.
    note!("{}", report(&*link, &SequenceAccounting::new(), 0, start, None));
    let mut last_message = start;
    let mut last_report = start;
    let mut accounting = SequenceAccounting::new();
    let mut messages = 0u64;
    // A closed pipe or a full disk on stdout: the loop stops and the run ends with that failure.
    let mut stdout_error: Option<std::io::Error> = None;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let reason = loop {
        if links::interrupted() {
            break "interrupted";
        }
        if args.count.is_some_and(|n| messages >= n) {
            break "count";
        }
        match link.receive() {
            Ok(Some(m)) => {
                messages += 1;
                last_message = Instant::now();
                accounting.observe(&m);
                let line = json::message(&m);
                if let Err(e) = writeln!(out, "{line}").and_then(|()| out.flush()) {
                    stdout_error = Some(e);
                    break "stdout closed";
                }
                continue;
            }
            Ok(None) => {}
            Err(e) => return Err(anyhow::anyhow!("receiving on {}: {e}", link.describe()).into()),
        }
        if link.state() == LinkState::Ended {
            break "end of input";
        }
        let now = Instant::now();
        if idle_timeout.is_some_and(|t| now.duration_since(last_message) >= t) {
            break "idle timeout";
        }
        if now.duration_since(last_report) >= REPORT_EVERY {
            last_report = now;
            note!("{}", report(&*link, &accounting, messages, start, None));
        }
        link.wait_readable(WAIT_SLICE);
    };
    drop(out);
    let _ = link.close(Duration::from_secs(1));
    note!("{}", report(&*link, &accounting, messages, start, Some(reason)));
    if let Some(e) = link.last_io_error() {
        return Err(anyhow::anyhow!("reading {}: {e}", link.describe()).into());
    }
    if let Some(e) = stdout_error {
        return Err(crate::console::stdout_failure(e));
    }
    Ok(())
}

fn report(
    link: &dyn Link,
    accounting: &SequenceAccounting,
    messages: u64,
    start: Instant,
    stopped: Option<&str>,
) -> serde_json::Value {
    serde_json::json!({
        "command": "listen",
        "link": link.describe(),
        "state": link.state().as_str(),
        "elapsed_s": start.elapsed().as_secs_f64(),
        "messages": messages,
        "stopped": stopped,
        "sequence": links::sequence_json(accounting),
        "counters": links::counters_json(&link.counters()),
    })
}
