//! The unsafe libc calls behind SocketCAN: a raw CAN socket, interface lookup by name, bind, error filter, and
//! non-blocking frame reads and writes.
//!
//! Layouts and constants are written out here, each traced to its kernel header, and pinned by size/offset tests
//! (and, where `libc` has them, cross-checked against `libc`'s values).
#![allow(unsafe_code)]

use std::io;
use std::mem::{offset_of, size_of};
use std::os::fd::{AsRawFd, BorrowedFd, FromRawFd, OwnedFd};

/// `AF_CAN` = `PF_CAN` = 29 (`linux/socket.h`).
pub const AF_CAN: libc::c_int = 29;
/// `CAN_RAW` = 1, the raw protocol of the CAN family (`linux/can.h`).
pub const CAN_RAW: libc::c_int = 1;
/// `SOL_CAN_BASE` = 100 (`linux/can.h`).
pub const SOL_CAN_BASE: libc::c_int = 100;
/// `SOL_CAN_RAW` = `SOL_CAN_BASE + CAN_RAW` (`linux/can/raw.h`).
pub const SOL_CAN_RAW: libc::c_int = SOL_CAN_BASE + CAN_RAW;
/// `CAN_RAW_ERR_FILTER` = 2, the error-class mask socket option (`linux/can/raw.h`, enum after `CAN_RAW_FILTER`).
pub const CAN_RAW_ERR_FILTER: libc::c_int = 2;
/// `SIOCGIFINDEX` = 0x8933, interface name to index (`linux/sockios.h`).
pub const SIOCGIFINDEX: libc::c_ulong = 0x8933;
/// `IFNAMSIZ` = 16 (`linux/if.h`).
pub const IFNAMSIZ: usize = 16;

/// `CAN_EFF_FLAG`: extended 29-bit identifier (`linux/can.h`).
pub const CAN_EFF_FLAG: u32 = 0x8000_0000;
/// `CAN_RTR_FLAG`: remote transmission request (`linux/can.h`).
pub const CAN_RTR_FLAG: u32 = 0x4000_0000;
/// `CAN_ERR_FLAG`: error message frame (`linux/can.h`).
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
/// `CAN_SFF_MASK`: standard 11-bit identifier bits (`linux/can.h`).
pub const CAN_SFF_MASK: u32 = 0x0000_07FF;
/// `CAN_EFF_MASK`: extended 29-bit identifier bits (`linux/can.h`).
pub const CAN_EFF_MASK: u32 = 0x1FFF_FFFF;
/// `CAN_ERR_TX_TIMEOUT`: error class, TX timeout by the netdevice driver (`linux/can/error.h`).
pub const CAN_ERR_TX_TIMEOUT: u32 = 0x0000_0001;
/// `CAN_ERR_CRTL`: error class, controller problems, details in `data[1]` (`linux/can/error.h`).
pub const CAN_ERR_CRTL: u32 = 0x0000_0004;
/// `CAN_ERR_BUSOFF`: error class, bus off (`linux/can/error.h`).
pub const CAN_ERR_BUSOFF: u32 = 0x0000_0040;
/// `CAN_ERR_RESTARTED`: error class, controller restarted (`linux/can/error.h`).
pub const CAN_ERR_RESTARTED: u32 = 0x0000_0100;

/// `struct can_frame` (`linux/can.h`): 16 bytes, data 8-aligned at offset 8.
#[repr(C, align(8))]
#[derive(Clone, Copy, Debug, Default)]
pub struct CanFrameRaw {
    /// 32-bit id with EFF/RTR/ERR flags.
    pub can_id: u32,
    /// Payload length 0..=8 (`len`, formerly `can_dlc`).
    pub len: u8,
    /// `__pad`.
    pub pad: u8,
    /// `__res0`.
    pub res0: u8,
    /// `len8_dlc`: raw DLC 9..15 for 8-byte frames (unused here).
    pub len8_dlc: u8,
    /// Payload.
    pub data: [u8; 8],
}

/// Size of `struct can_frame` (`CAN_MTU`, `linux/can.h`).
pub const CAN_MTU: usize = 16;

/// `struct sockaddr_can` (`linux/can.h`): family, interface index, and a 16-byte, 8-aligned address union
/// (`tp` rx/tx ids or `j1939` name/pgn/addr) that raw sockets leave zero.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct SockaddrCan {
    /// `AF_CAN`.
    pub can_family: libc::sa_family_t,
    /// Interface index from `SIOCGIFINDEX`; 0 binds to every CAN interface.
    pub can_ifindex: libc::c_int,
    /// `can_addr` union, unused by CAN_RAW.
    pub can_addr: [u64; 2],
}

/// The part of `struct ifreq` (`linux/if.h`) that `SIOCGIFINDEX` uses: the name, then `ifr_ifindex` at offset 16
/// inside a union whose largest member (`struct ifmap`) is 24 bytes on 64-bit targets.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct IfreqIndex {
    /// `ifr_name`, NUL-terminated.
    pub ifr_name: [libc::c_char; IFNAMSIZ],
    /// `ifr_ifindex`.
    pub ifr_ifindex: libc::c_int,
    /// Rest of the union, so the kernel may copy a whole `struct ifreq`.
    pub pad: [u8; 20],
}

const _: () = assert!(size_of::<CanFrameRaw>() == CAN_MTU);
const _: () = assert!(offset_of!(CanFrameRaw, data) == 8);
const _: () = assert!(size_of::<SockaddrCan>() == 24);
const _: () = assert!(offset_of!(SockaddrCan, can_ifindex) == 4);
const _: () = assert!(offset_of!(IfreqIndex, ifr_ifindex) == 16);
const _: () = assert!(size_of::<IfreqIndex>() >= 32);

/// `socket(AF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW)`. Fails with `EAFNOSUPPORT` on a kernel
/// without `CONFIG_CAN`.
pub fn can_raw_socket() -> io::Result<OwnedFd> {
    // SAFETY: socket takes only integer arguments.
    let fd = unsafe {
        libc::socket(
            AF_CAN,
            libc::SOCK_RAW | libc::SOCK_NONBLOCK | libc::SOCK_CLOEXEC,
            CAN_RAW,
        )
    };
    if fd < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: socket returned a fresh fd that nothing else owns.
    Ok(unsafe { OwnedFd::from_raw_fd(fd) })
}

/// The interface index of `name` via `ioctl(SIOCGIFINDEX)` on `sock`.
pub fn interface_index(sock: BorrowedFd<'_>, name: &str) -> io::Result<libc::c_int> {
    let bytes = name.as_bytes();
    if bytes.is_empty() || bytes.len() >= IFNAMSIZ || bytes.contains(&0) {
        return Err(io::Error::from_raw_os_error(libc::EINVAL));
    }
    let mut req = IfreqIndex {
        ifr_name: [0; IFNAMSIZ],
        ifr_ifindex: 0,
        pad: [0; 20],
    };
    for (dst, &src) in req.ifr_name.iter_mut().zip(bytes) {
        *dst = src as libc::c_char;
    }
    // SAFETY: SIOCGIFINDEX reads ifr_name and writes ifr_ifindex of the ifreq we point at, which is live, writable
    // and at least as large as the kernel's struct ifreq.
    if unsafe { libc::ioctl(sock.as_raw_fd(), SIOCGIFINDEX as _, &mut req) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(req.ifr_ifindex)
}

/// Subscribe to the error classes in `mask` (`setsockopt(SOL_CAN_RAW, CAN_RAW_ERR_FILTER)`).
pub fn set_error_filter(sock: BorrowedFd<'_>, mask: u32) -> io::Result<()> {
    // SAFETY: we pass a pointer to a live u32 (`can_err_mask_t`) and its exact size.
    let rc = unsafe {
        libc::setsockopt(
            sock.as_raw_fd(),
            SOL_CAN_RAW,
            CAN_RAW_ERR_FILTER,
            (&mask as *const u32).cast(),
            size_of::<u32>() as libc::socklen_t,
        )
    };
    if rc < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

/// Bind the raw socket to interface `ifindex`.
pub fn bind(sock: BorrowedFd<'_>, ifindex: libc::c_int) -> io::Result<()> {
    let addr = SockaddrCan {
        can_family: AF_CAN as libc::sa_family_t,
        can_ifindex: ifindex,
        can_addr: [0; 2],
    };
    // SAFETY: `addr` is a live sockaddr_can and we pass its exact size.
    let rc = unsafe {
        libc::bind(
            sock.as_raw_fd(),
            (&addr as *const SockaddrCan).cast(),
            size_of::<SockaddrCan>() as libc::socklen_t,
        )
    };
    if rc < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

/// Write one 16-byte `struct can_frame`.
pub fn write_frame(sock: BorrowedFd<'_>, frame: &[u8; CAN_MTU]) -> io::Result<()> {
    // SAFETY: `frame` is valid for CAN_MTU readable bytes.
    let n = unsafe { libc::write(sock.as_raw_fd(), frame.as_ptr().cast(), CAN_MTU) };
    if n < 0 {
        Err(io::Error::last_os_error())
    } else if n as usize != CAN_MTU {
        Err(io::Error::new(io::ErrorKind::WriteZero, "short CAN frame write"))
    } else {
        Ok(())
    }
}

/// Read one frame; `Ok(n)` with `n` the bytes the kernel delivered (16 for a classic frame).
pub fn read_frame(sock: BorrowedFd<'_>, frame: &mut [u8; CAN_MTU]) -> io::Result<usize> {
    // SAFETY: `frame` is valid for CAN_MTU writable bytes.
    let n = unsafe { libc::read(sock.as_raw_fd(), frame.as_mut_ptr().cast(), CAN_MTU) };
    if n < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(n as usize)
    }
}

/// Wait up to `timeout_ms` for `events` on the socket; returns the `revents`.
pub fn poll_socket(
    sock: BorrowedFd<'_>,
    events: libc::c_short,
    timeout_ms: i32,
) -> io::Result<libc::c_short> {
    crate::link::serial::sys::poll_fd(sock, events, timeout_ms)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_match_the_kernel_headers() {
        assert_eq!(size_of::<CanFrameRaw>(), 16);
        assert_eq!(align_of::<CanFrameRaw>(), 8);
        assert_eq!(size_of::<CanFrameRaw>(), size_of::<libc::can_frame>());
        assert_eq!(size_of::<SockaddrCan>(), size_of::<libc::sockaddr_can>());
        #[cfg(target_pointer_width = "64")]
        assert_eq!(size_of::<IfreqIndex>(), size_of::<libc::ifreq>());
    }

    /// The same numbers read from the kernel headers themselves by a compiled C probe.
    #[test]
    fn layouts_match_a_c_probe_of_linux_can_h() {
        let c = crate::c_probe::run(
            &crate::c_probe::Compiler {
                env_var: "CC",
                default: "cc",
            },
            &[],
            "probe.c",
            r#"#include <stdio.h>
#include <stddef.h>
#include <sys/socket.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <linux/can/error.h>
#define P(name, v) printf("%s %ld\n", name, (long)(v))
int main(void) {
  P("can_frame", sizeof(struct can_frame)); P("can_frame.data", offsetof(struct can_frame, data));
  P("sockaddr_can", sizeof(struct sockaddr_can)); P("ifreq", sizeof(struct ifreq));
  P("AF_CAN", AF_CAN); P("CAN_RAW", CAN_RAW); P("SOL_CAN_RAW", SOL_CAN_RAW);
  P("CAN_RAW_ERR_FILTER", CAN_RAW_ERR_FILTER); P("SIOCGIFINDEX", SIOCGIFINDEX);
  P("CAN_EFF_FLAG", CAN_EFF_FLAG); P("CAN_RTR_FLAG", CAN_RTR_FLAG); P("CAN_ERR_FLAG", CAN_ERR_FLAG);
  P("CAN_ERR_BUSOFF", CAN_ERR_BUSOFF); P("IFNAMSIZ", IFNAMSIZ);
  return 0;
}
"#,
        );
        let rust: &[(&str, i64)] = &[
            ("can_frame", size_of::<CanFrameRaw>() as i64),
            ("can_frame.data", offset_of!(CanFrameRaw, data) as i64),
            ("sockaddr_can", size_of::<SockaddrCan>() as i64),
            ("ifreq", size_of::<libc::ifreq>() as i64),
            ("AF_CAN", AF_CAN as i64),
            ("CAN_RAW", CAN_RAW as i64),
            ("SOL_CAN_RAW", SOL_CAN_RAW as i64),
            ("CAN_RAW_ERR_FILTER", CAN_RAW_ERR_FILTER as i64),
            ("SIOCGIFINDEX", SIOCGIFINDEX as i64),
            ("CAN_EFF_FLAG", CAN_EFF_FLAG as i64),
            ("CAN_RTR_FLAG", CAN_RTR_FLAG as i64),
            ("CAN_ERR_FLAG", CAN_ERR_FLAG as i64),
            ("CAN_ERR_BUSOFF", CAN_ERR_BUSOFF as i64),
            ("IFNAMSIZ", IFNAMSIZ as i64),
        ];
        crate::c_probe::assert_matches(&c, rust);
    }

    #[test]
    fn constants_match_libc() {
        assert_eq!(AF_CAN, libc::AF_CAN);
        assert_eq!(CAN_RAW, libc::CAN_RAW);
        assert_eq!(SOL_CAN_RAW, libc::SOL_CAN_RAW);
        assert_eq!(CAN_RAW_ERR_FILTER, libc::CAN_RAW_ERR_FILTER);
        assert_eq!(SIOCGIFINDEX, libc::SIOCGIFINDEX as libc::c_ulong);
        assert_eq!(CAN_EFF_FLAG, libc::CAN_EFF_FLAG);
        assert_eq!(CAN_RTR_FLAG, libc::CAN_RTR_FLAG);
        assert_eq!(CAN_ERR_FLAG, libc::CAN_ERR_FLAG);
        assert_eq!(CAN_ERR_BUSOFF, libc::CAN_ERR_BUSOFF);
        assert_eq!(IFNAMSIZ, libc::IFNAMSIZ);
    }

    #[test]
    fn bad_interface_names_are_rejected_before_the_kernel() {
        // Any fd will do: the name check happens first. Use stdin's borrowed fd without owning it.
        let fd = io::stdin();
        let fd = std::os::fd::AsFd::as_fd(&fd);
        for bad in ["", "name-way-too-long0", "a\0b"] {
            assert_eq!(
                interface_index(fd, bad).unwrap_err().raw_os_error(),
                Some(libc::EINVAL),
                "{bad:?}"
            );
        }
    }
}
