//! `supine wire sample`: print the documented sample messages (`supine_core::wire::sample`) in one encoding.
//!
//! - `json`: one object per message and line (fields in `json.rs`).
//! - `candump`: one CAN frame per line, `(seconds.micros) can0 ID#DATA`, logged at the message's capture time.
//! - `slcan`: one frame per line, each ended by `\r` only, never `\r\n` (python-can's slcan reader drops the frame
//!   after a stray `\n`), so the output can be written straight into an SLCAN device or pty. To read it on a
//!   terminal, pipe through `tr '\r' '\n'`.
//! - `cobs-hex`: one serial frame per line, `00 ‖ COBS ‖ 00` as upper-case hex.

use std::io::Write;

use anyhow::Context;
use supine_core::wire::can::CanBase;
use supine_core::wire::serial::MAX_WIRE_LEN;
use supine_core::wire::{Message, can_map, candump, sample, slcan};

use super::{Format, SampleArgs, json};
use crate::failure::Failure;

/// Run `supine wire sample`.
pub fn run(args: &SampleArgs) -> Result<(), Failure> {
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let written = sample::MESSAGES
        .iter()
        .try_for_each(|m| write_message(&mut out, m, args.format));
    match written.and_then(|()| Ok(out.flush()?)) {
        Ok(()) => Ok(()),
        // `supine wire sample | head` closing the pipe early: quiet, with the status of a SIGPIPE death.
        Err(e) => match e.downcast::<std::io::Error>() {
            Ok(io) => Err(crate::console::stdout_failure(io)),
            Err(e) => Err(e.context("writing samples to stdout").into()),
        },
    }
}

fn write_message(out: &mut impl Write, m: &Message, format: Format) -> anyhow::Result<()> {
    match format {
        Format::Json => writeln!(out, "{}", json::message(m))?,
        Format::CobsHex => {
            let mut buf = [0u8; MAX_WIRE_LEN];
            let n = m.encode_serial(&mut buf).context("encoding a serial frame")?;
            let hex: String = buf
                .get(..n)
                .unwrap_or(&[])
                .iter()
                .map(|b| format!("{b:02X}"))
                .collect();
            writeln!(out, "{hex}")?;
        }
        Format::Candump | Format::Slcan => {
            let group = can_map::encode_group(m, CanBase::DEFAULT).context("encoding CAN frames")?;
            for f in &group {
                if format == Format::Slcan {
                    let mut line = [0u8; slcan::MAX_LINE];
                    let n = slcan::encode(f, &mut line).context("SLCAN line buffer too small")?;
                    out.write_all(line.get(..n).unwrap_or(&[]))?;
                } else {
                    let mut line = String::new();
                    candump::encode(f, m.timestamp.as_us(), "can0", &mut line)?;
                    writeln!(out, "{line}")?;
                }
            }
        }
    }
    Ok(())
}
