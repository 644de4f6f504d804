//! Interoperability with the real libOpenNI2 (feature `openni2`; run by tests/run.sh with `--include-ignored`):
//! files from our writer play frame-exact through OpenNI2, files from OpenNI2's own Recorder read exactly with our
//! reader. (Enumeration without a device is in `openni2_no_device.rs`: its own process, because a file opened
//! earlier in the same process shows up in OpenNI2's device list.)
#![cfg(feature = "openni2")]

use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Duration;

use supine_core::camera::Intrinsics;
use supine_drivers::oni::{Codec, OniReader, OniWriter};
use supine_drivers::openni2::OpenNi2Source;
use supine_drivers::source::{DepthSource, SourceErrorKind};

/// libOpenNI2 is one process-wide library: run these tests one at a time.
static OPENNI: Mutex<()> = Mutex::new(());

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("supine-openni2-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Depth-like 640x480 frames that differ per frame: a tilted plane, a moving box, holes, and far values.
fn frame(t: usize) -> Vec<u16> {
    (0..640 * 480)
        .map(|i| {
            let (u, v) = (i % 640, i / 640);
            if (u * 13 + v * 7 + t * 3).is_multiple_of(41) {
                0
            } else if (200 + t * 10..300 + t * 10).contains(&u) && (100..380).contains(&v) {
                (850 + t * 7 + (u % 5)) as u16
            } else {
                (1200 + v * 6 + u / 2 + t) as u16
            }
        })
        .collect()
}

fn write_ours(path: &PathBuf, codec: Codec, n: usize) -> Vec<(Vec<u16>, u64)> {
    let frames: Vec<(Vec<u16>, u64)> = (0..n).map(|t| (frame(t), 5_000 + t as u64 * 33_333)).collect();
    let mut w = OniWriter::create(path, &Intrinsics::KINECT_V1, codec).unwrap();
    for (px, ts) in &frames {
        w.write_frame(px, *ts).unwrap();
    }
    w.finish().unwrap();
    frames
}

fn read_through_openni2(src: &mut OpenNi2Source) -> Vec<(Vec<u16>, u64, u32)> {
    let mut out = Vec::new();
    loop {
        match src.next_frame(Duration::from_millis(500)) {
            Ok(f) => out.push((f.depth_mm().to_vec(), f.capture.as_us(), f.index)),
            Err(e) => {
                assert_eq!(e.kind(), SourceErrorKind::EndOfStream, "{e}");
                return out;
            }
        }
    }
}

#[test]
#[ignore = "needs libOpenNI2; run by tests/run.sh"]
fn our_files_play_frame_exact_through_libopenni2() {
    let _g = OPENNI.lock().unwrap_or_else(|p| p.into_inner());
    for codec in [Codec::None, Codec::Z16, Codec::Z16Table] {
        let path = scratch(&format!("ours-{codec}.oni"));
        let frames = write_ours(&path, codec, 12);
        let mut src = OpenNi2Source::open(Some(path.to_str().unwrap())).unwrap();
        assert!(src.is_file());
        let k = src.intrinsics();
        assert!(
            (k.fx - Intrinsics::KINECT_V1.fx).abs() < 0.05,
            "{codec}: FOV from xnFOV gives fx {}",
            k.fx
        );
        let got = read_through_openni2(&mut src);
        assert_eq!(got.len(), frames.len(), "{codec}: every frame, none repeated");
        for (i, ((px, ts, idx), (want, want_ts))) in got.iter().zip(&frames).enumerate() {
            assert_eq!(*idx, i as u32 + 1, "{codec}: frame {i} index");
            assert_eq!(ts, want_ts, "{codec}: frame {i} timestamp");
            assert!(px == want, "{codec}: frame {i} pixels differ");
        }
        drop(src);
        let _ = std::fs::remove_file(&path);
    }
}

#[test]
#[ignore = "needs libOpenNI2; run by tests/run.sh"]
fn our_reader_reads_a_file_recorded_by_openni2() {
    let _g = OPENNI.lock().unwrap_or_else(|p| p.into_inner());
    let ours = scratch("for-rerecord.oni");
    let theirs = scratch("rerecorded-by-openni2.oni");
    let frames = write_ours(&ours, Codec::None, 8);
    {
        let mut src = OpenNi2Source::open(Some(ours.to_str().unwrap())).unwrap();
        src.start_openni2_recording(theirs.to_str().unwrap()).unwrap();
        let got = read_through_openni2(&mut src);
        assert_eq!(got.len(), frames.len());
        src.stop_openni2_recording();
    }
    let mut r = OniReader::open(&theirs).unwrap();
    assert_eq!(
        r.info().codec,
        Codec::Z16Table,
        "OpenNI's Recorder always writes 16zT depth"
    );
    assert_eq!((r.info().width, r.info().height), (640, 480));
    let mut recorded = Vec::new();
    loop {
        match r.read_frame() {
            Ok(f) => recorded.push((f.depth_mm().to_vec(), f.capture.as_us(), f.index)),
            Err(e) => {
                assert_eq!(e.kind(), SourceErrorKind::EndOfStream, "{e}");
                break;
            }
        }
    }
    // The Recorder starts asynchronously (its own thread handles START), so it may miss the first frame the player
    // had already produced; everything it did record must be an exact, contiguous run of our frames.
    assert!(
        recorded.len() + 2 >= frames.len() && !recorded.is_empty(),
        "recorded {} frames",
        recorded.len()
    );
    let k0 = frames
        .iter()
        .position(|(px, _)| *px == recorded[0].0)
        .expect("the first recorded frame is one of ours");
    assert_eq!(
        k0 + recorded.len(),
        frames.len(),
        "the recording runs to the last frame"
    );
    for (j, (px, ts, id)) in recorded.iter().enumerate() {
        let (want, want_ts) = &frames[k0 + j];
        assert!(
            px == want,
            "recorded frame {j} pixels differ from our frame {}",
            k0 + j
        );
        // The Recorder rebases time so that its first frame is at 0 and keeps the deltas; ids count from 1.
        assert_eq!(*ts, want_ts - frames[k0].1, "recorded frame {j} timestamp");
        assert_eq!(*id, j as u32 + 1);
    }
    let _ = std::fs::remove_file(&theirs);
    let _ = std::fs::remove_file(&ours);
}
