//! The real binary never writes over one of its inputs, leaves an old output intact when a run fails, and fails at
//! start on an output it cannot write (issue 11, items 1 and 7).

mod common;

use std::time::Duration;

use common::*;

const LIMIT: Duration = Duration::from_secs(120);

#[test]
fn demo_json_over_the_recording_is_refused_through_symlinks_and_dotdot() {
    let dir = scratch("json-over-recording");
    let rec = copy_recording(&dir, "patient.oni");
    let before = std::fs::read(&rec).unwrap();
    std::os::unix::fs::symlink(&rec, dir.join("alias.json")).unwrap();
    std::fs::create_dir(dir.join("sub")).unwrap();
    for json in ["patient.oni", "alias.json", "sub/../patient.oni"] {
        let out = run_within(
            supine().current_dir(&dir).args([
                "demo",
                "--frames",
                "2",
                "--recording",
                "patient.oni",
                "--json",
                json,
            ]),
            LIMIT,
        );
        assert_eq!(out.status.code(), Some(2), "--json {json}: {}", stderr(&out));
        assert!(
            stderr(&out).contains("same file as --recording"),
            "{}",
            stderr(&out)
        );
        assert_eq!(
            std::fs::read(&rec).unwrap(),
            before,
            "--json {json} changed the recording"
        );
    }
    // Nor through the packet sink.
    let out = run_within(
        supine().current_dir(&dir).args([
            "demo",
            "--frames",
            "2",
            "--recording",
            "patient.oni",
            "--sink",
            "file:./patient.oni",
        ]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_eq!(std::fs::read(&rec).unwrap(), before);
    assert_eq!(files_in(&dir), ["alias.json", "patient.oni", "sub"]);
}

#[test]
fn record_out_over_its_source_is_refused() {
    let dir = scratch("record-over-source");
    let rec = copy_recording(&dir, "in.oni");
    let before = std::fs::read(&rec).unwrap();
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["record", "--source", "file:in.oni", "--out", "./in.oni"]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("same file as --source"), "{}", stderr(&out));
    assert_eq!(std::fs::read(&rec).unwrap(), before);
}

#[test]
fn a_failed_demo_leaves_the_old_json_intact_and_no_temporary_file() {
    let dir = scratch("failed-demo-json");
    copy_recording(&dir, "rec.oni");
    std::fs::write(dir.join("report.json"), "old report").unwrap();
    // Every write to the sink fails: the run fails, after the frames.
    let out = run_within(
        supine().current_dir(&dir).args([
            "demo",
            "--frames",
            "3",
            "--recording",
            "rec.oni",
            "--json",
            "report.json",
            "--sink",
            "file:/dev/full",
        ]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_eq!(
        std::fs::read_to_string(dir.join("report.json")).unwrap(),
        "old report"
    );
    assert_eq!(files_in(&dir), ["rec.oni", "report.json"]);
}

#[test]
fn a_successful_demo_replaces_the_json() {
    let dir = scratch("ok-demo-json");
    copy_recording(&dir, "rec.oni");
    std::fs::write(dir.join("report.json"), "old report").unwrap();
    let out = run_within(
        supine().current_dir(&dir).args([
            "demo",
            "--frames",
            "3",
            "--recording",
            "rec.oni",
            "--json",
            "report.json",
        ]),
        LIMIT,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let json = std::fs::read_to_string(dir.join("report.json")).unwrap();
    assert!(json.contains("\"frames\": 3"), "{json}");
    assert_eq!(files_in(&dir), ["rec.oni", "report.json"]);
}

#[test]
fn an_unwritable_json_fails_before_any_frame() {
    let dir = scratch("unwritable-json");
    copy_recording(&dir, "rec.oni");
    let out = run_within(
        supine().current_dir(&dir).args([
            "demo",
            "--recording",
            "rec.oni",
            "--json",
            "missing-dir/report.json",
        ]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("--json missing-dir/report.json"), "{err}");
    // Nothing was played: no summary on stdout, no frame count on stderr.
    assert!(out.stdout.is_empty(), "{}", String::from_utf8_lossy(&out.stdout));
    assert!(!err.contains("frames"), "{err}");
    assert_eq!(err.lines().count(), 1, "one error line: {err}");
}

#[test]
fn record_to_an_unwritable_out_fails_before_opening_the_source() {
    let dir = scratch("unwritable-out");
    copy_recording(&dir, "rec.oni");
    std::fs::create_dir(dir.join("a-dir")).unwrap();
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["record", "--source", "file:rec.oni", "--out", "a-dir"]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(err.contains("--out a-dir: is a directory"), "{err}");
    assert!(!err.contains("recording"), "nothing recorded: {err}");
}

#[test]
fn a_failed_recording_keeps_the_old_file_and_names_the_partial_one() {
    let dir = scratch("failed-record");
    let full = std::fs::read(demo_recording()).unwrap();
    // Cut inside the third frame: two frames play, then the source fails.
    std::fs::write(dir.join("cut.oni"), &full[..400_000]).unwrap();
    std::fs::write(dir.join("out.oni"), "previous recording").unwrap();
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["record", "--source", "file:cut.oni", "--out", "out.oni"]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert_eq!(
        std::fs::read_to_string(dir.join("out.oni")).unwrap(),
        "previous recording"
    );
    let partial: Vec<String> = files_in(&dir)
        .into_iter()
        .filter(|f| f.ends_with(".partial"))
        .collect();
    assert_eq!(partial.len(), 1, "{:?}", files_in(&dir));
    assert!(
        err.contains(&partial[0]),
        "the error names the partial file: {err}"
    );
    // The path of the source appears once, not twice.
    assert_eq!(err.matches("cut.oni").count(), 1, "{err}");
}

#[test]
fn a_successful_recording_replaces_the_old_file() {
    let dir = scratch("ok-record");
    copy_recording(&dir, "rec.oni");
    std::fs::write(dir.join("out.oni"), "previous recording").unwrap();
    let out = run_within(
        supine().current_dir(&dir).args([
            "record",
            "--source",
            "file:rec.oni",
            "--out",
            "out.oni",
            "--frames",
            "2",
        ]),
        LIMIT,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let bytes = std::fs::read(dir.join("out.oni")).unwrap();
    assert_eq!(&bytes[..4], b"NI10");
    assert_eq!(files_in(&dir), ["out.oni", "rec.oni"]);
}

#[test]
fn a_capture_sink_is_complete_or_absent() {
    let dir = scratch("capture-sink");
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["wire", "send", "--sink", "file:cap.bin", "--count", "2"]),
        LIMIT,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(files_in(&dir), ["cap.bin"]);
    assert!(std::fs::metadata(dir.join("cap.bin")).unwrap().len() > 0);
}

#[test]
fn a_demo_that_fails_mid_run_leaves_an_old_capture_sink_intact() {
    let dir = scratch("failed-demo-sink");
    let full = std::fs::read(demo_recording()).unwrap();
    // Cut inside the third frame: the run fails after two frames were sent to the capture.
    std::fs::write(dir.join("cut.oni"), &full[..400_000]).unwrap();
    std::fs::write(dir.join("cap.bin"), "old capture").unwrap();
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["demo", "--recording", "cut.oni", "--sink", "file:cap.bin"]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert_eq!(
        std::fs::read_to_string(dir.join("cap.bin")).unwrap(),
        "old capture"
    );
    let partial: Vec<String> = files_in(&dir)
        .into_iter()
        .filter(|f| f.ends_with(".partial"))
        .collect();
    assert!(partial.len() <= 1, "{:?}", files_in(&dir));
    for p in &partial {
        assert!(
            stderr(&out).contains(p.as_str()),
            "the partial capture is named: {}",
            stderr(&out)
        );
    }
}

#[test]
fn a_recording_to_a_full_disk_is_one_error() {
    let dir = scratch("record-dev-full");
    copy_recording(&dir, "rec.oni");
    let out = run_within(
        supine().current_dir(&dir).args([
            "record",
            "--source",
            "file:rec.oni",
            "--out",
            "/dev/full",
            "--frames",
            "3",
        ]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert!(
        !err.contains("on drop"),
        "no second report of the same failure: {err}"
    );
    assert_eq!(err.matches("No space left on device").count(), 1, "{err}");
}

#[test]
fn an_output_through_a_symlink_replaces_the_file_and_keeps_the_link() {
    let dir = scratch("json-symlink");
    copy_recording(&dir, "rec.oni");
    std::fs::create_dir(dir.join("reports")).unwrap();
    std::fs::write(dir.join("reports/latest.json"), "old").unwrap();
    std::os::unix::fs::symlink("reports/latest.json", dir.join("report.json")).unwrap();
    let out = run_within(
        supine().current_dir(&dir).args([
            "demo",
            "--frames",
            "2",
            "--recording",
            "rec.oni",
            "--json",
            "report.json",
        ]),
        LIMIT,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        std::fs::symlink_metadata(dir.join("report.json"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert!(
        std::fs::read_to_string(dir.join("reports/latest.json"))
            .unwrap()
            .contains("\"frames\": 2")
    );
    assert_eq!(files_in(&dir.join("reports")), ["latest.json"]);
}

#[test]
fn demo_draws_the_overlay_png_of_a_frame() {
    let dir = scratch("demo-png");
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["demo", "--frames", "12", "--png", "f.png", "--png-frame", "11"]),
        LIMIT,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let png = std::fs::read(dir.join("f.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    // IHDR: 640 x 480, 8-bit RGB.
    assert_eq!(&png[16..26], &[0, 0, 2, 128, 0, 0, 1, 224, 8, 2]);

    // A frame past the end is an error, and no file is left behind.
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["demo", "--frames", "3", "--png", "g.png", "--png-frame", "5"]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("--png-frame 5"), "{}", stderr(&out));
    assert_eq!(files_in(&dir), ["f.png"]);
}
