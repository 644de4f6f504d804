//! The Kinect effects beyond per-pixel noise (`docs/noise-model.md`, "Correlation window and registration"): blob
//! dropouts of the 9x9 correlation window, edge fattening and mixed pixels at depth jumps, registration of depth to
//! the RGB camera (its border and the IR camera's occlusion holes), and the state that correlates noise between
//! consecutive frames of a sequence. Each is off when its manifest parameter is absent, and then consumes no random
//! numbers, so images made without it stay byte-identical.
//!
//! Cost: the edges' three row max filters (about 15 reads of 1/z per pixel of the band) dominate, then one draw
//! per 32x32 blob cell with its disc painted, the shadow-side band's row pass and registration's second row scan;
//! all told the default model makes a dataset 20–40 % slower than the legacy chain (`docs/noise-model.md`). Temporal state: 12 B per pixel.

use super::RenderBuffers;
use rand::RngCore;
use rand_chacha::ChaCha8Rng;

/// Blob-shaped dropouts: where the correlation window finds too few dots (dark or grazing surfaces, speckle
/// contrast), the PS1080 leaves a hole about the window's size. Modelled as discs placed at most one per grid cell.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BlobDropouts {
    /// Grid cell size, pixels (at most one blob per cell).
    pub cell_px: u16,
    /// Probability that a cell holds a blob on a surface seen head-on.
    pub rate: f32,
    /// Extra probability at grazing incidence: added as `grazing_rate·s²`, `s` = (θ − 60°)/30° clamped to 0..1.
    pub grazing_rate: f32,
    /// Smallest blob radius, pixels.
    pub min_radius_px: f32,
    /// Largest blob radius, pixels.
    pub max_radius_px: f32,
}

/// Edge effects of the correlation window at depth jumps: background pixels within `fatten_px` of a nearer surface
/// take the nearer depth (foreground fattening); at big jumps the next `hole_px` pixels get no depth; elsewhere
/// those up to `mixed_px` pixels farther read, with probability `mixed`, a disparity between the two sides (mixed,
/// "flying" pixels).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EdgeEffects {
    /// Foreground fattening, pixels (0: none).
    pub fatten_px: u8,
    /// Smallest depth step that counts as a jump, metres.
    pub min_step_m: f32,
    /// Width of the band beyond the fattened edge that has no depth at big jumps (the window straddles both
    /// surfaces and finds no match), pixels (0: none).
    pub hole_px: u8,
    /// A jump is big for `hole_px` when its sides differ by at least this in 1/z, 1/m.
    pub hole_min_inv_m: f32,
    /// Width of the band beyond the fattened edge that has no depth left of a big jump's near surface (the
    /// projector-shadow side: the window straddling the edge finds no match there either), pixels (0: none).
    #[serde(default, skip_serializing_if = "is_zero_u8")]
    pub shadow_hole_px: u8,
    /// `shadow_hole_px` applies only where the near surface is at least this wide (pixels along the row), so thin
    /// slivers keep their background.
    #[serde(default, skip_serializing_if = "is_zero_u8")]
    pub shadow_hole_min_width_px: u8,
    /// Width of the band beyond the fattened edge where mixed pixels occur, pixels.
    pub mixed_px: u8,
    /// Probability that a pixel in that band reads a mixed depth (disparity uniform in between).
    pub mixed: f32,
    /// Mixed pixels fade with the step: full `mixed` up to half this step in 1/z (1/m), none from this step on (the
    /// window blends disparities that differ by a pixel or two, and finds no match across larger ones); 0: no
    /// fade.
    #[serde(default, skip_serializing_if = "is_zero_f32")]
    pub mixed_max_inv_m: f32,
    /// Mixed pixels ramp from the near side to the far one across the band (the pixel next to the fattened edge
    /// reads mostly the near disparity, the last mostly the far one, each uniform within its share; decided at the
    /// pixel, not its jittered read) instead of each drawing uniformly between the two: the real frames spread a
    /// small step over two or three pixels in order.
    #[serde(default, skip_serializing_if = "is_false")]
    pub mixed_ramp: bool,
}

impl EdgeEffects {
    /// Probability of a mixed pixel next to a step of `dinv` in 1/z (1/m).
    pub fn mixed_probability(&self, dinv: f32) -> f32 {
        if self.mixed_max_inv_m <= 0.0 {
            return self.mixed;
        }
        self.mixed * (2.0 - 2.0 * dinv / self.mixed_max_inv_m).clamp(0.0, 1.0)
    }
}

fn is_zero_f32(x: &f32) -> bool {
    *x == 0.0
}

fn is_false(x: &bool) -> bool {
    !*x
}

/// Serde helper: skip a zero width, so manifests without the field stay as they were.
pub(crate) fn is_zero_u8(x: &u8) -> bool {
    *x == 0
}

/// Registration of depth to the RGB camera (OpenNI2 `setImageRegistrationMode`, `--registered` data): the image is
/// seen from the RGB camera, which is `rgb_baseline_m` toward the projector from the IR camera. Surfaces the IR camera
/// cannot see get no depth (holes right of foreground objects), the projector shadow narrows to the remaining
/// baseline, and the part of the RGB image the IR image does not cover is a border without depth.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Registration {
    /// IR camera to RGB camera along +x, metres (2.5 cm on the Kinect v1).
    pub rgb_baseline_m: f32,
    /// Border without depth: left, top, right, bottom, pixels.
    pub border_px: [u16; 4],
}

impl Registration {
    /// Whether full-image pixel (u, v) of a `w` x `h` image lies in the border.
    pub fn in_border(&self, u: usize, v: usize, w: usize, h: usize) -> bool {
        let [l, t, r, b] = self.border_px.map(|x| x as usize);
        u < l || v < t || u + r >= w || v + b >= h
    }
}

/// Mark pixels of row `row` (a full row of `buf`) that the IR camera, `fb_px_m` = f·b px·m to the left of the
/// viewer, cannot see: scanning left to right in IR coordinates `u_ir = u + f·b/z`, a pixel whose `u_ir` is not right
/// of every `u_ir` to its left is hidden (the mirror of the projector-shadow scan).
pub fn mark_left_occlusion(buf: &RenderBuffers, row: usize, fb_px_m: f32, hidden: &mut [bool]) {
    let w = buf.width;
    let mut max_u = f32::NEG_INFINITY;
    for u in 0..w {
        let iz = buf.inv_z[row * w + u];
        if iz <= 0.0 {
            continue;
        }
        let ui = u as f32 + fb_px_m * iz;
        if ui < max_u - 0.25 {
            hidden[row * w + u] = true;
        } else {
            max_u = max_u.max(ui);
        }
    }
}

/// One cell's blob: centre (full-image pixels), radius and the uniform that decides whether it is present.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BlobCell {
    /// Centre x.
    pub cx: f32,
    /// Centre y.
    pub cy: f32,
    /// Radius, pixels.
    pub r: f32,
    /// Uniform in [0, 1): the blob is present where this is below the cell's probability.
    pub u: f32,
}

impl BlobCell {
    /// A fresh cell at grid position (`gx`, `gy`) from two draws of `rng`.
    pub fn draw(rng: &mut ChaCha8Rng, gx: usize, gy: usize, b: &BlobDropouts) -> BlobCell {
        let (a, c) = (rng.next_u64(), rng.next_u64());
        let unit = |x: u64| (x & 0xFF_FFFF) as f32 / (1u32 << 24) as f32;
        let cell = b.cell_px as f32;
        BlobCell {
            cx: (gx as f32 + unit(a)) * cell,
            cy: (gy as f32 + unit(a >> 24)) * cell,
            r: b.min_radius_px + (b.max_radius_px - b.min_radius_px) * unit(c),
            u: unit(c >> 24),
        }
    }
}

/// Paint the present blobs of `cells` into `mask` (a `w`-wide full image) over the band `[x0, x1) x [y0, y1)`; a
/// cell's probability comes from `prob_at(centre pixel index)`.
pub fn paint_blobs(
    cells: &[BlobCell],
    w: usize,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    prob_at: &dyn Fn(usize) -> f32,
    mask: &mut [bool],
) {
    let h = mask.len() / w;
    for c in cells {
        let (ux, uy) = ((c.cx as usize).min(w - 1), (c.cy as usize).min(h - 1));
        if c.u >= prob_at(uy * w + ux) {
            continue;
        }
        let r2 = c.r * c.r;
        let ya = ((c.cy - c.r).floor().max(y0 as f32)) as usize;
        let yb = ((c.cy + c.r).ceil() as usize + 1).min(y1);
        for y in ya..yb {
            let dy = y as f32 - c.cy;
            let half = r2 - dy * dy;
            if half < 0.0 {
                continue;
            }
            let half = half.sqrt();
            let xa = ((c.cx - half).ceil().max(x0 as f32)) as usize;
            let xb = (((c.cx + half).floor() + 1.0).max(0.0) as usize).min(x1);
            for x in xa..xb {
                mask[y * w + x] = true;
            }
        }
    }
}

/// Max of `inv_z` over the 2r+1 pixels of the row around each pixel of the band `[x0, x1) x [y0, y1)`: the nearest
/// surface within the correlation window along the disparity search (rows), written into `out` (full-image indexing).
pub fn nearest_within(
    buf: &RenderBuffers,
    r: usize,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    out: &mut Vec<f32>,
) {
    let w = buf.width;
    // Only the band is read back: no need to clear the rest.
    out.resize(w * buf.height, 0.0);
    for y in y0..y1 {
        let row = &buf.inv_z[y * w..(y + 1) * w];
        for x in x0..x1 {
            let (a, b) = (x.saturating_sub(r), (x + r + 1).min(w));
            out[y * w + x] = row[a..b].iter().cloned().fold(0.0, f32::max);
        }
    }
}

/// Whether a surface at `near` (1/z) lies nearer than one at `iz` by more than `min_step_m`: z_far − z_near >
/// min_step, compared in 1/z without a division.
pub fn nearer_by(iz: f32, near: f32, min_step_m: f32) -> bool {
    iz > 0.0 && near > iz && (near - iz) > min_step_m * iz * near
}

/// For each pixel of the band, how far along the row (in pixels) the nearest surface lies that is nearer than the
/// pixel by more than `min_step_m` ([`nearer_by`]), if within `r`; 0 where none is.
/// Written into `out` (full-image indexing).
pub fn distance_to_nearer(
    buf: &RenderBuffers,
    r: usize,
    min_step_m: f32,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    out: &mut Vec<u8>,
) {
    let w = buf.width;
    // Only the band is read back: no need to clear the rest.
    out.resize(w * buf.height, 0);
    for y in y0..y1 {
        let row = &buf.inv_z[y * w..(y + 1) * w];
        for x in x0..x1 {
            let iz = row[x];
            out[y * w + x] = (1..=r.min(u8::MAX as usize))
                .find(|&d| {
                    (x >= d && nearer_by(iz, row[x - d], min_step_m))
                        || (x + d < w && nearer_by(iz, row[x + d], min_step_m))
                })
                .unwrap_or(0) as u8;
        }
    }
}

/// Near side (1/z) of the depth discontinuities that lie within `r` pixels to the left of each pixel of the band:
/// a discontinuity is a step of at least `min_inv_m` in 1/z between horizontal neighbours with the near surface on
/// the left (a slope never steps that much between neighbours unless near grazing); 0 where there is none. Only
/// this side: the real frames show the extra hole right of foreground objects (the IR-occlusion side), not left.
/// Written into `out` (full-image indexing); `steps` is scratch.
pub fn near_side_of_steps(
    buf: &RenderBuffers,
    r: usize,
    min_inv_m: f32,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    steps: &mut Vec<f32>,
    out: &mut Vec<f32>,
) {
    let w = buf.width;
    // Only the band is read back: no need to clear the rest.
    out.resize(w * buf.height, 0.0);
    steps.clear();
    steps.resize(w, 0.0);
    let sa = x0.saturating_sub(r);
    for y in y0..y1 {
        let row = &buf.inv_z[y * w..(y + 1) * w];
        steps[sa..x1].fill(0.0);
        for u in sa.max(1)..x1 {
            let (a, b) = (row[u - 1], row[u]);
            if b > 0.0 && a - b >= min_inv_m {
                steps[u] = a;
            }
        }
        for x in x0..x1 {
            out[y * w + x] = steps[x.saturating_sub(r).max(sa)..=x]
                .iter()
                .cloned()
                .fold(0.0, f32::max);
        }
    }
}

/// Like [`near_side_of_steps`], for the other side: near side (1/z) of the discontinuities that lie within `r`
/// pixels to the right of each pixel of the band, with the near surface on the right and at least `min_width` pixels
/// wide (its 1/z within `min_inv_m / 2` of the step's near side that far), maxed into `out` (which
/// [`near_side_of_steps`] filled for the band). `steps` is scratch.
pub fn max_near_side_of_steps_left(
    buf: &RenderBuffers,
    r: usize,
    min_inv_m: f32,
    min_width: usize,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    steps: &mut Vec<f32>,
    out: &mut [f32],
) {
    let w = buf.width;
    steps.clear();
    steps.resize(w, 0.0);
    let sb = (x1 + r).min(w);
    let width = min_width.max(1);
    for y in y0..y1 {
        let row = &buf.inv_z[y * w..(y + 1) * w];
        steps[x0..sb].fill(0.0);
        for u in x0..sb {
            if u + 1 >= w {
                break;
            }
            let (a, b) = (row[u], row[u + 1]);
            // The far pixel u left of the near pixel u + 1, whose surface continues `width` pixels to the right.
            if a > 0.0
                && b - a >= min_inv_m
                && u + width < w
                && row[u + 1..=u + width].iter().all(|&n| n >= b - 0.5 * min_inv_m)
            {
                steps[u] = b;
            }
        }
        for x in x0..x1 {
            let m = steps[x..=(x + r).min(sb - 1)].iter().cloned().fold(0.0, f32::max);
            let o = &mut out[y * w + x];
            *o = o.max(m);
        }
    }
}

/// What a sequence carries from frame to frame when `temporal_correlation` > 0: the previous frame's three normal
/// draws per pixel and its blob cells. Fresh (and reset) when the image size or rectangle changes.
#[derive(Debug, Clone, Default)]
pub struct TemporalState {
    /// Previous normal draws (lateral u, lateral v, axial) per pixel of the rectangle.
    pub draws: Vec<[f32; 3]>,
    /// Previous blob cells of the band.
    pub cells: Vec<BlobCell>,
    /// The rectangle and band the state belongs to (x0, y0, w, h of the rect; gx0, gy0, gw, gh of the grid).
    pub key: Option<[usize; 8]>,
}
