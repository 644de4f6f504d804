//! Where the noise report's depth frames come from: a directory (or file) of 16-bit depth PNGs (mm), OpenNI `.oni`
//! recordings, ROS 2 MCAP bags (`sensor_msgs/msg/Image` 16UC1 or 32FC1), a synthetic dataset (`dataset.json`: the
//! stored crops) or a synthetic sequence (`sequence.json` + `sequence.oni`). Each frame is measured as it is read
//! ([`super::stats::measure`]), so memory stays at one frame.
//!
//! Cost: decoding only (PNG inflate, 16zT, zstd, or a body file per dataset body).

use super::stats::{Counts, Frame, Window, measure};
use anyhow::{Context, Result, bail, ensure};
use std::path::{Path, PathBuf};
use supine_core::camera::Intrinsics;
use supine_drivers::DepthSource;

/// What a source held: its description and one [`Counts`] per frame measured.
#[derive(Debug, Clone)]
pub struct Measured {
    /// What was read (kind and path).
    pub description: String,
    /// Per-frame counts, in reading order.
    pub frames: Vec<Counts>,
}

/// Measure up to `max_frames` frames of `path` inside `window`. `camera` is used for depth images that carry no
/// intrinsics (PNGs); the other kinds bring their own.
pub fn measure_source(
    path: &Path,
    camera: Intrinsics,
    window: Window,
    max_frames: usize,
) -> Result<Measured> {
    ensure!(path.exists(), "{} does not exist", path.display());
    let mut frames = Vec::new();
    let description;
    if path.join("dataset.json").is_file() {
        description = format!("synthetic dataset {}", path.display());
        measure_dataset(path, window, max_frames, &mut frames)?;
    } else if path.join("sequence.json").is_file() {
        description = format!("synthetic sequence {}", path.display());
        measure_oni(&path.join("sequence.oni"), window, max_frames, &mut frames)?;
    } else {
        let files = depth_files(path)?;
        ensure!(
            !files.is_empty(),
            "{} holds no depth PNG, .oni or .mcap file, dataset.json or sequence.json",
            path.display()
        );
        description = format!("{} file(s) from {}", files.len(), path.display());
        for f in files {
            if frames.len() >= max_frames {
                break;
            }
            match f
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .as_deref()
            {
                Some("png") => {
                    let (w, h, px) = crate::render::noise::read_depth_png(&f)?;
                    frames.push(measure(&full_frame(&px, w, h, camera), window));
                }
                Some("oni") => measure_oni(&f, window, max_frames, &mut frames)?,
                Some("mcap") => measure_mcap(&f, camera, window, max_frames, &mut frames)?,
                _ => unreachable!("depth_files keeps only these"),
            }
        }
    }
    ensure!(!frames.is_empty(), "{}: no frame measured", path.display());
    Ok(Measured { description, frames })
}

fn full_frame(px: &[u16], w: usize, h: usize, camera: Intrinsics) -> Frame<'_> {
    Frame {
        depth: px,
        w,
        h,
        x0: 0,
        y0: 0,
        full: true,
        camera,
    }
}

/// The depth files of `path` (itself if a file), sorted by name.
fn depth_files(path: &Path) -> Result<Vec<PathBuf>> {
    let keep = |p: &Path| {
        matches!(
            p.extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .as_deref(),
            Some("png" | "oni" | "mcap")
        )
    };
    if path.is_file() {
        ensure!(keep(path), "{} is not a .png, .oni or .mcap file", path.display());
        return Ok(vec![path.to_path_buf()]);
    }
    let mut out: Vec<PathBuf> = std::fs::read_dir(path)
        .with_context(|| format!("listing {}", path.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && keep(p))
        .collect();
    out.sort();
    Ok(out)
}

fn measure_dataset(dir: &Path, window: Window, max_frames: usize, out: &mut Vec<Counts>) -> Result<()> {
    let ds = crate::dataset::Dataset::open(dir)?;
    let k = ds.manifest.intrinsics;
    let camera = Intrinsics {
        fx: k[0],
        fy: k[1],
        cx: k[2],
        cy: k[3],
        width: k[4] as u16,
        height: k[5] as u16,
    };
    let mut ids: Vec<u32> = ds.train.iter().chain(&ds.test).copied().collect();
    ids.sort_unstable();
    for i in ids {
        let rec = ds.read_body(i)?;
        for v in &rec.views {
            if out.len() >= max_frames {
                return Ok(());
            }
            let frame = Frame {
                depth: &v.depth_mm,
                w: v.crop.w as usize,
                h: v.crop.h as usize,
                x0: v.crop.x0 as usize,
                y0: v.crop.y0 as usize,
                full: v.crop.w == camera.width && v.crop.h == camera.height,
                camera,
            };
            out.push(measure(&frame, window));
        }
    }
    Ok(())
}

fn measure_oni(path: &Path, window: Window, max_frames: usize, out: &mut Vec<Counts>) -> Result<()> {
    let mut reader =
        supine_drivers::oni::OniReader::open(path).with_context(|| format!("opening {}", path.display()))?;
    let camera = reader.intrinsics();
    while out.len() < max_frames {
        match reader.read_frame() {
            Ok(f) => {
                let (w, h) = (f.width() as usize, f.height() as usize);
                out.push(measure(&full_frame(f.depth_mm(), w, h, camera), window));
            }
            Err(e) if e.kind() == supine_drivers::SourceErrorKind::EndOfStream => break,
            Err(e) => return Err(anyhow::anyhow!("reading {}: {e}", path.display())),
        }
    }
    Ok(())
}

/// ROS 2 bags: every `sensor_msgs/msg/Image` message with encoding 16UC1 (mm) or 32FC1 (m); intrinsics from a
/// `sensor_msgs/msg/CameraInfo` message when the bag has one (else `camera`).
fn measure_mcap(
    path: &Path,
    camera: Intrinsics,
    window: Window,
    max_frames: usize,
    out: &mut Vec<Counts>,
) -> Result<()> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut images = Vec::new();
    let mut info = None;
    for msg in mcap::MessageStream::new(&bytes).with_context(|| format!("parsing {}", path.display()))? {
        let msg = msg.with_context(|| format!("parsing {}", path.display()))?;
        let schema = msg.channel.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("");
        match schema {
            "sensor_msgs/msg/Image" => images.push(msg.data.into_owned()),
            "sensor_msgs/msg/CameraInfo" if info.is_none() => info = Some(cdr::camera_info(&msg.data)?),
            _ => {}
        }
    }
    ensure!(
        !images.is_empty(),
        "{} has no sensor_msgs/msg/Image message",
        path.display()
    );
    for data in images {
        if out.len() >= max_frames {
            break;
        }
        let img =
            cdr::depth_image(&data).with_context(|| format!("decoding an image of {}", path.display()))?;
        let mut k = info.unwrap_or(camera);
        k.width = img.width as u16;
        k.height = img.height as u16;
        out.push(measure(
            &full_frame(&img.depth_mm, img.width, img.height, k),
            window,
        ));
    }
    Ok(())
}

/// Just enough CDR (little- or big-endian, as the encapsulation header says) for depth images and camera info.
mod cdr {
    use anyhow::{Result, bail, ensure};
    use supine_core::camera::Intrinsics;

    struct Reader<'a> {
        buf: &'a [u8],
        pos: usize,
        little: bool,
    }

    impl<'a> Reader<'a> {
        fn new(buf: &'a [u8]) -> Result<Self> {
            ensure!(buf.len() >= 4, "CDR message shorter than its header");
            let little = match buf[1] {
                0 | 2 => false,
                1 | 3 => true,
                k => bail!("unknown CDR encapsulation {k}"),
            };
            // Alignment counts from the end of the 4-byte encapsulation header.
            Ok(Reader {
                buf: &buf[4..],
                pos: 0,
                little,
            })
        }
        fn align(&mut self, n: usize) {
            self.pos = self.pos.div_ceil(n) * n;
        }
        fn take(&mut self, n: usize) -> Result<&'a [u8]> {
            ensure!(self.pos + n <= self.buf.len(), "CDR message truncated");
            let s = &self.buf[self.pos..self.pos + n];
            self.pos += n;
            Ok(s)
        }
        fn u32(&mut self) -> Result<u32> {
            self.align(4);
            let b: [u8; 4] = self.take(4)?.try_into()?;
            Ok(if self.little {
                u32::from_le_bytes(b)
            } else {
                u32::from_be_bytes(b)
            })
        }
        fn f64(&mut self) -> Result<f64> {
            self.align(8);
            let b: [u8; 8] = self.take(8)?.try_into()?;
            Ok(if self.little {
                f64::from_le_bytes(b)
            } else {
                f64::from_be_bytes(b)
            })
        }
        fn string(&mut self) -> Result<String> {
            let n = self.u32()? as usize;
            let s = self.take(n)?;
            Ok(String::from_utf8_lossy(s.strip_suffix(&[0]).unwrap_or(s)).into_owned())
        }
        fn header(&mut self) -> Result<()> {
            self.u32()?; // stamp.sec
            self.u32()?; // stamp.nanosec
            self.string()?; // frame_id
            Ok(())
        }
    }

    /// A decoded depth image in millimetres.
    pub struct DepthImage {
        pub width: usize,
        pub height: usize,
        pub depth_mm: Vec<u16>,
    }

    /// Decode a `sensor_msgs/msg/Image` of encoding 16UC1 (mm) or 32FC1 (metres, NaN = none).
    pub fn depth_image(data: &[u8]) -> Result<DepthImage> {
        let mut r = Reader::new(data)?;
        r.header()?;
        let (height, width) = (r.u32()? as usize, r.u32()? as usize);
        let encoding = r.string()?;
        let big = r.take(1)?[0] != 0;
        let step = r.u32()? as usize;
        let n = r.u32()? as usize;
        let px = r.take(n)?;
        ensure!(
            width > 0 && height > 0 && width <= 4096 && height <= 4096,
            "image size {width}x{height}"
        );
        let bpp = match encoding.as_str() {
            "16UC1" | "mono16" => 2,
            "32FC1" => 4,
            other => bail!("depth encoding {other:?} (expected 16UC1 or 32FC1)"),
        };
        ensure!(
            step >= width * bpp && n >= step * height,
            "image data shorter than {height} rows of {step} B"
        );
        let mut depth_mm = Vec::with_capacity(width * height);
        for y in 0..height {
            for c in px[y * step..y * step + width * bpp].chunks_exact(bpp) {
                depth_mm.push(if bpp == 2 {
                    let b = [c[0], c[1]];
                    if big {
                        u16::from_be_bytes(b)
                    } else {
                        u16::from_le_bytes(b)
                    }
                } else {
                    let b = [c[0], c[1], c[2], c[3]];
                    let m = if big {
                        f32::from_be_bytes(b)
                    } else {
                        f32::from_le_bytes(b)
                    };
                    if m.is_finite() && m > 0.0 {
                        (m * 1000.0).round().min(65535.0) as u16
                    } else {
                        0
                    }
                });
            }
        }
        Ok(DepthImage {
            width,
            height,
            depth_mm,
        })
    }

    /// The pinhole of a `sensor_msgs/msg/CameraInfo` (K), with its image size.
    pub fn camera_info(data: &[u8]) -> Result<Intrinsics> {
        let mut r = Reader::new(data)?;
        r.header()?;
        let (height, width) = (r.u32()?, r.u32()?);
        r.string()?; // distortion_model
        let nd = r.u32()? as usize;
        ensure!(nd <= 64, "{nd} distortion coefficients");
        for _ in 0..nd {
            r.f64()?;
        }
        let mut k = [0f64; 9];
        for v in &mut k {
            *v = r.f64()?;
        }
        ensure!(
            k[0] > 0.0 && k[4] > 0.0,
            "camera info with focal lengths {} and {}",
            k[0],
            k[4]
        );
        Ok(Intrinsics {
            fx: k[0] as f32,
            fy: k[4] as f32,
            cx: k[2] as f32,
            cy: k[5] as f32,
            width: width as u16,
            height: height as u16,
        })
    }
}

/// Refuse a path that is none of the supported kinds (used by the CLI for a clear message).
pub fn check_kind(path: &Path) -> Result<()> {
    if path.join("dataset.json").is_file() || path.join("sequence.json").is_file() {
        return Ok(());
    }
    if depth_files(path)?.is_empty() {
        bail!(
            "{} holds no depth PNG, .oni or .mcap file, dataset.json or sequence.json",
            path.display()
        );
    }
    Ok(())
}
