//! The tracking evaluation's plot over time, one PNG per sequence: torso surface error per variant and the last
//! variant's rigid floor (top, a thin black line: the error its model would have at the best rigid pose), the
//! state of each variant as a coloured band (middle), the true occluded fraction of the torso (bottom). Drawn with
//! the evaluation charts' raster (no plotting dependency); a few ms per plot.

use anyhow::Result;
use std::path::Path;
use supine_core::tracker::Variant;

use super::tracking::FrameScore;
use crate::forest::chart::{COLORS, Canvas, text_w};

/// Error axis maximum, mm (larger errors are drawn at the top).
const ERROR_MAX_MM: f32 = 60.0;

fn state_colour(state: &str) -> [u8; 3] {
    match state {
        "tracking" => [90, 170, 90],
        "degraded" => [170, 200, 90],
        "occluded" => [240, 180, 60],
        "lost" => [210, 60, 60],
        "acquiring" | "reacquiring" => [120, 160, 220],
        "initialising" => [190, 190, 190],
        _ => [120, 60, 160],
    }
}

/// Write the plot of `runs` (one score list per variant) for sequence `name` to `path`.
pub fn write_png(path: &Path, name: &str, runs: &[(Variant, Vec<FrameScore>)]) -> Result<()> {
    let frames = runs.iter().map(|(_, s)| s.len()).max().unwrap_or(0).max(1);
    let (w, left, right) = (1000usize, 60usize, 20usize);
    let (err_top, err_h) = (70usize, 260usize);
    let band_h = 16usize;
    let bands_top = err_top + err_h + 30;
    let occ_top = bands_top + runs.len() * (band_h + 6) + 30;
    let occ_h = 80usize;
    let h = occ_top + occ_h + 40;
    let mut c = Canvas::new(w, h);
    let plot_w = w - left - right;
    let x_of = |i: usize| left + i * plot_w / frames;
    c.text(
        left,
        10,
        &format!("TRACKING {name}: TORSO SURFACE ERROR MM, STATE, OCCLUDED FRACTION"),
        2,
        [0, 0, 0],
    );
    let mut lx = left;
    for (vi, (v, _)) in runs.iter().enumerate() {
        c.rect(lx, 38, lx + 14, 52, COLORS[vi % COLORS.len()]);
        c.text(lx + 20, 41, v.name(), 1, [0, 0, 0]);
        lx += 20 + text_w(v.name(), 1) + 30;
    }
    if let Some((v, _)) = runs.last() {
        let label = format!("RIGID FLOOR OF {}", v.name());
        c.rect(lx, 44, lx + 14, 46, [0, 0, 0]);
        c.text(lx + 20, 41, &label, 1, [0, 0, 0]);
    }
    // Error panel with a grid every 10 mm.
    for k in 0..=6 {
        let y = err_top + err_h - k * err_h / 6;
        c.rect(left, y, left + plot_w, y + 1, [215, 215, 215]);
        c.text(8, y.saturating_sub(3), &format!("{}", k * 10), 1, [0, 0, 0]);
    }
    for (vi, (_, scores)) in runs.iter().enumerate() {
        let col = COLORS[vi % COLORS.len()];
        for (i, s) in scores.iter().enumerate() {
            if let Some(e) = s.torso_mm {
                let y = err_top + err_h - ((e / ERROR_MAX_MM).clamp(0.0, 1.0) * err_h as f32) as usize;
                let x = x_of(i);
                c.rect(x, y.saturating_sub(1), (x_of(i + 1)).max(x + 2), y + 2, col);
            }
        }
    }
    if let Some((_, scores)) = runs.last() {
        for (i, s) in scores.iter().enumerate() {
            if let Some(e) = s.torso_floor_mm {
                let y = err_top + err_h - ((e / ERROR_MAX_MM).clamp(0.0, 1.0) * err_h as f32) as usize;
                c.rect(x_of(i), y, x_of(i + 1).max(x_of(i) + 1), y + 1, [0, 0, 0]);
            }
        }
    }
    for (vi, (v, scores)) in runs.iter().enumerate() {
        let y = bands_top + vi * (band_h + 6);
        c.text(left, y.saturating_sub(10), v.name(), 1, [0, 0, 0]);
        for (i, s) in scores.iter().enumerate() {
            c.rect(
                x_of(i),
                y,
                x_of(i + 1).max(x_of(i) + 1),
                y + band_h,
                state_colour(&s.state),
            );
        }
    }
    c.text(
        left,
        occ_top - 12,
        "OCCLUDED FRACTION OF THE TORSO (0-1)",
        1,
        [0, 0, 0],
    );
    c.rect(
        left,
        occ_top + occ_h,
        left + plot_w,
        occ_top + occ_h + 1,
        [0, 0, 0],
    );
    if let Some((_, scores)) = runs.first() {
        for (i, s) in scores.iter().enumerate() {
            let bh = (s.occluded.clamp(0.0, 1.0) * occ_h as f32) as usize;
            c.rect(
                x_of(i),
                occ_top + occ_h - bh,
                x_of(i + 1).max(x_of(i) + 1),
                occ_top + occ_h,
                [100, 100, 100],
            );
        }
    }
    let mut sx = left;
    for st in [
        "initialising",
        "acquiring",
        "tracking",
        "degraded",
        "occluded",
        "lost",
        "reacquiring",
    ] {
        c.rect(sx, h - 24, sx + 12, h - 12, state_colour(st));
        c.text(sx + 16, h - 22, st, 1, [0, 0, 0]);
        sx += 16 + text_w(st, 1) + 20;
    }
    c.save(path)
}
