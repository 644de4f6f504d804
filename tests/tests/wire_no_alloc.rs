//! The wire decoders (and encoders) never touch the heap: a counting global allocator watches this thread while
//! many frames go through the serial, CAN, SLCAN and candump paths, and must see zero allocations.

use std::fmt::Write;

use supine_core::wire::can::{CanBase, CanFrame};
use supine_core::wire::reassembly::CanReassembler;
use supine_core::wire::sample::MESSAGES;
use supine_core::wire::serial::MAX_WIRE_LEN;
use supine_core::wire::slcan::{self, SlcanReader};
use supine_core::wire::stream::SerialDecoder;
use supine_core::wire::{can_map, candump, consumer::ArmConsumer};
use supine_tests::alloc_count::{Counting, count_allocations, counter_is_installed};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// A `fmt::Write` into a stack buffer.
struct StackText {
    buf: [u8; 96],
    len: usize,
}

impl Write for StackText {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let dst = self
            .buf
            .get_mut(self.len..self.len + s.len())
            .ok_or(std::fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.len += s.len();
        Ok(())
    }
}

const ROUNDS: usize = 200;

#[test]
fn decoding_makes_no_heap_allocation() {
    // Inputs are built before watching starts: the serial stream with noise, and every CAN frame of the samples.
    let mut serial = Vec::new();
    for m in &MESSAGES {
        let mut buf = [0u8; MAX_WIRE_LEN];
        let n = m.encode_serial(&mut buf).unwrap();
        serial.extend_from_slice(&[0x55, 0xAA, 0x13]);
        serial.extend_from_slice(&buf[..n]);
    }
    let frames: Vec<CanFrame> = MESSAGES
        .iter()
        .flat_map(|m| can_map::encode_group(m, CanBase::DEFAULT).unwrap())
        .collect();

    let mut serial_msgs = 0usize;
    let mut can_msgs = 0usize;
    let mut slcan_msgs = 0usize;
    let mut candump_msgs = 0usize;
    let mut encoded = 0usize;
    let mut decoder: SerialDecoder = SerialDecoder::new();
    let mut consumer: ArmConsumer = ArmConsumer::new();
    let mut reassembler = CanReassembler::new(CanBase::DEFAULT);
    let mut slcan_r = CanReassembler::new(CanBase::DEFAULT);
    let mut candump_r = CanReassembler::new(CanBase::DEFAULT);
    let mut reader: SlcanReader = SlcanReader::new();
    let ((), allocations) = count_allocations(|| {
        for _ in 0..ROUNDS {
            for chunk in serial.chunks(13) {
                decoder.feed_all(chunk, |_| serial_msgs += 1);
                consumer.feed(chunk);
            }
            for f in &frames {
                if let Some(Ok(_)) = reassembler.push(f) {
                    can_msgs += 1;
                }
                let mut line = [0u8; slcan::MAX_LINE];
                let n = slcan::encode(f, &mut line).unwrap_or(0);
                for &b in &line[..n] {
                    if let Some(Ok(p)) = reader.push(b)
                        && let Some(Ok(_)) = slcan_r.push(&p.frame)
                    {
                        slcan_msgs += 1;
                    }
                }
                let mut text = StackText { buf: [0; 96], len: 0 };
                if candump::encode(f, 1_234_567_890, "can0", &mut text).is_ok()
                    && let Ok(l) = candump::parse(&text.buf[..text.len])
                    && let Some(Ok(_)) = candump_r.push(&l.frame)
                {
                    candump_msgs += 1;
                }
            }
            for m in &MESSAGES {
                let mut buf = [0u8; MAX_WIRE_LEN];
                encoded += usize::from(m.encode_serial(&mut buf).is_ok());
                encoded += usize::from(can_map::encode_group(m, CanBase::DEFAULT).is_ok());
            }
        }
    });

    let expected = ROUNDS * MESSAGES.len();
    assert_eq!(
        (serial_msgs, can_msgs, slcan_msgs, candump_msgs, encoded),
        (expected, expected, expected, expected, 2 * expected)
    );
    assert_eq!(consumer.link_stats().messages as usize, expected);
    assert_eq!(allocations, 0, "the wire paths allocated {allocations} times");
}

#[test]
fn the_counter_does_count() {
    // Guard against a counter that never counts, which would make the test above vacuous.
    assert!(counter_is_installed());
}
