//! The link error type: a small, stable [`LinkErrorKind`] for callers to match on, a static description of what failed,
//! and the OS error underneath when there is one. Building one allocates nothing (the description is `&'static str`
//! or, only on the open path, a `String`).

use std::borrow::Cow;
use std::fmt;
use std::io;

/// What kind of failure a link reports, in the manner of `embedded_can::LinkErrorKind`: callers match on this, not on
/// messages.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LinkErrorKind {
    /// The device, path or interface does not exist, or this kernel lacks the protocol family (no SocketCAN).
    NotFound,
    /// The device exists but we may not open it (permissions, busy).
    PermissionDenied,
    /// The device went away (unplug, hang-up, end of file); a reconnect may follow.
    Disconnected,
    /// Another operating-system I/O error.
    Io,
    /// The CAN controller reported bus-off.
    BusOff,
    /// Received bytes or frames failed a check (COBS, CRC, E2E counter, SLCAN syntax).
    Corrupt,
    /// The operation or message is not supported by this link (e.g. receiving on `stdout`).
    Unsupported,
    /// The link spec string is malformed.
    InvalidSpec,
    /// A deadline passed (flush at close).
    Timeout,
    /// A message could not be encoded (too large for the framing).
    Encode,
}

impl LinkErrorKind {
    /// A short, stable, lower-case name for counters and JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            LinkErrorKind::NotFound => "not_found",
            LinkErrorKind::PermissionDenied => "permission_denied",
            LinkErrorKind::Disconnected => "disconnected",
            LinkErrorKind::Io => "io",
            LinkErrorKind::BusOff => "bus_off",
            LinkErrorKind::Corrupt => "corrupt",
            LinkErrorKind::Unsupported => "unsupported",
            LinkErrorKind::InvalidSpec => "invalid_spec",
            LinkErrorKind::Timeout => "timeout",
            LinkErrorKind::Encode => "encode",
        }
    }
}

/// Implemented by every link error, like `embedded_can::Error`: the kind is what callers dispatch on.
pub trait Error: fmt::Debug + fmt::Display {
    /// The kind of this error.
    fn kind(&self) -> LinkErrorKind;
}

/// A link failure: kind, what was being done, and the OS error if any.
#[derive(Debug)]
pub struct LinkError {
    kind: LinkErrorKind,
    what: Cow<'static, str>,
    source: Option<io::Error>,
}

impl LinkError {
    /// An error of `kind` described by `what` (e.g. "opening /dev/ttyUSB0").
    pub fn new(kind: LinkErrorKind, what: impl Into<Cow<'static, str>>) -> Self {
        LinkError {
            kind,
            what: what.into(),
            source: None,
        }
    }

    /// An error caused by an OS error; the kind is derived from the errno.
    pub fn io(what: impl Into<Cow<'static, str>>, err: io::Error) -> Self {
        LinkError {
            kind: kind_of_io(&err),
            what: what.into(),
            source: Some(err),
        }
    }

    /// The OS error underneath, if any.
    pub fn os_error(&self) -> Option<&io::Error> {
        self.source.as_ref()
    }
}

impl Error for LinkError {
    fn kind(&self) -> LinkErrorKind {
        self.kind
    }
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.source {
            Some(err) => write!(f, "{}: {err}", self.what),
            None => write!(f, "{}", self.what),
        }
    }
}

impl std::error::Error for LinkError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.source.as_ref().map(|e| e as _)
    }
}

/// Map an OS error to a link error kind (errno values from `asm-generic/errno-base.h` and `errno.h`).
pub fn kind_of_io(err: &io::Error) -> LinkErrorKind {
    match err.raw_os_error() {
        Some(libc::ENOENT) | Some(libc::ENODEV) | Some(libc::EAFNOSUPPORT) | Some(libc::EPROTONOSUPPORT) => {
            LinkErrorKind::NotFound
        }
        Some(libc::EACCES) | Some(libc::EPERM) | Some(libc::EBUSY) => LinkErrorKind::PermissionDenied,
        Some(libc::EIO) | Some(libc::ENXIO) | Some(libc::EPIPE) | Some(libc::ENETDOWN)
        | Some(libc::EBADF) => LinkErrorKind::Disconnected,
        Some(libc::ETIMEDOUT) => LinkErrorKind::Timeout,
        _ => match err.kind() {
            io::ErrorKind::NotFound => LinkErrorKind::NotFound,
            io::ErrorKind::PermissionDenied => LinkErrorKind::PermissionDenied,
            io::ErrorKind::TimedOut => LinkErrorKind::Timeout,
            io::ErrorKind::UnexpectedEof | io::ErrorKind::BrokenPipe => LinkErrorKind::Disconnected,
            _ => LinkErrorKind::Io,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errno_maps_to_kind() {
        assert_eq!(
            kind_of_io(&io::Error::from_raw_os_error(libc::EAFNOSUPPORT)),
            LinkErrorKind::NotFound
        );
        assert_eq!(
            kind_of_io(&io::Error::from_raw_os_error(libc::ENOENT)),
            LinkErrorKind::NotFound
        );
        assert_eq!(
            kind_of_io(&io::Error::from_raw_os_error(libc::EIO)),
            LinkErrorKind::Disconnected
        );
        assert_eq!(
            kind_of_io(&io::Error::from_raw_os_error(libc::EACCES)),
            LinkErrorKind::PermissionDenied
        );
        assert_eq!(
            kind_of_io(&io::Error::from_raw_os_error(libc::EINVAL)),
            LinkErrorKind::Io
        );
    }

    #[test]
    fn display_names_what_and_cause() {
        let e = LinkError::io("opening /dev/ttyX", io::Error::from_raw_os_error(libc::ENOENT));
        let text = e.to_string();
        assert!(text.starts_with("opening /dev/ttyX: "), "{text}");
        assert_eq!(e.kind(), LinkErrorKind::NotFound);
    }
}
