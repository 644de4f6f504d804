//! The serial framing as a link [`Codec`]: `0x00 ‖ COBS(version ‖ kind ‖ postcard ‖ CRC-32C) ‖ 0x00` per message,
//! decoded by the wire module's streaming [`SerialDecoder`]. Used by `serial:`, `file:` and `stdout`.
//!
//! Per message: one CRC pass, one COBS pass, one postcard walk, into a pre-sized slot; no allocation.

use supine_core::wire::Message;
use supine_core::wire::serial::MAX_WIRE_LEN;
use supine_core::wire::stream::{SerialDecoder, SerialStats};

use crate::link::codec::{Codec, Decoded, Framing};
use crate::link::error::{LinkError, LinkErrorKind};

/// COBS-framed messages.
#[derive(Debug, Default)]
pub struct SerialCodec {
    decoder: SerialDecoder,
}

impl SerialCodec {
    /// A codec with an empty decoder.
    pub fn new() -> Self {
        SerialCodec {
            decoder: SerialDecoder::new(),
        }
    }

    /// The decoder's own statistics.
    pub fn stats(&self) -> &SerialStats {
        self.decoder.stats()
    }
}

impl Codec for SerialCodec {
    fn framing(&self) -> Framing {
        Framing::Serial
    }

    fn max_encoded_len(&self) -> usize {
        MAX_WIRE_LEN
    }

    fn encode(&mut self, msg: &Message, out: &mut Vec<u8>) -> Result<(), LinkError> {
        // Within the slot's capacity (MAX_WIRE_LEN): no reallocation.
        out.resize(MAX_WIRE_LEN, 0);
        match msg.encode_serial(out) {
            Ok(n) => {
                out.truncate(n);
                Ok(())
            }
            Err(_) => {
                out.clear();
                Err(LinkError::new(
                    LinkErrorKind::Encode,
                    "message does not fit a serial frame",
                ))
            }
        }
    }

    fn preamble(&mut self, _out: &mut Vec<u8>) {
        // Every frame starts with its own 0x00, which resynchronises the receiver after a cut-off frame.
    }

    fn postamble(&mut self, _out: &mut Vec<u8>) {}

    fn decode(&mut self, input: &[u8], _now_us: u64) -> (usize, Decoded) {
        let fed = self.decoder.feed(input);
        let used = input.len() - fed.rest.len();
        let out = match fed.event {
            None => Decoded::NeedMore,
            Some(Ok(m)) => Decoded::Message(m),
            Some(Err(e)) => Decoded::Error(e.into()),
        };
        (used, out)
    }

    fn reset_rx(&mut self) {
        self.decoder.reset();
    }
}
