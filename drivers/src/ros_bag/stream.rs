//! A forward-only walk over the records of an MCAP file, read from disk as the `mcap` crate's sans-io reader asks
//! (chunks are decompressed one at a time, so memory stays at about one chunk whatever the bag's size), plus the
//! channel inventory from the summary section when the file has one.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::source::{SourceError, SourceErrorKind};

/// The longest non-chunk record accepted (a depth image is 1.2 MB at 640x480 32FC1); a corrupt length field above
/// it is an error instead of a huge allocation.
const RECORD_LIMIT: usize = 256 << 20;

/// An MCAP `McapError` as a source error of `path`.
pub(super) fn mcap_error(name: &str, e: mcap::McapError) -> SourceError {
    let kind = match e {
        mcap::McapError::UnsupportedCompression(_) => SourceErrorKind::Unsupported,
        _ => SourceErrorKind::CorruptData,
    };
    let hint = match e {
        mcap::McapError::UnsupportedCompression(_) => {
            " (this build reads zstd and uncompressed chunks: `mcap compress --compression zstd` converts a bag)"
        }
        _ => "",
    };
    SourceError::new(kind, format!("{name}: {e}{hint}"))
}

/// Records of one MCAP file in file order.
pub(super) struct Stream {
    file: File,
    reader: LinearReader,
    name: String,
}

impl Stream {
    /// Start at the beginning of `path`; `name` prefixes error messages.
    pub(super) fn open(path: &Path, name: &str) -> Result<Self, SourceError> {
        let file = File::open(path).map_err(|e| SourceError::io(name.to_owned(), e))?;
        let options = LinearReaderOptions::default().with_record_length_limit(RECORD_LIMIT);
        Ok(Stream {
            file,
            reader: LinearReader::new_with_options(options),
            name: name.to_owned(),
        })
    }

    /// Feed records to `f` until it returns `Some` (that value is returned) or the file ends (`Ok(None)`).
    pub(super) fn next_with<T>(
        &mut self,
        mut f: impl FnMut(Record<'_>) -> Option<T>,
    ) -> Result<Option<T>, SourceError> {
        loop {
            match self.reader.next_event() {
                None => return Ok(None),
                Some(Err(e)) => return Err(mcap_error(&self.name, e)),
                Some(Ok(LinearReadEvent::ReadRequest(n))) => {
                    let buf = self.reader.insert(n);
                    let got = loop {
                        match self.file.read(buf) {
                            Ok(k) => break k,
                            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                            Err(e) => return Err(SourceError::io(format!("reading {}", self.name), e)),
                        }
                    };
                    self.reader.notify_read(got);
                }
                Some(Ok(LinearReadEvent::Record { data, opcode })) => {
                    let record = mcap::parse_record(opcode, data).map_err(|e| mcap_error(&self.name, e))?;
                    if let Some(v) = f(record) {
                        return Ok(Some(v));
                    }
                }
            }
        }
    }
}

/// One channel of a bag, as its summary or a full scan lists it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// Channel id in the file.
    pub id: u16,
    /// Topic name, e.g. `/camera/depth/image_raw`.
    pub topic: String,
    /// Schema name, e.g. `sensor_msgs/msg/Image` (empty without a schema).
    pub schema: String,
    /// Message encoding, e.g. `cdr`.
    pub encoding: String,
    /// Messages on the channel, when the file's statistics (or the scan) counted them.
    pub messages: Option<u64>,
}

/// The channels of a bag: from the summary section when there is a readable one, else from a scan of the whole
/// file (which tolerates a truncated end: a crashed recording lists what it holds).
pub(super) fn inventory(path: &Path, name: &str) -> Result<Vec<ChannelInfo>, SourceError> {
    match summary_inventory(path, name) {
        Ok(Some(channels)) => return Ok(channels),
        Ok(None) => {}
        Err(e) => tracing::warn!("{e}; scanning the whole file instead"),
    }
    let mut stream = Stream::open(path, name)?;
    let mut schemas = BTreeMap::new();
    let mut channels: BTreeMap<u16, ChannelInfo> = BTreeMap::new();
    let end = stream.next_with(|record| {
        match record {
            Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                channels.insert(
                    c.id,
                    ChannelInfo {
                        id: c.id,
                        schema: schemas.get(&c.schema_id).cloned().unwrap_or_default(),
                        topic: c.topic,
                        encoding: c.message_encoding,
                        messages: Some(0),
                    },
                );
            }
            Record::Message { header, .. } => {
                if let Some(c) = channels.get_mut(&header.channel_id) {
                    c.messages = c.messages.map(|n| n + 1);
                }
            }
            _ => {}
        }
        None::<()>
    });
    if let Err(e) = end {
        if channels.is_empty() {
            return Err(e);
        }
        tracing::warn!("{e}: the bag ends early; listing the channels before that point");
    }
    Ok(channels.into_values().collect())
}

/// The MCAP magic that starts and ends a file.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// The footer record (opcode, length, summary start, summary offset start, CRC) plus the end magic.
const FOOTER_AND_MAGIC: u64 = 1 + 8 + 20 + 8;

/// Channels from the summary section; `Ok(None)` when the file has none (or no footer: truncated).
fn summary_inventory(path: &Path, name: &str) -> Result<Option<Vec<ChannelInfo>>, SourceError> {
    let mut file = File::open(path).map_err(|e| SourceError::io(name.to_owned(), e))?;
    let len = file
        .metadata()
        .map_err(|e| SourceError::io(name.to_owned(), e))?
        .len();
    if len < FOOTER_AND_MAGIC + MAGIC.len() as u64 {
        return Ok(None);
    }
    let mut tail = [0u8; FOOTER_AND_MAGIC as usize];
    let read = |file: &mut File, at: u64, buf: &mut [u8]| {
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(buf))
            .map_err(|e| SourceError::io(format!("reading {name}"), e))
    };
    read(&mut file, len - FOOTER_AND_MAGIC, &mut tail)?;
    if &tail[29..] != MAGIC || tail[0] != 0x02 || tail[1..9] != 20u64.to_le_bytes() {
        return Ok(None);
    }
    let u64_at = |i: usize| u64::from_le_bytes(tail[i..i + 8].try_into().unwrap_or([0; 8]));
    let (start, offsets) = (u64_at(9), u64_at(17));
    if start == 0 {
        return Ok(None);
    }
    let end = if offsets != 0 {
        offsets
    } else {
        len - FOOTER_AND_MAGIC
    };
    let bad = |why: &str| {
        SourceError::new(
            SourceErrorKind::CorruptData,
            format!("{name}: summary section {why}"),
        )
    };
    if start < MAGIC.len() as u64 || start > end || end > len - FOOTER_AND_MAGIC {
        return Err(bad(&format!(
            "at {start}..{end} lies outside the file of {len} B"
        )));
    }
    if end - start > RECORD_LIMIT as u64 {
        return Err(bad(&format!("of {} B is implausibly large", end - start)));
    }
    let mut summary = vec![0u8; (end - start) as usize];
    read(&mut file, start, &mut summary)?;
    let mut schemas = BTreeMap::new();
    let mut channels = Vec::new();
    let mut counts = None;
    let mut rest = &summary[..];
    while !rest.is_empty() {
        if rest.len() < 9 {
            return Err(bad("ends inside a record header"));
        }
        let opcode = rest[0];
        let body_len = u64::from_le_bytes(rest[1..9].try_into().unwrap_or([0; 8]));
        if body_len > (rest.len() - 9) as u64 {
            return Err(bad("ends inside a record"));
        }
        let (body, next) = rest[9..].split_at(body_len as usize);
        rest = next;
        match mcap::parse_record(opcode, body).map_err(|e| mcap_error(name, e))? {
            Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => channels.push(c),
            Record::Statistics(s) => counts = Some(s.channel_message_counts),
            _ => {}
        }
    }
    if channels.is_empty() {
        return Ok(None);
    }
    Ok(Some(
        channels
            .into_iter()
            .map(|c| ChannelInfo {
                id: c.id,
                schema: schemas.get(&c.schema_id).cloned().unwrap_or_default(),
                messages: counts.as_ref().map(|m| m.get(&c.id).copied().unwrap_or(0)),
                topic: c.topic,
                encoding: c.message_encoding,
            })
            .collect(),
    ))
}
