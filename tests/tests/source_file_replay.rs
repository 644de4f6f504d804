//! Depth sources across crates: a recording opened by its CLI source string, replayed through the wrappers the
//! service stacks on a live source (recording, fault injection), frame for frame.

use std::time::Duration;

use supine_core::camera::Intrinsics;
use supine_drivers::fault::{FaultySource, SourceFaultConfig};
use supine_drivers::oni::{Codec, OniReader, OniWriter};
use supine_drivers::recording::Recording;
use supine_drivers::source::{self, DepthSource, SourceErrorKind, SourceSpec};

fn frames(n: usize) -> Vec<Vec<u16>> {
    (0..n)
        .map(|t| (0..640 * 480).map(|i| (800 + (i % 640) + t * 3) as u16).collect())
        .collect()
}

#[test]
fn file_spec_replays_through_recording_and_fault_injection() {
    let dir = std::env::temp_dir().join(format!("supine-source-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("in.oni");
    let copy = dir.join("copy.oni");
    let want = frames(6);
    let mut w = OniWriter::create(&input, &Intrinsics::KINECT_V1, Codec::Z16).unwrap();
    for (t, px) in want.iter().enumerate() {
        w.write_frame(px, t as u64 * 33_333).unwrap();
    }
    w.finish().unwrap();

    let spec: SourceSpec = format!("file:{}", input.display()).parse().unwrap();
    let src = source::open(&spec).unwrap();
    assert!(
        src.describe().contains("16zP 640x480, 6 frames"),
        "{}",
        src.describe()
    );
    let rec = Recording::create(src, &copy, Codec::Z16Table).unwrap();
    let mut faulty = FaultySource::new(
        rec,
        SourceFaultConfig {
            disconnect_after: Some(4),
            ..SourceFaultConfig::none(9)
        },
    );
    for (t, px) in want.iter().take(4).enumerate() {
        let f = faulty.next_frame(Duration::from_millis(10)).unwrap();
        assert_eq!(f.index, t as u32 + 1);
        assert!(f.depth_mm() == &px[..]);
    }
    assert_eq!(
        faulty.next_frame(Duration::ZERO).unwrap_err().kind(),
        SourceErrorKind::Disconnected
    );
    let rec = faulty.into_inner();
    assert_eq!(rec.frames_recorded(), 4);
    rec.finish().unwrap();

    let mut r = OniReader::open(&copy).unwrap();
    for px in want.iter().take(4) {
        assert!(r.read_frame().unwrap().depth_mm() == &px[..]);
    }
    assert_eq!(r.read_frame().unwrap_err().kind(), SourceErrorKind::EndOfStream);
    std::fs::remove_dir_all(&dir).unwrap();
}
