//! `supine wire …`: see, decode and send the wire protocol without any tracking running.

mod decode;
pub mod json;
mod listen;
mod sample;
mod send;

use clap::{Args, Subcommand, ValueEnum};

use crate::failure::Failure;

/// The wire subcommands.
#[derive(Subcommand)]
pub enum WireCommand {
    /// Print the documented sample messages in one encoding, one per line.
    Sample(SampleArgs),
    /// Decode a byte or text stream from stdin into JSON lines; corrupt input is counted, never fatal.
    Decode(DecodeArgs),
    /// Link bring-up: send the sample messages through a real link (serial, SLCAN, CAN).
    Send(SendArgs),
    /// Link bring-up: print what arrives from the arm controller as JSON lines, with error counters.
    Listen(ListenArgs),
}

/// Encodings the wire tools print or read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// One JSON object per message (print only).
    Json,
    /// can-utils log format, `(0.000000) can0 123#0102...`, one CAN frame per line.
    Candump,
    /// Lawicel SLCAN ASCII lines (`t1238...`), `\r`-terminated.
    Slcan,
    /// One serial frame (postcard + CRC + COBS, 0x00-delimited) per line as hex.
    CobsHex,
}

/// Arguments of `supine wire sample`.
#[derive(Args)]
pub struct SampleArgs {
    /// Output encoding.
    #[arg(long, value_enum)]
    pub format: Format,
}

/// Arguments of `supine wire decode`.
#[derive(Args)]
pub struct DecodeArgs {
    /// Input encoding (json is not accepted here).
    #[arg(long, value_enum)]
    pub format: Format,
}

/// Arguments of `supine wire send`.
#[derive(Args)]
pub struct SendArgs {
    /// Where to send: `stdout`, `serial:PATH[@BAUD]`, `slcan:PATH[@BAUD]`, `can:IFACE`, `file:PATH`.
    #[arg(long)]
    pub sink: String,
    /// How many rounds of the sample set to send (default: one round).
    #[arg(long, default_value_t = 1, value_parser = crate::numbers::positive_u32)]
    pub count: u32,
    /// Rounds per second.
    #[arg(long, default_value_t = 30.0)]
    pub rate: f64,
}

/// Arguments of `supine wire listen`.
#[derive(Args)]
pub struct ListenArgs {
    /// What to listen on: `serial:PATH[@BAUD]`, `slcan:PATH[@BAUD]`, `can:IFACE`, `file:PATH`.
    #[arg(long)]
    pub link: String,
    /// Stop after this many decoded messages (default: run until interrupted or the link ends).
    #[arg(long, value_parser = crate::numbers::positive_u64)]
    pub count: Option<u64>,
    /// Stop after this many seconds without any message.
    #[arg(long)]
    pub idle_timeout: Option<f64>,
}

/// Run one wire subcommand.
pub fn run(cmd: WireCommand) -> Result<(), Failure> {
    match cmd {
        WireCommand::Sample(args) => sample::run(&args),
        WireCommand::Decode(args) => decode::run(&args),
        WireCommand::Send(args) => send::run(&args),
        WireCommand::Listen(args) => listen::run(&args),
    }
}
