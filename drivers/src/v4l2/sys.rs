//! Raw V4L2: the structs, constants and ioctl numbers of `linux/videodev2.h` that the Kinect depth capture needs, and
//! thin safe wrappers (`ioctl`, `mmap`, `poll`) over them. All `unsafe` of the V4L2 backend lives here.
//!
//! Every item names its source in `/usr/include/linux/videodev2.h` (or `asm-generic/ioctl.h`); the test
//! `layouts_match_the_kernel_header` compiles a C probe against the installed header and compares every size,
//! offset and ioctl number. Layouts assume a 64-bit Linux target (x86-64, aarch64): `struct timeval` and the pointer
//! member of `v4l2_window` set the alignment of `v4l2_buffer` and `v4l2_format`.
#![allow(unsafe_code)]

use std::ffi::CString;
use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::Path;
use std::time::Duration;

// ---- asm-generic/ioctl.h: _IOC(dir, type, nr, size) = dir << 30 | size << 16 | type << 8 | nr ----
const IOC_NRSHIFT: u32 = 0; // _IOC_NRSHIFT
const IOC_TYPESHIFT: u32 = 8; // _IOC_TYPESHIFT = _IOC_NRSHIFT + _IOC_NRBITS(8)
const IOC_SIZESHIFT: u32 = 16; // _IOC_SIZESHIFT = _IOC_TYPESHIFT + _IOC_TYPEBITS(8)
const IOC_DIRSHIFT: u32 = 30; // _IOC_DIRSHIFT = _IOC_SIZESHIFT + _IOC_SIZEBITS(14)
const IOC_WRITE: u32 = 1; // _IOC_WRITE
const IOC_READ: u32 = 2; // _IOC_READ

const fn ioc(dir: u32, ty: u8, nr: u8, size: usize) -> u32 {
    (dir << IOC_DIRSHIFT)
        | ((size as u32) << IOC_SIZESHIFT)
        | ((ty as u32) << IOC_TYPESHIFT)
        | ((nr as u32) << IOC_NRSHIFT)
}
/// `_IOR(type, nr, T)`.
const fn ior<T>(ty: u8, nr: u8) -> u32 {
    ioc(IOC_READ, ty, nr, size_of::<T>())
}
/// `_IOW(type, nr, T)`.
const fn iow<T>(ty: u8, nr: u8) -> u32 {
    ioc(IOC_WRITE, ty, nr, size_of::<T>())
}
/// `_IOWR(type, nr, T)`.
const fn iowr<T>(ty: u8, nr: u8) -> u32 {
    ioc(IOC_READ | IOC_WRITE, ty, nr, size_of::<T>())
}

/// `VIDIOC_QUERYCAP _IOR('V', 0, struct v4l2_capability)`.
pub const VIDIOC_QUERYCAP: u32 = ior::<V4l2Capability>(b'V', 0);
/// `VIDIOC_ENUM_FMT _IOWR('V', 2, struct v4l2_fmtdesc)`.
pub const VIDIOC_ENUM_FMT: u32 = iowr::<V4l2FmtDesc>(b'V', 2);
/// `VIDIOC_G_FMT _IOWR('V', 4, struct v4l2_format)`.
#[allow(dead_code)] // checked by the layout test; S_FMT already returns the format
pub const VIDIOC_G_FMT: u32 = iowr::<V4l2Format>(b'V', 4);
/// `VIDIOC_S_FMT _IOWR('V', 5, struct v4l2_format)`.
pub const VIDIOC_S_FMT: u32 = iowr::<V4l2Format>(b'V', 5);
/// `VIDIOC_REQBUFS _IOWR('V', 8, struct v4l2_requestbuffers)`.
pub const VIDIOC_REQBUFS: u32 = iowr::<V4l2RequestBuffers>(b'V', 8);
/// `VIDIOC_QUERYBUF _IOWR('V', 9, struct v4l2_buffer)`.
pub const VIDIOC_QUERYBUF: u32 = iowr::<V4l2Buffer>(b'V', 9);
/// `VIDIOC_QBUF _IOWR('V', 15, struct v4l2_buffer)`.
pub const VIDIOC_QBUF: u32 = iowr::<V4l2Buffer>(b'V', 15);
/// `VIDIOC_DQBUF _IOWR('V', 17, struct v4l2_buffer)`.
pub const VIDIOC_DQBUF: u32 = iowr::<V4l2Buffer>(b'V', 17);
/// `VIDIOC_STREAMON _IOW('V', 18, int)`.
pub const VIDIOC_STREAMON: u32 = iow::<libc::c_int>(b'V', 18);
/// `VIDIOC_STREAMOFF _IOW('V', 19, int)`.
pub const VIDIOC_STREAMOFF: u32 = iow::<libc::c_int>(b'V', 19);

/// `V4L2_CAP_VIDEO_CAPTURE` (videodev2.h "Values for 'capabilities' field").
pub const CAP_VIDEO_CAPTURE: u32 = 0x0000_0001;
/// `V4L2_CAP_STREAMING`.
pub const CAP_STREAMING: u32 = 0x0400_0000;
/// `V4L2_CAP_DEVICE_CAPS`: `device_caps` is valid.
pub const CAP_DEVICE_CAPS: u32 = 0x8000_0000;
/// `V4L2_BUF_TYPE_VIDEO_CAPTURE` (enum v4l2_buf_type).
pub const BUF_TYPE_VIDEO_CAPTURE: u32 = 1;
/// `V4L2_MEMORY_MMAP` (enum v4l2_memory).
pub const MEMORY_MMAP: u32 = 1;
/// `V4L2_FIELD_NONE` (enum v4l2_field).
pub const FIELD_NONE: u32 = 1;

/// `v4l2_fourcc(a, b, c, d)`: `a | b << 8 | c << 16 | d << 24`.
pub const fn fourcc(code: &[u8; 4]) -> u32 {
    (code[0] as u32) | (code[1] as u32) << 8 | (code[2] as u32) << 16 | (code[3] as u32) << 24
}
/// `V4L2_PIX_FMT_Y10BPACK v4l2_fourcc('Y', '1', '0', 'B')`: 10-bit greyscale, bit-packed (gspca_kinect depth).
pub const PIX_FMT_Y10BPACK: u32 = fourcc(b"Y10B");

/// `struct v4l2_capability` (104 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct V4l2Capability {
    /// `__u8 driver[16]`.
    pub driver: [u8; 16],
    /// `__u8 card[32]`.
    pub card: [u8; 32],
    /// `__u8 bus_info[32]`.
    pub bus_info: [u8; 32],
    /// `__u32 version`.
    pub version: u32,
    /// `__u32 capabilities` (of the physical device).
    pub capabilities: u32,
    /// `__u32 device_caps` (of this node).
    pub device_caps: u32,
    /// `__u32 reserved[3]`.
    pub reserved: [u32; 3],
}

/// `struct v4l2_fmtdesc` (64 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct V4l2FmtDesc {
    /// `__u32 index`.
    pub index: u32,
    /// `__u32 type` (enum v4l2_buf_type).
    pub type_: u32,
    /// `__u32 flags`.
    pub flags: u32,
    /// `__u8 description[32]`.
    pub description: [u8; 32],
    /// `__u32 pixelformat`.
    pub pixelformat: u32,
    /// `__u32 mbus_code`.
    pub mbus_code: u32,
    /// `__u32 reserved[3]`.
    pub reserved: [u32; 3],
}

/// `struct v4l2_pix_format` (48 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct V4l2PixFormat {
    /// `__u32 width`.
    pub width: u32,
    /// `__u32 height`.
    pub height: u32,
    /// `__u32 pixelformat`.
    pub pixelformat: u32,
    /// `__u32 field` (enum v4l2_field).
    pub field: u32,
    /// `__u32 bytesperline`.
    pub bytesperline: u32,
    /// `__u32 sizeimage`.
    pub sizeimage: u32,
    /// `__u32 colorspace`.
    pub colorspace: u32,
    /// `__u32 priv`.
    pub priv_: u32,
    /// `__u32 flags`.
    pub flags: u32,
    /// `union { __u32 ycbcr_enc; __u32 hsv_enc; }`.
    pub ycbcr_enc: u32,
    /// `__u32 quantization`.
    pub quantization: u32,
    /// `__u32 xfer_func`.
    pub xfer_func: u32,
}

/// The `fmt` union of `struct v4l2_format`: 200 bytes, pointer-aligned (`struct v4l2_window` holds pointers).
#[repr(C)]
#[derive(Clone, Copy)]
pub union V4l2FormatUnion {
    /// `struct v4l2_pix_format pix`.
    pub pix: V4l2PixFormat,
    /// `__u8 raw_data[200]`.
    pub raw_data: [u8; 200],
    /// Alignment of the pointer members of `struct v4l2_window`.
    pub align: [usize; 0],
}

/// `struct v4l2_format` (208 bytes on 64-bit).
#[repr(C)]
#[derive(Clone, Copy)]
pub struct V4l2Format {
    /// `__u32 type` (enum v4l2_buf_type).
    pub type_: u32,
    /// `union fmt`.
    pub fmt: V4l2FormatUnion,
}

/// `struct v4l2_requestbuffers` (20 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct V4l2RequestBuffers {
    /// `__u32 count`.
    pub count: u32,
    /// `__u32 type`.
    pub type_: u32,
    /// `__u32 memory` (enum v4l2_memory).
    pub memory: u32,
    /// `__u32 capabilities`.
    pub capabilities: u32,
    /// `__u8 flags`.
    pub flags: u8,
    /// `__u8 reserved[3]`.
    pub reserved: [u8; 3],
}

/// `struct v4l2_timecode` (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct V4l2Timecode {
    /// `__u32 type`.
    pub type_: u32,
    /// `__u32 flags`.
    pub flags: u32,
    /// `__u8 frames`.
    pub frames: u8,
    /// `__u8 seconds`.
    pub seconds: u8,
    /// `__u8 minutes`.
    pub minutes: u8,
    /// `__u8 hours`.
    pub hours: u8,
    /// `__u8 userbits[4]`.
    pub userbits: [u8; 4],
}

/// The `m` union of `struct v4l2_buffer` (8 bytes on 64-bit).
#[repr(C)]
#[derive(Clone, Copy)]
pub union V4l2BufferM {
    /// `__u32 offset` (MMAP).
    pub offset: u32,
    /// `unsigned long userptr`.
    pub userptr: libc::c_ulong,
    /// `struct v4l2_plane *planes`.
    pub planes: *mut libc::c_void,
    /// `__s32 fd` (DMABUF).
    pub fd: i32,
}

/// `struct v4l2_buffer` (88 bytes on 64-bit).
#[repr(C)]
#[derive(Clone, Copy)]
pub struct V4l2Buffer {
    /// `__u32 index`.
    pub index: u32,
    /// `__u32 type`.
    pub type_: u32,
    /// `__u32 bytesused`.
    pub bytesused: u32,
    /// `__u32 flags`.
    pub flags: u32,
    /// `__u32 field`.
    pub field: u32,
    /// `struct timeval timestamp`.
    pub timestamp: libc::timeval,
    /// `struct v4l2_timecode timecode`.
    pub timecode: V4l2Timecode,
    /// `__u32 sequence`.
    pub sequence: u32,
    /// `__u32 memory`.
    pub memory: u32,
    /// `union m`.
    pub m: V4l2BufferM,
    /// `__u32 length`.
    pub length: u32,
    /// `__u32 reserved2`.
    pub reserved2: u32,
    /// `union { __s32 request_fd; __u32 reserved; }`.
    pub request_fd: i32,
}

impl V4l2Buffer {
    /// A zeroed MMAP capture buffer descriptor for `index`.
    pub fn mmap_capture(index: u32) -> Self {
        // SAFETY: V4l2Buffer is plain old data (integers, a timeval, a union of integers/pointers); all-zero is a
        // valid value of every field, and the kernel expects zeroed reserved fields.
        let mut b: V4l2Buffer = unsafe { std::mem::zeroed() };
        b.index = index;
        b.type_ = BUF_TYPE_VIDEO_CAPTURE;
        b.memory = MEMORY_MMAP;
        b
    }

    /// The mmap offset of an MMAP buffer.
    pub fn offset(&self) -> u32 {
        // SAFETY: every bit pattern is a valid u32; for MMAP buffers the kernel wrote `offset`.
        unsafe { self.m.offset }
    }
}

impl V4l2Format {
    /// A capture format request for `width` x `height` of `pixelformat`, progressive.
    pub fn capture(width: u32, height: u32, pixelformat: u32) -> Self {
        // SAFETY: plain old data; all-zero is valid for every member of the union and the struct.
        let mut f: V4l2Format = unsafe { std::mem::zeroed() };
        f.type_ = BUF_TYPE_VIDEO_CAPTURE;
        f.fmt.pix = V4l2PixFormat {
            width,
            height,
            pixelformat,
            field: FIELD_NONE,
            bytesperline: 0,
            sizeimage: 0,
            colorspace: 0,
            priv_: 0,
            flags: 0,
            ycbcr_enc: 0,
            quantization: 0,
            xfer_func: 0,
        };
        f
    }

    /// The pixel format member (what S_FMT/G_FMT use for single-planar capture).
    pub fn pix(&self) -> V4l2PixFormat {
        // SAFETY: `pix` is 48 bytes of u32 at the start of the 200-byte union; every bit pattern is valid.
        unsafe { self.fmt.pix }
    }
}

/// Open a V4L2 device node read-write, non-blocking (frames are waited for with [`poll_readable`]).
pub fn open_device(path: &Path) -> io::Result<OwnedFd> {
    use std::os::unix::ffi::OsStrExt;
    let c = CString::new(path.as_os_str().as_bytes())
        .map_err(|_| io::Error::from(io::ErrorKind::InvalidInput))?;
    // SAFETY: `c` is a valid NUL-terminated path; open has no other preconditions.
    let fd = unsafe { libc::open(c.as_ptr(), libc::O_RDWR | libc::O_NONBLOCK | libc::O_CLOEXEC) };
    if fd < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: `fd` was just returned by open and is owned by nobody else.
    Ok(unsafe { OwnedFd::from_raw_fd(fd) })
}

/// `ioctl(fd, request, arg)` for a request whose argument is `*mut T`, retrying on EINTR.
fn ioctl<T>(fd: &OwnedFd, request: u32, arg: &mut T) -> io::Result<()> {
    loop {
        // SAFETY: `arg` is a valid, exclusively borrowed `T`, and every caller pairs `request` with the `T` its
        // definition in videodev2.h names (the request encodes size_of::<T>(), checked by the layout test).
        let r = unsafe { libc::ioctl(fd.as_raw_fd(), request as _, arg as *mut T) };
        if r >= 0 {
            return Ok(());
        }
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}

/// `VIDIOC_QUERYCAP`.
pub fn querycap(fd: &OwnedFd) -> io::Result<V4l2Capability> {
    let mut cap = V4l2Capability {
        driver: [0; 16],
        card: [0; 32],
        bus_info: [0; 32],
        version: 0,
        capabilities: 0,
        device_caps: 0,
        reserved: [0; 3],
    };
    ioctl(fd, VIDIOC_QUERYCAP, &mut cap)?;
    Ok(cap)
}

/// `VIDIOC_ENUM_FMT` for capture format `index`; `Ok(None)` past the last one (EINVAL).
pub fn enum_fmt(fd: &OwnedFd, index: u32) -> io::Result<Option<V4l2FmtDesc>> {
    let mut d = V4l2FmtDesc {
        index,
        type_: BUF_TYPE_VIDEO_CAPTURE,
        flags: 0,
        description: [0; 32],
        pixelformat: 0,
        mbus_code: 0,
        reserved: [0; 3],
    };
    match ioctl(fd, VIDIOC_ENUM_FMT, &mut d) {
        Ok(()) => Ok(Some(d)),
        Err(e) if e.raw_os_error() == Some(libc::EINVAL) => Ok(None),
        Err(e) => Err(e),
    }
}

/// `VIDIOC_S_FMT`: the driver adjusts `fmt` to what it will deliver.
pub fn s_fmt(fd: &OwnedFd, fmt: &mut V4l2Format) -> io::Result<()> {
    ioctl(fd, VIDIOC_S_FMT, fmt)
}

/// `VIDIOC_REQBUFS` for `count` MMAP capture buffers; returns the count granted.
pub fn reqbufs(fd: &OwnedFd, count: u32) -> io::Result<u32> {
    let mut r = V4l2RequestBuffers {
        count,
        type_: BUF_TYPE_VIDEO_CAPTURE,
        memory: MEMORY_MMAP,
        ..Default::default()
    };
    ioctl(fd, VIDIOC_REQBUFS, &mut r)?;
    Ok(r.count)
}

/// `VIDIOC_QUERYBUF` for MMAP buffer `index`.
pub fn querybuf(fd: &OwnedFd, index: u32) -> io::Result<V4l2Buffer> {
    let mut b = V4l2Buffer::mmap_capture(index);
    ioctl(fd, VIDIOC_QUERYBUF, &mut b)?;
    Ok(b)
}

/// `VIDIOC_QBUF`: give MMAP buffer `index` to the driver.
pub fn qbuf(fd: &OwnedFd, index: u32) -> io::Result<()> {
    let mut b = V4l2Buffer::mmap_capture(index);
    ioctl(fd, VIDIOC_QBUF, &mut b)
}

/// `VIDIOC_DQBUF`: take a filled buffer (EAGAIN if none is ready on a non-blocking fd).
pub fn dqbuf(fd: &OwnedFd) -> io::Result<V4l2Buffer> {
    let mut b = V4l2Buffer::mmap_capture(0);
    ioctl(fd, VIDIOC_DQBUF, &mut b)?;
    Ok(b)
}

/// `VIDIOC_STREAMON` / `VIDIOC_STREAMOFF` for video capture.
pub fn stream(fd: &OwnedFd, on: bool) -> io::Result<()> {
    let mut ty: libc::c_int = BUF_TYPE_VIDEO_CAPTURE as libc::c_int;
    ioctl(fd, if on { VIDIOC_STREAMON } else { VIDIOC_STREAMOFF }, &mut ty)
}

/// Wait until `fd` is readable; `Ok(false)` on timeout.
pub fn poll_readable(fd: &OwnedFd, timeout: Duration) -> io::Result<bool> {
    let mut p = libc::pollfd {
        fd: fd.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    let ms = timeout.as_millis().min(i32::MAX as u128) as libc::c_int;
    loop {
        // SAFETY: `p` is one valid pollfd and we pass nfds = 1.
        let r = unsafe { libc::poll(&mut p, 1, ms) };
        if r > 0 {
            if p.revents & (libc::POLLERR | libc::POLLHUP | libc::POLLNVAL) != 0
                && p.revents & libc::POLLIN == 0
            {
                return Err(io::Error::from_raw_os_error(libc::ENODEV));
            }
            return Ok(true);
        }
        if r == 0 {
            return Ok(false);
        }
        let e = io::Error::last_os_error();
        if e.kind() != io::ErrorKind::Interrupted {
            return Err(e);
        }
    }
}

/// A read-only shared mapping of one driver buffer, unmapped on drop.
pub struct Mapping {
    ptr: *mut libc::c_void,
    len: usize,
}

impl Mapping {
    /// Map `len` bytes of the device at `offset` (from QUERYBUF).
    pub fn new(fd: &OwnedFd, len: usize, offset: u32) -> io::Result<Self> {
        // SAFETY: a fresh mapping chosen by the kernel (addr NULL) of a device fd; no existing memory is affected.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ,
                libc::MAP_SHARED,
                fd.as_raw_fd(),
                offset as libc::off_t,
            )
        };
        if ptr == libc::MAP_FAILED {
            return Err(io::Error::last_os_error());
        }
        Ok(Mapping { ptr, len })
    }

    /// The first `len` bytes of the mapping (clamped to its size).
    pub fn bytes(&self, len: usize) -> &[u8] {
        // SAFETY: `ptr` maps `self.len` readable bytes for the lifetime of `self`; we read at most that. The driver
        // only writes a buffer while it is queued, and callers read only dequeued buffers.
        unsafe { std::slice::from_raw_parts(self.ptr as *const u8, len.min(self.len)) }
    }
}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: `ptr`/`len` are exactly what mmap returned and nothing borrows the mapping any more.
        unsafe {
            libc::munmap(self.ptr, self.len);
        }
    }
}

// SAFETY: the mapping is plain memory owned by this value; moving it to another thread is fine.
unsafe impl Send for Mapping {}

/// A NUL-padded C string field as text.
pub fn c_field(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::offset_of;

    #[test]
    fn sizes_on_64_bit_linux() {
        assert_eq!(size_of::<V4l2Capability>(), 104);
        assert_eq!(size_of::<V4l2FmtDesc>(), 64);
        assert_eq!(size_of::<V4l2PixFormat>(), 48);
        assert_eq!(size_of::<V4l2RequestBuffers>(), 20);
        #[cfg(target_pointer_width = "64")]
        {
            assert_eq!(size_of::<V4l2Format>(), 208);
            assert_eq!(size_of::<V4l2Buffer>(), 88);
            assert_eq!(VIDIOC_QUERYCAP, 0x8068_5600);
            assert_eq!(VIDIOC_S_FMT, 0xC0D0_5605);
            assert_eq!(VIDIOC_DQBUF, 0xC058_5611);
        }
        assert_eq!(VIDIOC_STREAMON, 0x4004_5612);
        assert_eq!(PIX_FMT_Y10BPACK, 0x4230_3159);
    }

    /// Compiles a C probe against the installed `linux/videodev2.h` and compares every number; a missing compiler or
    /// header is a failure (every Rust toolchain links with `cc`, and the kernel headers come with libc6-dev).
    #[test]
    fn layouts_match_the_kernel_header() {
        let c = crate::c_probe::run(
            &crate::c_probe::Compiler {
                env_var: "CC",
                default: "cc",
            },
            &[],
            "probe.c",
            r#"#include <stdio.h>
#include <stddef.h>
#include <linux/videodev2.h>
#define P(name, v) printf("%s %lu\n", name, (unsigned long)(v))
int main(void) {
  P("cap", sizeof(struct v4l2_capability)); P("cap.device_caps", offsetof(struct v4l2_capability, device_caps));
  P("fmtdesc", sizeof(struct v4l2_fmtdesc)); P("fmtdesc.pixelformat", offsetof(struct v4l2_fmtdesc, pixelformat));
  P("pix", sizeof(struct v4l2_pix_format)); P("pix.sizeimage", offsetof(struct v4l2_pix_format, sizeimage));
  P("format", sizeof(struct v4l2_format)); P("format.fmt", offsetof(struct v4l2_format, fmt));
  P("reqbufs", sizeof(struct v4l2_requestbuffers));
  P("buffer", sizeof(struct v4l2_buffer)); P("buffer.timestamp", offsetof(struct v4l2_buffer, timestamp));
  P("buffer.sequence", offsetof(struct v4l2_buffer, sequence)); P("buffer.m", offsetof(struct v4l2_buffer, m));
  P("buffer.length", offsetof(struct v4l2_buffer, length));
  P("QUERYCAP", VIDIOC_QUERYCAP); P("ENUM_FMT", VIDIOC_ENUM_FMT); P("G_FMT", VIDIOC_G_FMT); P("S_FMT", VIDIOC_S_FMT);
  P("REQBUFS", VIDIOC_REQBUFS); P("QUERYBUF", VIDIOC_QUERYBUF); P("QBUF", VIDIOC_QBUF); P("DQBUF", VIDIOC_DQBUF);
  P("STREAMON", VIDIOC_STREAMON); P("STREAMOFF", VIDIOC_STREAMOFF);
  P("Y10B", V4L2_PIX_FMT_Y10BPACK); P("CAP_STREAMING", V4L2_CAP_STREAMING);
  P("CAP_DEVICE_CAPS", V4L2_CAP_DEVICE_CAPS); P("MEMORY_MMAP", V4L2_MEMORY_MMAP); P("FIELD_NONE", V4L2_FIELD_NONE);
  return 0;
}
"#,
        );
        let rust: &[(&str, i64)] = &[
            ("cap", size_of::<V4l2Capability>() as i64),
            ("cap.device_caps", offset_of!(V4l2Capability, device_caps) as i64),
            ("fmtdesc", size_of::<V4l2FmtDesc>() as i64),
            ("fmtdesc.pixelformat", offset_of!(V4l2FmtDesc, pixelformat) as i64),
            ("pix", size_of::<V4l2PixFormat>() as i64),
            ("pix.sizeimage", offset_of!(V4l2PixFormat, sizeimage) as i64),
            ("format", size_of::<V4l2Format>() as i64),
            ("format.fmt", offset_of!(V4l2Format, fmt) as i64),
            ("reqbufs", size_of::<V4l2RequestBuffers>() as i64),
            ("buffer", size_of::<V4l2Buffer>() as i64),
            ("buffer.timestamp", offset_of!(V4l2Buffer, timestamp) as i64),
            ("buffer.sequence", offset_of!(V4l2Buffer, sequence) as i64),
            ("buffer.m", offset_of!(V4l2Buffer, m) as i64),
            ("buffer.length", offset_of!(V4l2Buffer, length) as i64),
            ("QUERYCAP", VIDIOC_QUERYCAP as i64),
            ("ENUM_FMT", VIDIOC_ENUM_FMT as i64),
            ("G_FMT", VIDIOC_G_FMT as i64),
            ("S_FMT", VIDIOC_S_FMT as i64),
            ("REQBUFS", VIDIOC_REQBUFS as i64),
            ("QUERYBUF", VIDIOC_QUERYBUF as i64),
            ("QBUF", VIDIOC_QBUF as i64),
            ("DQBUF", VIDIOC_DQBUF as i64),
            ("STREAMON", VIDIOC_STREAMON as i64),
            ("STREAMOFF", VIDIOC_STREAMOFF as i64),
            ("Y10B", PIX_FMT_Y10BPACK as i64),
            ("CAP_STREAMING", CAP_STREAMING as i64),
            ("CAP_DEVICE_CAPS", CAP_DEVICE_CAPS as i64),
            ("MEMORY_MMAP", MEMORY_MMAP as i64),
            ("FIELD_NONE", FIELD_NONE as i64),
        ];
        crate::c_probe::assert_matches(&c, rust);
    }
}
