//! Helpers for the tests that run the real `supine` binary: a scratch directory per test, the committed demo
//! recording, running with a deadline so that a hang fails the test instead of the suite, and the service on a pty
//! with the test as the arm.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use supine_drivers::link::serial::{SerialPort, open_pty};

/// The binary under test. Under an emulated test run (cross/test: cargo's `CARGO_TARGET_<TRIPLE>_RUNNER`, qemu,
/// is in the environment) it is started through the same runner, since the kernel cannot execute it directly.
pub fn supine() -> Command {
    let exe = env!("CARGO_BIN_EXE_supine");
    let runner_var = format!(
        "CARGO_TARGET_{}_UNKNOWN_LINUX_GNU_RUNNER",
        std::env::consts::ARCH.to_uppercase()
    );
    let runner = std::env::var(runner_var).ok().filter(|r| !r.trim().is_empty());
    let mut c = match runner {
        Some(r) => {
            let mut words = r.split_whitespace();
            let mut c = Command::new(words.next().unwrap_or_default());
            c.args(words).arg(exe);
            c
        }
        None => Command::new(exe),
    };
    // The committed default models, wherever the test runs from (scratch directories have no models/artifacts).
    c.env_remove("SUPINE_LOG").env(
        "SUPINE_MODELS",
        concat!(env!("CARGO_MANIFEST_DIR"), "/../models/artifacts"),
    );
    c
}

/// A fresh, empty scratch directory named after the test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("supine-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The committed synthetic demo recording.
pub fn demo_recording() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/artifacts/demo/sequence.oni")
}

/// A copy of the demo recording in `dir`, as `name`.
pub fn copy_recording(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::copy(demo_recording(), &p).unwrap();
    p
}

/// Wait for `child` for at most `limit`; kill it and panic if it is still running then.
pub fn wait_within(mut child: Child, limit: Duration) -> Output {
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "still running after {limit:?}; stderr: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Run `cmd` (stdin empty, stdout and stderr captured) and fail if it takes longer than `limit`.
pub fn run_within(cmd: &mut Command, limit: Duration) -> Output {
    let child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_within(child, limit)
}

/// stderr as text.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The files in `dir`, sorted by name.
pub fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Make a FIFO at `path` with mkfifo(1) (the tests stay free of unsafe code).
pub fn mkfifo(path: &Path) {
    let st = Command::new("mkfifo").arg(path).status().unwrap();
    assert!(st.success(), "mkfifo {}", path.display());
}

/// Send SIGTERM to a child with kill(1).
pub fn terminate(child: &Child) {
    let st = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
}

/// `supine run` on a serial link to a pty, the test holding the pty's master end as the arm controller would.
pub struct ServiceOnPty {
    /// The arm's end of the link.
    pub arm: SerialPort,
    /// The service.
    pub child: Child,
    /// Where its stderr goes.
    pub log: PathBuf,
}

/// Start `supine run` in a scratch directory `name` with the config `config(dir, pty slave path)` writes (its path
/// returned), stdout discarded, stderr to a file.
pub fn serve_on_pty(name: &str, config: impl FnOnce(&Path, &Path) -> PathBuf) -> ServiceOnPty {
    let dir = scratch(name);
    let pty = open_pty().expect("openpty");
    let arm = SerialPort::from_fd(pty.fd, "pty master (the arm)").unwrap();
    let cfg = config(&dir, &pty.slave_path);
    let log = dir.join("stderr.log");
    let child = supine()
        .args(["run", "--config"])
        .arg(&cfg)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    ServiceOnPty { arm, child, log }
}
