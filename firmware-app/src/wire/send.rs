//! `supine wire send`: link bring-up. Sends the documented sample messages through a real link, `--count`
//! rounds at `--rate` rounds per second (round `r` adds `r` to every sequence number, so a receiver can count
//! losses), then closes the link cleanly (queue flushed, SLCAN `C\r`) and prints a summary with the link's
//! counters on stderr: one human line, then one JSON object. SIGINT/SIGTERM end the run early, still cleanly.

use std::time::{Duration, Instant};

use serde_json::json;
use supine_core::wire::sample;
use supine_drivers::link::{self, Link, LinkOptions, LinkSpec};

use super::SendArgs;
use crate::failure::Failure;
use crate::links;
use crate::note;

/// Slowest accepted `--rate` (one round a day).
const MIN_RATE_HZ: f64 = 1.0 / 86_400.0;
/// Fastest accepted `--rate`.
const MAX_RATE_HZ: f64 = 100_000.0;

/// How long closing may take to flush the queue.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(3);

/// Run `supine wire send`.
pub fn run(args: &SendArgs) -> Result<(), Failure> {
    let spec: LinkSpec = args
        .sink
        .parse()
        .map_err(|e| Failure::usage(format!("--sink: {e}")))?;
    // Bounded so that the period and every round's due time stay representable (no Duration overflow).
    if !(args.rate.is_finite() && (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&args.rate)) {
        return Err(Failure::usage(format!(
            "--rate: {} is out of range (1/86400 = {MIN_RATE_HZ:.9} to {MAX_RATE_HZ:.0} rounds per second)",
            args.rate
        )));
    }
    let period = Duration::from_secs_f64(1.0 / args.rate);
    links::catch_interrupts().map_err(|e| anyhow::anyhow!("installing the SIGINT handler: {e}"))?;
    let mut link = link::open(&spec, &LinkOptions::default()).map_err(|e| anyhow::anyhow!("{e}"))?;
    tracing::info!(link = link.describe(), rounds = args.count, "link open, sending");

    let start = Instant::now();
    let mut rounds = 0u32;
    let mut encode_failures = 0u64;
    'rounds: for round in 0..args.count {
        for mut m in sample::messages() {
            if links::interrupted() {
                break 'rounds;
            }
            m.seq = m.seq.wrapping_add(round as u16);
            if let Err(e) = link.send(&m) {
                encode_failures += 1;
                tracing::warn!(kind = m.kind().name(), error = %e, "message not sent");
            }
        }
        rounds += 1;
        if round + 1 == args.count {
            break;
        }
        // Keep the writer going until the next round is due.
        let Some(due) = period.checked_mul(round + 1).and_then(|d| start.checked_add(d)) else {
            break;
        };
        while !links::interrupted() {
            link.poll();
            let now = Instant::now();
            if now >= due {
                break;
            }
            std::thread::sleep((due - now).min(Duration::from_millis(2)));
        }
    }
    let closed = link.close(CLOSE_TIMEOUT);
    let c = link.counters();
    let elapsed = start.elapsed().as_secs_f64();
    note!(
        "supine wire send: {} round(s) to {} in {:.2} s: {} messages sent, {} dropped, {} reconnects{}",
        rounds,
        link.describe(),
        elapsed,
        c.sent,
        c.dropped,
        c.reconnects,
        if links::interrupted() {
            " (interrupted)"
        } else {
            ""
        }
    );
    let summary = json!({
        "command": "send",
        "link": link.describe(),
        "rounds": rounds,
        "messages_per_round": sample::messages().len(),
        "elapsed_s": elapsed,
        "interrupted": links::interrupted(),
        "closed_cleanly": closed.is_ok(),
        "counters": links::counters_json(&c),
    });
    note!("{summary}");
    // A sink whose writes failed (ENOSPC, EIO, ...) makes the run fail, naming the OS error once.
    if let Some(e) = link.last_io_error() {
        if link.describe() == "stdout" && e.contains("(os error 32)") {
            return Err(Failure::BrokenPipe);
        }
        return Err(anyhow::anyhow!(
            "writing to {}: {e} ({} write error(s), {} of {} messages not delivered)",
            link.describe(),
            c.io_errors,
            c.queued.saturating_sub(c.sent),
            c.queued
        )
        .into());
    }
    if encode_failures > 0 {
        return Err(anyhow::anyhow!(
            "{encode_failures} message(s) could not be encoded for {}",
            link.describe()
        )
        .into());
    }
    closed.map_err(|e| anyhow::anyhow!("closing {}: {e}", link.describe()))?;
    Ok(())
}
