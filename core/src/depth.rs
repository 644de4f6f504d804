//! A borrowed depth frame: what every depth source lends the pipeline, once per sensor frame.
//!
//! Depth is `u16` millimetres along the optical axis, row-major, 0 = no measurement (the OpenNI convention).
//! Constructing a frame checks the buffer length once; reading it costs nothing more.

/// Kinect v1 depth image width in pixels.
pub const WIDTH: usize = 640;
/// Kinect v1 depth image height in pixels.
pub const HEIGHT: usize = 480;
/// Pixels in one Kinect v1 depth image.
pub const PIXELS: usize = WIDTH * HEIGHT;
/// The depth value that marks a pixel without a measurement.
pub const NO_DEPTH: u16 = 0;

use crate::normal_memo::NormalMemo;
use crate::time::Timestamp;

/// A depth image lent by a source, with its capture time and index.
#[derive(Debug, Clone, Copy)]
pub struct DepthFrame<'a> {
    depth_mm: &'a [u16],
    width: u16,
    height: u16,
    /// Capture time of the frame on the source's clock (sensor or recording timestamp).
    pub capture: Timestamp,
    /// Frame index as counted by the source (starts at whatever the source reports; gaps mean dropped frames).
    pub index: u32,
    /// The memo of this frame's observed normals, when the caller lent one ([`DepthFrame::with_normal_memo`]).
    normals: Option<NormalMemo<'a>>,
}

/// Why a buffer cannot be viewed as a depth frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum FrameError {
    /// The buffer does not hold `width * height` pixels.
    WrongLength {
        /// Pixels expected (`width * height`).
        expected: usize,
        /// Pixels in the buffer.
        actual: usize,
    },
    /// Width or height is zero.
    Empty,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FrameError::WrongLength { expected, actual } => {
                write!(f, "depth buffer holds {actual} pixels, expected {expected}")
            }
            FrameError::Empty => f.write_str("depth frame has zero width or height"),
        }
    }
}

impl<'a> DepthFrame<'a> {
    /// View `depth_mm` as a `width` x `height` frame; fails if the length does not match.
    pub fn new(
        depth_mm: &'a [u16],
        width: u16,
        height: u16,
        capture: Timestamp,
        index: u32,
    ) -> Result<Self, FrameError> {
        let expected = width as usize * height as usize;
        if expected == 0 {
            return Err(FrameError::Empty);
        }
        if depth_mm.len() != expected {
            return Err(FrameError::WrongLength {
                expected,
                actual: depth_mm.len(),
            });
        }
        Ok(DepthFrame {
            depth_mm,
            width,
            height,
            capture,
            index,
            normals: None,
        })
    }

    /// This frame with `memo` for its observed normals: ICP's association then computes each pixel's normal once
    /// however many fits read it ([`crate::normal_memo`]). `memo` must be fresh for this frame
    /// ([`crate::normal_memo::MemoStamp::next`]) and serve its size; one that does not is ignored.
    pub fn with_normal_memo<'b>(&self, memo: NormalMemo<'b>) -> DepthFrame<'b>
    where
        'a: 'b,
    {
        DepthFrame {
            normals: memo.fits(self.width, self.height).then_some(memo),
            ..*self
        }
    }

    /// The memo of this frame's observed normals, if one was lent.
    pub fn normal_memo(&self) -> Option<&NormalMemo<'a>> {
        self.normals.as_ref()
    }

    /// The pixels, row-major, millimetres, 0 = no depth.
    pub fn depth_mm(&self) -> &'a [u16] {
        self.depth_mm
    }

    /// Width in pixels.
    pub fn width(&self) -> u16 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u16 {
        self.height
    }

    /// Depth at pixel (u, v) in millimetres, `None` outside the image; 0 means no measurement.
    #[inline]
    pub fn at(&self, u: i32, v: i32) -> Option<u16> {
        // Negative coordinates wrap to large unsigned ones: one compare per axis (the forest reads two per node).
        if u as u32 >= self.width as u32 || v as u32 >= self.height as u32 {
            return None;
        }
        self.depth_mm
            .get(v as usize * self.width as usize + u as usize)
            .copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn length_is_checked() {
        let buf = [0u16; 12];
        assert!(DepthFrame::new(&buf, 4, 3, Timestamp::default(), 0).is_ok());
        assert_eq!(
            DepthFrame::new(&buf, 4, 4, Timestamp::default(), 0).unwrap_err(),
            FrameError::WrongLength {
                expected: 16,
                actual: 12
            }
        );
        assert_eq!(
            DepthFrame::new(&buf[..0], 0, 3, Timestamp::default(), 0).unwrap_err(),
            FrameError::Empty
        );
    }

    #[test]
    fn pixel_access_is_bounds_checked() {
        let mut buf = [0u16; 12];
        buf[2 * 4 + 3] = 1234;
        let f = DepthFrame::new(&buf, 4, 3, Timestamp::from_us(7).unwrap(), 1).unwrap();
        assert_eq!(f.at(3, 2), Some(1234));
        assert_eq!(f.at(4, 2), None);
        assert_eq!(f.at(-1, 0), None);
    }
}
