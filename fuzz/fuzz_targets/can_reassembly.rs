//! CAN reassembly: arbitrary frame sequences (ids mostly inside the supine block, any length, remote or not)
//! through the reassembler. Every message it completes must re-encode to a group that reassembles to the same
//! message, and the counters must account for every frame offered. Records flagged "sealed" get a correct
//! CRC-8 for their id (the fuzzer could rarely guess it), so complete groups and their decoding are reached.
#![no_main]

use libfuzzer_sys::fuzz_target;
use supine_core::wire::can::{self, CanBase, CanFrame, CanId, ExtendedId, StandardId};
use supine_core::wire::can_map::encode_group;
use supine_core::wire::reassembly::CanReassembler;

fuzz_target!(|data: &[u8]| {
    let base = CanBase::DEFAULT;
    let mut r = CanReassembler::new(base);
    let mut offered = 0u32;
    let mut rest = data;
    // Record: id low byte, flags (bit 7 remote, bit 6 extended, bit 5 outside the block, bit 4 sealed, bits 0..3
    // length), data.
    while let [id, flags, tail @ ..] = rest {
        let len = usize::from(flags & 0x0F).min(8).min(tail.len());
        let (payload, next) = tail.split_at(len);
        rest = next;
        let raw = if flags & 0x20 != 0 {
            u16::from(*id)
        } else {
            0x100 + u16::from(*id) % 0x70
        };
        let id = if flags & 0x40 != 0 {
            CanId::Extended(ExtendedId::new(u32::from(raw)).unwrap())
        } else {
            CanId::Standard(StandardId::new(raw).unwrap())
        };
        let mut bytes = [0u8; 8];
        bytes[..len].copy_from_slice(payload);
        let offset = base.offset_of(id);
        if let (true, 8, Some(off)) = (flags & 0x10 != 0, len, offset) {
            let signals: [u8; 6] = bytes[2..].try_into().unwrap();
            bytes = can::seal(can::data_id(off), bytes[1], &signals);
        }
        let frame = if flags & 0x80 != 0 {
            CanFrame::new_remote(id, len as u8).unwrap()
        } else {
            CanFrame::new(id, &bytes[..len]).unwrap()
        };
        offered += 1;
        if let Some(Ok(m)) = r.push(&frame) {
            let group = encode_group(&m, base).expect("a reassembled message always re-encodes");
            let mut again = CanReassembler::new(base);
            let out: Vec<_> = group.iter().filter_map(|f| again.push(f)).collect();
            assert_eq!(out, [Ok(m)]);
        }
    }
    r.flush();
    let s = r.stats();
    assert_eq!(s.frames, offered);
    assert!(s.foreign + s.bad_length + s.bad_crc + s.duplicates <= offered);
});
