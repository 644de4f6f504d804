//! The .oni reader: a [`DepthSource`] over a file (see the [module docs](super)).

use std::fs::File;
use std::io::{BufReader, ErrorKind as IoKind, Read, Seek};
use std::path::Path;
use std::time::Duration;

use supine_core::camera::{Intrinsics, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD};
use supine_core::depth::DepthFrame;

use super::codec::{decode_16z, decode_16z_table, decode_raw};
use super::{
    Codec, FILE_HEADER_LEN, FILE_MAGIC, MAX_FIELDS, MAX_PAYLOAD, NODE_TYPE_DEPTH, PIXEL_FORMAT_DEPTH_1_MM,
    PIXEL_FORMAT_DEPTH_100_UM, RECORD_HEADER_LEN, RECORD_MAGIC, record_type as rt,
};
use crate::source::{DepthSource, SourceError, SourceErrorKind, capture_time};

/// What an .oni file says about its depth stream.
#[derive(Debug, Clone, PartialEq)]
pub struct OniInfo {
    /// File version (major, minor, maintenance, build).
    pub version: (u8, u8, u16, u32),
    /// The node id of the depth stream read.
    pub node_id: u32,
    /// The depth codec.
    pub codec: Codec,
    /// Image width, pixels (`xnMapOutputMode`).
    pub width: u16,
    /// Image height, pixels.
    pub height: u16,
    /// Nominal frame rate.
    pub fps: u32,
    /// Fields of view in radians (`xnFOV`), if the file has them.
    pub fov_rad: Option<(f64, f64)>,
    /// `xnDeviceMaxDepth`, if present.
    pub max_depth: Option<u64>,
    /// `oniPixelFormat` (100 = 1 mm, 101 = 100 µm).
    pub pixel_format: u64,
    /// Frame count from NODE_ADDED; `None` for a file that was never finished (the Recorder's UINT32_MAX).
    pub frames: Option<u32>,
}

/// Reads the first depth stream of an .oni file, frame by frame.
pub struct OniReader<R: Read + Seek = BufReader<File>> {
    input: R,
    pos: u64,
    info: OniInfo,
    name: String,
    depth: Vec<u16>,
    payload: Vec<u8>,
    fields: Vec<u8>,
    max_payload: usize,
    done: bool,
    /// Frames of our node returned so far.
    frames_read: u32,
    /// Records skipped because their type is none OpenNI writes (a corrupt header).
    unknown_records: u32,
}

impl<R: Read + Seek> std::fmt::Debug for OniReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OniReader")
            .field("name", &self.name)
            .field("info", &self.info)
            .field("pos", &self.pos)
            .finish()
    }
}

/// Every record type OpenNI writes; any other is a damaged header.
const KNOWN_RECORDS: [u32; 13] = [
    rt::NODE_ADDED_1_0_0_4,
    rt::INT_PROPERTY,
    rt::REAL_PROPERTY,
    rt::STRING_PROPERTY,
    rt::GENERAL_PROPERTY,
    rt::NODE_REMOVED,
    rt::NODE_DATA_BEGIN,
    rt::NODE_STATE_READY,
    rt::NEW_DATA,
    rt::END,
    rt::NODE_ADDED_1_0_0_5,
    rt::NODE_ADDED,
    rt::SEEK_TABLE,
];

/// A parsed record header.
#[derive(Debug, Clone, Copy)]
struct RecordHeader {
    kind: u32,
    node: u32,
    fields_len: usize,
    payload_len: usize,
}

/// The stream description gathered while reading records before the first frame.
#[derive(Default)]
struct Pending {
    node: Option<(u32, Codec, Option<u32>)>,
    mode: Option<(u32, u32, u32)>,
    fov: Option<(f64, f64)>,
    max_depth: Option<u64>,
    pixel_format: Option<u64>,
    cropping_enabled: bool,
}

impl OniReader<BufReader<File>> {
    /// Open an .oni file and read its stream description (up to the first frame).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, SourceError> {
        let path = path.as_ref();
        let file = File::open(path).map_err(|e| SourceError::io(format!("opening {}", path.display()), e))?;
        OniReader::new(
            BufReader::with_capacity(1 << 16, file),
            path.display().to_string(),
        )
        .map_err(|e| e.context(path.display()))
    }
}

impl<R: Read + Seek> OniReader<R> {
    /// Read an .oni stream from `input` (positioned at the file header); `name` appears in messages.
    pub fn new(mut input: R, name: impl Into<String>) -> Result<Self, SourceError> {
        let name = name.into();
        let mut header = [0u8; FILE_HEADER_LEN];
        read_exact_or(&mut input, &mut header, 0, "the file header")?;
        if header[0..4] != FILE_MAGIC {
            return Err(SourceError::new(
                SourceErrorKind::CorruptData,
                format!(
                    "not an .oni file: magic {:02x?}, expected \"NI10\"",
                    &header[0..4]
                ),
            ));
        }
        let version = (
            header[4],
            header[5],
            u16::from_le_bytes([header[6], header[7]]),
            le_u32(&header[8..12]),
        );
        if (version.0, version.1, version.2) != (1, 0, 1) {
            return Err(SourceError::new(
                SourceErrorKind::Unsupported,
                format!(
                    ".oni file version {}.{}.{}.{} is not supported (only 1.0.1.x, what OpenNI2 writes)",
                    version.0, version.1, version.2, version.3
                ),
            ));
        }
        let mut reader = OniReader {
            input,
            pos: FILE_HEADER_LEN as u64,
            info: OniInfo {
                version,
                node_id: 0,
                codec: Codec::None,
                width: 0,
                height: 0,
                fps: 0,
                fov_rad: None,
                max_depth: None,
                pixel_format: PIXEL_FORMAT_DEPTH_1_MM,
                frames: None,
            },
            name,
            depth: Vec::new(),
            payload: Vec::new(),
            fields: Vec::with_capacity(4096),
            max_payload: 0,
            done: false,
            frames_read: 0,
            unknown_records: 0,
        };
        reader.read_description()?;
        Ok(reader)
    }

    /// The stream description.
    pub fn info(&self) -> &OniInfo {
        &self.info
    }

    /// Read records up to the first frame of the first depth node, collecting its description.
    fn read_description(&mut self) -> Result<(), SourceError> {
        let mut p = Pending::default();
        loop {
            let start = self.pos;
            let Some(h) = self.read_header()? else {
                return Err(self.corrupt(start, "file ends before the first depth frame"));
            };
            let ours = p.node.map(|n| n.0) == Some(h.node);
            match h.kind {
                rt::NODE_ADDED | rt::NODE_ADDED_1_0_0_5 | rt::NODE_ADDED_1_0_0_4 if p.node.is_none() => {
                    self.read_fields(&h, start)?;
                    self.skip(h.payload_len)?;
                    let f = Fields::new(&self.fields);
                    let parsed = (|| {
                        let _name = f.string(0)?;
                        let at = 4usize.saturating_add(le_u32(f.get(0, 4)?) as usize);
                        let node_type = le_u32(f.get(at, 4)?) as i32;
                        let fourcc: [u8; 4] = f.get(at.saturating_add(4), 4)?.try_into().ok()?;
                        let frames = if h.kind == rt::NODE_ADDED_1_0_0_4 {
                            None
                        } else {
                            Some(le_u32(f.get(at.saturating_add(8), 4)?))
                        };
                        Some((node_type, fourcc, frames))
                    })();
                    let Some((node_type, fourcc, frames)) = parsed else {
                        return Err(self.corrupt(start, "malformed NODE_ADDED record"));
                    };
                    if node_type == NODE_TYPE_DEPTH {
                        let codec = Codec::from_fourcc(fourcc).ok_or_else(|| {
                            SourceError::new(
                                SourceErrorKind::Unsupported,
                                format!(
                                    "depth codec {:?} is not supported (NONE, 16zP, 16zT are)",
                                    String::from_utf8_lossy(&fourcc)
                                ),
                            )
                        })?;
                        p.node = Some((h.node, codec, frames.filter(|&n| n != u32::MAX)));
                    }
                }
                rt::INT_PROPERTY | rt::REAL_PROPERTY | rt::GENERAL_PROPERTY if ours => {
                    self.read_fields(&h, start)?;
                    self.skip(h.payload_len)?;
                    let Some((name, data)) = Fields::new(&self.fields).property() else {
                        return Err(self.corrupt(start, "malformed property record"));
                    };
                    let int = || data.try_into().ok().map(u64::from_le_bytes);
                    match (h.kind, name) {
                        (rt::GENERAL_PROPERTY, b"xnMapOutputMode") if data.len() >= 12 => {
                            p.mode = Some((le_u32(&data[0..4]), le_u32(&data[4..8]), le_u32(&data[8..12])));
                        }
                        (rt::GENERAL_PROPERTY, b"xnFOV") if data.len() == 16 => {
                            let h = f64::from_le_bytes(data[0..8].try_into().unwrap_or_default());
                            let v = f64::from_le_bytes(data[8..16].try_into().unwrap_or_default());
                            p.fov = Some((h, v));
                        }
                        (rt::GENERAL_PROPERTY, b"xnCropping") if data.len() >= 4 => {
                            p.cropping_enabled = le_u32(&data[0..4]) != 0;
                        }
                        (rt::INT_PROPERTY, b"xnDeviceMaxDepth") => p.max_depth = int(),
                        (rt::INT_PROPERTY, b"oniPixelFormat") => p.pixel_format = int(),
                        _ => {}
                    }
                }
                rt::NEW_DATA | rt::NODE_DATA_BEGIN if ours => {
                    if h.kind == rt::NEW_DATA {
                        // Rewind so that next_frame reads this frame.
                        self.seek_to(start)?;
                    } else {
                        self.skip(h.fields_len + h.payload_len)?;
                    }
                    return self.finish_description(p, start);
                }
                rt::END => return Err(self.corrupt(start, "the file has no depth stream with frames")),
                _ => self.skip(h.fields_len + h.payload_len)?,
            }
        }
    }

    fn finish_description(&mut self, p: Pending, at: u64) -> Result<(), SourceError> {
        let Some((node_id, codec, frames)) = p.node else {
            return Err(self.corrupt(at, "no depth node"));
        };
        let Some((w, h, fps)) = p.mode else {
            return Err(self.corrupt(at, "the depth stream has no xnMapOutputMode"));
        };
        if w == 0 || h == 0 || w > 1600 || h > 1200 {
            return Err(self.corrupt(at, &format!("implausible depth resolution {w}x{h}")));
        }
        if p.cropping_enabled {
            return Err(SourceError::new(
                SourceErrorKind::Unsupported,
                "cropped .oni depth streams are not supported",
            ));
        }
        let pixel_format = p.pixel_format.unwrap_or(PIXEL_FORMAT_DEPTH_1_MM);
        if pixel_format != PIXEL_FORMAT_DEPTH_1_MM && pixel_format != PIXEL_FORMAT_DEPTH_100_UM {
            return Err(SourceError::new(
                SourceErrorKind::Unsupported,
                format!("depth pixel format {pixel_format} is not supported (100 = 1 mm, 101 = 100 µm are)"),
            ));
        }
        let fov_rad = p.fov.filter(|&(h, v)| {
            let ok = |f: f64| f.is_finite() && f > 0.0 && f < std::f64::consts::PI;
            ok(h) && ok(v)
        });
        self.info = OniInfo {
            node_id,
            codec,
            width: w as u16,
            height: h as u16,
            fps,
            fov_rad,
            max_depth: p.max_depth,
            pixel_format,
            frames,
            ..self.info.clone()
        };
        let pixels = (w * h) as usize;
        self.max_payload = match codec {
            Codec::None => 2 * pixels,
            Codec::Z16 => 2 + 3 * pixels,
            Codec::Z16Table => 4 + 2 * 65_536 + 3 * pixels,
        }
        .min(MAX_PAYLOAD);
        self.depth = vec![0; pixels];
        self.payload = vec![0; self.max_payload];
        Ok(())
    }

    /// Read the next NEW_DATA of our node into `self.depth`; returns (timestamp, frame id).
    fn read_next(&mut self) -> Result<(u64, u32), SourceError> {
        loop {
            let start = self.pos;
            let Some(h) = self.read_header()? else {
                return Err(self.corrupt(start, "file ends without an END record (truncated recording?)"));
            };
            let ours = h.node == self.info.node_id;
            match h.kind {
                rt::NEW_DATA if ours => {
                    self.read_fields(&h, start)?;
                    let (Some(ts), Some(id)) = (self.fields.get(0..8), self.fields.get(8..12)) else {
                        return Err(self.corrupt(start, "NEW_DATA record too short"));
                    };
                    let ts = u64::from_le_bytes(ts.try_into().unwrap_or_default());
                    let id = le_u32(id);
                    if h.payload_len > self.max_payload {
                        return Err(self.corrupt(
                            start,
                            &format!(
                                "frame {id} payload of {} bytes is larger than any valid frame",
                                h.payload_len
                            ),
                        ));
                    }
                    let buf = &mut self.payload[..h.payload_len];
                    read_exact_or(&mut self.input, buf, start, "a frame payload")?;
                    self.pos += h.payload_len as u64;
                    let payload = &self.payload[..h.payload_len];
                    let decoded = match self.info.codec {
                        Codec::None => decode_raw(payload, &mut self.depth),
                        Codec::Z16 => decode_16z(payload, &mut self.depth),
                        Codec::Z16Table => decode_16z_table(payload, &mut self.depth),
                    };
                    if let Err(e) = decoded {
                        return Err(self.corrupt(start, &format!("frame {id} ({}): {e}", self.info.codec)));
                    }
                    if self.info.pixel_format == PIXEL_FORMAT_DEPTH_100_UM {
                        for d in &mut self.depth {
                            *d = ((*d as u32 + 5) / 10) as u16;
                        }
                    }
                    return Ok((ts, id));
                }
                rt::GENERAL_PROPERTY if ours => {
                    self.read_fields(&h, start)?;
                    self.skip(h.payload_len)?;
                    if let Some((b"xnMapOutputMode", data)) = Fields::new(&self.fields).property()
                        && data.len() >= 12
                        && (le_u32(&data[0..4]), le_u32(&data[4..8]))
                            != (self.info.width as u32, self.info.height as u32)
                    {
                        return Err(SourceError::new(
                            SourceErrorKind::Unsupported,
                            format!("{}: the depth resolution changes mid-stream", self.name),
                        ));
                    }
                }
                rt::NODE_REMOVED if ours => return Err(self.end_of_stream()),
                rt::END => return Err(self.end_of_stream()),
                kind => {
                    if !KNOWN_RECORDS.contains(&kind) {
                        self.unknown_records += 1;
                    }
                    self.skip(h.fields_len + h.payload_len)?;
                }
            }
        }
    }

    /// The end of the stream; a frame count that disagrees with the header's is warned about (a record whose
    /// header was damaged is skipped, so the file plays fewer frames than it says).
    fn end_of_stream(&self) -> SourceError {
        if let Some(declared) = self.info.frames
            && declared != self.frames_read
        {
            tracing::warn!(
                "{}: the header says {declared} frames but {} played ({} record(s) of unknown type skipped as corrupt)",
                self.name,
                self.frames_read,
                self.unknown_records
            );
        }
        SourceError::end_of_stream()
    }

    /// Frames of the depth stream returned so far.
    pub fn frames_read(&self) -> u32 {
        self.frames_read
    }

    /// Records skipped so far because their type is none OpenNI writes (a damaged record header).
    pub fn unknown_records(&self) -> u32 {
        self.unknown_records
    }

    /// Read a record header; `None` at a clean end of file.
    fn read_header(&mut self) -> Result<Option<RecordHeader>, SourceError> {
        let start = self.pos;
        let mut h = [0u8; RECORD_HEADER_LEN];
        let mut got = 0;
        while got < h.len() {
            match self.input.read(&mut h[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == IoKind::Interrupted => {}
                Err(e) => {
                    return Err(SourceError::io(
                        format!("{}: reading at offset {start}", self.name),
                        e,
                    ));
                }
            }
        }
        if got == 0 {
            return Ok(None);
        }
        if got < h.len() {
            return Err(self.corrupt(start, "file truncated inside a record header"));
        }
        self.pos += RECORD_HEADER_LEN as u64;
        if le_u32(&h[0..4]) != RECORD_MAGIC {
            return Err(self.corrupt(start, "bad record magic (expected \"NIR\\0\")"));
        }
        let fields_size = le_u32(&h[12..16]) as usize;
        let payload_len = le_u32(&h[16..20]) as usize;
        if !(RECORD_HEADER_LEN..=MAX_FIELDS).contains(&fields_size) {
            return Err(self.corrupt(start, &format!("record fields size {fields_size} out of range")));
        }
        Ok(Some(RecordHeader {
            kind: le_u32(&h[4..8]),
            node: le_u32(&h[8..12]),
            fields_len: fields_size - RECORD_HEADER_LEN,
            payload_len,
        }))
    }

    /// Read the fields of `h` (bounded by [`MAX_FIELDS`]) into `self.fields`.
    fn read_fields(&mut self, h: &RecordHeader, start: u64) -> Result<(), SourceError> {
        self.fields.resize(h.fields_len, 0);
        read_exact_or(&mut self.input, &mut self.fields, start, "record fields")?;
        self.pos += h.fields_len as u64;
        Ok(())
    }

    fn skip(&mut self, n: usize) -> Result<(), SourceError> {
        self.input
            .seek_relative(n as i64)
            .map_err(|e| SourceError::io(format!("{}: seeking past offset {}", self.name, self.pos), e))?;
        self.pos += n as u64;
        Ok(())
    }

    fn seek_to(&mut self, pos: u64) -> Result<(), SourceError> {
        self.input
            .seek(std::io::SeekFrom::Start(pos))
            .map_err(|e| SourceError::io(format!("{}: seeking to offset {pos}", self.name), e))?;
        self.pos = pos;
        Ok(())
    }

    fn corrupt(&self, at: u64, what: &str) -> SourceError {
        SourceError::new(
            SourceErrorKind::CorruptData,
            format!("{}: record at offset {at}: {what}", self.name),
        )
    }

    /// The next frame, without the [`DepthSource`] timeout (files never wait).
    pub fn read_frame(&mut self) -> Result<DepthFrame<'_>, SourceError> {
        if self.done {
            return Err(SourceError::end_of_stream());
        }
        let (ts, id) = match self.read_next() {
            Ok(v) => v,
            Err(e) => {
                // Every error of a file is final: the position is no longer at a record boundary.
                self.done = true;
                return Err(e);
            }
        };
        self.frames_read += 1;
        DepthFrame::new(
            &self.depth,
            self.info.width,
            self.info.height,
            capture_time(ts).map_err(|e| e.context(&self.name))?,
            id,
        )
        .map_err(|e| SourceError::new(SourceErrorKind::Other, format!("{}: {e}", self.name)))
    }
}

impl<R: Read + Seek> DepthSource for OniReader<R> {
    fn next_frame(&mut self, _timeout: Duration) -> Result<DepthFrame<'_>, SourceError> {
        self.read_frame()
    }

    fn intrinsics(&self) -> Intrinsics {
        let (h, v) = self
            .info
            .fov_rad
            .unwrap_or((KINECT_V1_HFOV_RAD as f64, KINECT_V1_VFOV_RAD as f64));
        Intrinsics::from_fov(self.info.width, self.info.height, h as f32, v as f32)
    }

    fn describe(&self) -> String {
        let frames = match self.info.frames {
            Some(n) => format!("{n} frames"),
            None => "unfinished recording".into(),
        };
        format!(
            "file:{} (.oni {} {}x{}, {frames})",
            self.name, self.info.codec, self.info.width, self.info.height
        )
    }
}

/// `read_exact`, with EOF reported as a truncated record at `start`.
fn read_exact_or(input: &mut impl Read, buf: &mut [u8], start: u64, what: &str) -> Result<(), SourceError> {
    input.read_exact(buf).map_err(|e| {
        if e.kind() == IoKind::UnexpectedEof {
            SourceError::new(
                SourceErrorKind::CorruptData,
                format!("file truncated in {what} (record at offset {start})"),
            )
        } else {
            SourceError::io(format!("reading {what} at offset {start}"), e)
        }
    })
}

fn le_u32(b: &[u8]) -> u32 {
    let mut a = [0u8; 4];
    let n = b.len().min(4);
    a[..n].copy_from_slice(&b[..n]);
    u32::from_le_bytes(a)
}

/// Bounds-checked access to a record's fields.
struct Fields<'a>(&'a [u8]);

impl<'a> Fields<'a> {
    fn new(b: &'a [u8]) -> Self {
        Fields(b)
    }

    fn get(&self, at: usize, len: usize) -> Option<&'a [u8]> {
        self.0.get(at..at.checked_add(len)?)
    }

    /// The string at `at` (u32 length including the NUL), without the NUL.
    fn string(&self, at: usize) -> Option<&'a [u8]> {
        let len = le_u32(self.get(at, 4)?) as usize;
        let s = self.get(at.saturating_add(4), len)?;
        Some(s.strip_suffix(&[0]).unwrap_or(s))
    }

    /// A property record's (name, data): string name, u32 size, data.
    fn property(&self) -> Option<(&'a [u8], &'a [u8])> {
        let name = self.string(0)?;
        let at = 4usize.saturating_add(le_u32(self.get(0, 4)?) as usize);
        let size = le_u32(self.get(at, 4)?) as usize;
        Some((name, self.get(at.saturating_add(4), size)?))
    }
}
