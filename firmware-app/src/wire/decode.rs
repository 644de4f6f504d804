//! `supine wire decode`: decode a capture from stdin into JSON lines.
//!
//! Input per format: `cobs-hex` lines of hex (whitespace inside a line allowed; the bytes of all lines form one
//! serial stream, so frames may span lines); `candump` can-utils log lines; `slcan` the raw byte stream of an
//! SLCAN adapter (`\r`, `\n` or BEL separated). CAN frames go through the reassembler at the default base id.
//!
//! stdout: one JSON object per decoded message (fields in `json.rs`). stderr, last: one summary line
//! `{"summary": {"format": ..., "messages": N, "duplicates": N, "errors": N, "bad_lines": N,
//! "serial"|"can"|"slcan": {counters}}}`. The same input faults count the same way in every format: a frame cut off
//! by the end of the input is an error (`serial.truncated`, `can.incomplete`, or a bad line), a line that is not a
//! frame or not hex is a bad line, and a message identical to the previous one of its kind is a duplicate (not
//! printed again, not an error).
//! Corrupt input is only counted: the exit code is 0 unless stdin cannot be read or stdout cannot be written.
//!
//! Streaming: stdin is decoded as it arrives, in reads of up to 64 KiB, and each read's messages are flushed before
//! the next; memory is bounded (one line of at most 64 KiB for the line formats; longer lines are bad lines).

use std::io::{Read, Write};

use serde_json::{Value, json};
use supine_core::wire::can::{CanBase, CanFrame};
use supine_core::wire::reassembly::{CanReassembler, CanStats};
use supine_core::wire::slcan::{SlcanReader, SlcanStats};
use supine_core::wire::stream::{SerialDecoder, SerialStats};
use supine_core::wire::{Kind, Message, candump};

use super::{DecodeArgs, Format, json};
use crate::failure::Failure;
use crate::{console, note};

/// Bytes read from stdin per call; also the largest unit of output latency (a message is printed once the read
/// that completed it returns).
const READ_CHUNK: usize = 64 * 1024;
/// Longest `cobs-hex` or `candump` line kept: 64 KiB of text. A longer line is counted as a bad line and skipped
/// without being stored, so memory stays bounded whatever the input.
const MAX_LINE: usize = 64 * 1024;

/// Run `supine wire decode`: stdin is read in chunks and decoded as it arrives; each chunk's messages are written
/// and flushed before the next read, so a live capture piped in is printed as it happens.
pub fn run(args: &DecodeArgs) -> Result<(), Failure> {
    if args.format == Format::Json {
        return Err(Failure::usage(
            "--format json is output only; decode reads candump, slcan or cobs-hex",
        ));
    }
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let mut decoder = match args.format {
        Format::CobsHex => Decoder::CobsHex(Box::default()),
        Format::Candump => Decoder::Candump(Box::default()),
        _ => Decoder::Slcan(Box::default()),
    };
    let mut stdin = std::io::stdin().lock();
    let mut buf = vec![0u8; READ_CHUNK];
    let mut repeats = Repeats::default();
    loop {
        let n = match stdin.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(anyhow::anyhow!("reading stdin: {e}").into()),
        };
        let mut emit = |m: &Message| repeats.print(&mut out, m);
        decoder
            .feed(&buf[..n], &mut emit)
            .map_err(console::stdout_failure)?;
        out.flush().map_err(console::stdout_failure)?;
    }
    let mut emit = |m: &Message| repeats.print(&mut out, m);
    let mut summary = decoder.finish(&mut emit).map_err(console::stdout_failure)?;
    out.flush().map_err(console::stdout_failure)?;
    // `messages` counts what was printed; identical repeats (of a whole message, or of one CAN frame) are
    // `duplicates`, not errors, in every format.
    summary["messages"] = json!(repeats.printed);
    let frame_repeats = summary["can"]["duplicates"].as_u64().unwrap_or(0);
    summary["duplicates"] = json!(repeats.duplicates + frame_repeats);
    note!("{}", json!({ "summary": summary }));
    Ok(())
}

/// Drops a message identical to the previous one of its kind (a repeated frame or group) and counts it.
#[derive(Default)]
struct Repeats {
    last: [Option<Message>; Kind::ALL.len()],
    printed: u64,
    duplicates: u64,
}

impl Repeats {
    fn print(&mut self, out: &mut impl Write, m: &Message) -> std::io::Result<()> {
        if let Some(last) = self.last.get_mut(m.kind() as usize) {
            if last.as_ref() == Some(m) {
                self.duplicates += 1;
                return Ok(());
            }
            *last = Some(*m);
        }
        self.printed += 1;
        writeln!(out, "{}", json::message(m))
    }
}

type Emit<'a> = dyn FnMut(&Message) -> std::io::Result<()> + 'a;

/// The streaming decoder of one input format.
enum Decoder {
    CobsHex(Box<CobsHex>),
    Candump(Box<Candump>),
    Slcan(Box<Slcan>),
}

impl Decoder {
    fn feed(&mut self, bytes: &[u8], emit: &mut Emit<'_>) -> std::io::Result<()> {
        match self {
            Decoder::CobsHex(d) => d.lines.feed(bytes, |line| d.state.line(line, emit)),
            Decoder::Candump(d) => d.lines.feed(bytes, |line| d.state.line(line, emit)),
            Decoder::Slcan(d) => bytes.iter().try_for_each(|&b| d.byte(b, emit)),
        }
    }

    fn finish(&mut self, emit: &mut Emit<'_>) -> std::io::Result<Value> {
        match self {
            Decoder::CobsHex(d) => {
                d.lines.finish(|line| d.state.line(line, emit))?;
                Ok(d.state.summary(d.lines.too_long))
            }
            Decoder::Candump(d) => {
                d.lines.finish(|line| d.state.line(line, emit))?;
                Ok(d.state.summary(d.lines.too_long))
            }
            Decoder::Slcan(d) => d.finish(emit),
        }
    }
}

/// Splits a byte stream into `\n`-terminated lines of at most [`MAX_LINE`] bytes, with one line of memory.
#[derive(Default)]
struct Lines {
    line: Vec<u8>,
    /// The current line went past `MAX_LINE`: its bytes are dropped until the next newline.
    overflow: bool,
    /// Lines dropped for being too long.
    too_long: u32,
}

impl Lines {
    fn feed(
        &mut self,
        mut bytes: &[u8],
        mut on_line: impl FnMut(&[u8]) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        while !bytes.is_empty() {
            let (part, rest, ended) = match bytes.iter().position(|&b| b == b'\n') {
                Some(i) => (&bytes[..i], &bytes[i + 1..], true),
                None => (bytes, &[][..], false),
            };
            bytes = rest;
            if !self.overflow {
                if self.line.len() + part.len() > MAX_LINE {
                    self.overflow = true;
                    self.line.clear();
                } else {
                    self.line.extend_from_slice(part);
                }
            }
            if ended {
                if std::mem::take(&mut self.overflow) {
                    self.too_long += 1;
                } else {
                    on_line(&self.line)?;
                }
                self.line.clear();
            }
        }
        Ok(())
    }

    /// A last line without its newline still counts.
    fn finish(&mut self, on_line: impl FnMut(&[u8]) -> std::io::Result<()>) -> std::io::Result<()> {
        if self.overflow || !self.line.is_empty() {
            self.feed(b"\n", on_line)?;
        }
        Ok(())
    }
}

#[derive(Default)]
struct CobsHex {
    lines: Lines,
    state: CobsHexState,
}

struct CobsHexState {
    decoder: SerialDecoder,
    bad_lines: u32,
}

impl Default for CobsHexState {
    fn default() -> Self {
        CobsHexState {
            decoder: SerialDecoder::new(),
            bad_lines: 0,
        }
    }
}

impl CobsHexState {
    fn line(&mut self, line: &[u8], emit: &mut Emit<'_>) -> std::io::Result<()> {
        let digits: Vec<u8> = line
            .iter()
            .copied()
            .filter(|b| !b.is_ascii_whitespace())
            .collect();
        let Some(bytes) = parse_hex(&digits) else {
            self.bad_lines += 1;
            return Ok(());
        };
        let mut rest = &bytes[..];
        while !rest.is_empty() {
            let fed = self.decoder.feed(rest);
            if let Some(Ok(m)) = fed.event {
                emit(&m)?;
            }
            rest = fed.rest;
        }
        Ok(())
    }

    fn summary(&mut self, too_long: u32) -> Value {
        // The end of the input: a frame still open is a truncated frame.
        self.decoder.finish();
        let s = self.decoder.stats();
        let bad_lines = self.bad_lines.saturating_add(too_long);
        json!({
            "format": "cobs-hex",
            "messages": s.messages,
            "errors": s.errors().saturating_add(bad_lines),
            "bad_lines": bad_lines,
            "serial": serial_stats(s),
        })
    }
}

#[derive(Default)]
struct Candump {
    lines: Lines,
    state: CandumpState,
}

struct CandumpState {
    reassembler: CanReassembler,
    bad_lines: u32,
}

impl Default for CandumpState {
    fn default() -> Self {
        CandumpState {
            reassembler: CanReassembler::new(CanBase::DEFAULT),
            bad_lines: 0,
        }
    }
}

impl CandumpState {
    fn line(&mut self, line: &[u8], emit: &mut Emit<'_>) -> std::io::Result<()> {
        if line.trim_ascii().is_empty() {
            return Ok(());
        }
        match candump::parse(line) {
            Ok(l) => push(&mut self.reassembler, &l.frame, emit),
            Err(_) => {
                self.bad_lines += 1;
                Ok(())
            }
        }
    }

    fn summary(&mut self, too_long: u32) -> Value {
        self.reassembler.flush();
        let s = self.reassembler.stats();
        let bad_lines = self.bad_lines.saturating_add(too_long);
        json!({
            "format": "candump",
            "messages": s.messages,
            "errors": s.errors().saturating_add(bad_lines),
            "bad_lines": bad_lines,
            "can": can_stats(s),
        })
    }
}

struct Slcan {
    reader: SlcanReader,
    reassembler: CanReassembler,
}

impl Default for Slcan {
    fn default() -> Self {
        Slcan {
            reader: SlcanReader::new(),
            reassembler: CanReassembler::new(CanBase::DEFAULT),
        }
    }
}

impl Slcan {
    fn byte(&mut self, b: u8, emit: &mut Emit<'_>) -> std::io::Result<()> {
        if let Some(Ok(f)) = self.reader.push(b) {
            push(&mut self.reassembler, &f.frame, emit)?;
        }
        Ok(())
    }

    fn finish(&mut self, emit: &mut Emit<'_>) -> std::io::Result<Value> {
        // A last line without its terminator still counts, as a frame or as a bad line.
        self.byte(b'\r', emit)?;
        self.reassembler.flush();
        let (s, l) = (self.reassembler.stats(), self.reader.stats());
        Ok(json!({
            "format": "slcan",
            "messages": s.messages,
            // A line that is not a frame (an adapter reply, text) counts as a bad line as in the other formats.
            "errors": s.errors().saturating_add(l.errors()).saturating_add(l.not_frames),
            "bad_lines": l.bad_lines.saturating_add(l.too_long).saturating_add(l.not_frames),
            "slcan": slcan_stats(l),
            "can": can_stats(s),
        }))
    }
}

fn push(r: &mut CanReassembler, frame: &CanFrame, emit: &mut Emit<'_>) -> std::io::Result<()> {
    if let Some(Ok(m)) = r.push(frame) {
        emit(&m)?;
    }
    Ok(())
}

fn parse_hex(digits: &[u8]) -> Option<Vec<u8>> {
    if !digits.len().is_multiple_of(2) {
        return None;
    }
    digits
        .chunks_exact(2)
        .map(|p| {
            std::str::from_utf8(p)
                .ok()
                .and_then(|s| u8::from_str_radix(s, 16).ok())
        })
        .collect()
}

fn serial_stats(s: &SerialStats) -> Value {
    json!({
        "messages": s.messages, "cobs": s.cobs, "oversized": s.oversized, "too_short": s.too_short,
        "bad_crc": s.bad_crc, "bad_version": s.bad_version, "unknown_kind": s.unknown_kind,
        "malformed": s.malformed, "truncated": s.truncated,
    })
}

fn can_stats(s: &CanStats) -> Value {
    json!({
        "frames": s.frames, "messages": s.messages, "foreign": s.foreign, "bad_length": s.bad_length,
        "bad_crc": s.bad_crc, "duplicates": s.duplicates, "incomplete": s.incomplete, "invalid": s.invalid,
    })
}

fn slcan_stats(s: &SlcanStats) -> Value {
    json!({
        "frames": s.frames, "not_frames": s.not_frames, "bad_lines": s.bad_lines, "too_long": s.too_long,
        "device_errors": s.device_errors,
    })
}
