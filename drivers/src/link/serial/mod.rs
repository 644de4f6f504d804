//! A serial port as a link [`Port`]: termios raw 8N1 without flow control, non-blocking, reopened with exponential
//! back-off after unplug, hang-up, end of file or EIO.
//!
//! Per call: one `read(2)` or `write(2)` syscall on the non-blocking fd, no allocation. Termios is set so that a
//! read with no data fails with `EAGAIN` (`VMIN = 1`, `VTIME = 0`, `O_NONBLOCK`), which keeps "nothing yet" apart
//! from a hang-up (read returns 0) and a closed pty master (`EIO`). The baud setting is ignored by ptys, so tests
//! over a pty check framing and content, not timing.

mod codec;
pub mod sys;

use std::io;
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::backoff::Backoff;
use super::error::{LinkError, LinkErrorKind, kind_of_io};
use super::port::{LinkState, Port, PortCounters};

pub use codec::SerialCodec;
pub use sys::{PtyMaster, TtyMode, open_pty, tty_mode};

/// An open (or reconnecting) serial port.
#[derive(Debug)]
pub struct SerialPort {
    path: PathBuf,
    baud: u32,
    fd: Option<OwnedFd>,
    backoff: Backoff,
    counters: PortCounters,
    last_error: Option<LinkErrorKind>,
    ended: bool,
    fresh: bool,
    /// False for a port made from an fd ([`SerialPort::from_fd`]): it has no path to reopen.
    reopens: bool,
}

fn open_configured(path: &Path, baud: u32) -> io::Result<OwnedFd> {
    let fd = sys::open_tty(path)?;
    if !sys::is_tty(fd.as_fd()) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "not a terminal device",
        ));
    }
    sys::configure_raw(fd.as_fd(), baud)?;
    Ok(fd)
}

impl SerialPort {
    /// Open `path` at `baud` in raw mode. Fails (and does not retry) when the first open fails, so that a typo in
    /// the device path is an immediate, clear error.
    pub fn open(path: &Path, baud: u32) -> Result<Self, LinkError> {
        let fd = open_configured(path, baud).map_err(|e| {
            LinkError::io(
                format!("opening serial port {} at {baud} baud", path.display()),
                e,
            )
        })?;
        Ok(SerialPort {
            path: path.to_owned(),
            baud,
            fd: Some(fd),
            backoff: Backoff::start(Instant::now()),
            counters: PortCounters::default(),
            last_error: None,
            ended: false,
            fresh: true,
            reopens: true,
        })
    }

    /// A port over an fd that is already open: a pty master (the device side in tests and emulators), a socket.
    /// The fd is made non-blocking; it is not reconfigured. It cannot be reopened, so errors that would take a
    /// device port down (such as `EIO` on a pty master while no slave is open) are only counted.
    pub fn from_fd(fd: OwnedFd, label: &str) -> Result<Self, LinkError> {
        sys::set_nonblocking(fd.as_fd(), true)
            .map_err(|e| LinkError::io(format!("making {label} non-blocking"), e))?;
        Ok(SerialPort {
            path: PathBuf::from(label),
            baud: 0,
            fd: Some(fd),
            backoff: Backoff::start(Instant::now()),
            counters: PortCounters::default(),
            last_error: None,
            ended: false,
            fresh: true,
            reopens: false,
        })
    }

    /// The device path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The configured baud rate.
    pub fn baud(&self) -> u32 {
        self.baud
    }

    /// The tty's current termios mode, when connected.
    pub fn mode(&self) -> Option<TtyMode> {
        self.fd.as_ref().and_then(|fd| tty_mode(fd.as_fd()).ok())
    }

    fn went_down(&mut self, kind: LinkErrorKind) {
        if !self.reopens {
            self.counters.io_errors += 1;
            self.last_error = Some(kind);
            return;
        }
        if self.fd.take().is_some() {
            self.counters.disconnects += 1;
            self.last_error = Some(kind);
            self.backoff = Backoff::start(Instant::now());
            tracing::warn!(path = %self.path.display(), kind = kind.as_str(), "serial port went down; reconnecting");
        }
    }

    fn on_error(&mut self, err: &io::Error) {
        match err.raw_os_error() {
            Some(libc::EAGAIN) | Some(libc::EINTR) => {}
            _ => {
                let kind = kind_of_io(err);
                if matches!(kind, LinkErrorKind::Disconnected | LinkErrorKind::NotFound) {
                    self.went_down(LinkErrorKind::Disconnected);
                } else {
                    self.counters.io_errors += 1;
                    self.last_error = Some(kind);
                }
            }
        }
    }
}

impl Port for SerialPort {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        let Some(fd) = &self.fd else { return 0 };
        if buf.is_empty() {
            return 0;
        }
        match sys::read(fd.as_fd(), buf) {
            Ok(0) => {
                // VMIN = 1 with O_NONBLOCK: 0 bytes means hang-up, not "no data".
                self.went_down(LinkErrorKind::Disconnected);
                0
            }
            Ok(n) => n,
            Err(e) => {
                self.on_error(&e);
                0
            }
        }
    }

    fn write(&mut self, buf: &[u8]) -> usize {
        let Some(fd) = &self.fd else { return 0 };
        if buf.is_empty() {
            return 0;
        }
        match sys::write(fd.as_fd(), buf) {
            Ok(n) => n,
            Err(e) => {
                self.on_error(&e);
                0
            }
        }
    }

    fn maintain(&mut self, now: Instant) -> bool {
        if self.ended {
            return false;
        }
        if self.fd.is_some() {
            return std::mem::take(&mut self.fresh);
        }
        if !self.backoff.due(now) {
            return false;
        }
        match open_configured(&self.path, self.baud) {
            Ok(fd) => {
                self.fd = Some(fd);
                self.counters.reconnects += 1;
                tracing::info!(path = %self.path.display(), "serial port reconnected");
                true
            }
            Err(e) => {
                self.counters.reconnect_failures += 1;
                self.backoff.failed(now);
                tracing::debug!(path = %self.path.display(), error = %e, "serial reconnect failed");
                false
            }
        }
    }

    fn state(&self) -> LinkState {
        if self.ended {
            LinkState::Ended
        } else if self.fd.is_some() {
            LinkState::Up
        } else {
            LinkState::Reconnecting
        }
    }

    fn disconnect(&mut self) {
        self.went_down(LinkErrorKind::Disconnected);
    }

    fn wait_writable(&mut self, timeout: Duration) {
        match &self.fd {
            Some(fd) => {
                let _ = sys::poll_fd(fd.as_fd(), sys::POLLOUT, timeout_ms(timeout));
            }
            None => std::thread::sleep(timeout.min(Duration::from_millis(10))),
        }
    }

    fn drain(&mut self, timeout: Duration) {
        let Some(fd) = &self.fd else { return };
        // tcdrain blocks without a timeout; a pty or a healthy UART drains quickly, so bound it by polling for
        // writability first and skip the drain if the device is stuck.
        if sys::poll_fd(fd.as_fd(), sys::POLLOUT, timeout_ms(timeout)).is_ok_and(|r| r & sys::POLLOUT != 0) {
            let _ = sys::drain(fd.as_fd());
        }
    }

    fn wait_readable(&mut self, timeout: Duration) {
        match &self.fd {
            Some(fd) => {
                let _ = sys::poll_fd(fd.as_fd(), sys::POLLIN, timeout_ms(timeout));
            }
            None => std::thread::sleep(timeout.min(Duration::from_millis(10))),
        }
    }

    fn counters(&self) -> PortCounters {
        self.counters
    }

    fn last_error(&self) -> Option<LinkErrorKind> {
        self.last_error
    }

    fn shutdown(&mut self) {
        self.fd = None;
        self.ended = true;
    }
}

/// A duration as a poll(2) timeout in milliseconds, rounded up, saturating.
pub(crate) fn timeout_ms(timeout: Duration) -> i32 {
    let ms = timeout.as_micros().div_ceil(1000);
    i32::try_from(ms).unwrap_or(i32::MAX)
}
