//! The depth-image statistics of the noise report, measured the same way on real and synthetic frames: holes inside
//! smooth surfaces, holes at depth jumps (by side), mixed ("flying") pixels per jump, invalid fraction versus
//! incidence angle and depth, quantisation steps versus depth, and the registration border. Only the depth image
//! enters (no labels), so both sides are judged by one estimator.
//!
//! Cost: two passes over the image (rows for runs and jumps; a ±`NORMAL_STEP` px stencil per pixel for the incidence
//! angle), about 3 ms per 640x480 frame.

use serde::{Deserialize, Serialize};
use supine_core::camera::Intrinsics;

/// A step of more than this between horizontal neighbours is a depth jump (mm).
pub const JUMP_MM: u16 = 80;
/// A discontinuity is "big" when its sides differ by at least this in 1/z (1/m): the projector shadow or the
/// registration hole it casts is then a few pixels wide, so whether a hole appears is a property of the sensor.
pub const BIG_JUMP_INV_M: f32 = 0.1;
/// Holes at big jumps longer than this (px) are left out of the width fit (dark objects, not sensor geometry).
pub const FIT_MAX_HOLE_PX: u32 = 64;
/// Lower bounds of the bands (1/m, Δ(1/z)) that split the big discontinuities by size.
pub const BIG_JUMP_BANDS_INV_M: [f32; 4] = [0.1, 0.15, 0.25, 0.5];
/// Lower bounds of the bands (mm) that split the jumps by their gap.
pub const JUMP_GAP_BANDS_MM: [i32; 4] = [80, 160, 320, 640];
/// A jump's side is flat when the next pixel outward differs from its end by at most this (mm).
pub const FLAT_MM: i32 = 30;
/// Half-width of the stencil that estimates the surface normal from depth, pixels.
pub const NORMAL_STEP: usize = 4;
/// Bins of the hole-length histograms: lengths 1 to 63 px one by one, the last bin 64 px and longer.
pub const LENGTH_BINS: usize = 64;
/// Upper bounds of the incidence-angle bins, degrees.
pub const ANGLE_BINS_DEG: [f32; 7] = [20.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0];
/// Upper bounds of the depth bins, mm.
pub const DEPTH_BINS_MM: [u16; 6] = [1250, 1750, 2250, 2750, 3500, u16::MAX];
/// Centres (mm) of the ±100 mm bands where the quantisation step is measured.
pub const STEP_BANDS_MM: [u16; 5] = [1800, 2000, 2200, 2500, 3000];

/// One depth image to measure: `depth` (mm, 0 = none) covers `[x0, x0 + w) x [y0, y0 + h)` of a `full_w x full_h`
/// image (a dataset crop, or the whole frame).
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// Depth, row-major `w * h`.
    pub depth: &'a [u16],
    /// Width of `depth`.
    pub w: usize,
    /// Height of `depth`.
    pub h: usize,
    /// Column of `depth`'s left edge in the full image.
    pub x0: usize,
    /// Row of `depth`'s top edge in the full image.
    pub y0: usize,
    /// Whether `depth` is the full frame (the registration border is measured only then).
    pub full: bool,
    /// Intrinsics of the full image.
    pub camera: Intrinsics,
}

/// Depth window of the comparison: only surfaces inside it are counted, so frames of different scenes are compared
/// at the same distances.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Window {
    /// Nearest depth counted, mm.
    pub min_mm: u16,
    /// Farthest depth counted, mm.
    pub max_mm: u16,
}

impl Window {
    fn holds(&self, d: u16) -> bool {
        d >= self.min_mm && d <= self.max_mm
    }
}

/// Accumulated counts over one or more frames.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Counts {
    /// Frames measured.
    pub frames: u32,
    /// Valid pixels inside the window.
    pub valid_px: u64,
    /// Holes inside smooth surfaces (bounded by valid pixels less than [`JUMP_MM`] apart), by length ([`LENGTH_BINS`]).
    pub smooth_holes: Vec<u64>,
    /// Sum of the smooth holes' lengths, pixels.
    pub smooth_hole_px: u64,
    /// Holes at depth jumps whose near side is on the right (the projector-shadow side), by length ([`LENGTH_BINS`]).
    pub edge_holes_near_right: Vec<u64>,
    /// Holes at depth jumps whose near side is on the left, by length ([`LENGTH_BINS`]).
    pub edge_holes_near_left: Vec<u64>,
    /// Depth jumps between valid pixels (directly or through up to two mixed pixels).
    pub jumps: u64,
    /// Big discontinuities ([`BIG_JUMP_INV_M`]) crossed without a hole (valid to valid).
    pub big_jumps: u64,
    /// Big discontinuities with a hole, near side right / left.
    pub big_holes: [u64; 2],
    /// Least-squares sums `[n, Σx, Σy, Σx², Σxy]` of hole length y (px) against x = fx·Δ(1/z) (px·m) for big
    /// holes up to [`FIT_MAX_HOLE_PX`], near side right and left: a shadow is `y = x·baseline + extra`.
    pub hole_fit: [[f64; 5]; 2],
    /// Mixed pixels found inside those jumps.
    pub mixed_px: u64,
    /// Big discontinuities by size, per [`BIG_JUMP_BANDS_INV_M`] band: `[valid near right, valid near left, hole
    /// near right, hole near left]` (how the share with a hole depends on the step: the scenes differ in steps).
    #[serde(default)]
    pub big_by_band: Vec<[u64; 4]>,
    /// Jumps by their gap, per [`JUMP_GAP_BANDS_MM`] band: `[jumps, mixed pixels, jumps between flat sides, mixed
    /// pixels of those]` (flat: the pixel beyond each end continues within [`FLAT_MM`], so the step is a
    /// discontinuity between surfaces, not a steep slope sampled every pixel).
    #[serde(default)]
    pub jumps_by_gap: Vec<[u64; 4]>,
    /// Per [`ANGLE_BINS_DEG`]: `[valid, invalid]` pixels on smooth surfaces.
    pub by_angle: Vec<[u64; 2]>,
    /// Per [`DEPTH_BINS_MM`]: `[valid, invalid]` pixels on smooth surfaces.
    pub by_depth: Vec<[u64; 2]>,
    /// Which depth values (mm, up to 8191) occur: the quantisation levels.
    pub levels_seen: Vec<u64>,
    /// Registration border of full frames: all-invalid columns at the left and right, rows at the top and bottom
    /// (summed over full frames).
    pub border_px: [u64; 4],
    /// Full frames whose border was measured.
    pub border_frames: u32,
}

/// Highest depth whose level is recorded (mm).
const LEVEL_MAX_MM: usize = 8191;

fn bin_of(len: u32) -> usize {
    (len as usize).clamp(1, LENGTH_BINS) - 1
}

impl Counts {
    /// Empty counts with every histogram sized.
    pub fn new() -> Counts {
        Counts {
            smooth_holes: vec![0; LENGTH_BINS],
            edge_holes_near_right: vec![0; LENGTH_BINS],
            edge_holes_near_left: vec![0; LENGTH_BINS],
            by_angle: vec![[0; 2]; ANGLE_BINS_DEG.len()],
            by_depth: vec![[0; 2]; DEPTH_BINS_MM.len()],
            big_by_band: vec![[0; 4]; BIG_JUMP_BANDS_INV_M.len()],
            jumps_by_gap: vec![[0; 4]; JUMP_GAP_BANDS_MM.len()],
            levels_seen: vec![0; LEVEL_MAX_MM.div_ceil(64) + 1],
            ..Counts::default()
        }
    }

    /// Add `other` into `self`.
    pub fn add(&mut self, other: &Counts) {
        let sum = |a: &mut Vec<u64>, b: &Vec<u64>| a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        self.frames += other.frames;
        self.valid_px += other.valid_px;
        sum(&mut self.smooth_holes, &other.smooth_holes);
        self.smooth_hole_px += other.smooth_hole_px;
        sum(&mut self.edge_holes_near_right, &other.edge_holes_near_right);
        sum(&mut self.edge_holes_near_left, &other.edge_holes_near_left);
        self.jumps += other.jumps;
        self.big_jumps += other.big_jumps;
        self.big_holes[0] += other.big_holes[0];
        self.big_holes[1] += other.big_holes[1];
        for (a, b) in self.hole_fit.iter_mut().zip(&other.hole_fit) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
        self.mixed_px += other.mixed_px;
        for (a, b) in self.big_by_band.iter_mut().zip(&other.big_by_band) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
        for (a, b) in self.jumps_by_gap.iter_mut().zip(&other.jumps_by_gap) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
        for (a, b) in self.by_angle.iter_mut().zip(&other.by_angle) {
            a[0] += b[0];
            a[1] += b[1];
        }
        for (a, b) in self.by_depth.iter_mut().zip(&other.by_depth) {
            a[0] += b[0];
            a[1] += b[1];
        }
        for (a, b) in self.levels_seen.iter_mut().zip(&other.levels_seen) {
            *a |= b;
        }
        for i in 0..4 {
            self.border_px[i] += other.border_px[i];
        }
        self.border_frames += other.border_frames;
    }

    /// Holes inside smooth surfaces per 1000 valid pixels.
    pub fn smooth_holes_per_kpx(&self) -> f64 {
        1000.0 * self.smooth_holes.iter().sum::<u64>() as f64 / self.valid_px.max(1) as f64
    }

    /// Mean length of a hole inside a smooth surface, pixels.
    pub fn smooth_hole_mean_px(&self) -> f64 {
        self.smooth_hole_px as f64 / self.smooth_holes.iter().sum::<u64>().max(1) as f64
    }

    /// Mixed pixels per depth jump.
    pub fn mixed_per_jump(&self) -> f64 {
        self.mixed_px as f64 / self.jumps.max(1) as f64
    }

    /// Depth jumps per 1000 valid pixels.
    pub fn jumps_per_kpx(&self) -> f64 {
        1000.0 * self.jumps as f64 / self.valid_px.max(1) as f64
    }

    /// Edge holes (both sides) per depth jump.
    pub fn edge_holes_per_jump(&self) -> f64 {
        let holes: u64 = self
            .edge_holes_near_right
            .iter()
            .chain(&self.edge_holes_near_left)
            .sum();
        holes as f64 / self.jumps.max(1) as f64
    }

    /// Share of big discontinuities that have a hole.
    pub fn big_hole_share(&self) -> f64 {
        let holes = self.big_holes[0] + self.big_holes[1];
        holes as f64 / (holes + self.big_jumps).max(1) as f64
    }

    /// Share of the big holes whose near side is on the right (the projector-shadow side).
    pub fn big_holes_near_right_share(&self) -> f64 {
        self.big_holes[0] as f64 / (self.big_holes[0] + self.big_holes[1]).max(1) as f64
    }

    /// Share of the edge holes whose near side is on the right (the projector-shadow side).
    pub fn edge_holes_near_right_share(&self) -> f64 {
        let r: u64 = self.edge_holes_near_right.iter().sum();
        let l: u64 = self.edge_holes_near_left.iter().sum();
        r as f64 / (r + l).max(1) as f64
    }

    /// The quantisation step (mm) near each of [`STEP_BANDS_MM`] from the levels seen (`None` with too few levels):
    /// meaningful per frame (pooling devices with other `f·b` interleaves their levels; [`super::side`] takes the
    /// median over frames).
    pub fn steps_mm(&self) -> Vec<Option<f32>> {
        let mut seen = Vec::new();
        for d in 0..=LEVEL_MAX_MM {
            if self.levels_seen[d / 64] >> (d % 64) & 1 == 1 {
                seen.push(d as u16);
            }
        }
        STEP_BANDS_MM
            .iter()
            .map(|&c| crate::render::noise::measured_step_mm(&seen, c - 100, c + 100))
            .collect()
    }

    /// Invalid share of smooth-surface pixels per bin (`None` where the bin holds under 200 pixels).
    pub fn invalid_fraction(bins: &[[u64; 2]]) -> Vec<Option<f64>> {
        bins.iter()
            .map(|&[v, i]| (v + i >= 200).then(|| i as f64 / (v + i) as f64))
            .collect()
    }

    /// Mean registration border `[left, top, right, bottom]` in pixels over the full frames (`None` without any).
    pub fn border_mean_px(&self) -> Option<[f64; 4]> {
        (self.border_frames > 0).then(|| self.border_px.map(|b| b as f64 / self.border_frames as f64))
    }
}

/// Fit `y = baseline·x + extra` to [`Counts::hole_fit`] sums: `(baseline mm, extra px)`; `None` under 10 holes or
/// without spread in x.
pub fn hole_width_fit(f: &[f64; 5]) -> Option<(f64, f64)> {
    let [n, sx, sy, sxx, sxy] = *f;
    let den = n * sxx - sx * sx;
    if n < 10.0 || den <= 1e-9 * n * sxx {
        return None;
    }
    let slope = (n * sxy - sx * sy) / den;
    Some((slope * 1000.0, (sy - slope * sx) / n))
}

/// Median of a length histogram, pixels (`None` if empty; 64 stands for 64 and longer).
pub fn histogram_median(hist: &[u64]) -> Option<u32> {
    let total: u64 = hist.iter().sum();
    if total == 0 {
        return None;
    }
    let mut acc = 0;
    for (i, &c) in hist.iter().enumerate() {
        acc += c;
        if 2 * acc >= total {
            return Some(i as u32 + 1);
        }
    }
    None
}

/// Measure one frame inside `window`.
pub fn measure(frame: &Frame<'_>, window: Window) -> Counts {
    let mut c = Counts::new();
    c.frames = 1;
    let (w, h, d) = (frame.w, frame.h, frame.depth);
    assert_eq!(d.len(), w * h, "frame size");
    for &v in d {
        if v > 0 {
            if window.holds(v) {
                c.valid_px += 1;
            }
            if (v as usize) <= LEVEL_MAX_MM {
                c.levels_seen[v as usize / 64] |= 1 << (v as usize % 64);
            }
        }
    }
    let angle = AngleEstimator::new(frame);
    for y in 0..h {
        let row = &d[y * w..(y + 1) * w];
        rows_runs(row, y, window, &angle, frame.camera.fx, &mut c);
        row_jumps(row, window, &mut c);
    }
    for y in 0..h {
        for x in 0..w {
            let v = d[y * w + x];
            if v > 0
                && window.holds(v)
                && let Some(deg) = angle.at(x, y)
            {
                count_surface(&mut c, deg, v, 0);
            }
        }
    }
    if frame.full {
        let col_empty = |x: usize| (0..h).all(|y| d[y * w + x] == 0);
        let row_empty = |y: usize| d[y * w..(y + 1) * w].iter().all(|&v| v == 0);
        let left = (0..w).take_while(|&x| col_empty(x)).count();
        let right = (0..w).rev().take_while(|&x| col_empty(x)).count();
        let top = (0..h).take_while(|&y| row_empty(y)).count();
        let bottom = (0..h).rev().take_while(|&y| row_empty(y)).count();
        c.border_px = [left as u64, top as u64, right as u64, bottom as u64];
        c.border_frames = 1;
    }
    c
}

fn count_surface(c: &mut Counts, deg: f32, depth: u16, invalid: usize) {
    let a = ANGLE_BINS_DEG
        .iter()
        .position(|&b| deg <= b)
        .unwrap_or(ANGLE_BINS_DEG.len() - 1);
    let z = DEPTH_BINS_MM
        .iter()
        .position(|&b| depth <= b)
        .unwrap_or(DEPTH_BINS_MM.len() - 1);
    c.by_angle[a][invalid] += 1;
    c.by_depth[z][invalid] += 1;
}

/// Invalid runs bounded by valid pixels on both sides of a row: smooth-surface holes or holes at jumps.
fn rows_runs(row: &[u16], y: usize, window: Window, angle: &AngleEstimator<'_>, fx: f32, c: &mut Counts) {
    let mut x = 0;
    while x < row.len() {
        if row[x] != 0 {
            x += 1;
            continue;
        }
        let start = x;
        while x < row.len() && row[x] == 0 {
            x += 1;
        }
        if start == 0 || x == row.len() {
            continue; // not bounded on both sides (image or crop border)
        }
        let (l, r) = (row[start - 1], row[x]);
        let len = (x - start) as u32;
        if l.abs_diff(r) <= JUMP_MM {
            if window.holds(l) && window.holds(r) {
                c.smooth_holes[bin_of(len)] += 1;
                c.smooth_hole_px += len as u64;
                // The hole's pixels lie on the surface around it: count them at its angle and depth.
                if let Some(deg) = angle.at(start - 1, y).or_else(|| angle.at(x, y)) {
                    for _ in 0..len {
                        count_surface(c, deg, l.min(r), 1);
                    }
                }
            }
        } else if window.holds(l.min(r)) {
            let hist = if r < l {
                &mut c.edge_holes_near_right
            } else {
                &mut c.edge_holes_near_left
            };
            hist[bin_of(len)] += 1;
            let dinv = 1000.0 / l.min(r) as f32 - 1000.0 / l.max(r) as f32;
            if dinv >= BIG_JUMP_INV_M {
                let side = (r >= l) as usize; // 0: near side right
                c.big_holes[side] += 1;
                c.big_by_band[band_of_inv(dinv)][2 + side] += 1;
                if len <= FIT_MAX_HOLE_PX {
                    let (x, y) = ((fx * dinv) as f64, len as f64);
                    let f = &mut c.hole_fit[side];
                    f[0] += 1.0;
                    f[1] += x;
                    f[2] += y;
                    f[3] += x * x;
                    f[4] += x * y;
                }
            }
        }
    }
}

fn band_of_inv(dinv: f32) -> usize {
    BIG_JUMP_BANDS_INV_M
        .iter()
        .rposition(|&lo| dinv >= lo)
        .unwrap_or(0)
}

/// Depth jumps inside runs of valid pixels, and the mixed pixels within them: from a pixel `a`, the widest step of
/// up to 3 pixels to `b` with `|b − a| > JUMP_MM` whose inner pixels all lie strictly between, at least 15 % of the
/// gap away from both sides.
fn row_jumps(row: &[u16], window: Window, c: &mut Counts) {
    let mut i = 0;
    while i + 1 < row.len() {
        if row[i] == 0 || row[i + 1] == 0 {
            i += 1;
            continue;
        }
        let a = row[i] as i32;
        let mut taken = 0;
        for k in (1..=3usize).rev() {
            if i + k >= row.len() || row[i + 1..=i + k].contains(&0) {
                continue;
            }
            let b = row[i + k] as i32;
            let gap = (b - a).abs();
            if gap <= JUMP_MM as i32 {
                continue;
            }
            let margin = gap * 15 / 100;
            let (lo, hi) = (a.min(b) + margin, a.max(b) - margin);
            if row[i + 1..i + k]
                .iter()
                .all(|&m| (m as i32) > lo && (m as i32) < hi)
            {
                if window.holds(a.min(b) as u16) {
                    c.jumps += 1;
                    c.mixed_px += (k - 1) as u64;
                    let dinv = 1000.0 / a.min(b) as f32 - 1000.0 / a.max(b) as f32;
                    if dinv >= BIG_JUMP_INV_M {
                        c.big_jumps += 1;
                        c.big_by_band[band_of_inv(dinv)][(b > a) as usize] += 1;
                    }
                    let flat = |o: Option<&u16>, end: i32| {
                        o.is_some_and(|&o| o != 0 && (o as i32 - end).abs() <= FLAT_MM)
                    };
                    let is_flat = i > 0 && flat(row.get(i - 1), a) && flat(row.get(i + k + 1), b);
                    let band = JUMP_GAP_BANDS_MM.iter().rposition(|&lo| gap > lo).unwrap_or(0);
                    let g = &mut c.jumps_by_gap[band];
                    g[0] += 1;
                    g[1] += (k - 1) as u64;
                    if is_flat {
                        g[2] += 1;
                        g[3] += (k - 1) as u64;
                    }
                }
                taken = k;
                break;
            }
        }
        i += taken.max(1);
    }
}

/// Incidence angle (normal vs. ray) of a pixel from the depth around it: central differences over ±`NORMAL_STEP`
/// px in x and y, only where all four stencil pixels are valid and within `JUMP_MM` of the centre.
struct AngleEstimator<'a> {
    f: &'a Frame<'a>,
}

impl<'a> AngleEstimator<'a> {
    fn new(f: &'a Frame<'a>) -> Self {
        AngleEstimator { f }
    }

    fn point(&self, x: usize, y: usize) -> Option<[f32; 3]> {
        let d = self.f.depth[y * self.f.w + x];
        if d == 0 {
            return None;
        }
        let z = d as f32 * 0.001;
        let k = &self.f.camera;
        let (u, v) = ((x + self.f.x0) as f32, (y + self.f.y0) as f32);
        Some([(u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z])
    }

    fn at(&self, x: usize, y: usize) -> Option<f32> {
        let s = NORMAL_STEP;
        if x < s || y < s || x + s >= self.f.w || y + s >= self.f.h {
            return None;
        }
        let c = self.f.depth[y * self.f.w + x];
        let near = |xx: usize, yy: usize| {
            let v = self.f.depth[yy * self.f.w + xx];
            (v != 0 && v.abs_diff(c) <= JUMP_MM)
                .then(|| self.point(xx, yy))
                .flatten()
        };
        let (l, r, t, b) = (near(x - s, y)?, near(x + s, y)?, near(x, y - s)?, near(x, y + s)?);
        let du = [r[0] - l[0], r[1] - l[1], r[2] - l[2]];
        let dv = [b[0] - t[0], b[1] - t[1], b[2] - t[2]];
        let n = [
            du[1] * dv[2] - du[2] * dv[1],
            du[2] * dv[0] - du[0] * dv[2],
            du[0] * dv[1] - du[1] * dv[0],
        ];
        // The ray through the centre pixel (its own depth may be missing: use the stencil's mean).
        let p = [
            (l[0] + r[0]) * 0.5,
            (t[1] + b[1]) * 0.5,
            (l[2] + r[2] + t[2] + b[2]) * 0.25,
        ];
        let nn = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let pn = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        if nn <= 0.0 || pn <= 0.0 {
            return None;
        }
        let cos = ((n[0] * p[0] + n[1] * p[1] + n[2] * p[2]).abs() / (nn * pn)).min(1.0);
        Some(cos.acos().to_degrees())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(depth: &[u16], w: usize, h: usize) -> Frame<'_> {
        Frame {
            depth,
            w,
            h,
            x0: 0,
            y0: 0,
            full: true,
            camera: Intrinsics::KINECT_V1,
        }
    }

    const WINDOW: Window = Window {
        min_mm: 1000,
        max_mm: 3500,
    };

    #[test]
    fn holes_jumps_and_mixed_pixels_are_counted_as_defined() {
        let (w, h) = (60, 20);
        let mut d = vec![2000u16; w * h];
        for y in 0..h {
            let row = &mut d[y * w..(y + 1) * w];
            // A 5-px hole inside the smooth wall, then a jump to 1500 mm through one mixed pixel at 1750 mm, and a
            // 3-px hole between the near surface (left) and the wall.
            row[10..15].fill(0);
            row[31] = 1750;
            row[32..45].fill(1500);
            row[45..48].fill(0);
        }
        let c = measure(&frame(&d, w, h), WINDOW);
        assert_eq!(c.smooth_holes.iter().sum::<u64>(), h as u64);
        assert_eq!(histogram_median(&c.smooth_holes), Some(5));
        assert_eq!((c.jumps, c.mixed_px), (h as u64, h as u64));
        assert_eq!(
            c.edge_holes_near_left[2], h as u64,
            "3-px holes with the near side on the left"
        );
        assert_eq!(c.edge_holes_near_right.iter().sum::<u64>(), 0);
        assert_eq!(c.border_px, [0, 0, 0, 0]);
        // 1/1.5 − 1/2 = 0.167 /m: a big discontinuity, with its hole on the near-left side.
        assert_eq!(c.big_holes, [0, h as u64]);
        assert_eq!(c.big_jumps, h as u64);
        assert!((c.mixed_per_jump() - 1.0).abs() < 1e-12);
        let steps = c.steps_mm();
        assert!(
            steps.iter().all(Option::is_none),
            "three levels per band at most: no step"
        );
    }

    #[test]
    fn border_and_hole_width_fit() {
        let (w, h) = (40, 30);
        let mut d = vec![2500u16; w * h];
        for (i, v) in d.iter_mut().enumerate() {
            let (u, y) = (i % w, i / w);
            if u < 3 || y >= h - 2 {
                *v = 0;
            }
        }
        let c = measure(&frame(&d, w, h), WINDOW);
        assert_eq!(c.border_mean_px(), Some([3.0, 0.0, 0.0, 2.0]));
        // Holes of 2 + 0.05·x px against x = fx·Δ(1/z): the fit returns the baseline (mm) and the extra pixels.
        let mut f = [0f64; 5];
        for x in [
            40.0f64, 60.0, 80.0, 100.0, 120.0, 140.0, 160.0, 180.0, 200.0, 220.0,
        ] {
            let y = 2.0 + 0.05 * x;
            f = [f[0] + 1.0, f[1] + x, f[2] + y, f[3] + x * x, f[4] + x * y];
        }
        let (b, e) = hole_width_fit(&f).unwrap();
        assert!((b - 50.0).abs() < 1e-6 && (e - 2.0).abs() < 1e-6, "{b} {e}");
        assert!(hole_width_fit(&[3.0, 1.0, 1.0, 1.0, 1.0]).is_none());
    }

    #[test]
    fn real_bag_and_pngs_read_alike() {
        // The five tue frames as PNGs and as the ROS 2 bag give the same counts (skipped without shared/).
        let base = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/realdata");
        let bag = base.join("mcap/tue_person_depth_16UC1.mcap");
        if !bag.exists() {
            eprintln!("shared/realdata not available: skipped");
            return;
        }
        let k = Intrinsics::KINECT_V1;
        let from_bag = super::super::sources::measure_source(&bag, k, WINDOW, 10).unwrap();
        assert_eq!(from_bag.frames.len(), 5);
        let mut pngs: Vec<_> = std::fs::read_dir(base.join("derived"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("tue_"))
            .collect();
        pngs.sort();
        for (p, bag_counts) in pngs.iter().zip(&from_bag.frames) {
            let png = super::super::sources::measure_source(p, k, WINDOW, 1).unwrap();
            // The bag brings its camera info (fx 537), the PNG the default: only the angle bins may differ.
            assert_eq!(png.frames[0].smooth_holes, bag_counts.smooth_holes);
            assert_eq!(png.frames[0].jumps, bag_counts.jumps);
        }
        // Garbage is an error, not a panic.
        let dir = std::env::temp_dir().join(format!("supine-noise-report-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("bad.mcap"), b"not an mcap").unwrap();
        assert!(super::super::sources::measure_source(&dir.join("bad.mcap"), k, WINDOW, 1).is_err());
        std::fs::write(dir.join("bad.png"), b"not a png").unwrap();
        assert!(super::super::sources::measure_source(&dir.join("bad.png"), k, WINDOW, 1).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
