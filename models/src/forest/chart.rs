//! A small grouped bar chart written as an RGB PNG (no plotting dependency): one panel per metric, one group per
//! salient point, one bar per method, labelled with a built-in 5x7 pixel font. Cost: a few ms per chart.

use anyhow::{Context, Result};
use std::path::Path;

/// One panel: a title, the value range's top, and per group (label) the values per series.
pub struct Panel {
    /// Title (upper case reads best with the built-in font).
    pub title: String,
    /// Axis maximum.
    pub max: f32,
    /// Groups: label and one value per series.
    pub groups: Vec<(String, Vec<f32>)>,
    /// Decimals of the value printed above each bar.
    pub decimals: usize,
}

/// Series colours, in order.
pub const COLORS: [[u8; 3]; 4] = [[200, 90, 60], [60, 120, 200], [90, 170, 90], [150, 90, 170]];

fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1E],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        '/' => [0, 0x01, 0x02, 0x04, 0x08, 0x10, 0],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        _ => [0; 7],
    }
}

/// An RGB raster with filled rectangles and the built-in font (shared by the evaluation charts).
pub struct Canvas {
    w: usize,
    h: usize,
    px: Vec<u8>,
}

impl Canvas {
    /// A white `w` x `h` canvas.
    pub fn new(w: usize, h: usize) -> Self {
        Canvas {
            w,
            h,
            px: vec![255; w * h * 3],
        }
    }

    /// Write the canvas as an RGB PNG.
    pub fn save(&self, path: &Path) -> Result<()> {
        let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), self.w as u32, self.h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.write_header()?.write_image_data(&self.px)?;
        Ok(())
    }

    /// Fill `[x0, x1) x [y0, y1)` with colour `c` (clipped to the canvas).
    pub fn rect(&mut self, x0: usize, y0: usize, x1: usize, y1: usize, c: [u8; 3]) {
        for y in y0.min(self.h)..y1.min(self.h) {
            for x in x0.min(self.w)..x1.min(self.w) {
                self.px[(y * self.w + x) * 3..(y * self.w + x) * 3 + 3].copy_from_slice(&c);
            }
        }
    }

    /// Text at (x, y) top-left, `s` pixels per font pixel.
    pub fn text(&mut self, x: usize, y: usize, t: &str, s: usize, c: [u8; 3]) {
        for (i, ch) in t.chars().enumerate() {
            let g = glyph(ch);
            for (r, bits) in g.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        let px = x + (i * 6 + col) * s;
                        let py = y + r * s;
                        self.rect(px, py, px + s, py + s, c);
                    }
                }
            }
        }
    }
}

/// Width in pixels of `t` at scale `s`.
pub fn text_w(t: &str, s: usize) -> usize {
    t.chars().count() * 6 * s
}

/// Draw `panels` side by side over `series` (legend names) into `path`.
pub fn bar_chart(path: &Path, title: &str, series: &[&str], panels: &[Panel]) -> Result<()> {
    let (pw, ph) = (640usize, 420usize);
    let top = 60;
    let (w, h) = (pw * panels.len().max(1), ph + top + 40);
    let mut c = Canvas::new(w, h);
    c.text(20, 12, title, 2, [0, 0, 0]);
    let mut lx = 20;
    for (i, s) in series.iter().enumerate() {
        c.rect(lx, 40, lx + 14, 54, COLORS[i % COLORS.len()]);
        c.text(lx + 20, 41, s, 2, [0, 0, 0]);
        lx += 20 + text_w(s, 2) + 30;
    }
    for (pi, p) in panels.iter().enumerate() {
        let ox = pi * pw;
        let (x0, y0, x1, y1) = (ox + 50, top + 40, ox + pw - 20, top + ph - 50);
        c.text(ox + 50, top + 10, &p.title, 2, [0, 0, 0]);
        c.rect(x0, y1, x1, y1 + 2, [0, 0, 0]);
        c.rect(x0, y0, x0 + 2, y1, [0, 0, 0]);
        for k in 0..=4 {
            let v = p.max * k as f32 / 4.0;
            let y = y1 - ((y1 - y0) as f32 * k as f32 / 4.0) as usize;
            c.rect(x0 - 4, y, x1, y + 1, [210, 210, 210]);
            let label = format!("{v:.*}", p.decimals.min(2));
            c.text(ox + 4, y.saturating_sub(3), &label, 1, [0, 0, 0]);
        }
        let groups = p.groups.len().max(1);
        let gw = (x1 - x0 - 10) / groups;
        for (gi, (label, vals)) in p.groups.iter().enumerate() {
            let gx = x0 + 10 + gi * gw;
            let bw = (gw - 12) / vals.len().max(1);
            for (si, &v) in vals.iter().enumerate() {
                let frac = (v / p.max).clamp(0.0, 1.0);
                let bh = ((y1 - y0) as f32 * frac) as usize;
                let bx = gx + si * bw;
                c.rect(bx, y1 - bh, bx + bw - 2, y1, COLORS[si % COLORS.len()]);
                let vt = format!("{v:.*}", p.decimals);
                let vx = bx + (bw.saturating_sub(text_w(&vt, 1))) / 2;
                c.text(vx, (y1 - bh).saturating_sub(10), &vt, 1, [40, 40, 40]);
            }
            let lw = text_w(label, 1);
            c.text(
                gx + (gw.saturating_sub(lw + 12)) / 2,
                y1 + 10,
                label,
                1,
                [0, 0, 0],
            );
        }
    }
    c.save(path)
}
