//! Training data of the joint forest: one dataset view as the trainer holds it ([`TrainImage`]: the stored crop's
//! depth and per-pixel class), the clip the tracker would apply (the view's ground-truth bed planes), and the
//! sampled pixels with their targets. One image costs its crop (~2 x w x h bytes) while it is held. The trainer
//! reads each view as the tracker reads its frames: with the height ceiling over the bed planes
//! ([`supine_core::forest::sample::Ceiling`]), so the arm's links high above the patient are no depth in
//! training as they are in the product.

use crate::dataset::ViewTruth;
use crate::dataset::format::ViewRecord;
use crate::render::noise::Rect;
use crate::render::{Label, NO_PART};
use supine_core::body_model::BodyPart;
use supine_core::camera::Intrinsics;
use supine_core::forest::feature::DepthImage;
use supine_core::forest::sample::{Ceiling, Clip, SamplePixel, sample_pixels};
use supine_core::geometry::Plane;
use supine_core::salient::SalientPoint;

/// Class of a body-part pixel: its part id; then these two.
pub const CLASS_ARM: u8 = BodyPart::COUNT as u8;
/// Anything kept by the clip that is neither body nor arm (bed frame, noise).
pub const CLASS_OTHER: u8 = BodyPart::COUNT as u8 + 1;
/// Number of classes the trees are grown for (17 parts, the arm, other).
pub const CLASSES: usize = BodyPart::COUNT + 2;

/// Checks a height ceiling given to the trainer or the evaluation (`--ceiling-m`), metres.
pub fn check_ceiling(ceiling_m: f32) -> anyhow::Result<()> {
    anyhow::ensure!(
        (0.0..=10.0).contains(&ceiling_m),
        "--ceiling-m must be in [0, 10] m"
    );
    Ok(())
}

/// A view's bed planes from its truth, camera frame: the mattress and the head section (what the clip keeps points
/// above).
pub fn view_planes(truth: &ViewTruth) -> [Plane; 2] {
    [truth.planes_camera[1], truth.planes_camera[2]]
}

/// One view's crop: depth (mm) and class per pixel; reads outside the crop give 0 (no depth), as in the full frame.
#[derive(Debug, Clone)]
pub struct TrainImage {
    /// Crop within the 640x480 image.
    pub crop: Rect,
    /// Depth of the crop, mm, row-major.
    pub depth: Vec<u16>,
    /// Class per crop pixel ([`CLASS_ARM`], [`CLASS_OTHER`] or a part id).
    pub class: Vec<u8>,
}

impl TrainImage {
    /// From a decoded view, read through the tracker's height ceiling of `ceiling_m` over the view's bed planes
    /// (0: the view as rendered).
    pub fn from_view(v: &ViewRecord, k: &Intrinsics, ceiling_m: f32) -> TrainImage {
        let class = v
            .label
            .iter()
            .zip(&v.part)
            .map(|(&l, &p)| match Label::from_u8(l) {
                Label::Body if p != NO_PART && (p as usize) < BodyPart::COUNT => p,
                Label::Occluder => CLASS_ARM,
                _ => CLASS_OTHER,
            })
            .collect();
        let mut img = TrainImage {
            crop: v.crop,
            depth: v.depth_mm.clone(),
            class,
        };
        if ceiling_m > 0.0 {
            let planes = view_planes(&v.truth);
            let ceiling = Ceiling::new(&img, k, &planes, ceiling_m);
            let (x0, y0, w) = (img.crop.x0 as i32, img.crop.y0 as i32, img.crop.w.max(1) as usize);
            let depth = (0..img.depth.len())
                .map(|i| ceiling.depth_at(x0 + (i % w) as i32, y0 + (i / w) as i32))
                .collect();
            img.depth = depth;
        }
        img
    }

    /// Class at full-image pixel (x, y).
    pub fn class_at(&self, x: u16, y: u16) -> u8 {
        let (cx, cy) = (x.wrapping_sub(self.crop.x0), y.wrapping_sub(self.crop.y0));
        if cx < self.crop.w && cy < self.crop.h {
            self.class[cy as usize * self.crop.w as usize + cx as usize]
        } else {
            CLASS_OTHER
        }
    }
}

impl DepthImage for TrainImage {
    #[inline]
    fn depth_at(&self, x: i32, y: i32) -> u16 {
        let cx = x - self.crop.x0 as i32;
        let cy = y - self.crop.y0 as i32;
        if cx < 0 || cy < 0 || cx >= self.crop.w as i32 || cy >= self.crop.h as i32 {
            return 0;
        }
        self.depth[cy as usize * self.crop.w as usize + cx as usize]
    }
}

/// What the trainer keeps of one training image once sampled.
#[derive(Debug, Clone)]
pub struct ImageInfo {
    /// Body index in the dataset.
    pub body: u32,
    /// View index.
    pub view: u16,
    /// Ground-truth salient points, camera frame, metres.
    pub targets: [[f32; 3]; SalientPoint::COUNT],
    /// Whether the robot arm is in view.
    pub has_arm: bool,
}

/// One sampled training pixel.
#[derive(Debug, Clone, Copy)]
pub struct TrainSample {
    /// Index of its image in the trainer's image list.
    pub image: u32,
    /// The pixel (position, depth, 3D point).
    pub px: SamplePixel,
    /// Its class.
    pub class: u8,
}

/// Sample `n` pixels of `img` as the tracker's clip keeps them (seeded), with their classes.
pub fn sample_image(
    img: &TrainImage,
    truth: &ViewTruth,
    k: &Intrinsics,
    n: usize,
    seed: u64,
    image: u32,
    out: &mut Vec<TrainSample>,
) {
    let planes = view_planes(truth);
    let clip = Clip::over_image(&planes, k);
    let mut buf = vec![SamplePixel::default(); n];
    let got = sample_pixels(img, k, &clip, seed, &mut buf);
    out.extend(buf[..got].iter().map(|px| TrainSample {
        image,
        px: *px,
        class: img.class_at(px.x, px.y),
    }));
}
