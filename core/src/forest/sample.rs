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

/// Margin above the bed planes the tracker's clip keeps (Kinect noise at 1.5 m is about 5 mm), metres.
pub const CLIP_MARGIN_M: f32 = 0.02;
/// Farthest depth the tracker's clip keeps, mm.
pub const CLIP_MAX_DEPTH_MM: u16 = 4000;

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

impl<'a> Clip<'a> {
    /// The tracker's clip: the whole image of `k`, above `planes` by [`CLIP_MARGIN_M`], up to [`CLIP_MAX_DEPTH_MM`].
    pub fn over_image(planes: &'a [Plane], k: &Intrinsics) -> Self {
        Clip {
            above: planes,
            margin_m: CLIP_MARGIN_M,
            region: PixelRect {
                u0: 0,
                v0: 0,
                u1: k.width,
                v1: k.height,
            },
            max_depth_mm: CLIP_MAX_DEPTH_MM,
        }
    }

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

/// A view of a depth image in which every pixel higher than a ceiling above all of `N` planes reads as no depth: the
/// robot arm's links above the patient, which the forest never saw in training (its crops held the arm only near the
/// patient), are taken out of both the sampled pixels and the feature probes. Cost: one multiply-add per plane and
/// depth read.
#[derive(Clone, Copy, Debug)]
pub struct Ceiling<'a, D: ?Sized, const N: usize> {
    img: &'a D,
    /// Per plane, `s = z (a x + b y + c) + e` is the pixel's height above the plane minus the ceiling, metres.
    coeffs: [[f32; 4]; N],
}

impl<'a, D: DepthImage + ?Sized, const N: usize> Ceiling<'a, D, N> {
    /// `img` with pixels more than `height_m` above every plane of `planes` (camera frame, normals up) read as 0.
    pub fn new(img: &'a D, k: &Intrinsics, planes: &[Plane; N], height_m: f32) -> Self {
        let coeffs = planes.map(|pl| {
            let [nx, ny, nz] = pl.normal;
            let (a, b) = (nx / k.fx, ny / k.fy);
            [a, b, nz - a * k.cx - b * k.cy, pl.d - height_m]
        });
        Ceiling { img, coeffs }
    }
}

impl<D: DepthImage + ?Sized, const N: usize> DepthImage for Ceiling<'_, D, N> {
    #[inline]
    fn depth_at(&self, x: i32, y: i32) -> u16 {
        let d = self.img.depth_at(x, y);
        let z = d as f32 * 1e-3;
        let (xf, yf) = (x as f32, y as f32);
        let mut low = N == 0;
        for [a, b, c, e] in self.coeffs {
            low |= z * (a * xf + b * yf + c) + e <= 0.0;
        }
        if low { d } else { 0 }
    }

    fn warm_rows(&self, v0: u16, v1: u16) {
        self.img.warm_rows(v0, v1)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Vector3;

    /// 1.5 m everywhere, a block at 1.0 m in the middle (the arm over the bed).
    struct Scene;

    impl DepthImage for Scene {
        fn depth_at(&self, x: i32, y: i32) -> u16 {
            if !(0..640).contains(&x) || !(0..480).contains(&y) {
                0
            } else if (300..340).contains(&x) && (200..240).contains(&y) {
                1000
            } else {
                1500
            }
        }
    }

    #[test]
    fn ceiling_hides_what_is_high_above_every_plane() {
        let k = Intrinsics::KINECT_V1;
        // A "mattress" facing the camera at 1.5 m: the block is 0.5 m above it, the background on it.
        let mattress = Plane::through(Vector3::new(0.0, 0.0, 1.5), Vector3::new(0.0, 0.0, -1.0));
        let img = Ceiling::new(&Scene, &k, &[mattress], 0.3);
        assert_eq!(img.depth_at(320, 220), 0, "the block is 0.5 m up: hidden");
        assert_eq!(img.depth_at(100, 100), 1500, "the mattress itself stays");
        assert_eq!(img.depth_at(-1, 5), 0, "off the image stays no depth");
        let high = Ceiling::new(&Scene, &k, &[mattress], 0.6);
        assert_eq!(
            high.depth_at(320, 220),
            1000,
            "below a 0.6 m ceiling the block stays"
        );
        // Kept when low over ANY plane: a second plane 0.1 m behind the block keeps it.
        let near = Plane::through(Vector3::new(0.0, 0.0, 1.1), Vector3::new(0.0, 0.0, -1.0));
        let either = Ceiling::new(&Scene, &k, &[mattress, near], 0.3);
        assert_eq!(either.depth_at(320, 220), 1000);
    }

    #[test]
    fn ceiling_agrees_with_the_planes_signed_distance() {
        let k = Intrinsics::KINECT_V1;
        let tilted = Plane::through(
            Vector3::new(0.1, 0.2, 1.6),
            Vector3::new(0.3, -0.8, -0.5).normalize(),
        );
        let h = 0.25;
        let img = Ceiling::new(&Scene, &k, &[tilted], h);
        let mut kept = [0u32; 2];
        for y in (0..480).step_by(7) {
            for x in (0..640).step_by(7) {
                let d = Scene.depth_at(x, y);
                let s = tilted.signed_distance(&k.unproject(x as f32, y as f32, d as f32 * 1e-3));
                if (s - h).abs() < 1e-4 {
                    continue; // on the ceiling within rounding
                }
                let want = if s <= h { d } else { 0 };
                assert_eq!(img.depth_at(x, y), want, "pixel ({x}, {y}) at {s} m");
                kept[usize::from(want != 0)] += 1;
            }
        }
        assert!(kept[0] > 100 && kept[1] > 100, "both verdicts occur: {kept:?}");
    }
}
