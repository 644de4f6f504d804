//! Depth-difference features f = d(x + u/d(x)) - d(x + v/d(x)) (Shotton et al. 2011) with offsets `u`, `v` in
//! pixel·metres (so ±50 means ±50 px at 1 m) and depths in integer millimetres. Off-image and no-depth probes read
//! [`BACKGROUND_MM`]. Everything is integer, so the trainer and the head computer take the same branch bit for bit.
//! The division by depth is done once per sample ([`ProbeScale`], 16.16 fixed point; with the sample's pixel in
//! [`ProbeOrigin`]); a test then costs four multiply-add-shifts and two depth reads.

use crate::depth::DepthFrame;

/// Depth a probe reads off the image or where there is no measurement (Shotton's "large positive constant").
pub const BACKGROUND_MM: i32 = 10_000;
/// Largest |offset| component in pixel·metres the model file can store.
pub const MAX_OFFSET: i32 = 127;

/// One split test: go left when `f(u, v) < threshold_mm`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct SplitTest {
    /// First probe offset (x, y), pixel·metres.
    pub u: [i8; 2],
    /// Second probe offset (x, y), pixel·metres.
    pub v: [i8; 2],
    /// Threshold in millimetres.
    pub threshold_mm: i16,
}

/// A depth image the features read: millimetres, 0 = no depth, anything outside reads 0.
pub trait DepthImage {
    /// Depth at pixel (x, y) in mm, 0 outside the image or without a measurement.
    fn depth_at(&self, x: i32, y: i32) -> u16;

    /// Read one pixel per cache line of rows `v0..v1` so that the random reads that follow hit the cache (a frame
    /// fresh from the sensor is cold, and a stride the prefetcher follows costs less than thousands of scattered
    /// misses). Changes no result; images without a row layout do nothing.
    #[inline]
    fn warm_rows(&self, v0: u16, v1: u16) {
        let _ = (v0, v1);
    }
}

impl DepthImage for DepthFrame<'_> {
    #[inline]
    fn depth_at(&self, x: i32, y: i32) -> u16 {
        self.at(x, y).unwrap_or(0)
    }

    fn warm_rows(&self, v0: u16, v1: u16) {
        /// Pixels per 64-byte cache line.
        const LINE: usize = 32;
        let w = self.width() as usize;
        let d = self.depth_mm();
        let rows = d
            .get(v0 as usize * w..(v1 as usize * w).min(d.len()))
            .unwrap_or(&[]);
        let sum = rows.iter().step_by(LINE).fold(0u16, |a, &z| a.wrapping_add(z));
        // The sum is not wanted, only the loads: keep the compiler from dropping them.
        core::hint::black_box(sum);
    }
}

/// Depths below this are read as this for scaling offsets (keeps the fixed-point products in i32).
pub const MIN_SCALE_DEPTH_MM: u16 = 100;

/// A sample's offset scale 1000 / depth in 16.16 fixed point (one division per sample).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProbeScale(i32);

impl ProbeScale {
    /// The scale of a sample of depth `d_mm`.
    #[inline]
    pub fn new(d_mm: u16) -> Self {
        let d = d_mm.max(MIN_SCALE_DEPTH_MM) as i32;
        ProbeScale(((1000 << 16) + d / 2) / d)
    }

    /// Offset `o` pixel·metres in pixels, rounded (halves up).
    #[inline]
    pub fn pixels(self, o: i8) -> i32 {
        (o as i32 * self.0 + (1 << 15)) >> 16
    }
}

/// A sample's pixel in 16.16 fixed point with the rounding half already added, and its offset scale: a probe's
/// pixel is then one multiply-add and a shift per axis, the same pixel as `x + s.pixels(o)` (the sample's whole
/// pixels pass through the shift unchanged, so the sum rounds as the offset alone does).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProbeOrigin {
    x: i32,
    y: i32,
    s: i32,
}

impl ProbeOrigin {
    /// The origin of probes from pixel (x, y) with scale `s` (|x|, |y| < 2^14).
    #[inline]
    pub fn new(x: i32, y: i32, s: ProbeScale) -> Self {
        ProbeOrigin {
            x: (x << 16) + (1 << 15),
            y: (y << 16) + (1 << 15),
            s: s.0,
        }
    }

    /// The pixel at offset `off`, pixel·metres.
    #[inline]
    pub fn pixel(self, off: [i8; 2]) -> (i32, i32) {
        (
            (self.x + off[0] as i32 * self.s) >> 16,
            (self.y + off[1] as i32 * self.s) >> 16,
        )
    }

    /// The depth the probe at offset `off` reads ([`probe`]'s value).
    #[inline]
    pub fn probe<D: DepthImage + ?Sized>(self, img: &D, off: [i8; 2]) -> i32 {
        let (x, y) = self.pixel(off);
        match img.depth_at(x, y) {
            0 => BACKGROUND_MM,
            z => z as i32,
        }
    }
}

/// The depth a probe at offset `off` from pixel (x, y) with scale `s` reads.
#[inline]
pub fn probe<D: DepthImage + ?Sized>(img: &D, x: i32, y: i32, s: ProbeScale, off: [i8; 2]) -> i32 {
    ProbeOrigin::new(x, y, s).probe(img, off)
}

impl SplitTest {
    /// The feature value at pixel (x, y) with offset scale `s`, millimetres.
    #[inline]
    pub fn feature<D: DepthImage + ?Sized>(&self, img: &D, x: i32, y: i32, s: ProbeScale) -> i32 {
        probe(img, x, y, s, self.u) - probe(img, x, y, s, self.v)
    }

    /// [`Self::goes_left`] from a probe origin.
    #[inline]
    pub fn goes_left_from<D: DepthImage + ?Sized>(&self, img: &D, o: ProbeOrigin) -> bool {
        o.probe(img, self.u) - o.probe(img, self.v) < self.threshold_mm as i32
    }

    /// Whether the sample goes to the left child.
    #[inline]
    pub fn goes_left<D: DepthImage + ?Sized>(&self, img: &D, x: i32, y: i32, s: ProbeScale) -> bool {
        self.feature(img, x, y, s) < self.threshold_mm as i32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::Timestamp;

    #[test]
    fn offsets_scale_with_depth_and_background_reads_large() {
        let mut buf = [0u16; 100 * 10];
        for (i, d) in buf.iter_mut().enumerate() {
            *d = 1000 + (i % 100) as u16;
        }
        let f = DepthFrame::new(&buf, 100, 10, Timestamp::default(), 0).unwrap();
        // At 2 m an offset of 40 px·m moves 20 px.
        let s2 = ProbeScale::new(2000);
        assert_eq!(probe(&f, 10, 5, s2, [40, 0]), 1030);
        assert_eq!(probe(&f, 10, 5, s2, [-40, 0]), BACKGROUND_MM);
        assert_eq!(ProbeScale::new(1500).pixels(50), 33);
        assert_eq!(ProbeScale::new(1500).pixels(-50), -33);
        assert_eq!(ProbeScale::new(1).pixels(127), 1270);
        let t = SplitTest {
            u: [20, 0],
            v: [0, 0],
            threshold_mm: 10,
        };
        assert_eq!(t.feature(&f, 50, 5, ProbeScale::new(1000)), 20);
        assert!(!t.goes_left(&f, 50, 5, ProbeScale::new(1000)));
    }

    #[test]
    fn a_probe_origin_reaches_the_pixel_the_offset_scale_gives() {
        // Every stored offset at depths from the scale's floor to beyond the sensor's range, from pixels at the
        // image's edges and inside: the fixed-point origin must land where `x + s.pixels(o)` does.
        for d in (0..=5000u16).step_by(7).chain([1, 99, 100, 101, 65535]) {
            let s = ProbeScale::new(d);
            for (x, y) in [(0, 0), (639, 479), (1, 478), (320, 240), (-3, 500)] {
                let o = ProbeOrigin::new(x, y, s);
                for a in -128..=127i8 {
                    let b = a.wrapping_mul(37);
                    assert_eq!(
                        o.pixel([a, b]),
                        (x + s.pixels(a), y + s.pixels(b)),
                        "depth {d}, pixel ({x}, {y}), offset ({a}, {b})"
                    );
                }
            }
        }
    }

    #[test]
    fn warming_rows_reads_nothing_outside_and_changes_nothing() {
        let buf: [u16; 100 * 10] = core::array::from_fn(|i| i as u16);
        let f = DepthFrame::new(&buf, 100, 10, Timestamp::default(), 0).unwrap();
        // In range, past the last row, reversed, empty: all harmless.
        for (v0, v1) in [(0, 10), (3, 7), (8, 400), (400, 500), (7, 3), (5, 5)] {
            f.warm_rows(v0, v1);
        }
        assert_eq!(f.depth_at(99, 9), 999);
        assert_eq!(f.depth_mm(), &buf[..]);
    }
}
