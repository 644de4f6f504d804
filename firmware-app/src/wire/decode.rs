//! `supine wire decode`: decode a capture from stdin into JSON lines.
//!
//! Input per format: `cobs-hex` lines of hex (whitespace inside a line allowed; the bytes of all lines form one
//! serial stream, so frames may span lines); `candump` can-utils log lines; `slcan` the raw byte stream of an
//! SLCAN adapter (`\r`, `\n` or BEL separated). CAN frames go through the reassembler at the default base id.
//!
//! stdout: one JSON object per decoded message (fields in `json.rs`). stderr, last: one summary line
//! `{"summary": {"format": ..., "messages": N, "errors": N, "bad_lines": N, "serial"|"can"|"slcan": {counters}}}`.
//! Corrupt input is only counted: the exit code is 0 unless stdin cannot be read or stdout cannot be written.

use std::io::{Read, Write};

use anyhow::Context;
use serde_json::{Value, json};
use supine_core::wire::can::{CanBase, CanFrame};
use supine_core::wire::reassembly::{CanReassembler, CanStats};
use supine_core::wire::slcan::{SlcanReader, SlcanStats};
use supine_core::wire::stream::{SerialDecoder, SerialStats};
use supine_core::wire::{Message, candump};

use super::{DecodeArgs, Format, json};
use crate::failure::Failure;

/// Run `supine wire decode`.
pub fn run(args: &DecodeArgs) -> Result<(), Failure> {
    if args.format == Format::Json {
        return Err(Failure::usage(
            "--format json is output only; decode reads candump, slcan or cobs-hex",
        ));
    }
    let mut input = Vec::new();
    std::io::stdin()
        .read_to_end(&mut input)
        .context("reading stdin")?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut emit = |m: &Message| writeln!(out, "{}", json::message(m));
    let summary = match args.format {
        Format::CobsHex => decode_cobs_hex(&input, &mut emit),
        Format::Candump => decode_candump(&input, &mut emit),
        _ => decode_slcan(&input, &mut emit),
    }
    .context("writing to stdout")?;
    out.flush().context("writing to stdout")?;
    eprintln!("{}", json!({ "summary": summary }));
    Ok(())
}

type Emit<'a> = dyn FnMut(&Message) -> std::io::Result<()> + 'a;

fn decode_cobs_hex(input: &[u8], emit: &mut Emit<'_>) -> std::io::Result<Value> {
    let mut decoder: SerialDecoder = SerialDecoder::new();
    let mut bad_lines = 0u32;
    for line in input.split(|&b| b == b'\n') {
        let digits: Vec<u8> = line
            .iter()
            .copied()
            .filter(|b| !b.is_ascii_whitespace())
            .collect();
        let Some(bytes) = parse_hex(&digits) else {
            bad_lines += 1;
            continue;
        };
        let mut rest = &bytes[..];
        while !rest.is_empty() {
            let fed = decoder.feed(rest);
            if let Some(Ok(m)) = fed.event {
                emit(&m)?;
            }
            rest = fed.rest;
        }
    }
    let s = decoder.stats();
    Ok(json!({
        "format": "cobs-hex",
        "messages": s.messages,
        "errors": s.errors().saturating_add(bad_lines),
        "bad_lines": bad_lines,
        "serial": serial_stats(s),
    }))
}

fn decode_candump(input: &[u8], emit: &mut Emit<'_>) -> std::io::Result<Value> {
    let mut reassembler = CanReassembler::new(CanBase::DEFAULT);
    let mut bad_lines = 0u32;
    for line in input.split(|&b| b == b'\n') {
        if line.trim_ascii().is_empty() {
            continue;
        }
        match candump::parse(line) {
            Ok(l) => push(&mut reassembler, &l.frame, emit)?,
            Err(_) => bad_lines += 1,
        }
    }
    reassembler.flush();
    let s = reassembler.stats();
    Ok(json!({
        "format": "candump",
        "messages": s.messages,
        "errors": s.errors().saturating_add(bad_lines),
        "bad_lines": bad_lines,
        "can": can_stats(s),
    }))
}

fn decode_slcan(input: &[u8], emit: &mut Emit<'_>) -> std::io::Result<Value> {
    let mut reader: SlcanReader = SlcanReader::new();
    let mut reassembler = CanReassembler::new(CanBase::DEFAULT);
    for &b in input {
        if let Some(Ok(f)) = reader.push(b) {
            push(&mut reassembler, &f.frame, emit)?;
        }
    }
    // A last line without its terminator still counts, as a frame or as a bad line.
    if let Some(Ok(f)) = reader.push(b'\r') {
        push(&mut reassembler, &f.frame, emit)?;
    }
    reassembler.flush();
    let (s, l) = (reassembler.stats(), reader.stats());
    Ok(json!({
        "format": "slcan",
        "messages": s.messages,
        "errors": s.errors().saturating_add(l.errors()),
        "bad_lines": l.bad_lines.saturating_add(l.too_long),
        "slcan": slcan_stats(l),
        "can": can_stats(s),
    }))
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
        "malformed": s.malformed,
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
