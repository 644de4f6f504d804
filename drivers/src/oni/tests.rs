//! Writer→reader round trips, golden bytes and corrupt-file handling for the .oni module.

use std::io::Cursor;

use supine_core::camera::Intrinsics;

use super::*;
use crate::source::{DepthSource, SourceErrorKind};

fn config(w: u16, h: u16, codec: Codec) -> OniWriterConfig {
    let k = Intrinsics::from_fov(w, h, 1.0, 0.8);
    OniWriterConfig::new(&k, codec)
}

/// Deterministic depth-like frames: a slanted plane with a box and holes, different per frame.
fn frame(w: usize, h: usize, t: usize) -> Vec<u16> {
    (0..w * h)
        .map(|i| {
            let (u, v) = (i % w, i / w);
            if (u * 7 + v * 3 + t).is_multiple_of(23) {
                0
            } else if u > w / 3 && u < w / 2 && v > h / 4 {
                (900 + t * 5) as u16
            } else {
                (1500 + v * 4 + u + t * 3) as u16
            }
        })
        .collect()
}

fn write_file(cfg: OniWriterConfig, frames: &[(Vec<u16>, u64)]) -> Vec<u8> {
    let mut w = OniWriter::new(Cursor::new(Vec::new()), cfg).unwrap();
    for (f, ts) in frames {
        w.write_frame(f, *ts).unwrap();
    }
    w.finish().unwrap().into_inner()
}

fn read_all(bytes: &[u8]) -> (Vec<(Vec<u16>, u64, u32)>, crate::source::SourceError) {
    let mut r = OniReader::new(Cursor::new(bytes), "test.oni").unwrap();
    let mut out = Vec::new();
    loop {
        match r.read_frame() {
            Ok(f) => out.push((f.depth_mm().to_vec(), f.capture.as_us(), f.index)),
            Err(e) => return (out, e),
        }
    }
}

#[test]
fn round_trip_every_codec() {
    for codec in [Codec::None, Codec::Z16, Codec::Z16Table] {
        let frames: Vec<(Vec<u16>, u64)> = (0..5)
            .map(|t| (frame(64, 48, t), 1_000_000 + t as u64 * 33_333))
            .collect();
        let bytes = write_file(config(64, 48, codec), &frames);
        let r = OniReader::new(Cursor::new(&bytes[..]), "x").unwrap();
        assert_eq!(r.info().codec, codec);
        assert_eq!((r.info().width, r.info().height, r.info().fps), (64, 48, 30));
        assert_eq!(r.info().frames, Some(5));
        assert_eq!(r.info().max_depth, Some(10_000));
        let (hf, vf) = r.info().fov_rad.unwrap();
        assert!((hf - 1.0).abs() < 1e-6 && (vf - 0.8).abs() < 1e-6);
        let (got, end) = read_all(&bytes);
        assert_eq!(end.kind(), SourceErrorKind::EndOfStream, "{codec}: {end}");
        assert_eq!(got.len(), frames.len(), "{codec}");
        for (i, ((px, ts, id), (want, want_ts))) in got.iter().zip(&frames).enumerate() {
            assert_eq!(px, want, "{codec} frame {i} pixels");
            assert_eq!(ts, want_ts, "{codec} frame {i} timestamp");
            assert_eq!(*id, i as u32 + 1, "{codec} frame ids count from 1");
        }
    }
}

#[test]
fn full_vga_frames_round_trip_and_compress() {
    let frames: Vec<(Vec<u16>, u64)> = (0..2).map(|t| (frame(640, 480, t), t as u64 * 33_333)).collect();
    let raw = write_file(config(640, 480, Codec::None), &frames);
    let z = write_file(config(640, 480, Codec::Z16Table), &frames);
    assert!(z.len() * 2 < raw.len(), "16zT {} vs raw {}", z.len(), raw.len());
    let (got, _) = read_all(&z);
    assert_eq!(got[1].0, frames[1].0);
}

#[test]
fn intrinsics_come_from_the_file_fov() {
    let k = Intrinsics::KINECT_V1;
    let mut w = OniWriter::new(Cursor::new(Vec::new()), OniWriterConfig::new(&k, Codec::Z16)).unwrap();
    w.write_frame(&vec![1000; 640 * 480], 0).unwrap();
    let bytes = w.finish().unwrap().into_inner();
    let r = OniReader::new(Cursor::new(bytes), "k").unwrap();
    let got = r.intrinsics();
    assert!(
        (got.fx - k.fx).abs() < 0.01 && (got.fy - k.fy).abs() < 0.01,
        "{got:?}"
    );
    assert_eq!((got.cx, got.cy), (320.0, 240.0));
    assert!(
        r.describe().contains("16zP 640x480, 1 frames"),
        "{}",
        r.describe()
    );
}

/// Offsets of the tiny golden file: header 24, NODE_ADDED 74, properties 61+64+59+58+59, READY 28, BEGIN 40,
/// two NEW_DATA of 40+8, NODE_REMOVED 28, SEEK_TABLE 28+60, END 28.
#[test]
fn golden_bytes() {
    let frames = vec![(vec![1000, 0, 0xFFFF, 7], 0u64), (vec![1, 2, 3, 4], 33_333)];
    let bytes = write_file(config(2, 2, Codec::None), &frames);
    assert_eq!(bytes.len(), 707);
    #[rustfmt::skip]
    let header = [
        b'N', b'I', b'1', b'0', 1, 0, 1, 0, 0, 0, 0, 0,
        0x35, 0x82, 0, 0, 0, 0, 0, 0, // maxTimeStamp = 33333
        1, 0, 0, 0, // maxNodeId
    ];
    assert_eq!(bytes[..24], header);
    #[rustfmt::skip]
    let node_added = [
        b'N', b'I', b'R', 0, 0x0D, 0, 0, 0, 1, 0, 0, 0, 74, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
        6, 0, 0, 0, b'D', b'e', b'p', b't', b'h', 0,
        2, 0, 0, 0, b'N', b'O', b'N', b'E',
        2, 0, 0, 0, // frames
        0, 0, 0, 0, 0, 0, 0, 0, // minTS
        0x35, 0x82, 0, 0, 0, 0, 0, 0, // maxTS
        0x4F, 0x02, 0, 0, 0, 0, 0, 0, // seek table at 591
    ];
    assert_eq!(bytes[24..98], node_added);
    // The second NEW_DATA at 515: undo = 467 (the first), ts 33333, frame id 2, raw LE pixels.
    #[rustfmt::skip]
    let new_data = [
        b'N', b'I', b'R', 0, 0x0A, 0, 0, 0, 1, 0, 0, 0, 40, 0, 0, 0, 8, 0, 0, 0, 0xD3, 0x01, 0, 0, 0, 0, 0, 0,
        0x35, 0x82, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0,
        1, 0, 2, 0, 3, 0, 4, 0,
    ];
    assert_eq!(bytes[515..563], new_data);
    // xnCropping: 12 zero bytes, required by the player.
    assert_eq!(bytes[340 + 28..340 + 28 + 15], *b"\x0b\0\0\0xnCropping\0");
    // Seek table: entry 0 zero, then (ts, config 0, offset) per frame.
    let st = &bytes[591 + 28..591 + 28 + 60];
    assert_eq!(st[..20], [0; 20]);
    assert_eq!(st[20..28], 0u64.to_le_bytes());
    assert_eq!(st[32..40], 467u64.to_le_bytes());
    assert_eq!(st[40..48], 33_333u64.to_le_bytes());
    assert_eq!(st[52..60], 515u64.to_le_bytes());
    assert_eq!(bytes[679..683], *b"NIR\0");
    assert_eq!(bytes[683..687], 0x0Bu32.to_le_bytes());
}

#[test]
fn trailing_junk_after_end_is_ignored() {
    let frames = vec![(frame(8, 6, 0), 5u64)];
    let mut bytes = write_file(config(8, 6, Codec::Z16Table), &frames);
    bytes.extend_from_slice(&[0xAB; 1000]);
    let (got, end) = read_all(&bytes);
    assert_eq!(got.len(), 1);
    assert_eq!(end.kind(), SourceErrorKind::EndOfStream);
}

#[test]
fn truncated_files_deliver_whole_frames_then_say_truncated() {
    let frames: Vec<(Vec<u16>, u64)> = (0..3).map(|t| (frame(16, 12, t), t as u64)).collect();
    let bytes = write_file(config(16, 12, Codec::Z16), &frames);
    let full = read_all(&bytes).0;
    assert_eq!(full.len(), 3);
    // The tail is NODE_REMOVED (28), SEEK_TABLE (28 + 4 * 20), END (28): len - 170 is inside the third frame.
    for cut in [bytes.len() - 170, 500] {
        let (got, end) = read_all(&bytes[..cut]);
        assert!(got.len() < 3, "cut at {cut}");
        for (i, g) in got.iter().enumerate() {
            assert_eq!(g.0, frames[i].0);
        }
        assert_eq!(end.kind(), SourceErrorKind::CorruptData, "cut at {cut}: {end}");
        assert!(end.to_string().contains("truncated"), "cut at {cut}: {end}");
    }
    // Damage after NODE_REMOVED does not matter: the stream has ended by then.
    let (got, end) = read_all(&bytes[..bytes.len() - 1]);
    assert_eq!((got.len(), end.kind()), (3, SourceErrorKind::EndOfStream));
    // Cut inside the description: open fails clearly.
    let e = OniReader::new(Cursor::new(&bytes[..150]), "cut.oni").unwrap_err();
    assert_eq!(e.kind(), SourceErrorKind::CorruptData);
    assert!(e.to_string().contains("truncated"), "{e}");
    let e = OniReader::new(Cursor::new(&bytes[..10]), "cut.oni").unwrap_err();
    assert!(e.to_string().contains("file header"), "{e}");
}

#[test]
fn corrupt_files_give_clear_errors() {
    let frames = vec![(frame(8, 6, 0), 0u64), (frame(8, 6, 1), 1)];
    let good = write_file(config(8, 6, Codec::Z16Table), &frames);

    let mut bad_magic = good.clone();
    bad_magic[0] = b'X';
    let e = OniReader::new(Cursor::new(bad_magic), "m").unwrap_err();
    assert!(e.to_string().contains("not an .oni file"), "{e}");

    let mut old = good.clone();
    old[6] = 0; // version 1.0.0.0
    let e = OniReader::new(Cursor::new(old), "v").unwrap_err();
    assert_eq!(e.kind(), SourceErrorKind::Unsupported);

    let mut codec = good.clone();
    codec[24 + 28 + 10 + 4..24 + 28 + 10 + 8].copy_from_slice(b"JPEG");
    let e = OniReader::new(Cursor::new(codec), "c").unwrap_err();
    assert_eq!(e.kind(), SourceErrorKind::Unsupported);
    assert!(e.to_string().contains("JPEG"), "{e}");

    // A huge payload length in the first NEW_DATA (at 467) must not allocate or read it.
    let mut huge = good.clone();
    huge[467 + 16..467 + 20].copy_from_slice(&u32::MAX.to_le_bytes());
    let (got, e) = read_all(&huge);
    assert!(got.is_empty());
    assert!(e.to_string().contains("larger than any valid frame"), "{e}");

    let mut fields = good.clone();
    fields[467 + 12..467 + 16].copy_from_slice(&u32::MAX.to_le_bytes());
    let (_, e) = read_all(&fields);
    assert!(e.to_string().contains("fields size"), "{e}");

    let mut magic = good.clone();
    magic[467] = b'X';
    let (_, e) = read_all(&magic);
    assert!(
        e.to_string().contains("record magic") && e.to_string().contains("offset 467"),
        "{e}"
    );

    // A corrupt payload (table index past the table).
    let mut payload = good.clone();
    let p = 467 + 40;
    payload[p..p + 2].copy_from_slice(&1u16.to_le_bytes()); // K = 1
    let (_, e) = read_all(&payload);
    assert_eq!(e.kind(), SourceErrorKind::CorruptData);
    assert!(e.to_string().contains("16zT"), "{e}");
}

#[test]
fn writer_rejects_bad_frames() {
    let mut w = OniWriter::new(Cursor::new(Vec::new()), config(4, 2, Codec::Z16Table)).unwrap();
    assert_eq!(
        w.write_frame(&[0; 7], 0).unwrap_err().kind(),
        SourceErrorKind::InvalidArgument
    );
    w.write_frame(&[1; 8], 10).unwrap();
    assert!(
        w.write_frame(&[1; 8], 9)
            .unwrap_err()
            .to_string()
            .contains("before the previous")
    );
    let e = w.write_frame(&[10_000; 8], 11).unwrap_err();
    assert!(e.to_string().contains("10000"), "{e}");
    assert_eq!(w.frames_written(), 1);
    let bytes = w.finish().unwrap().into_inner();
    assert_eq!(read_all(&bytes).0.len(), 1);
    assert!(OniWriter::new(Cursor::new(Vec::new()), config(0, 2, Codec::None)).is_err());
}

#[test]
fn unfinished_file_still_reads() {
    // Simulate a crash: take the bytes before finish() (the writer flushes nothing itself for a Cursor).
    let mut w = OniWriter::new(Cursor::new(Vec::new()), config(8, 6, Codec::Z16)).unwrap();
    w.write_frame(&frame(8, 6, 0), 0).unwrap();
    w.write_frame(&frame(8, 6, 1), 1).unwrap();
    let snapshot = w.get_ref().unwrap().get_ref().clone();
    drop(w);
    let r = OniReader::new(Cursor::new(&snapshot[..]), "crash").unwrap();
    assert_eq!(r.info().frames, None);
    let (got, end) = read_all(&snapshot);
    assert_eq!(got.len(), 2);
    assert!(end.to_string().contains("without an END"), "{end}");
}

#[test]
fn dropped_writer_finishes_the_file() {
    let dir = std::env::temp_dir().join(format!("supine-oni-drop-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("drop.oni");
    {
        let mut w = OniWriter::create(&path, &Intrinsics::from_fov(8, 6, 1.0, 0.8), Codec::None).unwrap();
        w.write_frame(&frame(8, 6, 0), 0).unwrap();
    }
    let mut r = OniReader::open(&path).unwrap();
    assert_eq!(r.info().frames, Some(1));
    assert!(r.next_frame(std::time::Duration::ZERO).is_ok());
    assert_eq!(
        r.next_frame(std::time::Duration::ZERO).unwrap_err().kind(),
        SourceErrorKind::EndOfStream
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn depth_100um_is_converted_to_mm() {
    let mut bytes = write_file(config(2, 2, Codec::None), &[(vec![10, 15, 20_004, 0], 0)]);
    // oniPixelFormat value sits at 223 + 28 + 4 + 15 + 4.
    let at = 223 + 28 + 4 + 15 + 4;
    assert_eq!(bytes[at..at + 8], 100u64.to_le_bytes());
    bytes[at..at + 8].copy_from_slice(&101u64.to_le_bytes());
    let (got, _) = read_all(&bytes);
    assert_eq!(got[0].0, [1, 2, 2000, 0]);
}

#[test]
fn other_nodes_are_skipped() {
    // A foreign NEW_DATA (node 5) before our first frame is skipped; the reader only returns node 1's frames.
    let frames = vec![(vec![5, 6, 7, 8], 3u64)];
    let bytes = write_file(config(2, 2, Codec::None), &frames);
    let mut patched = bytes[..467].to_vec();
    let mut foreign = Vec::new();
    foreign.extend_from_slice(b"NIR\0");
    foreign.extend_from_slice(&0x0Au32.to_le_bytes());
    foreign.extend_from_slice(&5u32.to_le_bytes());
    foreign.extend_from_slice(&40u32.to_le_bytes());
    foreign.extend_from_slice(&3u32.to_le_bytes());
    foreign.extend_from_slice(&[0; 8 + 12 + 3]);
    patched.extend_from_slice(&foreign);
    patched.extend_from_slice(&bytes[467..]);
    let (got, end) = read_all(&patched);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].0, [5, 6, 7, 8]);
    assert_eq!(end.kind(), SourceErrorKind::EndOfStream);
}
