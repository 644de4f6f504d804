//! Just enough OMG CDR (XCDR1, the encoding rosbag2 stores) for `sensor_msgs/msg/Image` and
//! `sensor_msgs/msg/CameraInfo`: decoding for [`super::McapSource`] and encoding for writing test bags.
//!
//! A CDR message starts with a 4-byte encapsulation header (byte 1: 0/2 big-endian, 1/3 little-endian); primitives
//! are aligned to their size counted from the end of that header. Decoding an image costs one pass over its pixels
//! into the caller's buffer; nothing else is allocated (strings are borrowed).

use supine_core::camera::Intrinsics;

use crate::source::{SourceError, SourceErrorKind};

fn corrupt(msg: impl Into<std::borrow::Cow<'static, str>>) -> SourceError {
    SourceError::new(SourceErrorKind::CorruptData, msg)
}

/// A cursor over one CDR message.
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    little: bool,
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8]) -> Result<Self, SourceError> {
        if buf.len() < 4 {
            return Err(corrupt("CDR message shorter than its 4-byte header"));
        }
        let little = match buf[1] {
            0 | 2 => false,
            1 | 3 => true,
            k => return Err(corrupt(format!("unknown CDR encapsulation kind {k}"))),
        };
        Ok(Reader {
            buf: &buf[4..],
            pos: 0,
            little,
        })
    }

    fn align(&mut self, n: usize) {
        self.pos = self.pos.div_ceil(n) * n;
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], SourceError> {
        match self.pos.checked_add(n) {
            Some(end) if end <= self.buf.len() => {
                let s = &self.buf[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            _ => Err(corrupt("CDR message truncated")),
        }
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], SourceError> {
        self.align(N);
        let mut b = [0u8; N];
        b.copy_from_slice(self.take(N)?);
        Ok(b)
    }

    fn u8(&mut self) -> Result<u8, SourceError> {
        Ok(self.take(1)?[0])
    }

    fn u32(&mut self) -> Result<u32, SourceError> {
        let b = self.array::<4>()?;
        Ok(if self.little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    }

    fn i32(&mut self) -> Result<i32, SourceError> {
        Ok(self.u32()? as i32)
    }

    fn f64(&mut self) -> Result<f64, SourceError> {
        let b = self.array::<8>()?;
        Ok(if self.little {
            f64::from_le_bytes(b)
        } else {
            f64::from_be_bytes(b)
        })
    }

    fn string(&mut self) -> Result<&'a str, SourceError> {
        let n = self.u32()? as usize;
        let s = self.take(n)?;
        let s = s.strip_suffix(&[0]).unwrap_or(s);
        std::str::from_utf8(s).map_err(|_| corrupt("CDR string is not UTF-8"))
    }

    /// `std_msgs/msg/Header`: the stamp in ns since the epoch (negative seconds are corrupt) and the frame id.
    fn header(&mut self) -> Result<(u64, &'a str), SourceError> {
        let sec = self.i32()?;
        let nsec = self.u32()?;
        let frame_id = self.string()?;
        if sec < 0 || nsec >= 1_000_000_000 {
            return Err(corrupt(format!("header stamp {sec} s {nsec} ns is invalid")));
        }
        Ok((sec as u64 * 1_000_000_000 + nsec as u64, frame_id))
    }
}

/// The pixel layout of a depth image message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthEncoding {
    /// `16UC1` (or `mono16`): u16 millimetres, 0 = no depth.
    Mm16,
    /// `32FC1`: f32 metres, NaN, infinities and non-positive values = no depth.
    Metres32,
}

impl DepthEncoding {
    /// The ROS encoding string.
    pub fn as_str(self) -> &'static str {
        match self {
            DepthEncoding::Mm16 => "16UC1",
            DepthEncoding::Metres32 => "32FC1",
        }
    }

    fn bytes_per_pixel(self) -> usize {
        match self {
            DepthEncoding::Mm16 => 2,
            DepthEncoding::Metres32 => 4,
        }
    }
}

/// What [`decode_depth_image`] read besides the pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageInfo {
    /// Header stamp, ns since the epoch (0 when the publisher left it unset).
    pub stamp_ns: u64,
    /// Width in pixels.
    pub width: u16,
    /// Height in pixels.
    pub height: u16,
    /// Pixel encoding.
    pub encoding: DepthEncoding,
}

/// The largest image side accepted (a larger one is a corrupt message, not a reason to allocate gigabytes).
pub const MAX_SIDE: u32 = 4096;

/// Decode a `sensor_msgs/msg/Image` of encoding 16UC1/mono16 (mm) or 32FC1 (m → mm, rounded, saturating at
/// 65535) into `out`, which is resized to width × height (it allocates only when the size grows).
pub fn decode_depth_image(data: &[u8], out: &mut Vec<u16>) -> Result<ImageInfo, SourceError> {
    let mut r = Reader::new(data)?;
    let (stamp_ns, _frame_id) = r.header()?;
    let height = r.u32()?;
    let width = r.u32()?;
    let encoding = match r.string()? {
        "16UC1" | "mono16" => DepthEncoding::Mm16,
        "32FC1" => DepthEncoding::Metres32,
        other => {
            return Err(SourceError::new(
                SourceErrorKind::Unsupported,
                format!("image encoding {other:?} is not depth (expected 16UC1 or 32FC1)"),
            ));
        }
    };
    let big_endian = r.u8()? != 0;
    let step = r.u32()? as usize;
    let len = r.u32()? as usize;
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(corrupt(format!(
            "image size {width}x{height} (each side 1..={MAX_SIDE})"
        )));
    }
    let (w, h) = (width as usize, height as usize);
    let bpp = encoding.bytes_per_pixel();
    if step < w * bpp {
        return Err(corrupt(format!(
            "row step {step} B is shorter than {w} pixels of {bpp} B"
        )));
    }
    // The last row needs only its pixels, not the full step.
    let needed = step * (h - 1) + w * bpp;
    if len < needed {
        return Err(corrupt(format!(
            "image data holds {len} B, {needed} B needed for {w}x{h} {}",
            encoding.as_str()
        )));
    }
    let px = r.take(len)?;
    out.clear();
    out.reserve(w * h);
    for y in 0..h {
        let row = &px[y * step..y * step + w * bpp];
        match encoding {
            DepthEncoding::Mm16 => out.extend(row.chunks_exact(2).map(|c| {
                let b = [c[0], c[1]];
                if big_endian {
                    u16::from_be_bytes(b)
                } else {
                    u16::from_le_bytes(b)
                }
            })),
            DepthEncoding::Metres32 => out.extend(row.chunks_exact(4).map(|c| {
                let b = [c[0], c[1], c[2], c[3]];
                let m = if big_endian {
                    f32::from_be_bytes(b)
                } else {
                    f32::from_le_bytes(b)
                };
                metres_to_mm(m)
            })),
        }
    }
    Ok(ImageInfo {
        stamp_ns,
        width: width as u16,
        height: height as u16,
        encoding,
    })
}

/// One 32FC1 depth value in mm: rounded, saturating, 0 for no depth.
fn metres_to_mm(m: f32) -> u16 {
    if m.is_finite() && m > 0.0 {
        (m * 1000.0).round().min(65535.0) as u16
    } else {
        0
    }
}

/// The pinhole of a `sensor_msgs/msg/CameraInfo` (its K matrix) with its image size.
pub fn decode_camera_info(data: &[u8]) -> Result<Intrinsics, SourceError> {
    let mut r = Reader::new(data)?;
    r.header()?;
    let height = r.u32()?;
    let width = r.u32()?;
    r.string()?; // distortion_model: depth images of a Kinect are used as they come (no undistortion)
    let nd = r.u32()? as usize;
    if nd > 64 {
        return Err(corrupt(format!("camera info with {nd} distortion coefficients")));
    }
    for _ in 0..nd {
        r.f64()?;
    }
    let mut k = [0f64; 9];
    for v in &mut k {
        *v = r.f64()?;
    }
    // Checked as the f32 the pipeline uses: a tiny or huge f64 must not become 0 or infinity.
    let (fx, fy, cx, cy) = (k[0] as f32, k[4] as f32, k[2] as f32, k[5] as f32);
    let positive = |v: f32| v.is_finite() && v > 0.0;
    if !(positive(fx) && positive(fy) && cx.is_finite() && cy.is_finite()) {
        return Err(corrupt(format!(
            "camera info with focal lengths {} and {}, principal point ({}, {})",
            k[0], k[4], k[2], k[5]
        )));
    }
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(corrupt(format!("camera info image size {width}x{height}")));
    }
    Ok(Intrinsics {
        fx,
        fy,
        cx,
        cy,
        width: width as u16,
        height: height as u16,
    })
}

/// A little-endian CDR writer (what rosbag2 writes), for bags made by tests and tools.
struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    fn new() -> Self {
        Writer {
            buf: vec![0, 1, 0, 0],
        }
    }
    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - 4;
        self.buf.resize(4 + pos.div_ceil(n) * n, 0);
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    fn header(&mut self, stamp_ns: u64, frame_id: &str) {
        self.u32((stamp_ns / 1_000_000_000) as u32);
        self.u32((stamp_ns % 1_000_000_000) as u32);
        self.string(frame_id);
    }
}

/// Encode a 16UC1 `sensor_msgs/msg/Image` (little-endian, packed rows).
pub fn encode_image_16uc1(
    stamp_ns: u64,
    frame_id: &str,
    width: u32,
    height: u32,
    depth_mm: &[u16],
) -> Vec<u8> {
    let mut w = Writer::new();
    w.header(stamp_ns, frame_id);
    w.u32(height);
    w.u32(width);
    w.string("16UC1");
    w.buf.push(0); // is_bigendian
    w.u32(width * 2);
    w.u32(depth_mm.len() as u32 * 2);
    for d in depth_mm {
        w.buf.extend_from_slice(&d.to_le_bytes());
    }
    w.buf
}

/// Encode a 32FC1 `sensor_msgs/msg/Image` (little-endian, packed rows) from metres.
pub fn encode_image_32fc1(
    stamp_ns: u64,
    frame_id: &str,
    width: u32,
    height: u32,
    depth_m: &[f32],
) -> Vec<u8> {
    let mut w = Writer::new();
    w.header(stamp_ns, frame_id);
    w.u32(height);
    w.u32(width);
    w.string("32FC1");
    w.buf.push(0);
    w.u32(width * 4);
    w.u32(depth_m.len() as u32 * 4);
    for d in depth_m {
        w.buf.extend_from_slice(&d.to_le_bytes());
    }
    w.buf
}

/// Encode a `sensor_msgs/msg/CameraInfo` with the pinhole `k` (no distortion, identity R, P = [K | 0]).
pub fn encode_camera_info(stamp_ns: u64, frame_id: &str, k: &Intrinsics) -> Vec<u8> {
    let mut w = Writer::new();
    w.header(stamp_ns, frame_id);
    w.u32(k.height as u32);
    w.u32(k.width as u32);
    w.string("plumb_bob");
    w.u32(5);
    for _ in 0..5 {
        w.f64(0.0);
    }
    let (fx, fy, cx, cy) = (k.fx as f64, k.fy as f64, k.cx as f64, k.cy as f64);
    for v in [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
    for v in [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
    for v in [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0] {
        w.f64(v);
    }
    w.u32(0); // binning_x
    w.u32(0); // binning_y
    for _ in 0..4 {
        w.u32(0); // roi x, y, height, width
    }
    w.buf.push(0); // roi.do_rectify
    w.buf
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_16uc1_round_trips() {
        let px: Vec<u16> = (0..12).map(|i| i * 100).collect();
        let msg = encode_image_16uc1(1_700_000_000_123_456_789, "camera", 4, 3, &px);
        let mut out = Vec::new();
        let info = decode_depth_image(&msg, &mut out).unwrap();
        assert_eq!(out, px);
        assert_eq!(
            (info.width, info.height, info.encoding),
            (4, 3, DepthEncoding::Mm16)
        );
        assert_eq!(info.stamp_ns, 1_700_000_000_123_456_789);
    }

    #[test]
    fn image_32fc1_becomes_rounded_mm_with_no_depth_for_nan() {
        let m = [1.2344f32, 0.0, f32::NAN, -1.0, 70.0, f32::INFINITY];
        let msg = encode_image_32fc1(5, "", 3, 2, &m);
        let mut out = Vec::new();
        let info = decode_depth_image(&msg, &mut out).unwrap();
        assert_eq!(info.encoding, DepthEncoding::Metres32);
        assert_eq!(out, [1234, 0, 0, 0, 65535, 0]);
    }

    #[test]
    fn every_truncation_is_an_error_not_a_panic() {
        let px = [7u16; 6];
        let msg = encode_image_16uc1(1, "cam", 3, 2, &px);
        let mut out = Vec::new();
        for n in 0..msg.len() {
            let e = decode_depth_image(&msg[..n], &mut out).unwrap_err();
            assert_eq!(e.kind(), SourceErrorKind::CorruptData, "cut at {n}: {e}");
        }
        let info = encode_camera_info(1, "cam", &Intrinsics::KINECT_V1);
        // Decoding stops after K: the 4-byte header and 160 bytes of payload up to K's last element.
        for n in 0..164 {
            assert!(decode_camera_info(&info[..n]).is_err(), "cut at {n}");
        }
        assert!(decode_camera_info(&info[..164]).is_ok());
    }

    #[test]
    fn colour_images_are_unsupported_and_named() {
        let mut msg = encode_image_16uc1(1, "cam", 1, 1, &[1]);
        // Rewrite the encoding string "16UC1" as "rgb8\0" (same length with its terminator).
        let at = msg.windows(5).position(|w| w == b"16UC1").unwrap();
        msg[at..at + 5].copy_from_slice(b"rgb8\0");
        let e = decode_depth_image(&msg, &mut Vec::new()).unwrap_err();
        assert_eq!(e.kind(), SourceErrorKind::Unsupported);
        assert!(e.to_string().contains("rgb8"), "{e}");
    }

    #[test]
    fn absurd_sizes_are_refused_before_allocating() {
        let mut msg = encode_image_16uc1(1, "cam", 1, 1, &[1]);
        // height is the first u32 after the header: stamp (8) + frame_id len (4) + "cam\0" (4) = offset 16 + 4.
        msg[4 + 16..4 + 20].copy_from_slice(&100_000u32.to_le_bytes());
        let e = decode_depth_image(&msg, &mut Vec::new()).unwrap_err();
        assert!(e.to_string().contains("image size"), "{e}");
    }

    #[test]
    fn camera_info_with_a_focal_length_that_is_zero_as_f32_is_corrupt() {
        let k = Intrinsics {
            fx: 1.0,
            ..Intrinsics::KINECT_V1
        };
        let mut msg = encode_camera_info(1, "cam", &k);
        // K[0] is at payload offset 88 (after the header, the size, the model name and 5 distortion f64s).
        let at = 4 + 88;
        assert_eq!(f64::from_le_bytes(msg[at..at + 8].try_into().unwrap()), 1.0);
        msg[at..at + 8].copy_from_slice(&1e-300f64.to_le_bytes());
        let e = decode_camera_info(&msg).unwrap_err();
        assert!(e.to_string().contains("focal lengths"), "{e}");
    }

    /// What the fuzz target `ros_bag_cdr` checks, on valid messages damaged by a seeded generator (2000 cases):
    /// decode or a clear error, the pixel count matching the size reported.
    #[test]
    fn damaged_messages_decode_or_fail_cleanly() {
        let mut valid = encode_image_16uc1(7, "cam", 5, 4, &[900; 20]);
        valid.extend(encode_camera_info(7, "cam", &Intrinsics::KINECT_V1));
        // xorshift64*, seeded: the same cases every run.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            state.wrapping_mul(0x2545_f491_4f6c_dd1d)
        };
        for _ in 0..2000 {
            let mut msg = valid.clone();
            for _ in 0..1 + next() % 8 {
                let at = next() as usize % msg.len();
                msg[at] ^= next() as u8 | 1;
            }
            msg.truncate(1 + next() as usize % msg.len());
            let mut px = Vec::new();
            if let Ok(info) = decode_depth_image(&msg, &mut px) {
                assert_eq!(px.len(), info.width as usize * info.height as usize);
            }
            if let Ok(k) = decode_camera_info(&msg) {
                assert!(k.fx > 0.0 && k.fy > 0.0 && k.width > 0 && k.height > 0);
            }
        }
    }

    #[test]
    fn camera_info_round_trips() {
        let k = Intrinsics {
            fx: 537.03,
            fy: 537.56,
            cx: 320.66,
            cy: 227.7,
            width: 640,
            height: 480,
        };
        assert_eq!(decode_camera_info(&encode_camera_info(9, "cam", &k)).unwrap(), k);
    }
}
