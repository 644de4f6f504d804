//! The report's PNG: six panels of bars, real (orange) beside synthetic (blue): hole lengths inside smooth surfaces,
//! hole lengths at jumps (near side right, near side left), invalid share versus incidence angle and versus depth,
//! and the judged statistics as synthetic/real ratios (1 = equal; the grey band is ±25 %). Titles and bin labels
//! are drawn with a 3x5 pixel font, scaled 2x.
//!
//! Cost: one 960x640 RGB image.

use super::Report;
use super::stats::{ANGLE_BINS_DEG, DEPTH_BINS_MM};
use anyhow::Result;
use std::path::Path;

const W: usize = 960;
const H: usize = 640;
const REAL: [u8; 3] = [230, 120, 20];
const SYNTH: [u8; 3] = [40, 110, 220];
const INK: [u8; 3] = [20, 20, 20];

/// Hole-length groups of the histograms: inclusive `[lo, hi]` pixels.
const GROUPS: [(usize, usize, &str); 8] = [
    (1, 1, "1"),
    (2, 2, "2"),
    (3, 4, "3-4"),
    (5, 8, "5-8"),
    (9, 12, "9-12"),
    (13, 16, "13-16"),
    (17, 32, "17-32"),
    (33, 64, "33+"),
];

struct Canvas {
    px: Vec<u8>,
}

impl Canvas {
    fn rect(&mut self, x0: usize, y0: usize, x1: usize, y1: usize, c: [u8; 3]) {
        for y in y0.min(H)..y1.min(H) {
            for x in x0.min(W)..x1.min(W) {
                self.px[(y * W + x) * 3..(y * W + x) * 3 + 3].copy_from_slice(&c);
            }
        }
    }

    /// Text in the 3x5 font at scale 2 (unknown characters are blank).
    fn text(&mut self, x: usize, y: usize, s: &str) {
        let mut cx = x;
        for ch in s.chars() {
            let g = glyph(ch.to_ascii_uppercase());
            for row in 0..5 {
                for col in 0..3 {
                    if g >> (14 - (row * 3 + col)) & 1 == 1 {
                        self.rect(cx + col * 2, y + row * 2, cx + col * 2 + 2, y + row * 2 + 2, INK);
                    }
                }
            }
            cx += 8;
        }
    }

    /// A bar panel: `values[i] = (real, synthetic)` in 0..=`max`, labelled by `labels`.
    fn panel(
        &mut self,
        ox: usize,
        oy: usize,
        title: &str,
        labels: &[String],
        values: &[(f64, f64)],
        max: f64,
    ) {
        let (pw, ph) = (300usize, 240usize);
        self.text(ox, oy, title);
        let (bx, by, bh) = (ox, oy + 22, ph - 60);
        self.rect(bx, by + bh, bx + pw, by + bh + 1, INK);
        let slot = pw / values.len().max(1);
        for (i, &(r, s)) in values.iter().enumerate() {
            let x = bx + i * slot;
            let bar = |v: f64| ((v / max).clamp(0.0, 1.0) * bh as f64) as usize;
            let bw = (slot.saturating_sub(4)) / 2;
            self.rect(x + 1, by + bh - bar(r), x + 1 + bw, by + bh, REAL);
            self.rect(x + 1 + bw, by + bh - bar(s), x + 1 + 2 * bw, by + bh, SYNTH);
            if let Some(l) = labels.get(i) {
                self.text(x, by + bh + 6 + 14 * (i % 2), l);
            }
        }
        self.text(ox, by + bh + 36, &format!("MAX {max:.2}"));
    }
}

/// 3x5 glyphs, 15 bits row-major from the top-left.
fn glyph(c: char) -> u16 {
    match c {
        '0' => 0b111_101_101_101_111,
        '1' => 0b010_110_010_010_111,
        '2' => 0b111_001_111_100_111,
        '3' => 0b111_001_111_001_111,
        '4' => 0b101_101_111_001_001,
        '5' => 0b111_100_111_001_111,
        '6' => 0b111_100_111_101_111,
        '7' => 0b111_001_010_010_010,
        '8' => 0b111_101_111_101_111,
        '9' => 0b111_101_111_001_111,
        'A' => 0b010_101_111_101_101,
        'B' => 0b110_101_110_101_110,
        'C' => 0b011_100_100_100_011,
        'D' => 0b110_101_101_101_110,
        'E' => 0b111_100_110_100_111,
        'F' => 0b111_100_110_100_100,
        'G' => 0b011_100_101_101_011,
        'H' => 0b101_101_111_101_101,
        'I' => 0b111_010_010_010_111,
        'J' => 0b001_001_001_101_010,
        'K' => 0b101_101_110_101_101,
        'L' => 0b100_100_100_100_111,
        'M' => 0b101_111_111_101_101,
        'N' => 0b110_101_101_101_101,
        'O' => 0b010_101_101_101_010,
        'P' => 0b110_101_110_100_100,
        'Q' => 0b010_101_101_110_011,
        'R' => 0b110_101_110_101_101,
        'S' => 0b011_100_010_001_110,
        'T' => 0b111_010_010_010_010,
        'U' => 0b101_101_101_101_111,
        'V' => 0b101_101_101_101_010,
        'W' => 0b101_101_111_111_101,
        'X' => 0b101_101_010_101_101,
        'Y' => 0b101_101_010_010_010,
        'Z' => 0b111_001_010_100_111,
        '-' => 0b000_000_111_000_000,
        '+' => 0b000_010_111_010_000,
        '.' => 0b000_000_000_000_010,
        '/' => 0b001_001_010_100_100,
        ':' => 0b000_010_000_010_000,
        '%' => 0b101_001_010_100_101,
        '(' => 0b010_100_100_100_010,
        ')' => 0b010_001_001_001_010,
        '=' => 0b000_111_000_111_000,
        _ => 0,
    }
}

/// Normalise a length histogram into the shares of [`GROUPS`].
fn grouped(hist: &[u64]) -> Vec<f64> {
    let total = hist.iter().sum::<u64>().max(1) as f64;
    GROUPS
        .iter()
        .map(|&(lo, hi, _)| hist[lo - 1..hi.min(hist.len())].iter().sum::<u64>() as f64 / total)
        .collect()
}

/// Draw the report's PNG.
pub fn write_png(report: &Report, path: &Path) -> Result<()> {
    let mut c = Canvas {
        px: vec![255; W * H * 3],
    };
    let labels: Vec<String> = GROUPS.iter().map(|g| g.2.to_string()).collect();
    let pair = |a: Vec<f64>, b: Vec<f64>| a.into_iter().zip(b).collect::<Vec<_>>();
    let (r, s) = (&report.real.counts, &report.synthetic.counts);
    let hists = [
        ("SMOOTH HOLES: LENGTH PX", &r.smooth_holes, &s.smooth_holes),
        (
            "JUMP HOLES NEAR RIGHT",
            &r.edge_holes_near_right,
            &s.edge_holes_near_right,
        ),
        (
            "JUMP HOLES NEAR LEFT",
            &r.edge_holes_near_left,
            &s.edge_holes_near_left,
        ),
    ];
    for (i, (title, a, b)) in hists.iter().enumerate() {
        let v = pair(grouped(a), grouped(b));
        let max = v.iter().map(|p| p.0.max(p.1)).fold(0.05, f64::max);
        c.panel(10 + 320 * i, 10, title, &labels, &v, max);
    }
    let frac = |v: &[Option<f64>]| v.iter().map(|x| x.unwrap_or(0.0)).collect::<Vec<_>>();
    let a = pair(
        frac(&report.real.invalid_by_angle),
        frac(&report.synthetic.invalid_by_angle),
    );
    let amax = a.iter().map(|p| p.0.max(p.1)).fold(0.01, f64::max);
    let alabels: Vec<String> = ANGLE_BINS_DEG.iter().map(|b| format!("{b:.0}")).collect();
    c.panel(10, 330, "INVALID VS ANGLE DEG", &alabels, &a, amax);
    let d = pair(
        frac(&report.real.invalid_by_depth),
        frac(&report.synthetic.invalid_by_depth),
    );
    let dmax = d.iter().map(|p| p.0.max(p.1)).fold(0.01, f64::max);
    let dlabels: Vec<String> = DEPTH_BINS_MM
        .iter()
        .map(|&b| {
            if b == u16::MAX {
                "MORE".into()
            } else {
                format!("{:.1}", b as f32 / 1000.0)
            }
        })
        .collect();
    c.panel(330, 330, "INVALID VS DEPTH M", &dlabels, &d, dmax);
    // Ratios of the judged statistics: real bar is 1, synthetic bar its ratio; panel max 2.
    let rows: Vec<_> = report.rows.iter().filter(|r| r.close.is_some()).collect();
    let ratios: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| (1.0, r.relative_error.map_or(1.0, |e| 1.0 + e)))
        .collect();
    let rlabels: Vec<String> = (1..=rows.len()).map(|i| i.to_string()).collect();
    let band_top = 330 + 22 + (180.0 * (1.0 - 1.25 / 2.0)) as usize;
    let band_bottom = 330 + 22 + (180.0 * (1.0 - 0.75 / 2.0)) as usize;
    c.rect(650, band_top, 950, band_bottom, [225, 225, 225]);
    c.panel(650, 330, "SYNTH/REAL PER ROW", &rlabels, &ratios, 2.0);
    crate::dataset::preview::write_rgb_png(path, &c.px, W, H)
}
