//! stdout and stderr without panics: `print!`/`eprintln!` panic when the stream fails (a closed pipe, a full disk).
//!
//! [`out`] writes a command's result to stdout and turns a failure into a [`Failure`]: a closed pipe
//! (`supine info | head`) becomes [`Failure::BrokenPipe`], which ends the process quietly with the status a
//! program killed by SIGPIPE has (141), any other error (`> /dev/full`) a one-line runtime error (exit 1).
//! [`note!`](crate::note) writes progress and summaries to stderr; a failure there cannot be reported on stderr,
//! so it is remembered and `main` exits 1 instead of 0. Cost: one write and flush per call.

use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::failure::Failure;

static STDERR_FAILED: AtomicBool = AtomicBool::new(false);

/// Write `text` to stdout and flush it.
pub fn out(text: &str) -> Result<(), Failure> {
    let mut stdout = io::stdout().lock();
    stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
        .map_err(stdout_failure)
}

/// The failure for an error writing to stdout.
pub fn stdout_failure(e: io::Error) -> Failure {
    if e.kind() == io::ErrorKind::BrokenPipe {
        Failure::BrokenPipe
    } else {
        Failure::Runtime(anyhow::anyhow!("writing to stdout: {e}"))
    }
}

/// Write formatted text to stderr; a failure is remembered for [`stderr_failed`].
pub fn note_fmt(args: std::fmt::Arguments<'_>) {
    let mut stderr = io::stderr().lock();
    if stderr.write_fmt(args).and_then(|()| stderr.flush()).is_err() {
        STDERR_FAILED.store(true, Ordering::Relaxed);
    }
}

/// Whether some write to stderr failed.
pub fn stderr_failed() -> bool {
    STDERR_FAILED.load(Ordering::Relaxed)
}

/// `eprintln!` that never panics: a line on stderr (see [`note_fmt`]).
#[macro_export]
macro_rules! note {
    () => { $crate::console::note_fmt(format_args!("\n")) };
    ($($arg:tt)*) => { $crate::console::note_fmt(format_args!("{}\n", format_args!($($arg)*))) };
}

/// `eprint!` that never panics: text on stderr without a newline (progress lines).
#[macro_export]
macro_rules! note_raw {
    ($($arg:tt)*) => { $crate::console::note_fmt(format_args!($($arg)*)) };
}
