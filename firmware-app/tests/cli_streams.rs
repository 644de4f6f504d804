//! The real binary on closed pipes, full disks, FIFOs without a peer, failing sinks and live input (issue 11, items
//! 2, 3, 4 and 6): no panic, no hang, no spinning, one clear error.

mod common;

use std::io::{BufRead, BufReader, Write};
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::*;

const LIMIT: Duration = Duration::from_secs(120);

/// Run with stdout a pipe whose reader is already closed.
fn with_closed_stdout(args: &[&str], dir: &std::path::Path) -> std::process::Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let child = supine()
        .current_dir(dir)
        .args(args)
        .stdin(Stdio::null())
        .stdout(writer)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_within(child, LIMIT)
}

/// Run with stdout on /dev/full.
fn with_full_stdout(args: &[&str], dir: &std::path::Path) -> std::process::Output {
    let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
    let child = supine()
        .current_dir(dir)
        .args(args)
        .stdin(Stdio::null())
        .stdout(full)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_within(child, LIMIT)
}

fn commands(dir: &std::path::Path) -> Vec<Vec<String>> {
    let rec = copy_recording(dir, "rec.oni");
    let rec = rec.to_str().unwrap().to_owned();
    vec![
        vec!["info".into()],
        vec!["--help".into()],
        vec![
            "demo".into(),
            "--frames".into(),
            "2".into(),
            "--recording".into(),
            rec,
        ],
        vec!["wire".into(), "sample".into(), "--format".into(), "json".into()],
    ]
}

#[test]
fn a_closed_stdout_ends_quietly_with_the_sigpipe_status() {
    let dir = scratch("closed-stdout");
    for args in commands(&dir) {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = with_closed_stdout(&args, &dir);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(141), "{args:?}: {err}");
        assert!(
            !err.contains("panicked") && !err.contains("error"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn a_full_stdout_is_one_error_line_and_exit_1() {
    let dir = scratch("full-stdout");
    for args in commands(&dir) {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = with_full_stdout(&args, &dir);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        let last = err.lines().last().unwrap_or_default();
        assert_eq!(
            last, "supine: error: writing to stdout: No space left on device (os error 28)",
            "{args:?}: {err}"
        );
        assert_eq!(err.matches("supine: error").count(), 1, "{args:?}: {err}");
    }
}

#[test]
fn decode_with_a_full_stderr_exits_1_without_a_panic() {
    let dir = scratch("full-stderr");
    let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
    let mut child = supine()
        .current_dir(&dir)
        .args(["wire", "decode", "--format", "cobs-hex"])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(full)
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(b"00\n").unwrap();
    let out = wait_within(child, LIMIT);
    assert_eq!(out.status.code(), Some(1));
}

#[test]
fn send_to_a_failing_sink_names_the_error_once_backs_off_and_fails() {
    let dir = scratch("send-dev-full");
    let start = Instant::now();
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["wire", "send", "--sink", "file:/dev/full", "--count", "3"]),
        LIMIT,
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(err.matches("No space left on device").count(), 1, "{err}");
    // Backing off: a handful of write attempts in the few seconds the close waits, not millions.
    let summary: &str = err
        .lines()
        .find(|l| l.starts_with("{\"closed_cleanly\""))
        .unwrap();
    let v: serde_json::Value = serde_json::from_str(summary).unwrap();
    let attempts = v["counters"]["io_errors"].as_u64().unwrap();
    assert!(
        (1..=100).contains(&attempts),
        "{attempts} write attempts in {:?}",
        start.elapsed()
    );
}

#[test]
fn send_to_a_directory_and_listen_on_one_are_errors_naming_it() {
    let dir = scratch("dir-link");
    std::fs::create_dir(dir.join("d")).unwrap();
    for args in [
        ["wire", "send", "--sink", "file:d"],
        ["wire", "listen", "--link", "file:d"],
    ] {
        let out = run_within(supine().current_dir(&dir).args(args), LIMIT);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains("capture file d: Is a directory"), "{args:?}: {err}");
    }
}

#[test]
fn demo_to_a_failing_sink_exits_non_zero() {
    let dir = scratch("demo-dev-full");
    let rec = copy_recording(&dir, "rec.oni");
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["demo", "--frames", "3", "--sink", "file:/dev/full", "--recording"])
            .arg(&rec),
        LIMIT,
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("--sink file:/dev/full: No space left on device"),
        "{err}"
    );
}

#[test]
fn listen_on_a_fifo_without_writer_honours_the_idle_timeout_and_sigterm() {
    let dir = scratch("listen-fifo");
    let fifo = dir.join("f");
    mkfifo(&fifo);
    let out = run_within(
        supine()
            .current_dir(&dir)
            .args(["wire", "listen", "--link", "file:f", "--idle-timeout", "0.5"]),
        Duration::from_secs(20),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("\"stopped\":\"idle timeout\""),
        "{}",
        stderr(&out)
    );

    let child = supine()
        .current_dir(&dir)
        .args(["wire", "listen", "--link", "file:f"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    terminate(&child);
    let out = wait_within(child, Duration::from_secs(20));
    assert!(
        stderr(&out).contains("\"stopped\":\"interrupted\""),
        "{}",
        stderr(&out)
    );
}

#[test]
fn send_to_a_fifo_without_reader_honours_sigterm() {
    let dir = scratch("send-fifo");
    mkfifo(&dir.join("f"));
    let child = supine()
        .current_dir(&dir)
        .args(["wire", "send", "--sink", "file:f"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    terminate(&child);
    let out = wait_within(child, Duration::from_secs(20));
    assert!(!out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("panicked"), "{}", stderr(&out));
}

#[test]
fn demo_on_a_fifo_recording_is_an_error_not_a_hang() {
    let dir = scratch("demo-fifo");
    mkfifo(&dir.join("f.oni"));
    let out = run_within(
        supine().current_dir(&dir).args(["demo", "--recording", "f.oni"]),
        Duration::from_secs(20),
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("--recording f.oni: not a regular file"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn decode_prints_each_message_as_its_bytes_arrive() {
    let dir = scratch("decode-stream");
    let sample = supine()
        .args(["wire", "sample", "--format", "cobs-hex"])
        .output()
        .unwrap();
    let first_line = String::from_utf8(sample.stdout)
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .to_owned();
    let mut child = supine()
        .current_dir(&dir)
        .args(["wire", "decode", "--format", "cobs-hex"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    writeln!(stdin, "{first_line}").unwrap();
    stdin.flush().unwrap();
    // stdin stays open: the message must come out now, not at the end of the input.
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(line);
    });
    let line = rx.recv_timeout(Duration::from_secs(30));
    drop(stdin);
    let _ = wait_within(child, LIMIT);
    let line = line.expect("no message printed while stdin stayed open");
    assert!(line.contains("\"kind\":\"torso_pose\""), "{line}");
}

#[test]
fn decode_survives_an_endless_line_with_bounded_memory() {
    let dir = scratch("decode-long-line");
    let mut child = supine()
        .current_dir(&dir)
        .args(["wire", "decode", "--format", "candump"])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let chunk = vec![b'A'; 1 << 20];
    for _ in 0..64 {
        stdin.write_all(&chunk).unwrap();
    }
    stdin.write_all(b"\n").unwrap();
    drop(stdin);
    let out = wait_within(child, LIMIT);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("\"bad_lines\":1"), "{}", stderr(&out));
}
