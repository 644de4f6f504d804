//! The unsafe libc calls behind the serial link: open, termios raw mode and baud, non-blocking read/write, poll,
//! and pseudo-terminal pairs for tests and emulators.
//!
//! Every function takes or returns owned/borrowed fds (`OwnedFd`/`BorrowedFd`), so no raw fd outlives its owner.
//! Constants come from `libc`, which mirrors the kernel headers named next to each use; the termios2 path
//! (arbitrary baud rates) follows `asm-generic/termbits.h` and `asm-generic/ioctls.h`.
#![allow(unsafe_code)]

use std::ffi::CString;
use std::io;
use std::os::fd::{AsRawFd, BorrowedFd, FromRawFd, OwnedFd};
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};

/// Open a tty for reading and writing: `O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC` (`fcntl.h`).
///
/// `O_NOCTTY` keeps the port from becoming our controlling terminal (a hang-up must not signal us); `O_NONBLOCK`
/// makes open itself not wait for carrier detect and every later read/write return `EAGAIN` instead of blocking.
pub fn open_tty(path: &Path) -> io::Result<OwnedFd> {
    let c_path = CString::new(path.as_os_str().as_bytes())
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "path contains a NUL byte"))?;
    let flags = libc::O_RDWR | libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC;
    // SAFETY: `c_path` is a valid NUL-terminated string that lives across the call; open has no other inputs.
    let fd = unsafe { libc::open(c_path.as_ptr(), flags) };
    if fd < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: open returned a fresh fd that nothing else owns.
    Ok(unsafe { OwnedFd::from_raw_fd(fd) })
}

/// Whether an fd is a terminal (`isatty`).
pub fn is_tty(fd: BorrowedFd<'_>) -> bool {
    // SAFETY: isatty only inspects the fd, which `BorrowedFd` guarantees is open.
    unsafe { libc::isatty(fd.as_raw_fd()) == 1 }
}

/// The termios `speed_t` code for a standard baud rate (`asm-generic/termbits.h`), if there is one.
pub fn standard_speed(baud: u32) -> Option<libc::speed_t> {
    Some(match baud {
        1200 => libc::B1200,
        2400 => libc::B2400,
        4800 => libc::B4800,
        9600 => libc::B9600,
        19200 => libc::B19200,
        38400 => libc::B38400,
        57600 => libc::B57600,
        115200 => libc::B115200,
        230400 => libc::B230400,
        460800 => libc::B460800,
        500000 => libc::B500000,
        576000 => libc::B576000,
        921600 => libc::B921600,
        1000000 => libc::B1000000,
        1152000 => libc::B1152000,
        1500000 => libc::B1500000,
        2000000 => libc::B2000000,
        2500000 => libc::B2500000,
        3000000 => libc::B3000000,
        3500000 => libc::B3500000,
        4000000 => libc::B4000000,
        _ => return None,
    })
}

/// Put a tty into raw 8N1 mode without flow control at `baud`, `VMIN = 1`, `VTIME = 0`.
///
/// With `O_NONBLOCK` a read then fails with `EAGAIN` when no byte is waiting and returns 0 only on hang-up. With
/// `VMIN = 0` the kernel's n_tty returns 0 for "no data" even on a non-blocking fd, which the port would take for
/// a hang-up and reconnect in a loop, losing whatever arrived while the port was closed.
///
/// `cfmakeraw` clears ICRNL/IXON/ECHO/ICANON/OPOST and friends (without it 0x0d becomes 0x0a, XON is swallowed and
/// bytes echo back); then CLOCAL|CREAD on, CRTSCTS/CSTOPB/PARENB off, CS8. A standard rate goes through
/// `cfsetispeed/cfsetospeed`; any other rate through termios2 with `BOTHER` (`TCGETS2`/`TCSETS2`).
pub fn configure_raw(fd: BorrowedFd<'_>, baud: u32) -> io::Result<()> {
    let raw = fd.as_raw_fd();
    // SAFETY: termios is plain old data; zeroed is a valid value that tcgetattr overwrites.
    let mut tio: libc::termios = unsafe { std::mem::zeroed() };
    // SAFETY: `tio` is a valid, writable termios for the duration of the call.
    if unsafe { libc::tcgetattr(raw, &mut tio) } != 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: `tio` is a valid termios; cfmakeraw only edits its flag fields.
    unsafe { libc::cfmakeraw(&mut tio) };
    tio.c_cflag |= libc::CLOCAL | libc::CREAD;
    tio.c_cflag &= !(libc::CRTSCTS | libc::CSTOPB | libc::PARENB | libc::CSIZE);
    tio.c_cflag |= libc::CS8;
    tio.c_iflag &= !(libc::IXON | libc::IXOFF | libc::IXANY);
    tio.c_cc[libc::VMIN] = 1;
    tio.c_cc[libc::VTIME] = 0;
    let standard = standard_speed(baud);
    if let Some(speed) = standard {
        // SAFETY: `tio` is a valid termios and `speed` one of the B-codes the functions accept.
        let rc = unsafe { libc::cfsetispeed(&mut tio, speed) | libc::cfsetospeed(&mut tio, speed) };
        if rc != 0 {
            return Err(io::Error::last_os_error());
        }
    }
    // SAFETY: `tio` is a valid termios that outlives the call.
    if unsafe { libc::tcsetattr(raw, libc::TCSANOW, &tio) } != 0 {
        return Err(io::Error::last_os_error());
    }
    if standard.is_none() {
        set_custom_baud(fd, baud)?;
    }
    Ok(())
}

/// Set an arbitrary baud rate through termios2: clear `CBAUD`, set `BOTHER`, and put the rate in `c_ispeed/c_ospeed`.
fn set_custom_baud(fd: BorrowedFd<'_>, baud: u32) -> io::Result<()> {
    // SAFETY: termios2 is plain old data; zeroed is valid and TCGETS2 overwrites it.
    let mut t2: libc::termios2 = unsafe { std::mem::zeroed() };
    // SAFETY: TCGETS2 writes one `struct termios2` through the pointer, which points at a live, writable one.
    if unsafe { libc::ioctl(fd.as_raw_fd(), libc::TCGETS2, &mut t2) } != 0 {
        return Err(io::Error::last_os_error());
    }
    t2.c_cflag &= !libc::CBAUD;
    t2.c_cflag |= libc::BOTHER;
    // Input speed: the same BOTHER code shifted by IBSHIFT (termbits.h), so both directions use c_ispeed/c_ospeed.
    t2.c_cflag &= !(libc::CBAUD << libc::IBSHIFT);
    t2.c_cflag |= libc::BOTHER << libc::IBSHIFT;
    t2.c_ispeed = baud;
    t2.c_ospeed = baud;
    // SAFETY: TCSETS2 reads one `struct termios2` through the pointer, which points at a live one.
    if unsafe { libc::ioctl(fd.as_raw_fd(), libc::TCSETS2, &t2) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// What a tty's termios says, for tests and `supine info`: raw-mode flags and the speed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TtyMode {
    /// `ICANON` (line buffering) is off.
    pub noncanonical: bool,
    /// `ECHO` is off.
    pub no_echo: bool,
    /// `ICRNL` (CR to NL on input) and `IXON` (XON/XOFF) are off.
    pub no_input_translation: bool,
    /// `OPOST` (output post-processing) is off.
    pub no_output_processing: bool,
    /// 8 data bits, no parity, one stop bit, no RTS/CTS.
    pub eight_n_one: bool,
    /// The output speed in baud (termios2 `c_ospeed`).
    pub baud: u32,
}

/// Read back a tty's mode.
pub fn tty_mode(fd: BorrowedFd<'_>) -> io::Result<TtyMode> {
    // SAFETY: termios2 is plain old data; zeroed is valid and TCGETS2 overwrites it.
    let mut t2: libc::termios2 = unsafe { std::mem::zeroed() };
    // SAFETY: TCGETS2 writes one `struct termios2` through the pointer, which points at a live, writable one.
    if unsafe { libc::ioctl(fd.as_raw_fd(), libc::TCGETS2, &mut t2) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(TtyMode {
        noncanonical: t2.c_lflag & libc::ICANON == 0,
        no_echo: t2.c_lflag & libc::ECHO == 0,
        no_input_translation: t2.c_iflag & (libc::ICRNL | libc::IXON) == 0,
        no_output_processing: t2.c_oflag & libc::OPOST == 0,
        eight_n_one: t2.c_cflag & libc::CSIZE == libc::CS8
            && t2.c_cflag & (libc::PARENB | libc::CSTOPB | libc::CRTSCTS) == 0,
        baud: t2.c_ospeed,
    })
}

/// Non-blocking read: `Ok(0)` means end of file (a hung-up tty reads 0 or fails with `EIO`).
pub fn read(fd: BorrowedFd<'_>, buf: &mut [u8]) -> io::Result<usize> {
    // SAFETY: `buf` is valid for `buf.len()` writable bytes for the duration of the call.
    let n = unsafe { libc::read(fd.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) };
    if n < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(n as usize)
    }
}

/// Non-blocking write of as much of `buf` as the kernel takes now.
pub fn write(fd: BorrowedFd<'_>, buf: &[u8]) -> io::Result<usize> {
    // SAFETY: `buf` is valid for `buf.len()` readable bytes for the duration of the call.
    let n = unsafe { libc::write(fd.as_raw_fd(), buf.as_ptr().cast(), buf.len()) };
    if n < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(n as usize)
    }
}

/// `poll(2)` readiness bits (`asm-generic/poll.h`).
pub use libc::{POLLERR, POLLHUP, POLLIN, POLLNVAL, POLLOUT};

/// Wait up to `timeout_ms` (0: just look, negative: forever) for `events` on one fd; returns the `revents`.
pub fn poll_fd(fd: BorrowedFd<'_>, events: libc::c_short, timeout_ms: i32) -> io::Result<libc::c_short> {
    let mut pfd = libc::pollfd {
        fd: fd.as_raw_fd(),
        events,
        revents: 0,
    };
    loop {
        // SAFETY: `pfd` is one valid pollfd and we pass a count of 1.
        let rc = unsafe { libc::poll(&mut pfd, 1, timeout_ms) };
        if rc >= 0 {
            return Ok(pfd.revents);
        }
        let err = io::Error::last_os_error();
        if err.kind() != io::ErrorKind::Interrupted {
            return Err(err);
        }
    }
}

/// Wait until the tty has transmitted everything written to it (`tcdrain`); used only at close.
pub fn drain(fd: BorrowedFd<'_>) -> io::Result<()> {
    // SAFETY: tcdrain only takes the fd, which `BorrowedFd` guarantees is open.
    if unsafe { libc::tcdrain(fd.as_raw_fd()) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// A pseudo-terminal pair: the master end (the "device" side) and the path of the slave end (`/dev/pts/N`).
///
/// The slave is what a link opens like a serial port; tests and emulators read and write the master.
#[derive(Debug)]
pub struct PtyMaster {
    /// The master fd, opened `O_RDWR | O_NOCTTY | O_CLOEXEC`; blocking unless made non-blocking.
    pub fd: OwnedFd,
    /// Path of the slave end.
    pub slave_path: PathBuf,
}

/// Create a pty pair with `posix_openpt`, `grantpt`, `unlockpt`, `ptsname_r` (`stdlib.h`), and put the master in raw
/// mode so the test side sees exactly the bytes the link wrote.
pub fn open_pty() -> io::Result<PtyMaster> {
    // SAFETY: posix_openpt takes only flags.
    let raw = unsafe { libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC) };
    if raw < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: posix_openpt returned a fresh fd that nothing else owns.
    let fd = unsafe { OwnedFd::from_raw_fd(raw) };
    // SAFETY: grantpt and unlockpt only take the master fd, which is open.
    if unsafe { libc::grantpt(raw) } != 0 || unsafe { libc::unlockpt(raw) } != 0 {
        return Err(io::Error::last_os_error());
    }
    let mut name = [0 as libc::c_char; 128];
    // SAFETY: `name` is a writable buffer of the length we pass; ptsname_r NUL-terminates on success.
    let rc = unsafe { libc::ptsname_r(raw, name.as_mut_ptr(), name.len()) };
    if rc != 0 {
        return Err(io::Error::from_raw_os_error(rc));
    }
    // SAFETY: ptsname_r succeeded, so `name` holds a NUL-terminated string inside the buffer.
    let c_name = unsafe { std::ffi::CStr::from_ptr(name.as_ptr()) };
    let slave_path = PathBuf::from(std::ffi::OsStr::from_bytes(c_name.to_bytes()));
    // SAFETY: termios is plain old data; tcgetattr overwrites the zeroed value.
    let mut tio: libc::termios = unsafe { std::mem::zeroed() };
    // SAFETY: `tio` is valid and writable; the master fd is open.
    if unsafe { libc::tcgetattr(raw, &mut tio) } == 0 {
        // SAFETY: `tio` is a valid termios.
        unsafe { libc::cfmakeraw(&mut tio) };
        // SAFETY: `tio` is valid for the call.
        unsafe { libc::tcsetattr(raw, libc::TCSANOW, &tio) };
    }
    Ok(PtyMaster { fd, slave_path })
}

/// Switch `O_NONBLOCK` on or off for an fd (`fcntl(F_GETFL/F_SETFL)`).
pub fn set_nonblocking(fd: BorrowedFd<'_>, on: bool) -> io::Result<()> {
    // SAFETY: F_GETFL takes no argument and only reads the fd's status flags.
    let flags = unsafe { libc::fcntl(fd.as_raw_fd(), libc::F_GETFL) };
    if flags < 0 {
        return Err(io::Error::last_os_error());
    }
    let flags = if on {
        flags | libc::O_NONBLOCK
    } else {
        flags & !libc::O_NONBLOCK
    };
    // SAFETY: F_SETFL takes an int of status flags.
    if unsafe { libc::fcntl(fd.as_raw_fd(), libc::F_SETFL, flags) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}
