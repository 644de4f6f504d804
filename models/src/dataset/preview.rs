//! Preview images: depth colour-mapped (turbo-like ramp, near = red, far = blue, no depth = black) with the
//! ground-truth salient points drawn as coloured crosses and the probe tip as a white ring. For humans looking at
//! generated data; costs one pass over the image.

use super::format::ViewRecord;
use anyhow::{Context, Result};
use std::path::Path;

/// Cross colours of the salient points: head, left/right shoulder, belly, left/right hip.
pub const SALIENT_COLOURS: [[u8; 3]; 6] = [
    [255, 255, 255],
    [0, 255, 0],
    [0, 120, 255],
    [255, 255, 0],
    [255, 0, 255],
    [0, 255, 255],
];

/// Turbo-like colour of `t` in 0..1 (Google's polynomial approximation).
fn turbo(t: f32) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    let r = 0.1357 + t * (4.5974 - t * (42.3277 - t * (130.5887 - t * (150.5666 - t * 58.1375))));
    let g = 0.0914 + t * (2.1856 + t * (4.8052 - t * (14.0195 - t * (4.2109 + t * 2.7747))));
    let b = 0.1067 + t * (12.5925 - t * (60.1097 - t * (109.0745 - t * (88.5066 - t * 26.8183))));
    [r, g, b].map(|c| (c.clamp(0.0, 1.0) * 255.0) as u8)
}

/// Colour-map a full-size depth image (mm), near = warm. The ramp spans the patient (pixels labelled body, if
/// `label` is given: 100 mm in front to 250 mm behind), so body relief stays visible; without labels, the 2nd to
/// 98th percentile of valid pixels. No depth is black.
pub fn colour_depth(depth_mm: &[u16], label: Option<&[u8]>) -> Vec<u8> {
    let mut rgb = vec![0u8; depth_mm.len() * 3];
    let pick = |want_body: bool| -> Vec<u16> {
        depth_mm
            .iter()
            .enumerate()
            .filter(|&(i, &d)| {
                d > 0 && (!want_body || label.is_some_and(|l| l[i] == crate::render::Label::Body as u8))
            })
            .map(|(_, &d)| d)
            .collect()
    };
    let mut body = if label.is_some() { pick(true) } else { Vec::new() };
    let (lo, hi) = if body.len() > 100 {
        body.sort_unstable();
        (
            body[body.len() / 50] as f32 - 100.0,
            body[body.len() * 49 / 50] as f32 + 250.0,
        )
    } else {
        let mut valid = pick(false);
        if valid.is_empty() {
            return rgb;
        }
        valid.sort_unstable();
        (
            valid[valid.len() / 50] as f32,
            valid[valid.len() * 49 / 50] as f32,
        )
    };
    let hi = hi.max(lo + 1.0);
    for (px, &d) in rgb.chunks_exact_mut(3).zip(depth_mm) {
        if d > 0 {
            // Beyond the ramp's far end stays dark blue (turbo 0.08), distinct from black "no depth".
            px.copy_from_slice(&turbo((1.0 - (d as f32 - lo) / (hi - lo)).max(0.08)));
        }
    }
    rgb
}

/// Draw a cross of `colour` with a black outline at (u, v).
pub fn draw_cross(rgb: &mut [u8], width: usize, height: usize, u: f32, v: f32, colour: [u8; 3]) {
    if !(u.is_finite() && v.is_finite()) {
        return;
    }
    let (cu, cv) = (u.round() as i64, v.round() as i64);
    let mut put = |x: i64, y: i64, c: [u8; 3]| {
        if x >= 0 && y >= 0 && (x as usize) < width && (y as usize) < height {
            let i = (y as usize * width + x as usize) * 3;
            rgb[i..i + 3].copy_from_slice(&c);
        }
    };
    // A 3-px black bar under a 1-px coloured bar, both ways, so the cross reads on any colour.
    for d in -6i64..=6 {
        for o in -1i64..=1 {
            put(cu + d, cv + o, [0, 0, 0]);
            put(cu + o, cv + d, [0, 0, 0]);
        }
    }
    for d in -5i64..=5 {
        put(cu + d, cv, colour);
        put(cu, cv + d, colour);
    }
}

/// Draw a ring of radius `r` px.
pub fn draw_ring(rgb: &mut [u8], width: usize, height: usize, u: f32, v: f32, r: f32, colour: [u8; 3]) {
    for k in 0..96 {
        let a = k as f32 * std::f32::consts::TAU / 96.0;
        for (rr, c) in [(r + 1.0, [0, 0, 0]), (r, colour), (r - 1.0, [0, 0, 0])] {
            let (x, y) = (
                (u + rr * a.cos()).round() as i64,
                (v + rr * a.sin()).round() as i64,
            );
            if x >= 0 && y >= 0 && (x as usize) < width && (y as usize) < height {
                let i = (y as usize * width + x as usize) * 3;
                rgb[i..i + 3].copy_from_slice(&c);
            }
        }
    }
}

/// Full-size RGB preview of a dataset view: depth colour-mapped, salient points and probe tip drawn.
pub fn render_view(rec: &ViewRecord, width: usize, height: usize) -> Vec<u8> {
    let depth = rec.full_depth(width, height);
    let mut rgb = colour_depth(&depth, Some(&rec.full_label(width, height)));
    draw_truth(
        &mut rgb,
        width,
        height,
        &rec.truth.salient_pixels,
        rec.truth.probe.as_ref().map(|p| p.camera_from_probe),
    );
    rgb
}

/// Draw salient points (pixels) and, if given, the probe tip (camera frame pose) with Kinect intrinsics.
pub fn draw_truth(
    rgb: &mut [u8],
    width: usize,
    height: usize,
    salient_px: &[[f32; 2]; 6],
    camera_from_probe: Option<[[f32; 4]; 4]>,
) {
    for (p, c) in salient_px.iter().zip(SALIENT_COLOURS) {
        draw_cross(rgb, width, height, p[0], p[1], c);
    }
    if let Some(m) = camera_from_probe
        && let Some(uv) = supine_core::camera::Intrinsics::KINECT_V1
            .project(&supine_core::geometry::Point3::new(m[0][3], m[1][3], m[2][3]))
    {
        draw_ring(rgb, width, height, uv[0], uv[1], 7.0, [255, 255, 255]);
    }
}

/// Write an 8-bit RGB PNG.
pub fn write_rgb_png(path: &Path, rgb: &[u8], width: usize, height: usize) -> Result<()> {
    let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width as u32, height as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header()?;
    w.write_image_data(rgb)?;
    w.finish()?;
    Ok(())
}
