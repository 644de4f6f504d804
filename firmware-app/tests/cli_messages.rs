//! The real binary's messages and `supine info`'s model lookup (issue 11, items 6 and 8).

mod common;

use std::time::Duration;

use common::*;

const LIMIT: Duration = Duration::from_secs(60);

#[test]
fn counts_out_of_range_say_so_with_the_range_in_decimals() {
    let dir = scratch("out-of-range");
    for (args, want) in [
        (
            vec!["wire", "listen", "--link", "file:/dev/null", "--count", "0"],
            "0 is out of range (1 to 18446744073709551615)",
        ),
        (
            vec!["wire", "send", "--sink", "stdout", "--count", "0"],
            "0 is out of range (1 to 4294967295)",
        ),
        (
            vec!["demo", "--frames", "0"],
            "0 is out of range (1 to 4294967295)",
        ),
        (
            vec!["wire", "send", "--sink", "stdout", "--rate", "1e9"],
            "out of range (1/86400 = 0.000011574 to 100000",
        ),
    ] {
        let out = run_within(supine().current_dir(&dir).args(&args), LIMIT);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(stderr(&out).contains(want), "{args:?}: {}", stderr(&out));
    }
}

#[test]
fn an_invalid_supine_log_filter_is_a_warning() {
    let dir = scratch("bad-log");
    let out = run_within(
        supine()
            .current_dir(&dir)
            .env("SUPINE_LOG", "supine=[loud")
            .args(["wire", "sample", "--format", "json"]),
        LIMIT,
    );
    assert!(out.status.success());
    assert!(
        stderr(&out).contains("warning: SUPINE_LOG=\"supine=[loud\" is not a valid filter"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn logs_have_no_colour_when_stderr_is_not_a_terminal() {
    let dir = scratch("no-ansi");
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["-v", "wire", "send", "--sink", "file:cap.bin"]),
        LIMIT,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(err.contains("link open"), "{err}");
    assert!(!err.contains('\u{1b}'), "ANSI escape in {err:?}");
}

#[test]
fn info_fails_on_a_missing_models_directory() {
    let dir = scratch("info-missing");
    let out = run_within(
        supine().current_dir(&dir).args(["info", "--models", "nowhere"]),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("--models nowhere: no such directory"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn info_looks_in_supine_models_and_fails_on_an_invalid_model() {
    let dir = scratch("info-models");
    let models = dir.join("models");
    std::fs::create_dir(&models).unwrap();
    let mut body =
        std::fs::read(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/artifacts/body.sbm"))
            .unwrap();
    std::fs::write(models.join("body.sbm"), &body).unwrap();
    let out = run_within(
        supine()
            .current_dir(&dir)
            .env("SUPINE_MODELS", &models)
            .arg("info"),
        LIMIT,
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        text.contains(&format!("models ({}):", models.display())),
        "{text}"
    );
    assert!(text.contains("body.sbm") && text.contains("valid"), "{text}");

    let last = body.len() - 1;
    body[last] ^= 0xFF;
    std::fs::write(models.join("body.sbm"), &body).unwrap();
    let out = run_within(
        supine()
            .current_dir(&dir)
            .env("SUPINE_MODELS", &models)
            .arg("info"),
        LIMIT,
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stdout).contains("INVALID body model"));
    assert!(
        stderr(&out).contains("invalid model file(s)") && stderr(&out).contains("body.sbm"),
        "{}",
        stderr(&out)
    );
}

/// The committed demo recording with the record type of its tenth frame's header overwritten.
fn recording_with_a_damaged_frame_header() -> Vec<u8> {
    let mut d = std::fs::read(demo_recording()).unwrap();
    let word = |d: &[u8], at: usize| u32::from_le_bytes(d[at..at + 4].try_into().unwrap());
    let (mut pos, mut frames) = (24, 0);
    while pos + 28 <= d.len() {
        assert_eq!(word(&d, pos), 0x0052_494E, "record magic at {pos}");
        let (kind, fields, payload) = (word(&d, pos + 4), word(&d, pos + 12), word(&d, pos + 16));
        if kind == 0x0A {
            frames += 1;
            if frames == 10 {
                d[pos + 4..pos + 8].copy_from_slice(&0x55u32.to_le_bytes());
                return d;
            }
        }
        pos += (fields + payload) as usize;
    }
    panic!("fewer than 10 frames");
}

#[test]
fn a_recording_that_plays_fewer_frames_than_its_header_says_is_warned_about() {
    let dir = scratch("oni-short");
    std::fs::write(dir.join("damaged.oni"), recording_with_a_damaged_frame_header()).unwrap();
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["demo", "--recording", "damaged.oni"]),
        Duration::from_secs(120),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains(
            "damaged.oni: the header says 60 frames but 59 played (1 record(s) of unknown type skipped"
        ),
        "{err}"
    );
    let table = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        table.lines().any(|l| l.split_whitespace().eq(["frames", "59"])),
        "{table}"
    );
}
