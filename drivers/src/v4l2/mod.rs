//! Kinect v1 depth through the kernel's gspca_kinect driver (V4L2), with plain libc ioctls (no libv4l: its
//! conversion would turn `Y10B` into 8-bit RGB and drop bits).
//!
//! gspca_kinect must be loaded in depth mode (`modprobe gspca_kinect depth_mode=1`, before the Kinect binds); the node
//! then offers exactly one format, 640x480 `Y10B` at 30 fps. Flow: QUERYCAP, ENUM_FMT (look for `Y10B`), S_FMT,
//! REQBUFS (4 MMAP buffers), QUERYBUF + mmap, QBUF all, STREAMON; per frame poll, DQBUF, unpack + convert, QBUF.
//!
//! The 10-bit values are an **uncalibrated** disparity: they go through a [`DisparityTable`] built from a
//! [`DisparityCalibration`] (see [`crate::kinect_raw`] for the wall calibration procedure).
//!
//! # Timing and cost
//! `next_frame` polls the non-blocking fd for at most the timeout, dequeues the newest filled buffer (older ones are
//! requeued, so a slow caller sees gaps in the index rather than stale frames), unpacks 384000 bytes and looks up
//! 307200 table entries: about a millisecond, no allocation. Timestamps are the driver's (`CLOCK_MONOTONIC`, µs);
//! the index is the driver's sequence counter.

mod sys;

use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};
use std::time::Duration;

use supine_core::camera::Intrinsics;
use supine_core::depth::{DepthFrame, HEIGHT, PIXELS, WIDTH};

use crate::kinect_raw::{DisparityCalibration, DisparityTable, Y10B_FRAME_BYTES, unpack_y10b};
use crate::source::{DepthSource, SourceError, SourceErrorKind, capture_time};

/// Buffers requested from the driver.
const BUFFERS: u32 = 4;

/// A V4L2 capture node as `supine info` lists it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct V4l2DeviceInfo {
    /// Device node, e.g. `/dev/video0`.
    pub path: PathBuf,
    /// Driver name (`gspca_kinect` for a Kinect).
    pub driver: String,
    /// Card name.
    pub card: String,
    /// Whether the node offers `Y10B` capture (a Kinect in depth mode).
    pub offers_y10b: bool,
}

/// List `/dev/video*` capture nodes with their driver, card and whether they offer `Y10B`. Nodes that cannot be
/// opened are listed with the error in `driver`.
pub fn list_devices() -> Vec<V4l2DeviceInfo> {
    let mut paths: Vec<PathBuf> = match std::fs::read_dir("/dev") {
        Ok(dir) => dir
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("video"))
            })
            .collect(),
        Err(_) => Vec::new(),
    };
    paths.sort();
    paths
        .into_iter()
        .map(|path| match probe(&path) {
            Ok((driver, card, offers_y10b)) => V4l2DeviceInfo {
                path,
                driver,
                card,
                offers_y10b,
            },
            Err(e) => V4l2DeviceInfo {
                path,
                driver: format!("(cannot open: {e})"),
                card: String::new(),
                offers_y10b: false,
            },
        })
        .collect()
}

fn probe(path: &Path) -> std::io::Result<(String, String, bool)> {
    let fd = sys::open_device(path)?;
    let cap = sys::querycap(&fd)?;
    Ok((
        sys::c_field(&cap.driver),
        sys::c_field(&cap.card),
        offers_y10b(&fd)?,
    ))
}

fn offers_y10b(fd: &OwnedFd) -> std::io::Result<bool> {
    for index in 0..64 {
        match sys::enum_fmt(fd, index)? {
            Some(d) if d.pixelformat == sys::PIX_FMT_Y10BPACK => return Ok(true),
            Some(_) => {}
            None => break,
        }
    }
    Ok(false)
}

/// A live Kinect depth stream from a gspca_kinect V4L2 node.
pub struct V4l2Source {
    // Field order matters for drop: mappings go before the fd is closed.
    maps: Vec<sys::Mapping>,
    fd: OwnedFd,
    path: PathBuf,
    card: String,
    table: DisparityTable,
    depth: Vec<u16>,
    streaming: bool,
}

impl std::fmt::Debug for V4l2Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("V4l2Source")
            .field("path", &self.path)
            .field("card", &self.card)
            .finish()
    }
}

impl V4l2Source {
    /// Open `path`, check that it offers `Y10B` 640x480, map its buffers and start streaming.
    pub fn open(path: &Path, calibration: DisparityCalibration) -> Result<Self, SourceError> {
        let name = path.display().to_string();
        let io = |what: &str, e: std::io::Error| SourceError::io(format!("{name}: {what}"), e);
        let fd = sys::open_device(path).map_err(|e| io("opening the V4L2 device", e))?;
        let cap = sys::querycap(&fd).map_err(|e| io("VIDIOC_QUERYCAP (is it a V4L2 device?)", e))?;
        let caps = if cap.capabilities & sys::CAP_DEVICE_CAPS != 0 {
            cap.device_caps
        } else {
            cap.capabilities
        };
        let card = sys::c_field(&cap.card);
        if caps & sys::CAP_VIDEO_CAPTURE == 0 || caps & sys::CAP_STREAMING == 0 {
            return Err(SourceError::new(
                SourceErrorKind::Unsupported,
                format!("{name} ({card}) is not a streaming video capture device"),
            ));
        }
        if !offers_y10b(&fd).map_err(|e| io("VIDIOC_ENUM_FMT", e))? {
            return Err(SourceError::new(
                SourceErrorKind::Unsupported,
                format!(
                    "{name} ({}, {card}) offers no Y10B depth format: load gspca_kinect with depth_mode=1 \
                     (modprobe -r gspca_kinect; modprobe gspca_kinect depth_mode=1) and re-plug the Kinect",
                    sys::c_field(&cap.driver)
                ),
            ));
        }
        let mut fmt = sys::V4l2Format::capture(WIDTH as u32, HEIGHT as u32, sys::PIX_FMT_Y10BPACK);
        sys::s_fmt(&fd, &mut fmt).map_err(|e| io("VIDIOC_S_FMT Y10B 640x480", e))?;
        let pix = fmt.pix();
        if (pix.width, pix.height, pix.pixelformat) != (WIDTH as u32, HEIGHT as u32, sys::PIX_FMT_Y10BPACK)
            || (pix.bytesperline != 0 && pix.bytesperline != 800)
        {
            return Err(SourceError::new(
                SourceErrorKind::Unsupported,
                format!(
                    "{name}: driver chose {}x{} format {:#x} ({} bytes/line) instead of 640x480 Y10B",
                    pix.width, pix.height, pix.pixelformat, pix.bytesperline
                ),
            ));
        }
        let count = sys::reqbufs(&fd, BUFFERS).map_err(|e| io("VIDIOC_REQBUFS", e))?;
        if count == 0 {
            return Err(SourceError::new(
                SourceErrorKind::Io,
                format!("{name}: the driver granted no buffers"),
            ));
        }
        let mut maps = Vec::with_capacity(count as usize);
        for index in 0..count {
            let b = sys::querybuf(&fd, index).map_err(|e| io("VIDIOC_QUERYBUF", e))?;
            maps.push(sys::Mapping::new(&fd, b.length as usize, b.offset()).map_err(|e| io("mmap", e))?);
            sys::qbuf(&fd, index).map_err(|e| io("VIDIOC_QBUF", e))?;
        }
        sys::stream(&fd, true).map_err(|e| io("VIDIOC_STREAMON", e))?;
        tracing::info!("{name}: streaming Y10B 640x480 from {card} with {count} buffers");
        Ok(V4l2Source {
            maps,
            fd,
            path: path.to_owned(),
            card,
            table: DisparityTable::new(&calibration),
            depth: vec![0; PIXELS],
            streaming: true,
        })
    }

    fn map_err(&self, what: &'static str, e: std::io::Error) -> SourceError {
        match e.raw_os_error() {
            Some(libc::ENODEV) | Some(libc::EIO) | Some(libc::EPIPE) => SourceError::new(
                SourceErrorKind::Disconnected,
                format!("{}: {what}: device went away ({e})", self.path.display()),
            ),
            _ => SourceError::io(format!("{}: {what}", self.path.display()), e),
        }
    }
}

impl DepthSource for V4l2Source {
    fn next_frame(&mut self, timeout: Duration) -> Result<DepthFrame<'_>, SourceError> {
        if !sys::poll_readable(&self.fd, timeout).map_err(|e| self.map_err("poll", e))? {
            return Err(SourceError::timeout());
        }
        // Take the newest filled buffer; requeue older ones.
        let mut newest = match sys::dqbuf(&self.fd) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Err(SourceError::timeout()),
            Err(e) => return Err(self.map_err("VIDIOC_DQBUF", e)),
        };
        while let Ok(b) = sys::dqbuf(&self.fd) {
            sys::qbuf(&self.fd, newest.index).map_err(|e| self.map_err("VIDIOC_QBUF", e))?;
            newest = b;
        }
        let Some(map) = self.maps.get(newest.index as usize) else {
            // Give the buffer back anyway, or each such frame would leak one of the few streaming buffers.
            let _ = sys::qbuf(&self.fd, newest.index);
            return Err(SourceError::new(
                SourceErrorKind::CorruptData,
                "driver returned an unknown buffer index",
            ));
        };
        let used = newest.bytesused as usize;
        if used < Y10B_FRAME_BYTES {
            let _ = sys::qbuf(&self.fd, newest.index);
            return Err(SourceError::new(
                SourceErrorKind::CorruptData,
                format!(
                    "{}: short frame ({used} of {Y10B_FRAME_BYTES} bytes)",
                    self.path.display()
                ),
            ));
        }
        unpack_y10b(map.bytes(Y10B_FRAME_BYTES), &mut self.depth);
        self.table.convert_in_place(&mut self.depth);
        sys::qbuf(&self.fd, newest.index).map_err(|e| self.map_err("VIDIOC_QBUF", e))?;
        let ts = newest.timestamp;
        let capture_us = (ts.tv_sec.max(0) as u64) * 1_000_000 + ts.tv_usec.max(0) as u64;
        DepthFrame::new(
            &self.depth,
            WIDTH as u16,
            HEIGHT as u16,
            capture_time(capture_us)?,
            newest.sequence,
        )
        .map_err(|e| SourceError::new(SourceErrorKind::Other, e.to_string()))
    }

    fn intrinsics(&self) -> Intrinsics {
        Intrinsics::KINECT_V1
    }

    fn describe(&self) -> String {
        format!("v4l2:{} ({}, Y10B 640x480)", self.path.display(), self.card)
    }
}

impl Drop for V4l2Source {
    fn drop(&mut self) {
        if self.streaming
            && let Err(e) = sys::stream(&self.fd, false)
        {
            tracing::warn!("{}: VIDIOC_STREAMOFF failed: {e}", self.path.display());
        }
        self.maps.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_node_is_no_device() {
        let e = V4l2Source::open(
            Path::new("/dev/video-supine-missing"),
            DisparityCalibration::NOMINAL_10BIT,
        )
        .unwrap_err();
        assert_eq!(e.kind(), SourceErrorKind::NoDevice);
        assert!(e.to_string().contains("/dev/video-supine-missing"), "{e}");
    }

    #[test]
    fn a_non_v4l2_file_is_refused_clearly() {
        let e = V4l2Source::open(Path::new("/dev/null"), DisparityCalibration::NOMINAL_10BIT).unwrap_err();
        assert!(e.to_string().contains("QUERYCAP"), "{e}");
    }

    #[test]
    fn listing_never_fails() {
        // Whatever this machine has (usually nothing), every listed node is a /dev/video* path.
        for d in list_devices() {
            assert!(d.path.to_string_lossy().starts_with("/dev/video"), "{d:?}");
        }
    }
}
