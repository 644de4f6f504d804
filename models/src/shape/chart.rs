//! Fig. 5-style bar charts as PNGs (no text: the report's table carries the numbers). Groups along x, one bar per
//! method in each: subspace blue, fitting orange, combined green; a grey grid line every 0.1 (coefficients) or
//! 2 mm (vertex error).

use anyhow::Result;
use std::path::Path;

use crate::dataset::preview::write_rgb_png;

/// Method colours: subspace, fitting, combined.
pub const COLOURS: [[u8; 3]; 3] = [[40, 100, 200], [230, 130, 30], [40, 160, 60]];

/// Draw `groups[g][m]` (non-negative) as grouped bars scaled to `max`, grid every `grid`, into `path`.
pub fn bar_chart(path: &Path, groups: &[Vec<f64>], max: f64, grid: f64) -> Result<()> {
    let (gw, bw, h, pad) = (60usize, 16usize, 300usize, 20usize);
    let w = pad * 2 + groups.len() * gw;
    let mut rgb = vec![255u8; w * h * 3];
    let y_of = |v: f64| (h - pad) as f64 - (v / max).clamp(0.0, 1.0) * (h - 2 * pad) as f64;
    let mut g = 0.0;
    while g <= max + 1e-9 {
        let y = y_of(g) as usize;
        for x in pad..w - pad {
            rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[200, 200, 200]);
        }
        g += grid;
    }
    for (gi, bars) in groups.iter().enumerate() {
        for (m, &v) in bars.iter().enumerate() {
            let x0 = pad + gi * gw + 6 + m * bw;
            let top = y_of(v) as usize;
            for y in top..h - pad {
                for x in x0..x0 + bw - 2 {
                    rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&COLOURS[m % 3]);
                }
            }
        }
    }
    write_rgb_png(path, &rgb, w, h)
}

/// Write canonical images side by side as a greyscale PNG (paper Fig. 3): each image scaled to its own value
/// range (eigen-images are signed), unseen pixels black, every pixel drawn `zoom` x `zoom`.
pub fn image_strip(path: &Path, images: &[Vec<f32>], width: usize, height: usize, zoom: usize) -> Result<()> {
    let (tw, th) = (width * zoom, height * zoom);
    let w = images.len() * (tw + 4);
    let mut rgb = vec![255u8; w * th * 3];
    for (n, im) in images.iter().enumerate() {
        let vis: Vec<f32> = im.iter().copied().filter(|x| x.is_finite()).collect();
        let lo = vis.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = vis.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        for y in 0..th {
            for x in 0..tw {
                let v = im[(y / zoom) * width + x / zoom];
                let g = if v.is_finite() {
                    (40.0 + 215.0 * (v - lo) / (hi - lo).max(1e-9)) as u8
                } else {
                    0
                };
                let o = (y * w + n * (tw + 4) + x) * 3;
                rgb[o..o + 3].copy_from_slice(&[g, g, g]);
            }
        }
    }
    write_rgb_png(path, &rgb, w, th)
}
