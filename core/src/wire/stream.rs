//! Streaming serial receiver: feed bytes as they arrive, in chunks of any size, and get messages out.
//!
//! Allocation-free: one `[u8; N]` buffer holds the bytes since the last `0x00`. On `0x00` the buffer is
//! COBS-decoded in place and parsed (one CRC pass and one postcard walk per frame); any failure is counted by kind
//! and the decoder simply starts the next frame. Garbage, cut-off frames, frames longer than `N` and bad CRCs
//! therefore cost at most the frame they touch, and the leading `0x00` of every frame limits even that to the
//! damaged frame itself. Every path is total: there is no input on which it panics.

use super::error::DecodeError;
use super::message::Message;
use super::serial::{self, MAX_PLAIN_LEN};

/// The buffer size that holds every frame of this protocol version with its COBS overhead.
pub const DEFAULT_CAPACITY: usize = MAX_PLAIN_LEN + 2;

/// Counters of what a [`SerialDecoder`] has seen. Each counter saturates instead of wrapping.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SerialStats {
    /// Frames decoded into messages.
    pub messages: u32,
    /// Frames with broken COBS framing (typically garbage between delimiters).
    pub cobs: u32,
    /// Runs of bytes longer than the buffer before a delimiter (discarded up to the next `0x00`).
    pub oversized: u32,
    /// Frames shorter than version + kind + CRC.
    pub too_short: u32,
    /// Frames whose CRC-32C did not match.
    pub bad_crc: u32,
    /// Frames with a version this decoder does not understand.
    pub bad_version: u32,
    /// Frames of an unknown kind.
    pub unknown_kind: u32,
    /// Frames whose payload was truncated, had trailing bytes, held an out-of-range value or bad postcard.
    pub malformed: u32,
    /// Bytes of a frame still waiting for their closing `0x00` when the input ended ([`SerialDecoder::finish`]).
    pub truncated: u32,
}

impl SerialStats {
    /// All errors together.
    pub fn errors(&self) -> u32 {
        [
            self.cobs,
            self.oversized,
            self.too_short,
            self.bad_crc,
            self.bad_version,
            self.unknown_kind,
            self.malformed,
            self.truncated,
        ]
        .iter()
        .fold(0u32, |a, &b| a.saturating_add(b))
    }

    fn count(&mut self, e: DecodeError) {
        let c = match e {
            DecodeError::Cobs => &mut self.cobs,
            DecodeError::Oversized => &mut self.oversized,
            DecodeError::TooShort => &mut self.too_short,
            DecodeError::BadCrc => &mut self.bad_crc,
            DecodeError::BadVersion(_) => &mut self.bad_version,
            DecodeError::UnknownKind(_) => &mut self.unknown_kind,
            DecodeError::Truncated
            | DecodeError::TrailingBytes
            | DecodeError::InvalidValue
            | DecodeError::Malformed => &mut self.malformed,
        };
        *c = c.saturating_add(1);
    }
}

/// What one call to [`SerialDecoder::feed`] produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Feed<'a> {
    /// A decoded message or the error that ended a frame; `None` when `rest` is empty and no frame ended.
    pub event: Option<Result<Message, DecodeError>>,
    /// The input not consumed yet: feed it again.
    pub rest: &'a [u8],
}

/// Streaming COBS + CRC-32C + postcard decoder with a buffer of `N` bytes.
#[derive(Debug, Clone)]
pub struct SerialDecoder<const N: usize = DEFAULT_CAPACITY> {
    buf: [u8; N],
    len: usize,
    /// Set after an overflow: drop bytes until the next delimiter.
    discarding: bool,
    stats: SerialStats,
}

impl<const N: usize> Default for SerialDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> SerialDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        SerialDecoder {
            buf: [0; N],
            len: 0,
            discarding: false,
            stats: SerialStats {
                messages: 0,
                cobs: 0,
                oversized: 0,
                too_short: 0,
                bad_crc: 0,
                bad_version: 0,
                unknown_kind: 0,
                malformed: 0,
                truncated: 0,
            },
        }
    }

    /// What the decoder has seen so far.
    pub const fn stats(&self) -> &SerialStats {
        &self.stats
    }

    /// Take one byte; a message or error when it ended a frame.
    pub fn push(&mut self, byte: u8) -> Option<Result<Message, DecodeError>> {
        if byte == 0 {
            let len = core::mem::replace(&mut self.len, 0);
            if core::mem::replace(&mut self.discarding, false) || len == 0 {
                // End of an already counted oversized run, or an idle/leading delimiter.
                return None;
            }
            let result = match self.buf.get_mut(..len) {
                Some(frame) => serial::decode_cobs_in_place(frame),
                None => Err(DecodeError::Oversized),
            };
            match result {
                Ok(_) => self.stats.messages = self.stats.messages.saturating_add(1),
                Err(e) => self.stats.count(e),
            }
            return Some(result);
        }
        if self.discarding {
            return None;
        }
        match self.buf.get_mut(self.len) {
            Some(slot) => {
                *slot = byte;
                self.len += 1;
                None
            }
            None => {
                self.len = 0;
                self.discarding = true;
                self.stats.count(DecodeError::Oversized);
                Some(Err(DecodeError::Oversized))
            }
        }
    }

    /// Take bytes until a frame ends (or the input does); call again with `rest` until it is empty.
    pub fn feed<'a>(&mut self, input: &'a [u8]) -> Feed<'a> {
        for (i, &b) in input.iter().enumerate() {
            if let Some(event) = self.push(b) {
                return Feed {
                    event: Some(event),
                    rest: input.get(i + 1..).unwrap_or(&[]),
                };
            }
        }
        Feed {
            event: None,
            rest: &[],
        }
    }

    /// Feed all of `input`, calling `on_message` for each decoded message; errors are only counted.
    pub fn feed_all(&mut self, mut input: &[u8], mut on_message: impl FnMut(Message)) {
        while !input.is_empty() {
            let fed = self.feed(input);
            if let Some(Ok(m)) = fed.event {
                on_message(m);
            }
            input = fed.rest;
        }
    }

    /// The input ended (end of a capture): a frame still waiting for its closing `0x00` is counted as `truncated`
    /// and forgotten. A live link never calls this; its next bytes may still complete the frame.
    pub fn finish(&mut self) {
        if self.len > 0 && !self.discarding {
            self.stats.truncated = self.stats.truncated.saturating_add(1);
        }
        self.reset();
    }

    /// Forget a partly received frame (e.g. after the link was reopened); counters are kept.
    pub fn reset(&mut self) {
        self.len = 0;
        self.discarding = false;
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use std::vec::Vec;

    use super::*;
    use crate::wire::sample::MESSAGES;
    use crate::wire::serial::MAX_WIRE_LEN;

    #[test]
    fn a_frame_cut_off_by_the_end_of_input_is_counted_as_truncated() {
        let mut d: SerialDecoder = SerialDecoder::new();
        let full = wire(&MESSAGES[0]);
        d.feed_all(&full, |_| {});
        d.feed_all(&full[..full.len() / 2], |_| {});
        assert_eq!(d.stats().errors(), 0, "a live stream may still complete it");
        d.finish();
        assert_eq!(
            (d.stats().messages, d.stats().truncated, d.stats().errors()),
            (1, 1, 1)
        );
        d.finish();
        assert_eq!(d.stats().truncated, 1, "counted once");
    }

    fn wire(m: &Message) -> Vec<u8> {
        let mut buf = [0u8; MAX_WIRE_LEN];
        let n = m.encode_serial(&mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn run<const N: usize>(d: &mut SerialDecoder<N>, bytes: &[u8]) -> Vec<Result<Message, DecodeError>> {
        bytes.iter().filter_map(|&b| d.push(b)).collect()
    }

    #[test]
    fn oversized_frame_is_skipped_to_the_next_delimiter() {
        let (health, command) = (&MESSAGES[4], &MESSAGES[6]);
        let mut d: SerialDecoder<20> = SerialDecoder::new();
        let mut bytes = wire(health);
        bytes.extend(wire(command));
        assert_eq!(run(&mut d, &bytes), [Err(DecodeError::Oversized), Ok(*command)]);
        assert_eq!(
            (d.stats().oversized, d.stats().messages, d.stats().errors()),
            (1, 1, 1)
        );
    }

    #[test]
    fn truncated_frame_costs_only_itself() {
        let m = &MESSAGES[0];
        let full = wire(m);
        let mut bytes = full[..full.len() / 2].to_vec();
        bytes.extend(&full);
        let out = run(&mut SerialDecoder::<{ DEFAULT_CAPACITY }>::new(), &bytes);
        assert_eq!(out.len(), 2);
        assert!(out[0].is_err());
        assert_eq!(out[1], Ok(*m));
    }

    #[test]
    fn each_error_kind_has_its_counter() {
        let mut d: SerialDecoder = SerialDecoder::new();
        // COBS 03 01 02 decodes to two bytes: too short. 05 11 claims four data bytes: broken COBS.
        let out = run(&mut d, &[0, 0x03, 0x01, 0x02, 0, 0x05, 0x11, 0, 0, 0]);
        assert_eq!(out, [Err(DecodeError::TooShort), Err(DecodeError::Cobs)]);
        let mut bad = wire(&MESSAGES[5]);
        bad[5] ^= 0x01;
        assert_eq!(run(&mut d, &bad), [Err(DecodeError::BadCrc)]);
        let s = *d.stats();
        assert_eq!(
            (s.too_short, s.cobs, s.bad_crc, s.messages, s.errors()),
            (1, 1, 1, 0, 3)
        );
    }

    #[test]
    fn feed_returns_the_rest_after_each_event() {
        let mut bytes = wire(&MESSAGES[0]);
        bytes.extend(wire(&MESSAGES[1]));
        let mut d: SerialDecoder = SerialDecoder::new();
        let first = d.feed(&bytes);
        assert_eq!(first.event, Some(Ok(MESSAGES[0])));
        let second = d.feed(first.rest);
        assert_eq!(second.event, Some(Ok(MESSAGES[1])));
        assert!(second.rest.is_empty());
        assert_eq!(d.feed(&[]).event, None);
        d.feed_all(&bytes[..10], |_| ());
        d.reset();
        let w = wire(&MESSAGES[2]);
        let third = d.feed(&w);
        assert_eq!(third.event, Some(Ok(MESSAGES[2])));
    }
}
