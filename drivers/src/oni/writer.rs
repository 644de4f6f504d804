//! The .oni writer: the verified minimal recipe, streamed, patched at finish (see the [module docs](super)).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::Path;

use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;

use super::codec::{TableEncoder, encode_16z, encode_raw};
use super::{
    Codec, FILE_HEADER_LEN, FILE_MAGIC, FILE_VERSION, MAX_PAYLOAD, NODE_TYPE_DEPTH, PIXEL_FORMAT_DEPTH_1_MM,
    RECORD_HEADER_LEN, RECORD_MAGIC, record_type as rt,
};
use crate::source::{SourceError, SourceErrorKind};

/// The node id of the depth stream (the Recorder numbers streams from 1).
const NODE_ID: u32 = 1;
/// Offset of the NODE_ADDED record (right after the file header).
const NODE_ADDED_POS: u64 = FILE_HEADER_LEN as u64;

/// Everything the writer stores about the stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OniWriterConfig {
    /// Image width in pixels.
    pub width: u16,
    /// Image height in pixels.
    pub height: u16,
    /// Nominal frame rate written in `xnMapOutputMode` (playback at speed -1 ignores it).
    pub fps: u32,
    /// Horizontal field of view, radians (`xnFOV`).
    pub hfov_rad: f64,
    /// Vertical field of view, radians (`xnFOV`).
    pub vfov_rad: f64,
    /// The payload codec.
    pub codec: Codec,
    /// `xnDeviceMaxDepth` (the stream's MAX_VALUE); `16zT` can only store values below it. Default 10000 (Kinect).
    pub max_depth_mm: u16,
}

impl OniWriterConfig {
    /// A 30 fps configuration for frames with these intrinsics (size and fields of view) and codec.
    pub fn new(intrinsics: &Intrinsics, codec: Codec) -> Self {
        OniWriterConfig {
            width: intrinsics.width,
            height: intrinsics.height,
            fps: 30,
            hfov_rad: intrinsics.hfov_rad() as f64,
            vfov_rad: intrinsics.vfov_rad() as f64,
            codec,
            max_depth_mm: 10_000,
        }
    }

    fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    fn validate(&self) -> Result<(), SourceError> {
        let bad = |m: String| Err(SourceError::new(SourceErrorKind::InvalidArgument, m));
        if self.width == 0 || self.height == 0 || self.pixels() * 2 > MAX_PAYLOAD {
            return bad(format!(
                "cannot record {}x{} frames (at most 1600x1200)",
                self.width, self.height
            ));
        }
        let fov_ok = |f: f64| f.is_finite() && f > 0.0 && f < std::f64::consts::PI;
        if !fov_ok(self.hfov_rad) || !fov_ok(self.vfov_rad) {
            return bad(format!(
                "bad field of view {} x {} rad",
                self.hfov_rad, self.vfov_rad
            ));
        }
        if self.codec == Codec::Z16Table && self.max_depth_mm == 0 {
            return bad("16zT needs max_depth_mm > 0".into());
        }
        Ok(())
    }
}

/// Writes a depth stream to an .oni file that libOpenNI2 plays frame-exact (see the [module docs](super)).
pub struct OniWriter<W: Write + Seek = BufWriter<File>> {
    out: Option<W>,
    config: OniWriterConfig,
    pos: u64,
    frames: u32,
    max_ts: u64,
    last_ts: Option<u64>,
    last_new_data_pos: u64,
    /// (timestamp, record offset) of every NEW_DATA, for the seek table.
    index: Vec<(u64, u64)>,
    fields: Vec<u8>,
    payload: Vec<u8>,
    table: Option<TableEncoder>,
    description: String,
    /// A write failed: the file is abandoned, not completed on drop.
    failed: bool,
}

impl<W: Write + Seek> std::fmt::Debug for OniWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OniWriter")
            .field("target", &self.description)
            .field("config", &self.config)
            .field("frames", &self.frames)
            .finish()
    }
}

impl OniWriter<BufWriter<File>> {
    /// Create (truncate) `path` for frames with these intrinsics and codec, 30 fps, max depth 10000 mm.
    pub fn create(
        path: impl AsRef<Path>,
        intrinsics: &Intrinsics,
        codec: Codec,
    ) -> Result<Self, SourceError> {
        Self::create_with(path, OniWriterConfig::new(intrinsics, codec))
    }

    /// Create (truncate) `path` with a full configuration.
    pub fn create_with(path: impl AsRef<Path>, config: OniWriterConfig) -> Result<Self, SourceError> {
        let path = path.as_ref();
        config.validate()?;
        let file =
            File::create(path).map_err(|e| SourceError::io(format!("creating {}", path.display()), e))?;
        let mut w = OniWriter::new(BufWriter::with_capacity(1 << 20, file), config)?;
        w.description = path.display().to_string();
        Ok(w)
    }
}

impl<W: Write + Seek> OniWriter<W> {
    /// Start a recording on any seekable writer (positioned at its start): writes the header and stream description.
    pub fn new(out: W, config: OniWriterConfig) -> Result<Self, SourceError> {
        config.validate()?;
        let pixels = config.pixels();
        let table = (config.codec == Codec::Z16Table).then(|| TableEncoder::new(config.max_depth_mm));
        let mut w = OniWriter {
            out: Some(out),
            config,
            pos: 0,
            frames: 0,
            max_ts: 0,
            last_ts: None,
            last_new_data_pos: 0,
            index: Vec::with_capacity(1024),
            fields: Vec::with_capacity(256),
            // Worst case: 16z escapes every pixel (3 bytes), 16zT adds a table of up to 65536 values.
            payload: Vec::with_capacity(3 * pixels + 2 * 65_536 + 8),
            table,
            description: "in-memory .oni".into(),
            failed: false,
        };
        w.write_start()?;
        Ok(w)
    }

    /// The configuration this writer records with.
    pub fn config(&self) -> &OniWriterConfig {
        &self.config
    }

    /// The underlying writer (e.g. to look at an in-memory file before `finish`); `None` once finished.
    pub fn get_ref(&self) -> Option<&W> {
        self.out.as_ref()
    }

    /// Frames written so far.
    pub fn frames_written(&self) -> u32 {
        self.frames
    }

    /// Append one frame: exactly `width * height` pixels in mm, captured at `timestamp_us` (non-decreasing).
    pub fn write_frame(&mut self, depth_mm: &[u16], timestamp_us: u64) -> Result<(), SourceError> {
        if depth_mm.len() != self.config.pixels() {
            return Err(SourceError::new(
                SourceErrorKind::InvalidArgument,
                format!(
                    "frame has {} pixels, the recording is {}x{}",
                    depth_mm.len(),
                    self.config.width,
                    self.config.height
                ),
            ));
        }
        if let Some(last) = self.last_ts
            && timestamp_us < last
        {
            return Err(SourceError::new(
                SourceErrorKind::InvalidArgument,
                format!("timestamp {timestamp_us} µs is before the previous frame's {last} µs"),
            ));
        }
        if self.frames == u32::MAX - 1 {
            return Err(SourceError::new(
                SourceErrorKind::InvalidArgument,
                "too many frames for one .oni file",
            ));
        }
        self.payload.clear();
        let encoded = match self.config.codec {
            Codec::None => {
                encode_raw(depth_mm, &mut self.payload);
                Ok(())
            }
            Codec::Z16 => encode_16z(depth_mm, &mut self.payload),
            Codec::Z16Table => match self.table.as_mut() {
                Some(t) => t.encode(depth_mm, &mut self.payload),
                None => {
                    return Err(SourceError::new(
                        SourceErrorKind::Other,
                        "16zT writer lost its table",
                    ));
                }
            },
        };
        encoded.map_err(|e| {
            SourceError::new(
                SourceErrorKind::InvalidArgument,
                format!("frame {}: {e}", self.frames + 1),
            )
        })?;
        let frame_id = self.frames + 1;
        let record_pos = self.pos;
        self.fields.clear();
        self.fields.extend_from_slice(&timestamp_us.to_le_bytes());
        self.fields.extend_from_slice(&frame_id.to_le_bytes());
        let payload = std::mem::take(&mut self.payload);
        let result = self.emit(rt::NEW_DATA, NODE_ID, self.last_new_data_pos, &payload);
        self.payload = payload;
        result?;
        self.frames = frame_id;
        self.last_new_data_pos = record_pos;
        self.last_ts = Some(timestamp_us);
        self.max_ts = self.max_ts.max(timestamp_us);
        self.index.push((timestamp_us, record_pos));
        Ok(())
    }

    /// Append `frame`, using its `capture_us` as the timestamp.
    pub fn write(&mut self, frame: &DepthFrame<'_>) -> Result<(), SourceError> {
        if (frame.width(), frame.height()) != (self.config.width, self.config.height) {
            return Err(SourceError::new(
                SourceErrorKind::InvalidArgument,
                format!(
                    "frame is {}x{}, the recording is {}x{}",
                    frame.width(),
                    frame.height(),
                    self.config.width,
                    self.config.height
                ),
            ));
        }
        self.write_frame(frame.depth_mm(), frame.capture.as_us())
    }

    /// Complete the file (NODE_REMOVED, SEEK_TABLE, END, header patches), flush it and return the writer.
    pub fn finish(mut self) -> Result<W, SourceError> {
        if let Err(e) = self.finish_in_place() {
            // Reported here; the drop must not try again and log the same failure a second time.
            self.failed = true;
            return Err(e);
        }
        self.out
            .take()
            .ok_or_else(|| SourceError::new(SourceErrorKind::Other, "writer already finished"))
    }

    fn finish_in_place(&mut self) -> Result<(), SourceError> {
        if self.out.is_none() {
            return Ok(());
        }
        self.fields.clear();
        self.emit(rt::NODE_REMOVED, NODE_ID, NODE_ADDED_POS, &[])?;
        let seek_table_pos = self.pos;
        let mut table = Vec::with_capacity((self.index.len() + 1) * 20);
        table.extend_from_slice(&[0u8; 20]);
        for &(ts, pos) in &self.index {
            table.extend_from_slice(&ts.to_le_bytes());
            table.extend_from_slice(&0u32.to_le_bytes()); // configuration id: properties never change mid-stream
            table.extend_from_slice(&pos.to_le_bytes());
        }
        self.fields.clear();
        self.emit(rt::SEEK_TABLE, NODE_ID, 0, &table)?;
        self.fields.clear();
        self.emit(rt::END, 0, 0, &[])?;
        let end_pos = self.pos;
        // Patch NODE_ADDED and the header in place (same sizes), as the Recorder does at detach.
        self.node_added_fields(self.frames, 0, self.max_ts, seek_table_pos);
        let fields = std::mem::take(&mut self.fields);
        let header = self.file_header(self.max_ts);
        let out = self.out_mut()?;
        let io = |e| SourceError::io("finishing the .oni file", e);
        out.seek(SeekFrom::Start(NODE_ADDED_POS)).map_err(io)?;
        out.write_all(&record_header(rt::NODE_ADDED, NODE_ID, fields.len(), 0, 0))
            .map_err(io)?;
        out.write_all(&fields).map_err(io)?;
        out.seek(SeekFrom::Start(0)).map_err(io)?;
        out.write_all(&header).map_err(io)?;
        out.seek(SeekFrom::Start(end_pos)).map_err(io)?;
        out.flush().map_err(io)?;
        self.fields = fields;
        Ok(())
    }

    fn out_mut(&mut self) -> Result<&mut W, SourceError> {
        self.out
            .as_mut()
            .ok_or_else(|| SourceError::new(SourceErrorKind::Other, "writer already finished"))
    }

    fn file_header(&self, max_ts: u64) -> [u8; FILE_HEADER_LEN] {
        let mut h = [0u8; FILE_HEADER_LEN];
        h[0..4].copy_from_slice(&FILE_MAGIC);
        h[4] = FILE_VERSION.0;
        h[5] = FILE_VERSION.1;
        h[6..8].copy_from_slice(&FILE_VERSION.2.to_le_bytes());
        // h[8..12]: build 0
        h[12..20].copy_from_slice(&max_ts.to_le_bytes());
        h[20..24].copy_from_slice(&NODE_ID.to_le_bytes()); // maxNodeId
        h
    }

    /// Fill `self.fields` with NODE_ADDED's fields.
    fn node_added_fields(&mut self, frames: u32, min_ts: u64, max_ts: u64, seek_pos: u64) {
        self.fields.clear();
        push_str(&mut self.fields, "Depth");
        self.fields.extend_from_slice(&NODE_TYPE_DEPTH.to_le_bytes());
        self.fields.extend_from_slice(&self.config.codec.fourcc());
        self.fields.extend_from_slice(&frames.to_le_bytes());
        self.fields.extend_from_slice(&min_ts.to_le_bytes());
        self.fields.extend_from_slice(&max_ts.to_le_bytes());
        self.fields.extend_from_slice(&seek_pos.to_le_bytes());
    }

    fn write_start(&mut self) -> Result<(), SourceError> {
        // While recording the file claims "unbounded" (UINT64_MAX / UINT32_MAX) like the Recorder, so a file cut
        // short by a crash still plays every whole frame; finish() patches the real values.
        let header = self.file_header(u64::MAX);
        self.out_mut()?
            .write_all(&header)
            .map_err(|e| SourceError::io("writing the .oni header", e))?;
        self.pos = FILE_HEADER_LEN as u64;
        self.node_added_fields(u32::MAX, 0, u64::MAX, 0);
        self.emit(rt::NODE_ADDED, NODE_ID, 0, &[])?;
        let c = self.config;
        self.int_property("xnDeviceMaxDepth", c.max_depth_mm as u64)?;
        let mut mode = [0u8; 12];
        mode[0..4].copy_from_slice(&(c.width as u32).to_le_bytes());
        mode[4..8].copy_from_slice(&(c.height as u32).to_le_bytes());
        mode[8..12].copy_from_slice(&c.fps.to_le_bytes());
        self.general_property("xnMapOutputMode", &mode)?;
        self.int_property("oniPixelFormat", PIXEL_FORMAT_DEPTH_1_MM)?;
        let mut fov = [0u8; 16];
        fov[0..8].copy_from_slice(&c.hfov_rad.to_le_bytes());
        fov[8..16].copy_from_slice(&c.vfov_rad.to_le_bytes());
        self.general_property("xnFOV", &fov)?;
        // {i32 enabled = 0; u16 x, y, w, h}: required, or the player never delivers a frame.
        self.general_property("xnCropping", &[0u8; 12])?;
        self.fields.clear();
        self.emit(rt::NODE_STATE_READY, NODE_ID, 0, &[])?;
        self.fields.clear();
        self.fields.extend_from_slice(&u32::MAX.to_le_bytes());
        self.fields.extend_from_slice(&u64::MAX.to_le_bytes());
        self.emit(rt::NODE_DATA_BEGIN, NODE_ID, 0, &[])
    }

    fn int_property(&mut self, name: &str, value: u64) -> Result<(), SourceError> {
        self.fields.clear();
        push_str(&mut self.fields, name);
        self.fields.extend_from_slice(&8u32.to_le_bytes());
        self.fields.extend_from_slice(&value.to_le_bytes());
        self.emit(rt::INT_PROPERTY, NODE_ID, 0, &[])
    }

    fn general_property(&mut self, name: &str, data: &[u8]) -> Result<(), SourceError> {
        self.fields.clear();
        push_str(&mut self.fields, name);
        self.fields.extend_from_slice(&(data.len() as u32).to_le_bytes());
        self.fields.extend_from_slice(data);
        self.emit(rt::GENERAL_PROPERTY, NODE_ID, 0, &[])
    }

    /// Write a record: header, `self.fields`, `payload`.
    fn emit(&mut self, kind: u32, node: u32, undo: u64, payload: &[u8]) -> Result<(), SourceError> {
        let header = record_header(kind, node, self.fields.len(), payload.len(), undo);
        let fields = std::mem::take(&mut self.fields);
        let result = (|| {
            let out = self.out_mut()?;
            let io = |e| SourceError::io("writing an .oni record", e);
            out.write_all(&header).map_err(io)?;
            out.write_all(&fields).map_err(io)?;
            out.write_all(payload).map_err(io)
        })();
        self.pos += (RECORD_HEADER_LEN + fields.len() + payload.len()) as u64;
        self.fields = fields;
        // After a failed write the file cannot be completed; the drop must not try again and log a second error.
        self.failed |= result.is_err();
        result
    }
}

impl<W: Write + Seek> Drop for OniWriter<W> {
    fn drop(&mut self) {
        if self.out.is_some()
            && !self.failed
            && let Err(e) = self.finish_in_place()
        {
            tracing::error!("finishing {} on drop failed: {e}", self.description);
        }
    }
}

/// A record header for `fields_len` bytes of fields after it and `payload_len` bytes of payload.
fn record_header(
    kind: u32,
    node: u32,
    fields_len: usize,
    payload_len: usize,
    undo: u64,
) -> [u8; RECORD_HEADER_LEN] {
    let mut h = [0u8; RECORD_HEADER_LEN];
    h[0..4].copy_from_slice(&RECORD_MAGIC.to_le_bytes());
    h[4..8].copy_from_slice(&kind.to_le_bytes());
    h[8..12].copy_from_slice(&node.to_le_bytes());
    h[12..16].copy_from_slice(&((RECORD_HEADER_LEN + fields_len) as u32).to_le_bytes());
    h[16..20].copy_from_slice(&(payload_len as u32).to_le_bytes());
    h[20..28].copy_from_slice(&undo.to_le_bytes());
    h
}

/// An .oni string: u32 length including the NUL, the bytes, NUL.
fn push_str(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&((s.len() + 1) as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
    out.push(0);
}
