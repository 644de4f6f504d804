//! OpenNI .oni recordings in pure Rust: a writer whose files libOpenNI2 plays frame-exact, and a reader that is a
//! [`DepthSource`](crate::source::DepthSource), so replaying a file is just another source.
//!
//! # Writing a recording (the API other crates use)
//! ```no_run
//! use supine_core::camera::Intrinsics;
//! use supine_drivers::oni::{Codec, OniWriter};
//!
//! # fn main() -> Result<(), supine_drivers::source::SourceError> {
//! let mut writer = OniWriter::create("sequence.oni", &Intrinsics::KINECT_V1, Codec::Z16Table)?;
//! let depth = vec![1500u16; 640 * 480]; // row-major millimetres, 0 = no depth
//! for i in 0..30u64 {
//!     writer.write_frame(&depth, i * 33_333)?; // capture time in microseconds, non-decreasing
//! }
//! writer.finish()?; // patches the header, writes the seek table and END
//! # Ok(())
//! # }
//! ```
//! - [`OniWriter::create`] takes the intrinsics (only the image size and the fields of view are stored: .oni has no
//!   principal point, OpenNI assumes the image centre) and a [`Codec`]. [`OniWriterConfig`] sets the rest (frame
//!   rate, `xnDeviceMaxDepth`).
//! - [`OniWriter::write_frame`] takes exactly `width * height` pixels and a timestamp in µs; frame ids count from 1.
//!   [`OniWriter::write`] takes a [`DepthFrame`](supine_core::depth::DepthFrame) and uses its `capture` time.
//! - [`OniWriter::finish`] must be called to get a complete file; a writer dropped without it finishes best-effort
//!   and logs failures. An unfinished file (a crash) is still playable up to the last whole frame, like one from
//!   OpenNI's own Recorder.
//! - Codecs: [`Codec::None`] (raw, largest, fastest), [`Codec::Z16`] (`16zP`), [`Codec::Z16Table`] (`16zT`, what
//!   OpenNI's Recorder writes; values must be below `max_depth_mm`, default 10000). 16z cannot store values
//!   `>= 0x8000` after a large jump: depth in mm never gets there.
//!
//! # File layout (verified against libOpenNI2 2.2.0.33; see `shared/reference/oni-openni2-kinect.md` §1-2)
//! A 24-byte header (`"NI10"`, version 1.0.1.0, u64 maxTimeStamp, u32 maxNodeId), then records, each with a 28-byte
//! header (`"NIR\0"`, type, nodeId, fieldsSize including the header, payloadSize, u64 undoRecordPos); little-endian,
//! packed. The writer emits: NODE_ADDED ("Depth", type 2, codec), the properties `xnDeviceMaxDepth`, `xnMapOutputMode`,
//! `oniPixelFormat` (100), `xnFOV`, `xnCropping`, NODE_STATE_READY, NODE_DATA_BEGIN, one NEW_DATA per frame (frame ids
//! 1..N), and at finish NODE_REMOVED, SEEK_TABLE and END, then patches the header's maxTimeStamp and NODE_ADDED's
//! frame count, time range and seek-table position.
//!
//! The reader accepts what the writer and OpenNI's Recorder write: the first depth node, codecs `NONE`/`16zP`/`16zT`,
//! pixel formats DEPTH_1_MM and DEPTH_100_UM (converted to mm). It stops at END (real recordings carry junk after it),
//! skips records of other nodes and unknown record types, and reports truncated or corrupt files as
//! [`SourceErrorKind::CorruptData`](crate::source::SourceErrorKind) naming the offset, after delivering every intact frame.
//! Length fields are checked against fixed limits before anything is read, so a corrupt file can never make it
//! allocate more than the buffers sized at open.
//!
//! # Cost per frame
//! Writer: one encode pass into a buffer allocated at creation, one buffered write; the seek-table index grows by 16
//! bytes per frame (amortised doubling). Reader: one read of the record into a buffer allocated at open and one
//! decode pass into the depth buffer; no allocation.

mod codec;
mod reader;
mod writer;

pub use codec::{CodecError, TableEncoder, decode_16z, decode_16z_table, decode_raw, encode_16z, encode_raw};
pub use reader::{OniInfo, OniReader};
pub use writer::{OniWriter, OniWriterConfig};

/// The file magic, `"NI10"`.
pub const FILE_MAGIC: [u8; 4] = *b"NI10";
/// The file version the writer emits and the reader accepts: 1.0.1.x.
pub const FILE_VERSION: (u8, u8, u16) = (1, 0, 1);
/// Bytes in the file header.
pub const FILE_HEADER_LEN: usize = 24;
/// The record magic, `"NIR\0"` read as a little-endian u32.
pub const RECORD_MAGIC: u32 = 0x0052_494E;
/// Bytes in a record header (version 1.0.1.0 files).
pub const RECORD_HEADER_LEN: usize = 28;
/// The largest frame payload libOpenNI2's player accepts (`RECORD_MAX_SIZE` = 1600·1200·3).
pub const MAX_PAYLOAD: usize = 1600 * 1200 * 3;
/// The largest record fields block the reader accepts (properties such as the PS1080 `D2S` table are ~20 kB).
pub const MAX_FIELDS: usize = 1 << 20;
/// `ONI_PIXEL_FORMAT_DEPTH_1_MM` (OniCEnums.h).
pub const PIXEL_FORMAT_DEPTH_1_MM: u64 = 100;
/// `ONI_PIXEL_FORMAT_DEPTH_100_UM` (OniCEnums.h).
pub const PIXEL_FORMAT_DEPTH_100_UM: u64 = 101;
/// Node type of a depth stream in NODE_ADDED (`XN_NODE_TYPE_DEPTH`).
pub const NODE_TYPE_DEPTH: i32 = 2;

/// Record types (`RecordType` in OpenNI2 `Source/Drivers/OniFile/DataRecords.h`).
pub mod record_type {
    /// NODE_ADDED of file version 1.0.0.4 (read-only compatibility; never written).
    pub const NODE_ADDED_1_0_0_4: u32 = 0x02;
    /// Integer property.
    pub const INT_PROPERTY: u32 = 0x03;
    /// Real (f64) property.
    pub const REAL_PROPERTY: u32 = 0x04;
    /// String property.
    pub const STRING_PROPERTY: u32 = 0x05;
    /// General (opaque bytes) property.
    pub const GENERAL_PROPERTY: u32 = 0x06;
    /// A node was removed (undo position = its NODE_ADDED).
    pub const NODE_REMOVED: u32 = 0x07;
    /// Data of a node begins.
    pub const NODE_DATA_BEGIN: u32 = 0x08;
    /// The node is configured.
    pub const NODE_STATE_READY: u32 = 0x09;
    /// One frame.
    pub const NEW_DATA: u32 = 0x0A;
    /// End of the recording.
    pub const END: u32 = 0x0B;
    /// NODE_ADDED of file version 1.0.0.5 (read-only compatibility; never written).
    pub const NODE_ADDED_1_0_0_5: u32 = 0x0C;
    /// NODE_ADDED (current).
    pub const NODE_ADDED: u32 = 0x0D;
    /// Seek table: (frames + 1) × {u64 ts, u32 configId, u64 offset}.
    pub const SEEK_TABLE: u32 = 0x0E;
}

/// The depth codecs of .oni files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Codec {
    /// `NONE`: raw little-endian u16 pixels.
    None,
    /// `16zP`: the 16z delta stream.
    Z16,
    /// `16zT`: 16z over an embedded table of the frame's distinct values (what OpenNI's Recorder writes).
    Z16Table,
}

impl Codec {
    /// The FourCC as stored in NODE_ADDED (bytes in file order, e.g. `*b"16zT"`).
    pub fn fourcc(self) -> [u8; 4] {
        match self {
            Codec::None => *b"NONE",
            Codec::Z16 => *b"16zP",
            Codec::Z16Table => *b"16zT",
        }
    }

    /// The codec with this FourCC, if it is one of ours.
    pub fn from_fourcc(fourcc: [u8; 4]) -> Option<Codec> {
        match &fourcc {
            b"NONE" => Some(Codec::None),
            b"16zP" => Some(Codec::Z16),
            b"16zT" => Some(Codec::Z16Table),
            _ => None,
        }
    }

    /// The FourCC as text, e.g. `"16zT"`.
    pub fn name(self) -> &'static str {
        match self {
            Codec::None => "NONE",
            Codec::Z16 => "16zP",
            Codec::Z16Table => "16zT",
        }
    }
}

impl std::fmt::Display for Codec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Codec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "NONE" | "none" | "raw" => Ok(Codec::None),
            "16zP" | "16zp" | "16z" => Ok(Codec::Z16),
            "16zT" | "16zt" => Ok(Codec::Z16Table),
            other => Err(format!(
                "unknown .oni codec {other:?} (expected NONE, 16zP or 16zT)"
            )),
        }
    }
}

#[cfg(test)]
mod tests;
