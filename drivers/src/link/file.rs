//! `file:` and `stdout` as link [`Port`]s: a capture file written with the serial framing (or read back by
//! `supine wire listen --link file:PATH`), and standard output for piping frames into other tools.
//!
//! Per call: one `write(2)`/`read(2)` on a regular file or stdout, no allocation (none at all while a failed
//! write backs off). Regular files never return `EAGAIN`; FIFOs and devices are non-blocking; stdout to a full pipe
//! blocks (the only blocking port; a frame loop should not use `stdout`).

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Write};
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::backoff::Backoff;
use super::error::{LinkError, LinkErrorKind, kind_of_io};
use super::port::{LinkState, Port, PortCounters};

/// Whether a `file:` link writes a new capture or reads an existing one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FileMode {
    /// Create or truncate the file and append frames to it.
    #[default]
    Write,
    /// Read frames from the file until its end; the link then reports `Ended`.
    Read,
}

/// A capture file (or a FIFO or device named by a `file:` spec).
///
/// Writing a regular file goes to a temporary file beside it (`.NAME.PID.partial`), renamed over the target when
/// the link closes without a write error, so a failed run never leaves a half-written capture under the target's
/// name; an empty temporary file is removed, a partial one kept and named in [`Port::write_error`] (or in a
/// warning, when the port is dropped without being closed). FIFOs and
/// devices are opened non-blocking: a FIFO with no reader is waited for (SIGINT/SIGTERM end the wait once
/// [`super::signal::catch_interrupts`] is installed), one with no writer yet reads as "nothing yet", not as the
/// end. A write that fails (ENOSPC, EIO, ...) is counted, its OS error kept, and further writes back off
/// (50 ms doubling to 2 s) instead of retrying at once.
#[derive(Debug)]
pub struct FilePort {
    path: PathBuf,
    /// The temporary file written instead of `path` (regular files only).
    temp: Option<PathBuf>,
    file: Option<File>,
    mode: FileMode,
    counters: PortCounters,
    last_error: Option<LinkErrorKind>,
    write_error: Option<String>,
    backoff: Option<Backoff>,
    /// A FIFO being read: end of file before any byte only means no writer has opened it yet.
    fifo: bool,
    got_data: bool,
    fresh: bool,
}

/// How often an open of a FIFO without a reader is retried.
const FIFO_RETRY: Duration = Duration::from_millis(50);

impl FilePort {
    /// Open `path` for writing (a new capture replacing it at close) or reading. A directory is an error naming it.
    pub fn open(path: &Path, mode: FileMode) -> Result<Self, LinkError> {
        let meta = std::fs::metadata(path).ok();
        if meta.as_ref().is_some_and(|m| m.is_dir()) {
            return Err(LinkError::io(
                format!("capture file {}", path.display()),
                io::Error::from_raw_os_error(libc::EISDIR),
            ));
        }
        let special = meta.as_ref().is_some_and(|m| !m.is_file());
        let fifo = meta.as_ref().is_some_and(|m| m.file_type().is_fifo());
        let (file, temp) = match mode {
            FileMode::Read => {
                let mut o = OpenOptions::new();
                o.read(true);
                if special {
                    o.custom_flags(libc::O_NONBLOCK);
                }
                let file = o
                    .open(path)
                    .map_err(|e| LinkError::io(format!("opening capture file {}", path.display()), e))?;
                (file, None)
            }
            FileMode::Write if special => (open_special_for_writing(path)?, None),
            FileMode::Write => {
                let temp = temp_path(&real_path(path));
                let file = OpenOptions::new()
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .open(&temp)
                    .map_err(|e| LinkError::io(format!("creating capture file {}", path.display()), e))?;
                (file, Some(temp))
            }
        };
        Ok(FilePort {
            // Renamed over at close: through a symlink, the file it points to (the link stays).
            path: if temp.is_some() {
                real_path(path)
            } else {
                path.to_owned()
            },
            temp,
            file: Some(file),
            mode,
            counters: PortCounters::default(),
            last_error: None,
            write_error: None,
            backoff: None,
            fifo: fifo && mode == FileMode::Read,
            got_data: false,
            fresh: true,
        })
    }

    /// The file path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn fail(&mut self, err: &io::Error) {
        self.counters.io_errors += 1;
        self.last_error = Some(kind_of_io(err));
    }

    /// Close the file; a capture written without error replaces the target, else its temporary file is removed
    /// (empty) or kept (partial, named in the write error).
    fn finish(&mut self) {
        let Some(file) = self.file.take() else { return };
        if let Some(temp) = self.temp.take() {
            let synced = file.sync_data();
            drop(file);
            let ok = self.write_error.is_none() && synced.is_ok();
            if ok && std::fs::rename(&temp, &self.path).is_ok() {
                return;
            }
            if std::fs::metadata(&temp).is_ok_and(|m| m.len() > 0) {
                let note = format!("; the partial capture is kept in {}", temp.display());
                let msg = self
                    .write_error
                    .get_or_insert_with(|| "the capture was not completed".into());
                msg.push_str(&note);
            } else {
                let _ = std::fs::remove_file(&temp);
            }
        }
    }
}

/// A FIFO or device for writing, non-blocking. A FIFO without a reader (ENXIO) is retried until one opens it or
/// SIGINT/SIGTERM arrives.
fn open_special_for_writing(path: &Path) -> Result<File, LinkError> {
    loop {
        match OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)
        {
            Ok(f) => return Ok(f),
            Err(e) if e.raw_os_error() == Some(libc::ENXIO) && !super::signal::interrupted() => {
                std::thread::sleep(FIFO_RETRY);
            }
            Err(e) => {
                return Err(LinkError::io(
                    format!("opening {} for writing", path.display()),
                    e,
                ));
            }
        }
    }
}

/// `path`, or the file it points to when it is a symlink.
fn real_path(path: &Path) -> PathBuf {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => {
            std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned())
        }
        _ => path.to_owned(),
    }
}

/// `dir/.name.PID.partial` beside `target` (`*.partial` is git-ignored).
fn temp_path(target: &Path) -> PathBuf {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "capture".to_owned());
    let file = format!(".{name}.{}.partial", std::process::id());
    match target.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.join(file),
        _ => PathBuf::from(file),
    }
}

impl Drop for FilePort {
    /// Dropped without [`Port::shutdown`] (the link was not closed: the run failed): the target keeps its old
    /// content; an empty temporary file is removed, a partial one kept and logged.
    fn drop(&mut self) {
        self.file = None;
        if let Some(temp) = self.temp.take() {
            if std::fs::metadata(&temp).is_ok_and(|m| m.len() > 0) {
                tracing::warn!(
                    "{}: the link was not closed; the partial capture is kept in {}",
                    self.path.display(),
                    temp.display()
                );
            } else {
                let _ = std::fs::remove_file(&temp);
            }
        }
    }
}

impl Port for FilePort {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        if self.mode != FileMode::Read {
            return 0;
        }
        let Some(file) = &mut self.file else { return 0 };
        match file.read(buf) {
            Ok(0) if self.fifo && !self.got_data => 0,
            Ok(0) => {
                self.file = None;
                0
            }
            Ok(n) => {
                self.got_data = true;
                n
            }
            Err(e) if matches!(e.kind(), io::ErrorKind::Interrupted | io::ErrorKind::WouldBlock) => 0,
            Err(e) => {
                self.fail(&e);
                self.write_error.get_or_insert_with(|| e.to_string());
                self.file = None;
                0
            }
        }
    }

    fn write(&mut self, buf: &[u8]) -> usize {
        if self.mode != FileMode::Write {
            return 0;
        }
        let now = Instant::now();
        if self.backoff.as_ref().is_some_and(|b| !b.due(now)) {
            return 0;
        }
        let Some(file) = &mut self.file else { return 0 };
        match file.write(buf) {
            Ok(n) => {
                self.backoff = None;
                n
            }
            Err(e) if matches!(e.kind(), io::ErrorKind::Interrupted | io::ErrorKind::WouldBlock) => 0,
            Err(e) => {
                self.fail(&e);
                self.write_error.get_or_insert_with(|| e.to_string());
                match &mut self.backoff {
                    Some(b) => b.failed(now),
                    None => self.backoff = Some(Backoff::start(now)),
                }
                0
            }
        }
    }

    fn maintain(&mut self, _now: Instant) -> bool {
        self.file.is_some() && std::mem::take(&mut self.fresh)
    }

    fn state(&self) -> LinkState {
        if self.file.is_some() {
            LinkState::Up
        } else {
            LinkState::Ended
        }
    }

    fn disconnect(&mut self) {
        // A file cannot go away and come back; a forced disconnect is only counted.
        self.counters.disconnects += 1;
        self.counters.reconnects += 1;
    }

    fn wait_writable(&mut self, timeout: Duration) {
        // Backing off after a failed write: sleep instead of spinning until the next attempt is due.
        if self.backoff.is_some() {
            std::thread::sleep(timeout.min(Duration::from_millis(10)));
        }
    }

    fn drain(&mut self, _timeout: Duration) {
        if let Some(file) = &mut self.file {
            let _ = file.flush();
        }
    }

    fn wait_readable(&mut self, timeout: Duration) {
        // A FIFO has no data yet or no writer yet: wait a little rather than spin (a regular file always has data
        // or its end).
        if self.fifo {
            std::thread::sleep(timeout.min(Duration::from_millis(10)));
        }
    }

    fn counters(&self) -> PortCounters {
        self.counters
    }

    fn last_error(&self) -> Option<LinkErrorKind> {
        self.last_error
    }

    fn write_error(&self) -> Option<&str> {
        self.write_error.as_deref()
    }

    fn shutdown(&mut self) {
        self.finish();
    }
}

/// Standard output (send only).
#[derive(Debug, Default)]
pub struct StdoutPort {
    counters: PortCounters,
    write_error: Option<String>,
    last_error: Option<LinkErrorKind>,
    closed: bool,
    fresh: bool,
}

impl StdoutPort {
    /// Standard output as a port.
    pub fn new() -> Self {
        StdoutPort {
            fresh: true,
            ..Default::default()
        }
    }
}

impl Port for StdoutPort {
    fn read(&mut self, _buf: &mut [u8]) -> usize {
        0
    }

    fn write(&mut self, buf: &[u8]) -> usize {
        if self.closed {
            return 0;
        }
        // Flush every write: stdout is line-buffered, and binary frames must not wait for a 0x0A byte.
        let mut out = io::stdout().lock();
        match out.write(buf).and_then(|n| out.flush().map(|()| n)) {
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => 0,
            Err(e) => {
                self.counters.io_errors += 1;
                self.last_error = Some(kind_of_io(&e));
                self.write_error.get_or_insert_with(|| e.to_string());
                // Nothing more can go out on a closed pipe or a full disk: stop instead of retrying each frame.
                self.closed = true;
                0
            }
        }
    }

    fn maintain(&mut self, _now: Instant) -> bool {
        !self.closed && std::mem::take(&mut self.fresh)
    }

    fn state(&self) -> LinkState {
        if self.closed {
            LinkState::Ended
        } else {
            LinkState::Up
        }
    }

    fn disconnect(&mut self) {
        self.counters.disconnects += 1;
        self.counters.reconnects += 1;
    }

    fn wait_writable(&mut self, _timeout: Duration) {}

    fn drain(&mut self, _timeout: Duration) {
        let _ = io::stdout().lock().flush();
    }

    fn wait_readable(&mut self, timeout: Duration) {
        std::thread::sleep(timeout.min(Duration::from_millis(10)));
    }

    fn counters(&self) -> PortCounters {
        self.counters
    }

    fn last_error(&self) -> Option<LinkErrorKind> {
        self.last_error
    }

    fn write_error(&self) -> Option<&str> {
        self.write_error.as_deref()
    }

    fn shutdown(&mut self) {
        let _ = io::stdout().lock().flush();
        self.closed = true;
    }
}
