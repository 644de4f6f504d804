//! SLCAN and candump text parsers: one-shot line parsing, the streaming SLCAN line reader, and candump lines.
//! Whatever parses must print back to text that parses to the same frame.
#![no_main]

use libfuzzer_sys::fuzz_target;
use supine_core::wire::can::CanFrame;
use supine_core::wire::candump;
use supine_core::wire::slcan::{self, SlcanReader};

fn slcan_round_trip(f: &CanFrame) {
    let mut line = [0u8; slcan::MAX_LINE];
    let n = slcan::encode(f, &mut line).expect("MAX_LINE fits every frame");
    assert_eq!(slcan::parse(&line[..n]).map(|p| p.frame), Ok(*f));
}

fuzz_target!(|data: &[u8]| {
    if let Ok(p) = slcan::parse(data) {
        slcan_round_trip(&p.frame);
    }
    let mut reader: SlcanReader<32> = SlcanReader::new();
    for &b in data {
        if let Some(Ok(p)) = reader.push(b) {
            slcan_round_trip(&p.frame);
        }
    }
    if let Ok(l) = candump::parse(data) {
        let mut text = String::new();
        candump::encode(&l.frame, l.timestamp_us, l.interface, &mut text).unwrap();
        let again = candump::parse(text.as_bytes()).unwrap();
        assert_eq!(
            (again.frame, again.timestamp_us, again.interface),
            (l.frame, l.timestamp_us, l.interface)
        );
        slcan_round_trip(&l.frame);
    }
});
