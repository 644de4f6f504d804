//! The overlay picture of `supine demo --png FILE`: one frame's depth image (grey, near is bright, no data black)
//! with what the tracker made of it drawn over it: the fitted torso model's mesh (green), the six salient points
//! (red crosses), the probe tip (yellow) and its nearest point on the torso surface (cyan), joined by a line.
//!
//! Cost: one pass over the depth image and one over the torso mesh's triangles, on the one frame asked for; never
//! on the per-frame path of the service.

use std::io::Write;

use supine_core::geometry::Point3;

use crate::foxglove::FrameRecord;

/// An RGB picture, 8 bits per channel.
pub struct Picture {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

const TORSO: [u8; 3] = [40, 220, 90];
const SALIENT: [u8; 3] = [255, 40, 40];
const TIP: [u8; 3] = [255, 220, 0];
const SURFACE: [u8; 3] = [0, 220, 255];

impl Picture {
    fn set(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let i = (y as usize * self.width + x as usize) * 3;
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    fn line(&mut self, a: (f32, f32), b: (f32, f32), c: [u8; 3]) {
        let steps = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().clamp(1.0, 4096.0) as usize;
        for s in 0..=steps {
            let t = s as f32 / steps as f32;
            let (x, y) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            self.set(x.round() as i64, y.round() as i64, c);
        }
    }

    fn disc(&mut self, at: (f32, f32), r: i64, c: [u8; 3]) {
        let (cx, cy) = (at.0.round() as i64, at.1.round() as i64);
        for dy in -r..=r {
            for dx in -r..=r {
                if dx * dx + dy * dy <= r * r {
                    self.set(cx + dx, cy + dy, c);
                }
            }
        }
    }

    fn cross(&mut self, at: (f32, f32), r: f32, c: [u8; 3]) {
        for w in [-1.0, 0.0, 1.0] {
            self.line((at.0 - r, at.1 - r + w), (at.0 + r, at.1 + r + w), c);
            self.line((at.0 - r, at.1 + r + w), (at.0 + r, at.1 - r + w), c);
        }
    }

    /// Write as an 8-bit RGB PNG.
    pub fn write_png(&self, out: impl Write) -> Result<(), png::EncodingError> {
        let mut enc = png::Encoder::new(out, self.width as u32, self.height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header()?;
        w.write_image_data(&self.rgb)?;
        w.finish()
    }
}

/// Draw `record` (see the module docs).
pub fn render(record: &FrameRecord<'_>) -> Picture {
    let depth = record.depth.depth_mm();
    let (width, height) = (record.depth.width() as usize, record.depth.height() as usize);
    // Grey scale over the depths present (2nd to 98th percentile, so that a few far pixels do not wash it out).
    let mut valid: Vec<u16> = depth.iter().copied().filter(|&d| d > 0).collect();
    valid.sort_unstable();
    let pick = |p: f64| {
        valid
            .get(((valid.len().saturating_sub(1)) as f64 * p) as usize)
            .copied()
    };
    let (near, far) = match (pick(0.02), pick(0.98)) {
        (Some(a), Some(b)) if b > a => (a as f32, b as f32),
        _ => (500.0, 4500.0),
    };
    let mut rgb = Vec::with_capacity(width * height * 3);
    for &d in depth {
        let g = if d == 0 {
            0
        } else {
            (235.0 - 200.0 * ((d as f32 - near) / (far - near)).clamp(0.0, 1.0)) as u8
        };
        rgb.extend_from_slice(&[g, g, g]);
    }
    let mut pic = Picture { width, height, rgb };
    let k = record.intrinsics;
    let px = |p: &Point3| k.project(p).map(|q| (q.x, q.y));
    if let Some(t) = &record.torso {
        let v: Vec<Option<(f32, f32)>> = t
            .surface
            .vertices()
            .iter()
            .map(|p| px(&(t.camera_from_torso * p)))
            .collect();
        for i in 0..t.surface.triangle_count() {
            let [a, b, c] = t.surface.triangle(i);
            for (p, q) in [(a, b), (b, c), (c, a)] {
                if let (Some(Some(p)), Some(Some(q))) = (v.get(p), v.get(q)) {
                    pic.line(*p, *q, TORSO);
                }
            }
        }
    }
    if let Some(points) = record.salient {
        for p in points.iter().filter_map(px) {
            pic.cross(p, 6.0, SALIENT);
        }
    }
    if let Some(probe) = &record.probe {
        let tip = px(&probe.tip);
        let surface = probe.surface_point.as_ref().and_then(px);
        if let (Some(a), Some(b)) = (tip, surface) {
            pic.line(a, b, SURFACE);
        }
        if let Some(s) = surface {
            pic.disc(s, 3, SURFACE);
        }
        if let Some(t) = tip {
            pic.disc(t, 5, TIP);
        }
    }
    pic
}
