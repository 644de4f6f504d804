//! Serial receive path: COBS framing, CRC-32C, postcard payload, streaming resynchronisation.
//!
//! The first byte picks a chunk size so the streaming decoder sees every way of splitting the input; the rest
//! goes through a small-buffer and a default decoder, and through the one-shot frame decoder. Every message
//! that decodes must re-encode to a frame that decodes to the same message. A random frame almost never carries a
//! valid CRC-32C, so the input is also decoded with a correct CRC appended: that drives the fuzzer into the
//! version, kind and postcard checks behind the CRC.
#![no_main]

use libfuzzer_sys::fuzz_target;
use supine_core::crc::crc32c;
use supine_core::wire::Message;
use supine_core::wire::serial::{MAX_WIRE_LEN, decode_plain};
use supine_core::wire::stream::SerialDecoder;

fn check_round_trip(m: &Message) {
    let mut buf = [0u8; MAX_WIRE_LEN];
    let n = m
        .encode_serial(&mut buf)
        .expect("a decoded message always re-encodes");
    let mut d: SerialDecoder = SerialDecoder::new();
    let mut again = None;
    d.feed_all(&buf[..n], |x| again = Some(x));
    assert_eq!(again.as_ref(), Some(m));
}

fuzz_target!(|data: &[u8]| {
    let Some((&first, rest)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(first % 32) + 1;
    let mut small: SerialDecoder<24> = SerialDecoder::new();
    let mut normal: SerialDecoder = SerialDecoder::new();
    for c in rest.chunks(chunk) {
        small.feed_all(c, |m| check_round_trip(&m));
        normal.feed_all(c, |m| check_round_trip(&m));
    }
    let s = normal.stats();
    assert!(s.messages.saturating_add(s.errors()) <= rest.len() as u32 + 1);
    if let Ok(m) = decode_plain(rest) {
        check_round_trip(&m);
    }
    // Frames longer than the protocol's bound cannot be valid anyway; keep the sealed copy on the stack.
    let mut sealed = [0u8; 260];
    let n = rest.len();
    if n + 4 <= sealed.len() {
        sealed[..n].copy_from_slice(rest);
        sealed[n..n + 4].copy_from_slice(&crc32c(rest).to_le_bytes());
        if let Ok(m) = decode_plain(&sealed[..n + 4]) {
            check_round_trip(&m);
        }
    }
});
