//! The on-disk format of a dataset body file (`DIR/bodies/body_NNNNN.svd`) and its reader; the full description is
//! `docs/dataset-format.md`.
//!
//! ```text
//! file   := header body_json view*
//! header := "SVDB" u16 version=1  u16 n_views  u32 body_index  f32 level_scale  u32 body_json_len   (20 bytes, LE)
//! view   := "VIEW" u16 x0 u16 y0 u16 w u16 h  u32 view_json_len  u32 payload_len         (20 bytes, LE)
//!           view_json  payload
//! payload:= zlib (RFC 1950: deflate + Adler-32) of  delta_lo[w*h] delta_hi[w*h] label[w*h] part[w*h]  (u8 each)
//! ```
//! Depth is stored as the Kinect's quantised disparity level `k` (1/8 px units, 0 = no depth), the noise model's
//! direct output; millimetres are `KinectNoise::level_to_mm(level_scale, k)` = round(1000·level_scale/k). Each row
//! is coded as the wrapping difference from the pixel to its left (the first from 0), zigzag-coded (0, −1, 1, −2 →
//! 0, 1, 2, 3) and split into a plane of low bytes and a plane of high bytes: differences are small, so the high
//! plane is almost all zeros and both deflate well.
//! zlib's Adler-32 checks the decompressed payload (a fast checksum: a table CRC would cost as much as the
//! deflate). JSON blocks are UTF-8 [`BodyTruth`] /
//! [`ViewTruth`].
//!
//! Cost: encoding a 640x480 crop is one delta pass and one fast deflate (a few ms); decoding is the inverse. The reader
//! validates magic, version, lengths (against the file size) and the checksum, and reports a bad file as an error
//! naming it; it never panics on corrupt input.

use super::{BodyTruth, ViewTruth};
use crate::render::noise::{KinectNoise, Rect};
use anyhow::{Context, Result, bail, ensure};
use flate2::Compression;
use std::io::{Read, Write};

/// Magic of a body file.
pub const BODY_MAGIC: &[u8; 4] = b"SVDB";
/// Magic of a view record.
pub const VIEW_MAGIC: &[u8; 4] = b"VIEW";
/// Format version written and accepted.
pub const VERSION: u16 = 1;
/// Largest JSON block accepted (guards against corrupt length fields).
const MAX_JSON: usize = 1 << 20;

/// One decoded image of a body file (crop rectangle only).
#[derive(Debug, Clone, PartialEq)]
pub struct ViewRecord {
    /// Ground truth of the view.
    pub truth: ViewTruth,
    /// Crop rectangle within the 640x480 image.
    pub crop: Rect,
    /// Quantised disparity levels of the crop as stored (0 = no depth), row-major `w * h`.
    pub levels: Vec<u16>,
    /// Noisy depth of the crop, mm, 0 = no depth, row-major `w * h` (decoded from `levels`).
    pub depth_mm: Vec<u16>,
    /// [`crate::render::Label`] per crop pixel.
    pub label: Vec<u8>,
    /// Body-part id per crop pixel ([`crate::render::NO_PART`] off the body).
    pub part: Vec<u8>,
}

impl ViewRecord {
    /// The full 640x480 depth image (zeros outside the crop), as a source would deliver it.
    pub fn full_depth(&self, width: usize, height: usize) -> Vec<u16> {
        let mut out = vec![0u16; width * height];
        let (x0, y0, w) = (self.crop.x0 as usize, self.crop.y0 as usize, self.crop.w as usize);
        for (r, row) in self.depth_mm.chunks_exact(w.max(1)).enumerate() {
            let o = (y0 + r) * width + x0;
            out[o..o + w].copy_from_slice(row);
        }
        out
    }

    /// Full-image label map (0 = none outside the crop).
    pub fn full_label(&self, width: usize, height: usize) -> Vec<u8> {
        let mut out = vec![0u8; width * height];
        let (x0, y0, w) = (self.crop.x0 as usize, self.crop.y0 as usize, self.crop.w as usize);
        for (r, row) in self.label.chunks_exact(w.max(1)).enumerate() {
            let o = (y0 + r) * width + x0;
            out[o..o + w].copy_from_slice(row);
        }
        out
    }
}

/// A decoded body file.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyRecord {
    /// Depth of level `k` is `level_scale / k` metres.
    pub level_scale: f32,
    /// Per-body ground truth.
    pub truth: BodyTruth,
    /// The views in order.
    pub views: Vec<ViewRecord>,
}

/// Streams one body file: header and body truth at creation, then one view at a time.
pub struct BodyWriter<W: Write> {
    out: W,
    raw: Vec<u8>,
    views_left: u16,
}

impl<W: Write> BodyWriter<W> {
    /// Start a body file with `n_views` views whose levels decode with `level_scale`.
    pub fn new(
        mut out: W,
        body_index: u32,
        n_views: u16,
        level_scale: f32,
        truth: &BodyTruth,
    ) -> Result<Self> {
        let json = serde_json::to_vec(truth)?;
        out.write_all(BODY_MAGIC)?;
        out.write_all(&VERSION.to_le_bytes())?;
        out.write_all(&n_views.to_le_bytes())?;
        out.write_all(&body_index.to_le_bytes())?;
        out.write_all(&level_scale.to_le_bytes())?;
        out.write_all(&(json.len() as u32).to_le_bytes())?;
        out.write_all(&json)?;
        Ok(BodyWriter {
            out,
            raw: Vec::new(),
            views_left: n_views,
        })
    }

    /// Append one view: `levels` (disparity levels), `label` and `part` are the crop rectangle's pixels, row-major.
    pub fn write_view(
        &mut self,
        truth: &ViewTruth,
        crop: Rect,
        levels: &[u16],
        label: &[u8],
        part: &[u8],
    ) -> Result<()> {
        ensure!(self.views_left > 0, "more views written than announced");
        let n = crop.w as usize * crop.h as usize;
        ensure!(
            levels.len() == n && label.len() == n && part.len() == n,
            "view buffers do not match the crop"
        );
        self.raw.clear();
        self.raw.resize(2 * n, 0);
        let (lo, hi) = self.raw.split_at_mut(n);
        for (r, row) in levels.chunks_exact(crop.w.max(1) as usize).enumerate() {
            let mut prev = 0u16;
            for (c, &d) in row.iter().enumerate() {
                let [l, h] = zigzag(d.wrapping_sub(prev) as i16).to_le_bytes();
                let i = r * crop.w as usize + c;
                lo[i] = l;
                hi[i] = h;
                prev = d;
            }
        }
        self.raw.extend_from_slice(label);
        self.raw.extend_from_slice(part);
        let mut enc = flate2::write::ZlibEncoder::new(Vec::with_capacity(n), Compression::new(2));
        enc.write_all(&self.raw)?;
        let payload = enc.finish()?;
        let json = serde_json::to_vec(truth)?;
        let o = &mut self.out;
        o.write_all(VIEW_MAGIC)?;
        for v in [crop.x0, crop.y0, crop.w, crop.h] {
            o.write_all(&v.to_le_bytes())?;
        }
        o.write_all(&(json.len() as u32).to_le_bytes())?;
        o.write_all(&(payload.len() as u32).to_le_bytes())?;
        o.write_all(&json)?;
        o.write_all(&payload)?;
        self.views_left -= 1;
        Ok(())
    }

    /// Check every announced view was written and flush.
    pub fn finish(mut self) -> Result<W> {
        ensure!(
            self.views_left == 0,
            "{} announced views were not written",
            self.views_left
        );
        self.out.flush()?;
        Ok(self.out)
    }
}

/// Zigzag code of a signed difference (0, −1, 1, −2, … → 0, 1, 2, 3, …): small differences of either sign keep
/// the high byte zero, which deflate then stores almost for free.
fn zigzag(d: i16) -> u16 {
    ((d << 1) ^ (d >> 15)) as u16
}

/// Inverse of [`zigzag`].
fn unzigzag(z: u16) -> i16 {
    ((z >> 1) as i16) ^ -((z & 1) as i16)
}

/// A cursor over the bytes of a file with bounds-checked reads.
struct Cursor<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let Some(s) = self.b.get(self.pos..self.pos.saturating_add(n)) else {
            bail!("truncated at byte {} reading {what} ({n} bytes)", self.pos);
        };
        self.pos += n;
        Ok(s)
    }
    fn u16(&mut self, what: &str) -> Result<u16> {
        Ok(u16::from_le_bytes(self.take(2, what)?.try_into()?))
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into()?))
    }
}

/// Decode a body file held in memory.
pub fn decode_body(bytes: &[u8]) -> Result<BodyRecord> {
    let mut c = Cursor { b: bytes, pos: 0 };
    ensure!(
        c.take(4, "magic")? == BODY_MAGIC,
        "not a supine dataset body file (bad magic)"
    );
    let version = c.u16("version")?;
    ensure!(
        version == VERSION,
        "unsupported body file version {version} (expected {VERSION})"
    );
    let n_views = c.u16("view count")?;
    let _index = c.u32("body index")?;
    let level_scale = f32::from_le_bytes(c.take(4, "level scale")?.try_into()?);
    ensure!(
        level_scale.is_finite() && level_scale > 0.0,
        "bad level scale {level_scale}"
    );
    let json_len = c.u32("body json length")? as usize;
    ensure!(json_len <= MAX_JSON, "body json length {json_len} too large");
    let truth: BodyTruth =
        serde_json::from_slice(c.take(json_len, "body json")?).context("body ground truth")?;
    let mut views = Vec::with_capacity(n_views as usize);
    for v in 0..n_views {
        let start = c.pos;
        ensure!(
            c.take(4, "view magic")? == VIEW_MAGIC,
            "view {v}: bad magic at byte {start}"
        );
        let crop = Rect {
            x0: c.u16("x0")?,
            y0: c.u16("y0")?,
            w: c.u16("w")?,
            h: c.u16("h")?,
        };
        ensure!(
            crop.x0 as usize + crop.w as usize <= 640 && crop.y0 as usize + crop.h as usize <= 480,
            "view {v}: crop outside the image"
        );
        let json_len = c.u32("view json length")? as usize;
        let payload_len = c.u32("payload length")? as usize;
        ensure!(json_len <= MAX_JSON, "view {v}: json length {json_len} too large");
        let truth: ViewTruth = serde_json::from_slice(c.take(json_len, "view json")?)
            .with_context(|| format!("view {v} ground truth"))?;
        let payload = c.take(payload_len, "payload")?;
        let n = crop.w as usize * crop.h as usize;
        let mut raw = Vec::with_capacity(4 * n);
        // `take` bounds the output so a corrupt stream cannot inflate beyond the expected size.
        flate2::read::ZlibDecoder::new(payload)
            .take(4 * n as u64 + 1)
            .read_to_end(&mut raw)
            .with_context(|| format!("view {v}: payload"))?;
        ensure!(
            raw.len() == 4 * n,
            "view {v}: payload holds {} bytes, expected {}",
            raw.len(),
            4 * n
        );
        let mut levels = Vec::with_capacity(n);
        let w = crop.w.max(1) as usize;
        for i in 0..n {
            let d = unzigzag(u16::from_le_bytes([raw[i], raw[n + i]])) as u16;
            let prev = if i % w == 0 { 0 } else { levels[i - 1] };
            levels.push(d.wrapping_add(prev));
        }
        let depth_mm = levels
            .iter()
            .map(|&k| KinectNoise::level_to_mm(level_scale, k))
            .collect();
        views.push(ViewRecord {
            truth,
            crop,
            levels,
            depth_mm,
            label: raw[2 * n..3 * n].to_vec(),
            part: raw[3 * n..].to_vec(),
        });
    }
    ensure!(
        c.pos == bytes.len(),
        "{} trailing bytes after the last view",
        bytes.len() - c.pos
    );
    Ok(BodyRecord {
        level_scale,
        truth,
        views,
    })
}

/// Read and decode a body file.
pub fn read_body_file(path: &std::path::Path) -> Result<BodyRecord> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    decode_body(&bytes).with_context(|| format!("decoding {}", path.display()))
}
