//! SocketCAN as a link [`Port`]: a non-blocking raw CAN socket bound to one interface, moving whole 16-byte
//! `struct can_frame`s; error frames (bus-off, controller problems, TX timeout) are consumed here and counted.
//!
//! Per call: one `read(2)`/`write(2)` of 16 bytes, no allocation. `ENOBUFS`/`EAGAIN` on write (the interface's TX
//! queue is full) write nothing and leave the frame queued in the link; `ENETDOWN` (interface down) is counted;
//! `ENODEV` (interface removed) takes the port down and reopens it by name with back-off.

use std::io;
use std::os::fd::{AsFd, OwnedFd};
use std::time::{Duration, Instant};

use super::sys;
use crate::link::backoff::Backoff;
use crate::link::error::{LinkError, LinkErrorKind};
use crate::link::port::{LinkState, Port, PortCounters};
use crate::link::serial::timeout_ms;

/// Error classes the socket subscribes to (`CAN_RAW_ERR_FILTER`).
pub const ERROR_MASK: u32 =
    sys::CAN_ERR_BUSOFF | sys::CAN_ERR_CRTL | sys::CAN_ERR_TX_TIMEOUT | sys::CAN_ERR_RESTARTED;

/// Pack a classic CAN frame into the 16 bytes of `struct can_frame` (native-endian id, as the kernel expects).
/// Returns `None` for an id out of range or more than 8 data bytes.
pub fn pack_frame(id: u32, extended: bool, data: &[u8]) -> Option<[u8; sys::CAN_MTU]> {
    let limit = if extended {
        sys::CAN_EFF_MASK
    } else {
        sys::CAN_SFF_MASK
    };
    if id > limit || data.len() > 8 {
        return None;
    }
    let can_id = if extended { id | sys::CAN_EFF_FLAG } else { id };
    let mut out = [0u8; sys::CAN_MTU];
    out[..4].copy_from_slice(&can_id.to_ne_bytes());
    out[4] = data.len() as u8;
    out[8..8 + data.len()].copy_from_slice(data);
    Some(out)
}

/// A data frame unpacked from `struct can_frame` bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnpackedFrame {
    /// Identifier without flags.
    pub id: u32,
    /// 29-bit identifier.
    pub extended: bool,
    /// Remote transmission request.
    pub remote: bool,
    /// Payload length (0..=8).
    pub len: u8,
    /// Payload; bytes past `len` are zero.
    pub data: [u8; 8],
}

/// What a received `struct can_frame` was.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawFrameKind {
    /// A data or remote frame.
    Data(UnpackedFrame),
    /// An error frame; the value is its error-class bits (`CAN_ERR_*`).
    Error(u32),
    /// Bytes that are not a valid classic frame (length field over 8).
    Invalid,
}

/// Unpack the 16 bytes of a `struct can_frame`.
pub fn unpack_frame(raw: &[u8; sys::CAN_MTU]) -> RawFrameKind {
    let can_id = u32::from_ne_bytes([raw[0], raw[1], raw[2], raw[3]]);
    if can_id & sys::CAN_ERR_FLAG != 0 {
        return RawFrameKind::Error(can_id & sys::CAN_EFF_MASK);
    }
    let len = raw[4];
    if len > 8 {
        return RawFrameKind::Invalid;
    }
    let extended = can_id & sys::CAN_EFF_FLAG != 0;
    let id = can_id
        & if extended {
            sys::CAN_EFF_MASK
        } else {
            sys::CAN_SFF_MASK
        };
    let mut data = [0u8; 8];
    data[..len as usize].copy_from_slice(&raw[8..8 + len as usize]);
    RawFrameKind::Data(UnpackedFrame {
        id,
        extended,
        remote: can_id & sys::CAN_RTR_FLAG != 0,
        len,
        data,
    })
}

/// Map a SocketCAN open failure to a clear link error.
pub fn open_error(iface: &str, step: &'static str, err: io::Error) -> LinkError {
    match err.raw_os_error() {
        Some(libc::EAFNOSUPPORT) | Some(libc::EPROTONOSUPPORT) => LinkError::new(
            LinkErrorKind::NotFound,
            format!(
                "opening can:{iface}: this kernel has no SocketCAN support ({step} failed: {err}); \
                 use slcan:PATH with a serial SLCAN adapter instead"
            ),
        ),
        Some(libc::ENODEV) => LinkError::new(
            LinkErrorKind::NotFound,
            format!("opening can:{iface}: no network interface named `{iface}` ({step}: {err})"),
        ),
        _ => LinkError::io(format!("opening can:{iface}: {step}"), err),
    }
}

fn open_socket(iface: &str) -> Result<OwnedFd, LinkError> {
    let sock =
        sys::can_raw_socket().map_err(|e| open_error(iface, "socket(AF_CAN, SOCK_RAW, CAN_RAW)", e))?;
    let index =
        sys::interface_index(sock.as_fd(), iface).map_err(|e| open_error(iface, "ioctl(SIOCGIFINDEX)", e))?;
    sys::set_error_filter(sock.as_fd(), ERROR_MASK)
        .map_err(|e| open_error(iface, "setsockopt(CAN_RAW_ERR_FILTER)", e))?;
    sys::bind(sock.as_fd(), index).map_err(|e| open_error(iface, "bind", e))?;
    Ok(sock)
}

/// A raw CAN socket on one interface.
#[derive(Debug)]
pub struct SocketCanPort {
    iface: String,
    sock: Option<OwnedFd>,
    backoff: Backoff,
    counters: PortCounters,
    last_error: Option<LinkErrorKind>,
    ended: bool,
    fresh: bool,
}

impl SocketCanPort {
    /// Open a raw CAN socket bound to `iface`, subscribed to bus-off and controller error frames.
    pub fn open(iface: &str) -> Result<Self, LinkError> {
        let sock = open_socket(iface)?;
        Ok(SocketCanPort {
            iface: iface.to_owned(),
            sock: Some(sock),
            backoff: Backoff::start(Instant::now()),
            counters: PortCounters::default(),
            last_error: None,
            ended: false,
            fresh: true,
        })
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        &self.iface
    }

    fn on_error(&mut self, err: &io::Error) {
        match err.raw_os_error() {
            Some(libc::EAGAIN) | Some(libc::ENOBUFS) | Some(libc::EINTR) => {}
            Some(libc::ENETDOWN) => {
                self.counters.io_errors += 1;
                self.last_error = Some(LinkErrorKind::Disconnected);
            }
            Some(libc::ENODEV) | Some(libc::ENXIO) | Some(libc::EBADF) => {
                if self.sock.take().is_some() {
                    self.counters.disconnects += 1;
                    self.last_error = Some(LinkErrorKind::Disconnected);
                    self.backoff = Backoff::start(Instant::now());
                }
            }
            _ => {
                self.counters.io_errors += 1;
                self.last_error = Some(crate::link::error::kind_of_io(err));
            }
        }
    }
}

impl Port for SocketCanPort {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        let Some(sock) = &self.sock else { return 0 };
        let Some(out) = buf.get_mut(..sys::CAN_MTU) else {
            return 0;
        };
        let mut frame = [0u8; sys::CAN_MTU];
        loop {
            match sys::read_frame(sock.as_fd(), &mut frame) {
                Ok(sys::CAN_MTU) => match unpack_frame(&frame) {
                    RawFrameKind::Error(class) => {
                        if class & sys::CAN_ERR_BUSOFF != 0 {
                            self.counters.bus_off += 1;
                            self.last_error = Some(LinkErrorKind::BusOff);
                            tracing::warn!(iface = %self.iface, "CAN controller is bus-off");
                        } else {
                            self.counters.io_errors += 1;
                        }
                        continue;
                    }
                    _ => {
                        out.copy_from_slice(&frame);
                        return sys::CAN_MTU;
                    }
                },
                Ok(_) => {
                    // A CAN FD frame (72 bytes) is truncated to 16 by our buffer size; count and skip it.
                    self.counters.io_errors += 1;
                    continue;
                }
                Err(e) => {
                    self.on_error(&e);
                    return 0;
                }
            }
        }
    }

    fn write(&mut self, buf: &[u8]) -> usize {
        let Some(sock) = &self.sock else { return 0 };
        let Some(frame) = buf
            .get(..sys::CAN_MTU)
            .and_then(|b| <&[u8; sys::CAN_MTU]>::try_from(b).ok())
        else {
            return 0;
        };
        match sys::write_frame(sock.as_fd(), frame) {
            Ok(()) => sys::CAN_MTU,
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
        if self.sock.is_some() {
            return std::mem::take(&mut self.fresh);
        }
        if !self.backoff.due(now) {
            return false;
        }
        match open_socket(&self.iface) {
            Ok(sock) => {
                self.sock = Some(sock);
                self.counters.reconnects += 1;
                true
            }
            Err(_) => {
                self.counters.reconnect_failures += 1;
                self.backoff.failed(now);
                false
            }
        }
    }

    fn state(&self) -> LinkState {
        if self.ended {
            LinkState::Ended
        } else if self.sock.is_some() {
            LinkState::Up
        } else {
            LinkState::Reconnecting
        }
    }

    fn disconnect(&mut self) {
        if self.sock.take().is_some() {
            self.counters.disconnects += 1;
            self.backoff = Backoff::start(Instant::now());
        }
    }

    fn wait_writable(&mut self, timeout: Duration) {
        match &self.sock {
            Some(sock) => {
                let _ = sys::poll_socket(sock.as_fd(), libc::POLLOUT, timeout_ms(timeout));
            }
            None => std::thread::sleep(timeout.min(Duration::from_millis(10))),
        }
    }

    fn drain(&mut self, _timeout: Duration) {
        // A CAN socket has no drain: frames handed to the kernel are in the interface's queue.
    }

    fn wait_readable(&mut self, timeout: Duration) {
        match &self.sock {
            Some(sock) => {
                let _ = sys::poll_socket(sock.as_fd(), libc::POLLIN, timeout_ms(timeout));
            }
            None => std::thread::sleep(timeout.min(Duration::from_millis(10))),
        }
    }

    fn counters(&self) -> PortCounters {
        self.counters
    }

    fn unit(&self) -> usize {
        sys::CAN_MTU
    }

    fn last_error(&self) -> Option<LinkErrorKind> {
        self.last_error
    }

    fn shutdown(&mut self) {
        self.sock = None;
        self.ended = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::error::Error;

    #[test]
    fn pack_unpack_round_trip() {
        let raw = pack_frame(0x123, false, &[1, 2, 3]).unwrap();
        assert_eq!(raw[4], 3);
        assert_eq!(&raw[8..11], &[1, 2, 3]);
        assert_eq!(
            unpack_frame(&raw),
            RawFrameKind::Data(UnpackedFrame {
                id: 0x123,
                extended: false,
                remote: false,
                len: 3,
                data: [1, 2, 3, 0, 0, 0, 0, 0]
            })
        );
        let ext = pack_frame(0x1ABC_DEF0, true, &[0xFF; 8]).unwrap();
        assert_eq!(
            u32::from_ne_bytes(ext[..4].try_into().unwrap()),
            0x1ABC_DEF0 | sys::CAN_EFF_FLAG
        );
        match unpack_frame(&ext) {
            RawFrameKind::Data(f) => assert!(f.extended && f.id == 0x1ABC_DEF0 && f.len == 8),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn pack_rejects_out_of_range() {
        assert!(pack_frame(0x800, false, &[]).is_none());
        assert!(pack_frame(0x2000_0000, true, &[]).is_none());
        assert!(pack_frame(1, false, &[0; 9]).is_none());
    }

    #[test]
    fn error_and_invalid_frames_are_recognised() {
        let mut raw = [0u8; 16];
        raw[..4].copy_from_slice(&(sys::CAN_ERR_FLAG | sys::CAN_ERR_BUSOFF).to_ne_bytes());
        raw[4] = 8;
        assert_eq!(unpack_frame(&raw), RawFrameKind::Error(sys::CAN_ERR_BUSOFF));
        let mut bad = [0u8; 16];
        bad[4] = 9;
        assert_eq!(unpack_frame(&bad), RawFrameKind::Invalid);
    }

    #[test]
    fn no_socketcan_is_a_clear_not_found() {
        let err = open_error(
            "vcan0",
            "socket",
            io::Error::from_raw_os_error(libc::EAFNOSUPPORT),
        );
        assert_eq!(err.kind(), LinkErrorKind::NotFound);
        assert!(
            err.to_string().contains("this kernel has no SocketCAN support"),
            "{err}"
        );
        let err = open_error(
            "can9",
            "ioctl(SIOCGIFINDEX)",
            io::Error::from_raw_os_error(libc::ENODEV),
        );
        assert_eq!(err.kind(), LinkErrorKind::NotFound);
        assert!(
            err.to_string().contains("no network interface named `can9`"),
            "{err}"
        );
    }
}
