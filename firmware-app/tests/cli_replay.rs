//! `supine replay` (and `supine demo --record`): the committed recording to MCAP, the live view's flags, and the errors a user meets (a topic
//! for an .oni file, an MCAP without depth images, an output over the input, a missing file).

mod common;

use common::{demo_recording, scratch, supine};

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The file is an MCAP recording that was finished: the magic at both ends.
fn assert_finished_mcap(path: &std::path::Path) {
    let mcap = std::fs::read(path).unwrap();
    assert_eq!(&mcap[..8], b"\x89MCAP0\r\n");
    assert_eq!(
        &mcap[mcap.len() - 8..],
        b"\x89MCAP0\r\n",
        "a finished file ends with the magic"
    );
}

#[test]
fn replay_records_the_demo_to_mcap_and_reports_json() {
    let dir = scratch("replay-record");
    let out = supine()
        .current_dir(&dir)
        .arg("replay")
        .arg(demo_recording())
        .args(["--record", "demo.mcap", "--json", "r.json", "--frames", "12"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_finished_mcap(&dir.join("demo.mcap"));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
    assert_eq!(report["frames"], 12);
    assert_eq!(report["recorded_frames"], 12);
    assert_eq!(report["corrupt_frames"], 0);
    // The tracker ran: init takes the first frames, then it tracks (the demo's truth is not given: no accuracy).
    assert!(report["tracked_fraction"].as_f64().is_some(), "{report}");
    assert!(
        report["torso_surface_error_mm_mean"].is_null(),
        "no truth given: no accuracy figure"
    );
    assert!(report["states"]["initialising"].as_u64().unwrap() >= 1);
    // The recorder's thread allocates beside the tracker: allocations are not counted then.
    assert!(report["tracker_allocations_after_init"].is_null(), "{report}");
    assert!(
        text(&out.stdout).contains("12 frames to demo.mcap"),
        "{}",
        text(&out.stdout)
    );

    // The recording is Foxglove's, not a ROS 2 depth bag: replaying it says what it holds instead.
    let again = supine()
        .current_dir(&dir)
        .args(["replay", "demo.mcap"])
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(2), "{}", text(&again.stderr));
    let err = text(&again.stderr);
    assert!(
        err.contains("no CDR sensor_msgs/msg/Image topic") && err.contains("/depth"),
        "{err}"
    );
}

#[test]
fn a_topic_for_an_oni_file_is_a_usage_error() {
    let out = supine()
        .arg("replay")
        .arg(demo_recording())
        .args(["--topic", "/camera/depth/image_raw"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("--topic is for ROS 2 bags"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn record_over_the_input_and_a_missing_file_are_refused() {
    let dir = scratch("replay-refused");
    let input = common::copy_recording(&dir, "in.oni");
    let out = supine()
        .current_dir(&dir)
        .args(["replay", "in.oni", "--record", "in.oni"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("refusing to write over an input"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(
        std::fs::read(&input).unwrap(),
        std::fs::read(demo_recording()).unwrap()
    );

    let out = supine()
        .current_dir(&dir)
        .args(["replay", "nothere.mcap"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("nothere.mcap"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn view_flags_are_checked() {
    let out = supine()
        .arg("replay")
        .arg(demo_recording())
        .args(["--view", "nowhere"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("HOST:PORT"), "{}", text(&out.stderr));
    let out = supine()
        .arg("replay")
        .arg(demo_recording())
        .args(["--view-wait", "3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "--view-wait needs --view");
}

/// The demo's true probe poses as an arm capture (arm-state messages in the serial framing, as arm.cobs holds
/// them), 5 ms after each frame's capture.
fn arm_capture_of_the_demo(path: &std::path::Path) -> usize {
    use supine_core::geometry::{Matrix3, Rotation3, UnitQuaternion};
    use supine_core::time::Timestamp;
    use supine_core::wire::{ArmState, Body, Message, UnitQuatQ14};
    let truth = std::fs::read_to_string(demo_recording().with_file_name("truth.jsonl")).unwrap();
    let mut bytes = Vec::new();
    let mut n = 0;
    for (i, line) in truth.lines().enumerate() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let Some(rows) = v["world_from_probe"].as_array() else {
            continue;
        };
        let at = |r: usize, c: usize| rows[r][c].as_f64().unwrap() as f32;
        let rot = Matrix3::from_fn(at);
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot));
        let m = Message {
            seq: i as u16,
            timestamp: Timestamp::from_us(v["time_us"].as_u64().unwrap() + 5_000).unwrap(),
            body: Body::ArmState(ArmState {
                position_mm: [0, 1, 2].map(|r| (at(r, 3) * 1000.0).round() as i32),
                orientation: UnitQuatQ14::from_f32([q.w, q.i, q.j, q.k]).unwrap(),
            }),
        };
        let mut buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
        let len = m.encode_serial(&mut buf).unwrap();
        bytes.extend_from_slice(&buf[..len]);
        n += 1;
    }
    std::fs::write(path, bytes).unwrap();
    n
}

#[test]
fn replay_takes_arm_states_from_a_capture() {
    let dir = scratch("replay-arm");
    let arm = dir.join("arm.cobs");
    let n = arm_capture_of_the_demo(&arm);
    assert!(n > 10, "the demo has the arm in {n} frames");
    let truth = demo_recording().with_file_name("truth.jsonl");
    let out = supine()
        .current_dir(&dir)
        .args(["replay", "--frames", "30", "--json", "r.json", "--truth"])
        .arg(&truth)
        .arg("--arm")
        .arg(&arm)
        .arg(demo_recording())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains(&format!("{n} arm states from")),
        "{}",
        text(&out.stderr)
    );
    assert!(text(&out.stdout).contains("arm states"), "{}", text(&out.stdout));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
    // The tracker mapped the probe from the recorded states, and it is scored against the truth.
    let probe = report["probe_error_mm_mean"]
        .as_f64()
        .expect("no probe error with --arm");
    assert!(probe.is_finite() && probe < 500.0, "{report}");
    // No recorder or live view: the binary's counting allocator sees every allocation, and the per-frame path made
    // none once init was over (the unit test in allocs.rs shows the counter moves on an allocation).
    assert_eq!(report["tracker_allocations_after_init"], 0, "{report}");
    assert!(
        text(&out.stdout).contains("0 in the tracker over 20 frames"),
        "{}",
        text(&out.stdout)
    );

    std::fs::write(dir.join("junk.cobs"), b"\x00garbage\x00").unwrap();
    let out = supine()
        .current_dir(&dir)
        .args(["replay", "--arm", "junk.cobs"])
        .arg(demo_recording())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(
        err.contains("--arm") && err.contains("junk.cobs") && err.contains("no arm state"),
        "{err}"
    );
}

#[test]
fn demo_records_its_frames_to_mcap() {
    let dir = scratch("demo-record");
    let out = supine()
        .current_dir(&dir)
        .args([
            "demo",
            "--frames",
            "12",
            "--record",
            "demo.mcap",
            "--json",
            "r.json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_finished_mcap(&dir.join("demo.mcap"));
    let table = text(&out.stdout);
    assert!(table.contains("12 frames to demo.mcap"), "{table}");
    // The recorder's thread allocates beside the tracker: not counted then.
    assert!(table.contains("not counted"), "{table}");

    // The recording may not be written over the JSON report.
    let again = supine()
        .current_dir(&dir)
        .args(["demo", "--frames", "2", "--record", "r.json", "--json", "r.json"])
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(2), "{}", text(&again.stderr));
    assert!(
        text(&again.stderr).contains("--record and --json are both r.json"),
        "{}",
        text(&again.stderr)
    );
}
