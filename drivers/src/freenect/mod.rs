//! Kinect v1 depth through libfreenect (feature `freenect`, Debian `libfreenect-dev`, links `-lfreenect`).
//!
//! Mode: `FREENECT_DEPTH_REGISTERED` at 640x480 (millimetres, 0 = no depth, aligned to the RGB camera, as libfreenect's
//! OpenNI2 driver delivers it). libfreenect detaches gspca_kinect by itself.
//!
//! # Threading and timing
//! One event thread pumps `freenect_process_events_timeout` (100 ms slices); the depth callback copies each frame into
//! a back buffer and signals. `next_frame` waits on a condvar for at most the timeout and swaps the back buffer with
//! the front buffer it lends (double buffering: a pointer swap, no copy, no allocation). Only the newest frame is kept;
//! a slow caller sees gaps in the index (the callback's sequence number). Timestamps are host `CLOCK_MONOTONIC` µs
//! since the device was opened, taken in the callback (the Kinect's own 32-bit tick counter wraps every ~70 s).

mod sys;

use std::time::Duration;

use supine_core::camera::Intrinsics;
use supine_core::depth::{DepthFrame, HEIGHT, PIXELS, WIDTH};

use crate::source::{DepthSource, SourceError, SourceErrorKind, capture_time};

/// The number of Kinects libfreenect sees.
pub fn device_count() -> Result<usize, SourceError> {
    sys::device_count().map_err(|e| SourceError::new(SourceErrorKind::Io, e))
}

/// A live Kinect through libfreenect.
pub struct FreenectSource {
    kinect: sys::Kinect,
    front: Vec<u16>,
    index: u32,
    failed: bool,
}

impl std::fmt::Debug for FreenectSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FreenectSource")
            .field("index", &self.index)
            .finish()
    }
}

impl FreenectSource {
    /// Open Kinect `index` (0 = first); [`SourceErrorKind::NoDevice`] when there is no such Kinect.
    pub fn open(index: u32) -> Result<Self, SourceError> {
        let kinect = sys::Kinect::open(index).map_err(|e| match e {
            sys::OpenError::NoDevice(0) => SourceError::new(
                SourceErrorKind::NoDevice,
                "no Kinect found by libfreenect (is it plugged in and powered, and may this user access it via udev?)",
            ),
            sys::OpenError::NoDevice(n) => SourceError::new(
                SourceErrorKind::NoDevice,
                format!("no Kinect at freenect index {index}: libfreenect sees {n} device(s)"),
            ),
            sys::OpenError::Failed(msg) => SourceError::new(SourceErrorKind::Io, format!("freenect:{index}: {msg}")),
        })?;
        Ok(FreenectSource {
            kinect,
            front: vec![0; PIXELS],
            index,
            failed: false,
        })
    }
}

impl DepthSource for FreenectSource {
    fn next_frame(&mut self, timeout: Duration) -> Result<DepthFrame<'_>, SourceError> {
        if self.failed {
            return Err(SourceError::new(
                SourceErrorKind::Disconnected,
                "the Kinect event loop stopped",
            ));
        }
        match self.kinect.wait_frame(&mut self.front, timeout) {
            sys::Wait::Frame(capture_us, sequence) => DepthFrame::new(
                &self.front,
                WIDTH as u16,
                HEIGHT as u16,
                capture_time(capture_us)?,
                sequence,
            )
            .map_err(|e| SourceError::new(SourceErrorKind::Other, e.to_string())),
            sys::Wait::Timeout => Err(SourceError::timeout()),
            sys::Wait::Failed(msg) => {
                self.failed = true;
                Err(SourceError::new(
                    SourceErrorKind::Disconnected,
                    format!("freenect:{}: {msg}", self.index),
                ))
            }
        }
    }

    fn intrinsics(&self) -> Intrinsics {
        // Registered depth is in the RGB camera's geometry; libfreenect's OpenNI2 driver reports 58.5° x 45.6°.
        Intrinsics::KINECT_V1
    }

    fn describe(&self) -> String {
        format!("freenect:{} (registered depth 640x480)", self.index)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Needs libfreenect and no Kinect attached.
    #[test]
    #[ignore = "needs libfreenect; run by tests/run.sh"]
    fn no_kinect_is_a_clear_no_device_error() {
        assert_eq!(
            device_count().unwrap(),
            0,
            "this test expects a machine without a Kinect"
        );
        let e = FreenectSource::open(0).unwrap_err();
        assert_eq!(e.kind(), SourceErrorKind::NoDevice);
        assert!(e.to_string().contains("no Kinect found"), "{e}");
        let e = FreenectSource::open(3).unwrap_err();
        assert_eq!(e.kind(), SourceErrorKind::NoDevice);
    }
}
