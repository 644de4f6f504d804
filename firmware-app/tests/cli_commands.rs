//! The service follows the arm controller's shape commands: `supine run` on the committed demo recording, looped,
//! with this test as the arm on a pty. `set_shape_mode continuous` makes it send further body-shape revisions while
//! tracking; `set_shape_mode frozen` stops them; a `reinitialise` then runs a new init phase that keeps the frozen
//! shape. About 15 s in a debug build.

mod common;

use std::time::{Duration, Instant};

use common::{ServiceOnPty, serve_on_pty, terminate};
use supine_core::time::Timestamp;
use supine_core::wire::stream::SerialDecoder;
use supine_core::wire::{Body, Command, Message, ShapeMode, TrackerState};
use supine_drivers::link::Port;
use supine_drivers::link::serial::SerialPort;

const LIMIT: Duration = Duration::from_secs(300);
/// Frames tracked in the default mode before the first command: the lock refits' rounds are over by then.
const SETTLE_FRAMES: u64 = 150;
/// Frames a continuous round may take to arrive (the tracker's default spacing is 90 good tracked frames).
const CONTINUOUS_WITHIN: u64 = 600;
/// Frames a command may take to reach the tracker (written between two frames, read before the next).
const COMMAND_DELAY: u64 = 10;

fn config(dir: &std::path::Path, link: &std::path::Path) -> std::path::PathBuf {
    let models = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/artifacts");
    // A 1 s frame budget: the test checks what the commands do, not the budget (which depends on the load).
    let text = format!(
        "source = \"file:{models}/demo/sequence.oni\"\nloop_source = true\nlink = \"serial:{}@1000000\"\n\
         [models]\ndir = \"{models}\"\nbody = \"body.sbm\"\njoints = \"joints.jfor\"\nshape = \"shape.ssm\"\n\
         [budget]\nframe_ms = 1000.0\n[init]\nshape_frames = 10\ntimeout_s = 120.0\n[log]\nfilter = \"warn\"\n",
        link.display()
    );
    let path = dir.join("supine.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// What the arm does next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// Waits for the tracker to settle in the default mode.
    Settling,
    /// Has asked for continuous refinement (at the frame) and waits for a further revision.
    Continuous(u64),
    /// Has frozen the shape (at the frame) and watches that nothing changes.
    Frozen(u64),
    /// Has asked for a re-initialise (at the frame) and waits for the new init phase to end.
    Reinitialised(u64),
    /// Has ended the service.
    Done,
}

#[test]
fn the_service_follows_the_arms_shape_commands() {
    let started = Instant::now();
    let ServiceOnPty {
        mut arm,
        mut child,
        log: log_path,
    } = serve_on_pty("commands", config);
    let mut send_seq = 0u16;
    let mut send = |arm: &mut SerialPort, cmd: Command| {
        let m = Message {
            seq: send_seq,
            timestamp: Timestamp::from_us(started.elapsed().as_micros() as u64).unwrap(),
            body: Body::Command(cmd),
        };
        send_seq = send_seq.wrapping_add(1);
        let mut out = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
        let len = m.encode_serial(&mut out).unwrap();
        assert_eq!(arm.write(&out[..len]), len);
    };

    let mut decoder: SerialDecoder = SerialDecoder::new();
    let mut buf = [0u8; 4096];
    // Per frame (one health packet each) its state; every body-shape packet with the frame it came with.
    let mut states: Vec<TrackerState> = Vec::new();
    let mut shapes: Vec<(u64, u8, [i16; 20])> = Vec::new();
    let mut step = Step::Settling;
    let mut once_revisions = 0;
    let mut frozen: Option<(u8, [i16; 20])> = None;
    let status = loop {
        assert!(
            started.elapsed() < LIMIT,
            "the test ran past {LIMIT:?} at {step:?}"
        );
        let n = arm.read(&mut buf);
        decoder.feed_all(&buf[..n], |m| match m.body {
            Body::Health(h) => states.push(h.state),
            Body::BodyShape(b) => shapes.push((states.len() as u64, b.revision, b.coefficients_milli)),
            _ => {}
        });
        let frames = states.len() as u64;
        let last_shape = shapes.last().map(|&(_, r, c)| (r, c));
        match step {
            Step::Settling => {
                let tracked = states.iter().position(|&s| s.has_pose());
                if tracked.is_some_and(|t| frames >= t as u64 + SETTLE_FRAMES) {
                    once_revisions = last_shape.expect("no body shape sent").0;
                    send(&mut arm, Command::SetShapeMode(ShapeMode::Continuous));
                    step = Step::Continuous(frames);
                }
            }
            Step::Continuous(at) => {
                if last_shape.is_some_and(|(r, _)| r > once_revisions) {
                    send(&mut arm, Command::SetShapeMode(ShapeMode::Frozen));
                    step = Step::Frozen(frames);
                } else {
                    assert!(
                        frames < at + CONTINUOUS_WITHIN,
                        "no further revision {CONTINUOUS_WITHIN} frames after continuous: {shapes:?}"
                    );
                }
            }
            Step::Frozen(at) if frames >= at + 6 * COMMAND_DELAY => {
                frozen = last_shape;
                send(&mut arm, Command::Reinitialise);
                step = Step::Reinitialised(frames);
            }
            Step::Reinitialised(at) => {
                let after = &states[at as usize..];
                let init = after.iter().position(|&s| s == TrackerState::Initialising);
                if init.is_some_and(|i| after[i..].iter().filter(|&&s| s.has_pose()).count() >= 60) {
                    terminate(&child);
                    step = Step::Done;
                }
            }
            _ => {}
        }
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if n == 0 {
            arm.wait_readable(Duration::from_millis(5));
        }
    };
    let log = std::fs::read_to_string(&log_path).unwrap();
    assert!(status.success(), "exit {status:?}; stderr: {log}");
    assert!(!log.contains("panicked"), "{log}");
    let Step::Done = step else {
        panic!("the service ended at {step:?}: {log}");
    };
    // Revisions: the init phase's shape, the lock refits' rounds, at least one continuous round; none once frozen.
    assert!(once_revisions >= 2, "{shapes:?}");
    let (frozen_revision, frozen_shape) = frozen.unwrap();
    assert!(frozen_revision > once_revisions, "{shapes:?}");
    let reinit_at = shapes
        .iter()
        .position(|&(_, r, _)| r > frozen_revision)
        .expect("no shape sent after the re-initialise");
    let frozen_from = shapes.iter().position(|&(_, r, _)| r == frozen_revision).unwrap();
    for &(f, r, c) in &shapes[frozen_from..reinit_at] {
        assert_eq!((r, c), (frozen_revision, frozen_shape), "frame {f}: {shapes:?}");
    }
    // The new init phase adopts the frozen shape (a new revision, the same coefficients) and keeps it.
    for &(f, _, c) in &shapes[reinit_at..] {
        assert_eq!(c, frozen_shape, "frame {f}: {shapes:?}");
    }
}
