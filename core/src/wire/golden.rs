//! Golden bytes: every message kind as a serial frame and as CAN frames, frozen at protocol version 1.
//!
//! Loopback style (postcard's `tests/loopback.rs`): encoding a sample gives exactly these bytes and decoding these
//! bytes gives exactly the sample. The arrays are the version-1 freeze: when a later version appends fields, the
//! encode half moves to new arrays and `frozen_v1_still_decodes` keeps decoding these forever.

extern crate std;

use std::vec::Vec;

use super::can::{CanBase, CanFrame, CanId, E2ePacket, StandardId, data_id, seal};
use super::can_map::{self, encode_group};
use super::error::{DecodeError, EncodeError};
use super::reassembly::{CanError, CanReassembler, EXPIRY_FRAMES};
use super::sample::MESSAGES;
use super::serial::{Frame, MAX_PLAIN_LEN, MAX_WIRE_LEN, decode_plain};
use super::stream::SerialDecoder;
use super::types::{Confidence, Timestamp};
use super::{Body, Kind, Message, TorsoPose, UnitQuatQ14};
use crate::crc::{crc8_sae_j1850, crc32c};

/// Serial frame (decoded, before COBS) of sample torso_pose.
const TORSO_POSE: &[u8] = &[
    0x01, 0x02, 0x92, 0x08, 0xD2, 0x85, 0xD8, 0xCC, 0x04, 0x8A, 0x0A, 0xA7, 0x02, 0xA8, 0x0C, 0xA6, 0xB4,
    0x01, 0xC8, 0x06, 0xEB, 0x04, 0xC6, 0xB5, 0x01, 0x5D, 0x0C, 0x5E, 0xDF, 0x48,
];
/// Serial frame (decoded, before COBS) of sample salient_points.
const SALIENT_POINTS: &[u8] = &[
    0x01, 0x04, 0x92, 0x08, 0xD2, 0x85, 0xD8, 0xCC, 0x04, 0xE6, 0x15, 0xBF, 0x02, 0x94, 0x0D, 0x61, 0xB8,
    0x12, 0x32, 0x86, 0x0D, 0x5B, 0xCC, 0x12, 0xA7, 0x05, 0xFC, 0x0C, 0x58, 0xF4, 0x0D, 0xAB, 0x02, 0xCC,
    0x0D, 0x5F, 0x80, 0x0A, 0x3B, 0xAC, 0x0C, 0x54, 0x94, 0x0A, 0x91, 0x04, 0xA2, 0x0C, 0x3E, 0xA6, 0x39,
    0xDF, 0xD6,
];
/// Serial frame (decoded, before COBS) of sample probe.
const PROBE: &[u8] = &[
    0x01, 0x03, 0x92, 0x08, 0xD2, 0x85, 0xD8, 0xCC, 0x04, 0x46, 0xA4, 0x03, 0xEC, 0x01, 0x3E, 0xA8, 0x03,
    0xD0, 0x01, 0xD6, 0x45, 0xEB, 0x22, 0xEE, 0xF3, 0x01, 0x1C, 0x06, 0x08, 0x16, 0x4E, 0xE9,
];
/// Serial frame (decoded, before COBS) of sample body_shape.
const BODY_SHAPE: &[u8] = &[
    0x01, 0x06, 0x07, 0xD2, 0x85, 0xD8, 0xCC, 0x04, 0x03, 0xC4, 0x13, 0xDB, 0x06, 0xE8, 0x0C, 0xBE, 0x01,
    0xBB, 0x14, 0xE0, 0x03, 0x95, 0x01, 0xFC, 0x07, 0xB7, 0x03, 0x3C, 0xA2, 0x02, 0x77, 0x18, 0xBD, 0x01,
    0x50, 0x10, 0x2B, 0x22, 0x09, 0x06, 0x9B, 0x7A, 0x3F, 0x78,
];
/// Serial frame (decoded, before COBS) of sample health.
const HEALTH: &[u8] = &[
    0x01, 0x05, 0xD0, 0x01, 0xD2, 0x85, 0xD8, 0xCC, 0x04, 0x01, 0xB2, 0x17, 0xF4, 0x8F, 0x01, 0x03, 0x0B,
    0x38, 0x89, 0x08, 0xFD,
];
/// Serial frame (decoded, before COBS) of sample arm_state.
const ARM_STATE: &[u8] = &[
    0x01, 0x01, 0x81, 0x28, 0xC0, 0x9F, 0xD8, 0xCC, 0x04, 0xE4, 0x0A, 0xEF, 0x01, 0x92, 0x0E, 0xE6, 0x0C,
    0xC2, 0xFF, 0x01, 0x90, 0x05, 0xD7, 0x07, 0xE0, 0x76, 0xE7, 0x6D,
];
/// Serial frame (decoded, before COBS) of sample command.
const COMMAND: &[u8] = &[
    0x01, 0x00, 0x0C, 0xA0, 0xE4, 0xD8, 0xCC, 0x04, 0x04, 0x02, 0xBB, 0xE9, 0x2C, 0xF0,
];
/// CAN frames of sample torso_pose.
const TORSO_POSE_CAN: &[(u16, [u8; 8])] = &[
    (0x120, [0x76, 0x02, 0x12, 0x04, 0x5D, 0x00, 0x00, 0x00]),
    (0x121, [0xE6, 0x02, 0xD2, 0x02, 0x96, 0x49, 0x00, 0x00]),
    (0x122, [0xE4, 0x02, 0x85, 0x02, 0x6C, 0xFF, 0x14, 0x03]),
    (0x123, [0x3B, 0x02, 0x13, 0x2D, 0xA4, 0x01, 0xCA, 0xFE]),
    (0x124, [0xF7, 0x02, 0x63, 0x2D, 0x00, 0x00, 0x00, 0x00]),
];
/// CAN frames of sample salient_points.
const SALIENT_POINTS_CAN: &[(u16, [u8; 8])] = &[
    (0x140, [0xCC, 0x02, 0x12, 0x04, 0x00, 0x00, 0x00, 0x00]),
    (0x141, [0xA2, 0x02, 0xD2, 0x02, 0x96, 0x49, 0x00, 0x00]),
    (0x142, [0x8D, 0x02, 0x73, 0x05, 0x60, 0xFF, 0x4A, 0x03]),
    (0x143, [0x7D, 0x02, 0x9C, 0x04, 0x19, 0x00, 0x43, 0x03]),
    (0x144, [0xF9, 0x02, 0xA6, 0x04, 0xAC, 0xFE, 0x3E, 0x03]),
    (0x145, [0x3F, 0x02, 0x7A, 0x03, 0x6A, 0xFF, 0x66, 0x03]),
    (0x146, [0x32, 0x02, 0x80, 0x02, 0xE2, 0xFF, 0x16, 0x03]),
    (0x147, [0x51, 0x02, 0x8A, 0x02, 0xF7, 0xFE, 0x11, 0x03]),
    (0x148, [0x24, 0x02, 0x61, 0x5B, 0x58, 0x5F, 0x54, 0x3E]),
];
/// CAN frames of sample probe.
const PROBE_CAN: &[(u16, [u8; 8])] = &[
    (0x130, [0x10, 0x02, 0x12, 0x04, 0x06, 0x00, 0x0E, 0x00]),
    (0x131, [0xF8, 0x02, 0xD2, 0x02, 0x96, 0x49, 0x00, 0x00]),
    (0x132, [0xAE, 0x02, 0x23, 0x00, 0xD2, 0x00, 0x76, 0x00]),
    (0x133, [0xCA, 0x02, 0x1F, 0x00, 0xD4, 0x00, 0x68, 0x00]),
    (0x134, [0xEE, 0x02, 0x6B, 0x11, 0x4A, 0xF7, 0xF7, 0x3C]),
];
/// CAN frames of sample body_shape.
const BODY_SHAPE_CAN: &[(u16, [u8; 8])] = &[
    (0x160, [0x9C, 0x07, 0x07, 0x00, 0x03, 0x00, 0x00, 0x00]),
    (0x161, [0xAA, 0x07, 0xD2, 0x02, 0x96, 0x49, 0x00, 0x00]),
    (0x162, [0x1E, 0x07, 0xE2, 0x04, 0x52, 0xFE, 0x34, 0x03]),
    (0x163, [0x6E, 0x07, 0x5F, 0x00, 0xE2, 0xFA, 0xF0, 0x00]),
    (0x164, [0x78, 0x07, 0xB5, 0xFF, 0xFE, 0x01, 0x24, 0xFF]),
    (0x165, [0xD5, 0x07, 0x1E, 0x00, 0x91, 0x00, 0xC4, 0xFF]),
    (0x166, [0x66, 0x07, 0x0C, 0x00, 0xA1, 0xFF, 0x28, 0x00]),
    (0x167, [0x63, 0x07, 0x08, 0x00, 0xEA, 0xFF, 0x11, 0x00]),
    (0x168, [0xBF, 0x07, 0xFB, 0xFF, 0x03, 0x00, 0x00, 0x00]),
];
/// CAN frames of sample health.
const HEALTH_CAN: &[(u16, [u8; 8])] = &[
    (0x150, [0x63, 0x00, 0xD0, 0x00, 0x01, 0x00, 0xB2, 0x0B]),
    (0x151, [0x06, 0x00, 0xD2, 0x02, 0x96, 0x49, 0x00, 0x00]),
    (0x152, [0xD2, 0x00, 0xF4, 0x47, 0x00, 0x00, 0x00, 0x00]),
    (0x153, [0x20, 0x00, 0x03, 0x00, 0x00, 0x00, 0x00, 0x00]),
    (0x154, [0x0C, 0x00, 0x0B, 0x00, 0x00, 0x00, 0x00, 0x00]),
];
/// CAN frames of sample arm_state.
const ARM_STATE_CAN: &[(u16, [u8; 8])] = &[
    (0x110, [0x7D, 0x01, 0x01, 0x14, 0x00, 0x00, 0x00, 0x00]),
    (0x111, [0x13, 0x01, 0xC0, 0x0F, 0x96, 0x49, 0x00, 0x00]),
    (0x112, [0x31, 0x01, 0xB2, 0x02, 0x88, 0xFF, 0x89, 0x03]),
    (0x113, [0xF2, 0x01, 0x33, 0x03, 0xE1, 0x3F, 0x48, 0x01]),
    (0x114, [0x7D, 0x01, 0x14, 0xFE, 0x00, 0x00, 0x00, 0x00]),
];
/// CAN frames of sample command.
const COMMAND_CAN: &[(u16, [u8; 8])] = &[
    (0x100, [0xDA, 0x0C, 0x0C, 0x00, 0x04, 0x02, 0x00, 0x00]),
    (0x101, [0xB4, 0x0C, 0x20, 0x32, 0x96, 0x49, 0x00, 0x00]),
];

/// CAN frames as (id, data) pairs.
type CanBytes = &'static [(u16, [u8; 8])];

/// Sample messages with their golden bytes, in `MESSAGES` order.
const GOLDEN: [(&[u8], CanBytes); 7] = [
    (TORSO_POSE, TORSO_POSE_CAN),
    (SALIENT_POINTS, SALIENT_POINTS_CAN),
    (PROBE, PROBE_CAN),
    (BODY_SHAPE, BODY_SHAPE_CAN),
    (HEALTH, HEALTH_CAN),
    (ARM_STATE, ARM_STATE_CAN),
    (COMMAND, COMMAND_CAN),
];

fn frame(id: u16, data: [u8; 8]) -> CanFrame {
    CanFrame::new(CanId::Standard(StandardId::new(id).unwrap()), &data).unwrap()
}

/// Replace the CRC-32C of a decoded serial frame after editing it, so that the edit reaches the later checks.
fn recrc(bytes: &mut [u8]) {
    let n = bytes.len() - 4;
    let crc = crc32c(&bytes[..n]);
    bytes[n..].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn every_kind_has_a_sample_and_golden_bytes() {
    let mut kinds: Vec<Kind> = MESSAGES.iter().map(Message::kind).collect();
    kinds.sort();
    assert_eq!(kinds, Kind::ALL.to_vec());
}

#[test]
fn serial_frames_encode_to_golden_bytes() {
    for (m, (plain, _)) in MESSAGES.iter().zip(GOLDEN) {
        let mut buf = [0u8; MAX_PLAIN_LEN];
        let n = m.emit_plain(&mut buf).unwrap();
        assert_eq!(&buf[..n], plain, "{:?}", m.kind());
        // Independent checks of the envelope: version, kind and CRC-32C (catalogue-verified in crc.rs).
        assert_eq!(plain[0], 1);
        assert_eq!(plain[1], m.kind() as u8);
        let crc = u32::from_le_bytes(plain[plain.len() - 4..].try_into().unwrap());
        assert_eq!(crc, crc32c(&plain[..plain.len() - 4]));
    }
}

#[test]
fn frozen_v1_still_decodes() {
    for (m, (plain, can)) in MESSAGES.iter().zip(GOLDEN) {
        assert_eq!(decode_plain(plain), Ok(*m));
        let mut r = CanReassembler::new(CanBase::DEFAULT);
        let out: Vec<_> = can.iter().filter_map(|&(id, d)| r.push(&frame(id, d))).collect();
        assert_eq!(out, [Ok(*m)]);
    }
}

#[test]
fn hand_checked_envelope_of_torso_pose() {
    // seq 1042 = varint 92 08; timestamp 1 234 567 890 µs = varint D2 85 D8 CC 04; x = 645 -> zigzag 1290 = 8A 0A.
    assert_eq!(
        &TORSO_POSE[..11],
        &[0x01, 0x02, 0x92, 0x08, 0xD2, 0x85, 0xD8, 0xCC, 0x04, 0x8A, 0x0A]
    );
    // CAN TORSO_HEAD: counter 1042 & 0xF = 2, seq 0x0412 LE, confidence 93, CRC over data id 0x0120.
    let head = TORSO_POSE_CAN[0].1;
    assert_eq!(&head[1..], &[0x02, 0x12, 0x04, 93, 0, 0, 0]);
    assert_eq!(
        head[0],
        crc8_sae_j1850(&[0x20, 0x01, 0x02, 0x12, 0x04, 93, 0, 0, 0])
    );
}

#[test]
fn serial_wire_frames_are_cobs_with_both_delimiters() {
    for m in &MESSAGES {
        let mut wire = [0u8; MAX_WIRE_LEN];
        let n = m.encode_serial(&mut wire).unwrap();
        assert_eq!((wire[0], wire[n - 1]), (0, 0));
        assert!(!wire[1..n - 1].contains(&0));
        let mut d: SerialDecoder = SerialDecoder::new();
        let got: Vec<_> = wire[..n].iter().filter_map(|&b| d.push(b)).collect();
        assert_eq!(got, [Ok(*m)]);
    }
    // The example frame printed in SPEC.md.
    let mut wire = [0u8; MAX_WIRE_LEN];
    let n = MESSAGES[4].encode_serial(&mut wire).unwrap();
    let hex: std::string::String = wire[..n].iter().map(|b| std::format!("{b:02X}")).collect();
    assert_eq!(hex, "00160105D001D285D8CC0401B217F48F01030B388908FD00");
}

#[test]
fn can_groups_encode_to_golden_frames() {
    for (m, (_, can)) in MESSAGES.iter().zip(GOLDEN) {
        let group = encode_group(m, CanBase::DEFAULT).unwrap();
        let got: Vec<(u16, &[u8])> = group.iter().map(|f| (f.id().raw() as u16, f.data())).collect();
        let want: Vec<(u16, &[u8])> = can.iter().map(|(id, d)| (*id, &d[..])).collect();
        assert_eq!(got, want, "{:?}", m.kind());
        for (i, (id, d)) in can.iter().enumerate() {
            let off = (id - 0x100) as u8;
            assert_eq!(can_map::locate(off), Some((m.kind(), i)));
            let p = E2ePacket::new_checked(&d[..]).unwrap();
            assert_eq!(p.counter(), (m.seq & 0xF) as u8);
            assert_eq!(p.check_crc(data_id(off)), Ok(()));
        }
    }
}

#[test]
fn can_base_moves_ids_but_not_crcs() {
    let base = CanBase::new(0x400).unwrap();
    for (m, (_, can)) in MESSAGES.iter().zip(GOLDEN) {
        let group = encode_group(m, base).unwrap();
        for (f, (id, d)) in group.iter().zip(can.iter()) {
            assert_eq!(f.id().raw(), u32::from(*id) + 0x300);
            assert_eq!(f.data(), d);
        }
        let mut r = CanReassembler::new(base);
        let out: Vec<_> = group.iter().filter_map(|f| r.push(f)).collect();
        assert_eq!(out, [Ok(*m)]);
    }
}

// Tests for serial decode errors.

#[test]
fn too_short() {
    assert_eq!(decode_plain(&[]), Err(DecodeError::TooShort));
    assert_eq!(decode_plain(&HEALTH[..5]), Err(DecodeError::TooShort));
    let f = Frame::new_unchecked(&[0x01u8][..]);
    assert_eq!(
        (f.version(), f.kind_raw(), f.payload(), f.crc()),
        (1, 0xFF, &[][..], 0)
    );
}

#[test]
fn bad_crc_anywhere() {
    for i in 0..HEALTH.len() {
        let mut b = HEALTH.to_vec();
        b[i] ^= 0x10;
        assert_eq!(decode_plain(&b), Err(DecodeError::BadCrc), "flipped byte {i}");
    }
}

#[test]
fn bad_version() {
    for v in [0u8, 2, 0xFF] {
        let mut b = HEALTH.to_vec();
        b[0] = v;
        recrc(&mut b);
        assert_eq!(decode_plain(&b), Err(DecodeError::BadVersion(v)));
    }
}

#[test]
fn unknown_kind() {
    let mut b = HEALTH.to_vec();
    b[1] = 7;
    recrc(&mut b);
    assert_eq!(decode_plain(&b), Err(DecodeError::UnknownKind(7)));
}

#[test]
fn truncated_and_trailing_payloads() {
    let mut b = HEALTH.to_vec();
    b.remove(b.len() - 5);
    recrc(&mut b);
    assert_eq!(decode_plain(&b), Err(DecodeError::Truncated));
    let mut b = HEALTH.to_vec();
    b.insert(b.len() - 4, 0);
    recrc(&mut b);
    assert_eq!(decode_plain(&b), Err(DecodeError::TrailingBytes));
}

#[test]
fn out_of_range_values() {
    // Health state is byte 9 (after version, kind, seq 2 bytes, timestamp 5 bytes).
    let mut b = HEALTH.to_vec();
    b[9] = 8;
    recrc(&mut b);
    assert_eq!(decode_plain(&b), Err(DecodeError::InvalidValue));
    // Torso confidence is the last payload byte.
    let mut b = TORSO_POSE.to_vec();
    let at = b.len() - 5;
    assert_eq!(b[at], 93);
    b[at] = 101;
    recrc(&mut b);
    assert_eq!(decode_plain(&b), Err(DecodeError::InvalidValue));
    // Timestamp of 2^48 µs: varint 80 80 80 80 80 80 80 01 (8 bytes) replacing the 5-byte one.
    let mut b = HEALTH.to_vec();
    b.splice(4..9, [0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x01]);
    recrc(&mut b);
    assert_eq!(decode_plain(&b), Err(DecodeError::InvalidValue));
}

#[test]
fn malformed_varint() {
    let mut b = HEALTH.to_vec();
    b.splice(2..4, [0xFF, 0xFF, 0xFF, 0xFF]);
    recrc(&mut b);
    assert_eq!(decode_plain(&b), Err(DecodeError::Malformed));
}

#[test]
fn encode_errors() {
    let m = MESSAGES[1];
    let mut small = [0u8; 20];
    assert_eq!(m.emit_plain(&mut small), Err(EncodeError::BufferTooSmall));
    assert_eq!(m.encode_serial(&mut small), Err(EncodeError::BufferTooSmall));
    assert_eq!(m.emit_plain(&mut []), Err(EncodeError::BufferTooSmall));
    let far = Message {
        seq: 1,
        timestamp: Timestamp::from_us(5).unwrap(),
        body: Body::TorsoPose(TorsoPose {
            position_mm: [40_000, 0, 0],
            orientation: UnitQuatQ14::IDENTITY,
            confidence: Confidence::FULL,
        }),
    };
    assert_eq!(
        encode_group(&far, CanBase::DEFAULT),
        Err(EncodeError::NotRepresentable)
    );
    let mut buf = [0u8; MAX_WIRE_LEN];
    assert!(
        far.encode_serial(&mut buf).is_ok(),
        "serial carries the full i32 range"
    );
}

// Tests for CAN group errors.

#[test]
fn can_bad_crc_length_and_remote() {
    let (id, data) = HEALTH_CAN[0];
    let mut r = CanReassembler::new(CanBase::DEFAULT);
    let mut bad = data;
    bad[3] ^= 1;
    assert_eq!(r.push(&frame(id, bad)), Some(Err(CanError::BadCrc)));
    let short = CanFrame::new(CanId::Standard(StandardId::new(id).unwrap()), &data[..7]).unwrap();
    assert_eq!(r.push(&short), Some(Err(CanError::BadLength)));
    let rtr = CanFrame::new_remote(CanId::Standard(StandardId::new(id).unwrap()), 8).unwrap();
    assert_eq!(r.push(&rtr), Some(Err(CanError::BadLength)));
    // The same bytes under another supine id fail the CRC: the data id is part of it.
    assert_eq!(r.push(&frame(id + 1, data)), Some(Err(CanError::BadCrc)));
    let s = r.stats();
    assert_eq!((s.bad_crc, s.bad_length, s.messages), (2, 2, 0));
}

#[test]
fn can_foreign_frames_are_ignored() {
    let mut r = CanReassembler::new(CanBase::DEFAULT);
    assert_eq!(r.push(&frame(0x0FF, [0; 8])), None);
    assert_eq!(r.push(&frame(0x170, [0; 8])), None);
    // Inside the block but past the end of the command group (2 frames).
    assert_eq!(r.push(&frame(0x102, [0; 8])), None);
    assert_eq!(r.stats().foreign, 3);
    assert_eq!(r.stats().errors(), 0);
}

#[test]
fn can_reordered_duplicated_and_interleaved_groups() {
    let mut r = CanReassembler::new(CanBase::DEFAULT);
    let mut out = Vec::new();
    // Points in reverse order, with the pose interleaved and a duplicate.
    for (i, &(id, d)) in SALIENT_POINTS_CAN.iter().rev().enumerate() {
        out.extend(r.push(&frame(id, d)));
        if let Some(&(pid, pd)) = TORSO_POSE_CAN.get(i) {
            out.extend(r.push(&frame(pid, pd)));
        }
        if i == 3 {
            out.push(r.push(&frame(id, d)).unwrap());
        }
    }
    assert_eq!(out, [Err(CanError::Duplicate), Ok(MESSAGES[0]), Ok(MESSAGES[1])]);
    assert_eq!(r.stats().duplicates, 1);
}

#[test]
fn can_lost_frame_drops_only_its_group() {
    let mut r = CanReassembler::new(CanBase::DEFAULT);
    let mut out = Vec::new();
    for &(id, d) in &PROBE_CAN[..4] {
        out.extend(r.push(&frame(id, d)));
    }
    // The next probe report (seq + 1) arrives whole.
    let mut next = MESSAGES[2];
    next.seq += 1;
    for f in encode_group(&next, CanBase::DEFAULT).unwrap() {
        out.extend(r.push(&f));
    }
    assert_eq!(out, [Ok(next)]);
    assert_eq!(r.stats().incomplete, 1);
}

#[test]
fn can_partial_group_expires_instead_of_merging_with_a_later_one() {
    let mut r = CanReassembler::new(CanBase::DEFAULT);
    for &(id, d) in &PROBE_CAN[..2] {
        assert_eq!(r.push(&frame(id, d)), None);
    }
    // Sixteen sequence numbers later the counter is the same again; the stale half must not be reused.
    let mut later = MESSAGES[2];
    later.seq += 16;
    later.timestamp = Timestamp::from_us(later.timestamp.as_us() + 533_000).unwrap();
    if let Body::Probe(p) = &mut later.body {
        p.signed_distance_mm = 3;
    }
    // Meanwhile the tracker's other messages go by (other nodes' frames would not age the group).
    for _ in 0..40 {
        assert_eq!(r.push(&frame(0x7FF, [0; 8])), None);
    }
    let mut health = MESSAGES[4];
    let mut own = 0;
    while own <= EXPIRY_FRAMES {
        for f in encode_group(&health, CanBase::DEFAULT).unwrap() {
            assert!(matches!(r.push(&f), None | Some(Ok(_))));
            own += 1;
        }
        health.seq += 1;
    }
    let group = encode_group(&later, CanBase::DEFAULT).unwrap();
    let out: Vec<_> = group
        .iter()
        .skip(2)
        .chain(group.iter().take(2))
        .filter_map(|f| r.push(f))
        .collect();
    assert_eq!(out, [Ok(later)]);
    assert_eq!(r.stats().incomplete, 1);
}

#[test]
fn can_counter_must_match_sequence() {
    // A group whose frames agree on counter 5 but whose HEAD says seq 208 (counter 0).
    let mut r = CanReassembler::new(CanBase::DEFAULT);
    let mut out = Vec::new();
    for (i, &(id, d)) in HEALTH_CAN.iter().enumerate() {
        let mut sig = [0u8; 6];
        sig.copy_from_slice(&d[2..]);
        out.extend(r.push(&frame(id, seal(data_id(0x50 + i as u8), 5, &sig))));
    }
    assert_eq!(out, [Err(CanError::Invalid(DecodeError::InvalidValue))]);
    assert_eq!(r.stats().invalid, 1);
}

#[test]
fn can_invalid_values() {
    // Health state 9 in HEALTH_HEAD, resealed so the CRC is right.
    let mut r = CanReassembler::new(CanBase::DEFAULT);
    let mut out = Vec::new();
    for (i, &(id, d)) in HEALTH_CAN.iter().enumerate() {
        let mut sig = [0u8; 6];
        sig.copy_from_slice(&d[2..]);
        if i == 0 {
            sig[2] = 9;
        }
        out.extend(r.push(&frame(id, seal(data_id(0x50 + i as u8), d[1], &sig))));
    }
    assert_eq!(out, [Err(CanError::Invalid(DecodeError::InvalidValue))]);
}

#[test]
fn flush_counts_pending_groups() {
    let mut r = CanReassembler::new(CanBase::DEFAULT);
    let (id, d) = BODY_SHAPE_CAN[3];
    assert_eq!(r.push(&frame(id, d)), None);
    r.flush();
    r.flush();
    assert_eq!(r.stats().incomplete, 1);
}
