//! The transport under a link's codec: a byte stream (serial port, file, stdout) or a frame socket (SocketCAN).
//!
//! Ports never block the caller on read or write (a stdout pipe is the documented exception) and hide reconnects:
//! when the device goes away they count a disconnect, return 0 from read/write, and retry opening with
//! exponential back-off from [`Port::maintain`].

use std::time::{Duration, Instant};

use super::error::LinkErrorKind;

/// Where a port (and so a link) stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkState {
    /// Open; bytes or frames flow.
    Up,
    /// The device went away; reconnect attempts run with back-off.
    Reconnecting,
    /// The source ended for good (end of a capture file) or the link was closed.
    Ended,
}

impl LinkState {
    /// A short lower-case name for JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            LinkState::Up => "up",
            LinkState::Reconnecting => "reconnecting",
            LinkState::Ended => "ended",
        }
    }
}

/// Connection counters every port keeps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PortCounters {
    /// Times the device went away (hang-up, EIO, end of file on a tty, forced disconnect).
    pub disconnects: u64,
    /// Successful re-opens after a disconnect.
    pub reconnects: u64,
    /// Failed re-open attempts.
    pub reconnect_failures: u64,
    /// Read or write errors that were not a disconnect (counted, then ignored).
    pub io_errors: u64,
    /// Bus-off reports from a CAN controller.
    pub bus_off: u64,
}

/// A byte-stream or frame transport with hidden reconnects.
pub trait Port {
    /// Read what is available now into `buf`; 0 when nothing is (or the port is down). Frame ports return one
    /// whole frame of [`Port::unit`] bytes per call.
    fn read(&mut self, buf: &mut [u8]) -> usize;
    /// Write what the device takes now from `buf`; 0 when it takes nothing (full or down). Stream ports may write a
    /// prefix; frame ports write whole units or nothing.
    fn write(&mut self, buf: &[u8]) -> usize;
    /// Drive reconnects; returns true exactly once after each successful (re)open, so the link can resend its
    /// preamble and reset its decoder.
    fn maintain(&mut self, now: Instant) -> bool;
    /// Where the port stands.
    fn state(&self) -> LinkState;
    /// Drop the connection now (fault injection, operator request); reconnects follow with back-off.
    fn disconnect(&mut self);
    /// Block up to `timeout` until a write could make progress (used only when closing, never per frame).
    fn wait_writable(&mut self, timeout: Duration);
    /// Block up to `timeout` until all written bytes left the device (used only when closing).
    fn drain(&mut self, timeout: Duration);
    /// Block up to `timeout` until a read could return data (used by idle loops such as `supine wire listen`).
    fn wait_readable(&mut self, timeout: Duration);
    /// The port's counters.
    fn counters(&self) -> PortCounters;
    /// Bytes per write/read unit: 1 for streams, 16 for SocketCAN frames.
    fn unit(&self) -> usize {
        1
    }
    /// The last error kind that took the port down, if any.
    fn last_error(&self) -> Option<LinkErrorKind>;
    /// The first OS error a write failed with, in words, for ports whose writes can fail for good (files, stdout).
    fn write_error(&self) -> Option<&str> {
        None
    }
    /// Close for good: release the device. Later reads and writes return 0 and the state is `Ended`.
    fn shutdown(&mut self);
}
