//! `supine wire decode` counts the same input faults the same way in all three formats (issue 11, item 5): a
//! repeat is a duplicate, not an error; a line that is not a frame is a bad line and an error; a frame cut off by
//! the end of the input is an error of a named kind.

mod common;

use std::io::Write;
use std::process::Stdio;
use std::time::Duration;

use common::*;
use serde_json::Value;

fn sample(format: &str) -> Vec<u8> {
    let out = supine()
        .args(["wire", "sample", "--format", format])
        .output()
        .unwrap();
    assert!(out.status.success());
    // SLCAN lines end in `\r` only; the decoder takes `\n` as well, which keeps the splicing below simple.
    out.stdout
        .iter()
        .map(|&b| if b == b'\r' { b'\n' } else { b })
        .collect()
}

fn decode(format: &str, input: &[u8]) -> Value {
    let mut child = supine()
        .args(["wire", "decode", "--format", format])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(input).unwrap();
    let out = wait_within(child, Duration::from_secs(60));
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    let line = err.lines().last().unwrap();
    let printed = String::from_utf8_lossy(&out.stdout).lines().count() as u64;
    let v: Value = serde_json::from_str(line).unwrap();
    assert_eq!(
        v["summary"]["messages"], printed,
        "messages counts what was printed: {v}"
    );
    v["summary"].clone()
}

const FORMATS: [&str; 3] = ["cobs-hex", "candump", "slcan"];

#[test]
fn identical_repeats_are_duplicates_not_errors_in_every_format() {
    for f in FORMATS {
        let once = sample(f);
        let twice = [once.clone(), once].concat();
        let s = decode(f, &twice);
        assert_eq!(
            (s["messages"].as_u64(), s["duplicates"].as_u64()),
            (Some(7), Some(7)),
            "{f}: {s}"
        );
        assert_eq!(s["errors"], 0, "{f}: {s}");
    }
}

#[test]
fn a_line_that_is_not_a_frame_is_a_bad_line_in_every_format() {
    for f in FORMATS {
        let input = [b"hello there\n".to_vec(), sample(f)].concat();
        let s = decode(f, &input);
        assert_eq!(s["messages"], 7, "{f}: {s}");
        assert_eq!(
            (s["bad_lines"].as_u64(), s["errors"].as_u64()),
            (Some(1), Some(1)),
            "{f}: {s}"
        );
    }
}

#[test]
fn a_truncated_last_frame_is_an_error_in_every_format() {
    for f in FORMATS {
        let mut input = sample(f);
        // Drop the last line's second half and its newline: the last frame is cut off by the end of the input.
        input.pop();
        let last_start = input.iter().rposition(|&b| b == b'\n').unwrap() + 1;
        let cut = last_start + (input.len() - last_start) / 2;
        input.truncate(cut);
        let s = decode(f, &input);
        assert_eq!(s["messages"], 6, "{f}: {s}");
        assert!(s["errors"].as_u64().unwrap() >= 1, "{f}: {s}");
        let named = match f {
            "cobs-hex" => s["serial"]["truncated"] == 1 || s["bad_lines"] == 1,
            _ => s["can"]["incomplete"] == 1,
        };
        assert!(named, "{f}: the error has a named kind: {s}");
    }
}
