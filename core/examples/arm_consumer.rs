//! An arm controller's receive loop, as it would run on the arm's MCU: bytes come off the UART in arbitrary
//! chunks, [`ArmConsumer`] keeps the newest valid torso pose and judges it against the arm's clock.
//!
//! No heap: the stream is a fixed array built from the sample messages, with line noise and a corrupted frame
//! mixed in, and the decoder's buffer lives inside the consumer. Run with
//! `cargo run -p supine-core --example arm_consumer`.

use supine_core::wire::consumer::{ArmConsumer, Freshness, Limits};
use supine_core::wire::sample::{CAPTURE, MESSAGES};
use supine_core::wire::serial::MAX_WIRE_LEN;
use supine_core::wire::{Body, Message, Timestamp};

/// Room for every sample frame, twice, plus the noise.
const STREAM_CAP: usize = 2 * MESSAGES.len() * MAX_WIRE_LEN + 64;

/// Append `bytes` to the fixed stream; false when it is full.
fn append(stream: &mut [u8; STREAM_CAP], len: &mut usize, bytes: &[u8]) -> bool {
    match stream.get_mut(*len..*len + bytes.len()) {
        Some(dst) => {
            dst.copy_from_slice(bytes);
            *len += bytes.len();
            true
        }
        None => false,
    }
}

fn append_message(stream: &mut [u8; STREAM_CAP], len: &mut usize, m: &Message) -> bool {
    let mut frame = [0u8; MAX_WIRE_LEN];
    match m.encode_serial(&mut frame) {
        Ok(n) => append(stream, len, frame.get(..n).unwrap_or(&[])),
        Err(_) => false,
    }
}

fn report(consumer: &ArmConsumer, now_us: u64) {
    let Some(now) = Timestamp::from_us(now_us) else {
        return;
    };
    let limits = Limits::default();
    let verdict = match consumer.pose(now, limits) {
        Freshness::Missing => "no pose yet".to_owned(),
        Freshness::Fresh { data, age_us } => format!(
            "FRESH seq {} age {:.1} ms position {:?} mm",
            data.seq,
            age_us as f64 / 1000.0,
            data.value.position_mm
        ),
        Freshness::Stale { data, age_us } => {
            format!(
                "STALE seq {} age {:.1} ms: hold position",
                data.seq,
                age_us as f64 / 1000.0
            )
        }
        Freshness::FromFuture { data, ahead_us } => {
            format!(
                "FUTURE seq {} {:.1} ms ahead: clocks disagree",
                data.seq,
                ahead_us as f64 / 1000.0
            )
        }
    };
    let usable = consumer.usable_pose(now, limits).is_some();
    println!(
        "now {now_us} µs: {verdict}; usable {usable}; tracker {:?}; corrupt since last good {}",
        consumer.tracker_state().map(|s| s.name()),
        consumer.corrupt_since_last_good()
    );
}

fn main() {
    let mut stream = [0u8; STREAM_CAP];
    let mut len = 0usize;
    // Line noise before anything useful (no delimiter in it, so it would eat a frame without the leading 0x00).
    append(&mut stream, &mut len, &[0x13, 0x37, 0xFF, 0x42, 0x11]);
    for m in &MESSAGES {
        append_message(&mut stream, &mut len, m);
    }
    // The next depth frame's pose, damaged in transit: counted as corrupt, never used.
    let mut next = MESSAGES[0];
    next.seq = next.seq.wrapping_add(1);
    next.timestamp = Timestamp::from_us(CAPTURE.as_us() + 33_333).unwrap_or(next.timestamp);
    let start = len;
    append_message(&mut stream, &mut len, &next);
    if let Some(b) = stream.get_mut(start + 9) {
        *b ^= 0x20;
    }
    // An old pose replayed late (e.g. from a buffer): older than the held one, so ignored.
    let mut replay = MESSAGES[0];
    replay.seq = replay.seq.wrapping_sub(3);
    replay.timestamp = Timestamp::from_us(CAPTURE.as_us() - 100_000).unwrap_or(replay.timestamp);
    append_message(&mut stream, &mut len, &replay);

    let mut consumer: ArmConsumer = ArmConsumer::new();
    // UART driver hands over 17-byte chunks.
    for chunk in stream.get(..len).unwrap_or(&[]).chunks(17) {
        consumer.feed(chunk);
    }
    let stats = consumer.link_stats();
    println!(
        "decoded {} messages, {} bad CRC, {} broken COBS, {} not newer than held",
        stats.messages,
        stats.bad_crc,
        stats.cobs,
        consumer.not_newer()
    );
    if let Body::TorsoPose(p) = MESSAGES[0].body {
        println!(
            "sample pose: {:?} mm, quaternion {:?}",
            p.position_mm,
            p.orientation.to_f32()
        );
    }
    let t = CAPTURE.as_us();
    for now in [t + 12_000, t + 90_000, t + 250_000, t - 40_000] {
        report(&consumer, now);
    }
}
