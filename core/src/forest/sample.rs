//! Seeded sampling of pixels from a clipped frame: what the tracker's clipping keeps (pixels with depth, inside a
//! pixel region and at least a margin above every given plane: the bed's surfaces) is what the forest sees, in
//! training and at run time alike. Cost: a depth read and one plane test per plane per try, at most
//! [`MAX_TRIES_PER_SAMPLE`] tries per sample.

use crate::camera::Intrinsics;
use crate::forest::feature::DepthImage;
use crate::geometry::{Plane, Point3};
use crate::rng::SplitMix64;

/// Tries per requested sample before sampling gives up (a frame with few kept pixels returns fewer samples).
pub const MAX_TRIES_PER_SAMPLE: usize = 16;

/// A pixel rectangle `[u0, u1) x [v0, v1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelRect {
    /// First column.
    pub u0: u16,
    /// First row.
    pub v0: u16,
    /// One past the last column.
    pub u1: u16,
    /// One past the last row.
    pub v1: u16,
}

/// The clip the caller gives: pixels inside `region`, with depth in `(0, max_depth_mm]`, at least `margin_m` above
/// every plane of `above` (camera frame, normals pointing up from the surface).
#[derive(Clone, Copy, Debug)]
pub struct Clip<'a> {
    /// Planes the point must lie above.
    pub above: &'a [Plane],
    /// Margin above the planes, metres.
    pub margin_m: f32,
    /// Pixel region.
    pub region: PixelRect,
    /// Farthest depth kept, mm.
    pub max_depth_mm: u16,
}

/// One sampled pixel.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct SamplePixel {
    /// Column.
    pub x: u16,
    /// Row.
    pub y: u16,
    /// Depth, mm (> 0).
    pub d_mm: u16,
    /// Back-projected position in the camera frame, metres.
    pub p: [f32; 3],
}

impl Clip<'_> {
    /// Whether pixel (x, y) at depth `d_mm` is kept; returns its camera-frame point when it is.
    #[inline]
    pub fn keep(&self, k: &Intrinsics, x: u16, y: u16, d_mm: u16) -> Option<Point3> {
        let (kept, p) = self.test(k, x, y, d_mm);
        kept.then_some(p)
    }

    /// [`Self::keep`] without branches: the verdict and the pixel's camera-frame point (meaningless when not kept).
    #[inline]
    fn test(&self, k: &Intrinsics, x: u16, y: u16, d_mm: u16) -> (bool, Point3) {
        let p = k.unproject(x as f32, y as f32, d_mm as f32 * 1e-3);
        let mut kept = (d_mm != 0) & (d_mm <= self.max_depth_mm);
        for pl in self.above {
            kept &= pl.signed_distance(&p) >= self.margin_m;
        }
        (kept, p)
    }
}

/// Draw up to `out.len()` kept pixels uniformly from the clip's region with a generator seeded by `seed`; returns
/// how many were drawn (fewer when the region keeps too few pixels; the entry after the last one drawn may be
/// overwritten). Duplicates are possible, as in Shotton et al.
pub fn sample_pixels<D: DepthImage + ?Sized>(
    img: &D,
    k: &Intrinsics,
    clip: &Clip<'_>,
    seed: u64,
    out: &mut [SamplePixel],
) -> usize {
    let r = clip.region;
    let u1 = r.u1.min(k.width);
    let v1 = r.v1.min(k.height);
    if r.u0 >= u1 || r.v0 >= v1 {
        return 0;
    }
    let (w, h) = ((u1 - r.u0) as u32, (v1 - r.v0) as u32);
    let mut rng = SplitMix64::new(seed);
    let mut n = 0;
    let mut tries = out.len() * MAX_TRIES_PER_SAMPLE;
    // Branch-free on the clip's verdict (a coin flip per try the predictor cannot learn): every try is written to
    // the next free slot and kept by advancing the count, so consecutive tries' random depth reads overlap.
    // The slot past the last kept sample may hold a rejected try.
    while n < out.len() && tries > 0 {
        tries -= 1;
        let x = r.u0 + rng.below(w as usize) as u16;
        let y = r.v0 + rng.below(h as usize) as u16;
        let d = img.depth_at(x as i32, y as i32);
        let (kept, p) = clip.test(k, x, y, d);
        out[n] = SamplePixel {
            x,
            y,
            d_mm: d,
            p: p.coords.into(),
        };
        n += usize::from(kept);
    }
    n
}
