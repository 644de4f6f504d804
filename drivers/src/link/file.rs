//! `file:` and `stdout` as link [`Port`]s: a capture file written with the serial framing (or read back by
//! `supine wire listen --link file:PATH`), and standard output for piping frames into other tools.
//!
//! Per call: one `write(2)`/`read(2)` on a regular file or stdout, no allocation. Regular files never return
//! `EAGAIN`; stdout to a full pipe blocks (the only blocking port; a frame loop should not use `stdout`).

use std::fs::File;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

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

/// A capture file.
#[derive(Debug)]
pub struct FilePort {
    path: PathBuf,
    file: Option<File>,
    mode: FileMode,
    counters: PortCounters,
    last_error: Option<LinkErrorKind>,
    fresh: bool,
}

impl FilePort {
    /// Open `path` for writing (created/truncated) or reading.
    pub fn open(path: &Path, mode: FileMode) -> Result<Self, LinkError> {
        let file = match mode {
            FileMode::Write => File::create(path),
            FileMode::Read => File::open(path),
        }
        .map_err(|e| {
            let verb = if mode == FileMode::Write {
                "creating"
            } else {
                "opening"
            };
            LinkError::io(format!("{verb} capture file {}", path.display()), e)
        })?;
        Ok(FilePort {
            path: path.to_owned(),
            file: Some(file),
            mode,
            counters: PortCounters::default(),
            last_error: None,
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
}

impl Port for FilePort {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        if self.mode != FileMode::Read {
            return 0;
        }
        let Some(file) = &mut self.file else { return 0 };
        match file.read(buf) {
            Ok(0) => {
                self.file = None;
                0
            }
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => 0,
            Err(e) => {
                self.fail(&e);
                self.file = None;
                0
            }
        }
    }

    fn write(&mut self, buf: &[u8]) -> usize {
        if self.mode != FileMode::Write {
            return 0;
        }
        let Some(file) = &mut self.file else { return 0 };
        match file.write(buf) {
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => 0,
            Err(e) => {
                self.fail(&e);
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

    fn wait_writable(&mut self, _timeout: Duration) {}

    fn drain(&mut self, _timeout: Duration) {
        if let Some(file) = &mut self.file {
            let _ = file.flush();
            if self.mode == FileMode::Write {
                let _ = file.sync_data();
            }
        }
    }

    fn wait_readable(&mut self, _timeout: Duration) {}

    fn counters(&self) -> PortCounters {
        self.counters
    }

    fn last_error(&self) -> Option<LinkErrorKind> {
        self.last_error
    }

    fn shutdown(&mut self) {
        self.file = None;
    }
}

/// Standard output (send only).
#[derive(Debug, Default)]
pub struct StdoutPort {
    counters: PortCounters,
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
                if e.kind() == io::ErrorKind::BrokenPipe {
                    self.closed = true;
                }
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

    fn shutdown(&mut self) {
        let _ = io::stdout().lock().flush();
        self.closed = true;
    }
}
