//! A sequence written by `supine-models sequence` plays in the real libOpenNI2 frame by frame: every frame
//! OpenNI2 delivers equals, pixel for pixel, the depth image the generator rendered, with the timestamp of the
//! ground-truth file. (Feature `openni2`; run by tests/run.sh with `--include-ignored`.)
#![cfg(feature = "openni2")]

use std::time::Duration;

use supine_drivers::openni2::OpenNi2Source;
use supine_drivers::source::{DepthSource, SourceErrorKind};
use supine_models::scene::model_body::{BodyKind, open_source};
use supine_models::sequence::{SequenceConfig, generate};

#[test]
#[ignore = "needs libOpenNI2; run by tests/run.sh"]
fn generated_sequence_plays_frame_exact_in_libopenni2() {
    let dir = std::env::temp_dir().join(format!("supine-seq-openni2-{}", std::process::id()));
    let source = open_source(BodyKind::Model, None).expect("the committed body model");
    let cfg = SequenceConfig::new(12, 3, true);
    let mut rendered: Vec<Vec<u16>> = Vec::new();
    generate(source.as_ref(), &cfg, &dir, &mut |_, depth| {
        rendered.push(depth.to_vec())
    })
    .unwrap();
    assert_eq!(rendered.len(), 12);

    let truth: Vec<serde_json::Value> = std::fs::read_to_string(dir.join("truth.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(truth.len(), rendered.len());

    let path = dir.join("sequence.oni");
    let mut oni = OpenNi2Source::open(Some(path.to_str().unwrap())).expect("libOpenNI2 opens the sequence");
    for (i, want) in rendered.iter().enumerate() {
        let frame = oni
            .next_frame(Duration::from_secs(5))
            .unwrap_or_else(|e| panic!("frame {i}: {e}"));
        assert_eq!(
            frame.depth_mm(),
            &want[..],
            "frame {i} differs from the rendered depth"
        );
        let truth_us = truth[i]["time_us"].as_u64().unwrap();
        assert_eq!(frame.capture.as_us(), truth_us, "frame {i} timestamp");
        assert!(
            want.iter().any(|&d| d != 0),
            "frame {i} is empty: the test would prove nothing"
        );
    }
    match oni.next_frame(Duration::from_millis(500)) {
        Err(e) => assert!(
            matches!(e.kind(), SourceErrorKind::EndOfStream | SourceErrorKind::Timeout),
            "after the last frame: {e}"
        ),
        Ok(f) => panic!("libOpenNI2 delivered an extra frame {}", f.index),
    }
    drop(oni);
    let _ = std::fs::remove_dir_all(&dir);
}
