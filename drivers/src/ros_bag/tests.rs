//! McapSource on bags written here (16UC1, 32FC1, several topics, damage) and on the real bag in shared/realdata.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};

use mcap::records::MessageHeader;

use super::*;

/// A fresh bag path in the temp dir, removed when dropped.
struct TempBag(PathBuf);

impl TempBag {
    fn new() -> Self {
        static N: AtomicU32 = AtomicU32::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        TempBag(std::env::temp_dir().join(format!("supine-rosbag-test-{}-{n}.mcap", std::process::id())))
    }
}

impl Drop for TempBag {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// One topic of a test bag: its name, schema and messages as (log time ns, CDR payload).
struct Topic {
    name: &'static str,
    schema: &'static str,
    messages: Vec<(u64, Vec<u8>)>,
}

fn write_bag(topics: &[Topic], compression: Option<mcap::Compression>, summary: bool) -> Vec<u8> {
    let options = mcap::WriteOptions::new()
        .compression(compression)
        .profile("ros2")
        .emit_summary_records(summary)
        .emit_summary_offsets(summary)
        .emit_statistics(summary)
        .chunk_size(Some(4096));
    let mut w = options.create(std::io::Cursor::new(Vec::new())).unwrap();
    let mut all = Vec::new();
    for t in topics {
        let schema = w.add_schema(t.schema, "ros2msg", b"").unwrap();
        let channel = w.add_channel(schema, t.name, "cdr", &BTreeMap::new()).unwrap();
        for (log_time, data) in &t.messages {
            all.push((*log_time, channel, data));
        }
    }
    // Log-time order, as rosbag2 writes.
    all.sort_by_key(|(t, c, _)| (*t, *c));
    for (seq, (log_time, channel_id, data)) in all.into_iter().enumerate() {
        let header = MessageHeader {
            channel_id,
            sequence: seq as u32,
            log_time,
            publish_time: log_time,
        };
        w.write_to_known_channel(&header, data).unwrap();
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

const EPOCH_NS: u64 = 1_700_000_000_000_000_000;
const PERIOD_NS: u64 = 33_333_333;

fn depth_pattern(i: u64, w: u32, h: u32) -> Vec<u16> {
    (0..w * h)
        .map(|p| 800 + (p as u64 * 7 + i * 13) as u16 % 3000)
        .collect()
}

fn depth_topic(name: &'static str, frames: u64, w: u32, h: u32) -> Topic {
    Topic {
        name,
        schema: IMAGE_SCHEMA,
        messages: (0..frames)
            .map(|i| {
                let t = EPOCH_NS + i * PERIOD_NS;
                (
                    t,
                    encode_image_16uc1(t, "camera_depth", w, h, &depth_pattern(i, w, h)),
                )
            })
            .collect(),
    }
}

fn save(bytes: &[u8]) -> TempBag {
    let bag = TempBag::new();
    std::fs::write(&bag.0, bytes).unwrap();
    bag
}

/// A frame as read: pixels, capture µs, index.
type Played = (Vec<u16>, u64, u32);

/// Every frame until the end; errors other than the end are returned too.
fn drain(src: &mut McapSource) -> (Vec<Played>, Vec<SourceError>) {
    let (mut frames, mut errors) = (Vec::new(), Vec::new());
    loop {
        match src.next_frame(Duration::ZERO) {
            Ok(f) => frames.push((f.depth_mm().to_vec(), f.capture.as_us(), f.index)),
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) => errors.push(e),
        }
        assert!(frames.len() + errors.len() < 10_000, "a source that never ends");
    }
    (frames, errors)
}

#[test]
fn plays_a_16uc1_topic_with_its_camera_info_and_relative_stamps() {
    let k = Intrinsics {
        fx: 300.0,
        fy: 301.0,
        cx: 7.5,
        cy: 5.5,
        width: 16,
        height: 12,
    };
    let info = Topic {
        name: "/cam/depth/camera_info",
        schema: CAMERA_INFO_SCHEMA,
        // Published after the first image: the source finds it anyway.
        messages: vec![(EPOCH_NS + 1, encode_camera_info(EPOCH_NS, "camera_depth", &k))],
    };
    let bytes = write_bag(
        &[depth_topic("/cam/depth/image_raw", 5, 16, 12), info],
        Some(mcap::Compression::Zstd),
        true,
    );
    let bag = save(&bytes);
    let mut src = McapSource::open(&bag.0, None).unwrap();
    assert_eq!(src.topic(), "/cam/depth/image_raw");
    assert_eq!(src.intrinsics(), k);
    assert_eq!(src.origin_ns(), EPOCH_NS);
    assert!(
        src.describe().contains("16UC1 16x12, 5 frames"),
        "{}",
        src.describe()
    );
    let (frames, errors) = drain(&mut src);
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(frames.len(), 5);
    for (i, (px, us, index)) in frames.iter().enumerate() {
        assert_eq!(px, &depth_pattern(i as u64, 16, 12));
        assert_eq!(*us, i as u64 * PERIOD_NS / 1000);
        assert_eq!(*index, i as u32);
    }
    // End of stream is final.
    assert_eq!(
        src.next_frame(Duration::ZERO).unwrap_err().kind(),
        SourceErrorKind::EndOfStream
    );
}

#[test]
fn plays_32fc1_metres_as_mm_from_an_uncompressed_bag_without_summary() {
    let m: Vec<f32> = (0..12).map(|p| 0.5 + p as f32 * 0.25).collect();
    let topic = Topic {
        name: "/depth",
        schema: IMAGE_SCHEMA,
        messages: (0..3)
            .map(|i| {
                let t = EPOCH_NS + i * PERIOD_NS;
                (t, encode_image_32fc1(t, "cam", 4, 3, &m))
            })
            .collect(),
    };
    let bag = save(&write_bag(&[topic], None, false));
    let mut src = McapSource::open(&bag.0, None).unwrap();
    assert_eq!(src.encoding(), DepthEncoding::Metres32);
    // No camera info: the Kinect field of view at the image's size.
    assert_eq!(
        src.intrinsics(),
        Intrinsics::from_fov(4, 3, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD)
    );
    let (frames, errors) = drain(&mut src);
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(frames.len(), 3);
    let want: Vec<u16> = (0..12).map(|p| 500 + p * 250).collect();
    assert_eq!(frames[2].0, want);
}

#[test]
fn the_depth_topic_is_chosen_among_image_topics_and_ambiguity_lists_them() {
    let colour = Topic {
        name: "/cam/rgb/image_raw",
        schema: IMAGE_SCHEMA,
        messages: vec![],
    };
    let bag = save(&write_bag(
        &[colour, depth_topic("/cam/depth/image_raw", 2, 4, 3)],
        Some(mcap::Compression::Zstd),
        true,
    ));
    let src = McapSource::open(&bag.0, None).unwrap();
    assert_eq!(src.topic(), "/cam/depth/image_raw");

    let two = save(&write_bag(
        &[depth_topic("/a/depth", 1, 4, 3), depth_topic("/b/depth", 1, 4, 3)],
        None,
        true,
    ));
    let e = McapSource::open(&two.0, None).err().unwrap();
    assert_eq!(e.kind(), SourceErrorKind::InvalidArgument);
    let msg = e.to_string();
    assert!(
        msg.contains("/a/depth (1 messages)") && msg.contains("/b/depth") && msg.contains("--topic"),
        "{msg}"
    );
    assert_eq!(
        McapSource::open(&two.0, Some("/b/depth")).unwrap().topic(),
        "/b/depth"
    );
    let e = McapSource::open(&two.0, Some("/c")).err().unwrap();
    assert!(
        e.to_string().contains("no topic /c; image topics: /a/depth"),
        "{e}"
    );
}

#[test]
fn a_bag_without_images_names_what_it_has() {
    let other = Topic {
        name: "/tf",
        schema: "tf2_msgs/msg/TFMessage",
        messages: vec![(EPOCH_NS, vec![0, 1, 0, 0])],
    };
    let bag = save(&write_bag(&[other], None, true));
    let e = McapSource::open(&bag.0, None).err().unwrap();
    assert!(
        e.to_string()
            .contains("no CDR sensor_msgs/msg/Image topic; the bag has: /tf"),
        "{e}"
    );
    let e = McapSource::open(&bag.0, Some("/tf")).err().unwrap();
    assert!(e.to_string().contains("carries tf2_msgs/msg/TFMessage"), "{e}");
}

#[test]
fn bad_frames_are_errors_and_the_stream_goes_on() {
    let mut topic = depth_topic("/depth", 6, 4, 3);
    // Frame 2: another size; frame 3: a colour image; frame 4: a stamp earlier than frame 1.
    let t2 = topic.messages[2].0;
    topic.messages[2].1 = encode_image_16uc1(t2, "cam", 2, 2, &[1, 2, 3, 4]);
    let mut colour = encode_image_16uc1(topic.messages[3].0, "cam", 4, 3, &[5; 12]);
    let at = colour.windows(5).position(|w| w == b"16UC1").unwrap();
    colour[at..at + 5].copy_from_slice(b"bgr8\0");
    topic.messages[3].1 = colour;
    topic.messages[4].1 = encode_image_16uc1(EPOCH_NS, "cam", 4, 3, &[6; 12]);
    let bag = save(&write_bag(&[topic], Some(mcap::Compression::Zstd), true));
    let mut src = McapSource::open(&bag.0, None).unwrap();
    let (frames, errors) = drain(&mut src);
    let indices: Vec<u32> = frames.iter().map(|f| f.2).collect();
    assert_eq!(indices, [0, 1, 5]);
    let kinds: Vec<SourceErrorKind> = errors.iter().map(|e| e.kind()).collect();
    assert_eq!(
        kinds,
        [
            SourceErrorKind::CorruptData,
            SourceErrorKind::Unsupported,
            SourceErrorKind::CorruptData
        ]
    );
    assert!(
        errors[0]
            .to_string()
            .contains("image 2 of /depth: 2x2, the topic started at 4x3"),
        "{}",
        errors[0]
    );
    assert!(errors[1].to_string().contains("bgr8"), "{}", errors[1]);
    assert!(
        errors[2].to_string().contains("earlier than the previous frame"),
        "{}",
        errors[2]
    );
}

#[test]
fn truncated_and_damaged_files_are_clear_errors_never_panics() {
    let bytes = write_bag(
        &[depth_topic("/depth", 8, 16, 12)],
        Some(mcap::Compression::Zstd),
        true,
    );
    let bag = TempBag::new();
    let mut opened = 0;
    for cut in (0..bytes.len()).step_by(97).chain([bytes.len() - 1]) {
        std::fs::write(&bag.0, &bytes[..cut]).unwrap();
        match McapSource::open(&bag.0, None) {
            Err(e) => assert!(
                matches!(
                    e.kind(),
                    SourceErrorKind::CorruptData
                        | SourceErrorKind::InvalidArgument
                        | SourceErrorKind::EndOfStream
                ),
                "cut at {cut}: {e:?}"
            ),
            Ok(mut src) => {
                opened += 1;
                let (frames, errors) = drain(&mut src);
                assert!(frames.len() <= 8, "cut at {cut}");
                // A cut file ends with exactly one error saying so (unless only the footer's end was lost).
                assert!(errors.len() <= 1, "cut at {cut}: {errors:?}");
                for e in &errors {
                    assert_eq!(e.kind(), SourceErrorKind::CorruptData, "cut at {cut}: {e}");
                }
            }
        }
    }
    assert!(opened > 0, "no cut kept a readable first frame");
    // Flipped bytes in the middle: errors or frames, never a panic.
    for at in (8..bytes.len()).step_by(211) {
        let mut damaged = bytes.clone();
        damaged[at] ^= 0x5a;
        std::fs::write(&bag.0, &damaged).unwrap();
        if let Ok(mut src) = McapSource::open(&bag.0, None) {
            drain(&mut src);
        }
    }
}

#[test]
fn a_missing_file_is_no_device_and_not_mcap_is_corrupt() {
    let e = McapSource::open("/nonexistent/bag.mcap", None).err().unwrap();
    assert_eq!(e.kind(), SourceErrorKind::NoDevice);
    assert!(e.to_string().contains("/nonexistent/bag.mcap"), "{e}");
    let bag = save(b"this is not an mcap file at all, just text");
    let e = McapSource::open(&bag.0, None).err().unwrap();
    assert_eq!(e.kind(), SourceErrorKind::CorruptData, "{e}");
}

/// The real bag in shared/realdata (five frames of one man, 16UC1, camera info); skipped when absent (CI clones).
/// shared/ lies beside the checkout, or where `$SUPINE_SHARED_DIR` says (a worktree elsewhere).
#[test]
fn plays_the_real_tue_bag() {
    let shared = std::env::var_os("SUPINE_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let path = shared.join("realdata/mcap/tue_person_depth_16UC1.mcap");
    if !path.is_file() {
        eprintln!("shared/realdata not available: skipped");
        return;
    }
    let mut src = McapSource::open(&path, None).unwrap();
    assert_eq!(src.topic(), "/camera/depth/image_raw");
    let k = src.intrinsics();
    assert_eq!((k.width, k.height), (640, 480));
    assert!(
        (k.fx - 537.03).abs() < 0.01 && (k.cy - 227.7).abs() < 0.01,
        "{k:?}"
    );
    let (frames, errors) = drain(&mut src);
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(frames.len(), 5);
    for (i, (px, us, _)) in frames.iter().enumerate() {
        // A man about 2 m away: most valid pixels in 0.5-8 m, and 33.3 ms between frames.
        let valid: Vec<u16> = px.iter().copied().filter(|&d| d > 0).collect();
        assert!(valid.len() > px.len() / 4, "frame {i}: {} valid", valid.len());
        assert!(valid.iter().all(|&d| (300..=10_000).contains(&d)), "frame {i}");
        assert!(
            (*us as i64 - i as i64 * 33_333).abs() <= 1,
            "frame {i} at {us} µs"
        );
    }
}
