//! `--record OUT.mcap`: the frames' Foxglove messages into an MCAP file (JSON encoding, jsonschema schemas,
//! zstd chunks), so Foxglove opens it with the layout in docs/foxglove-layout.json.
//!
//! One channel per [`Topic`], declared at creation; [`McapRecorder::write`] appends one frame's messages with its log
//! time (monotonic: [`super::LogClock`]). Per frame: the JSON payloads are copied into the current chunk and zstd
//! compresses each full chunk; no seek until [`McapRecorder::finish`] writes the summary (statistics, indexes).

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use mcap::records::MessageHeader;

use super::{FrameMessages, Topic, schemas};

/// An MCAP file being written.
pub struct McapRecorder<W: Write + Seek> {
    writer: mcap::Writer<W>,
    channels: BTreeMap<Topic, u16>,
    sequence: u32,
    last_log_ns: Option<u64>,
}

/// Why the recording failed (I/O, or a log time that went back).
#[derive(Debug)]
pub struct RecordError(String);

impl std::fmt::Display for RecordError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for RecordError {}

impl RecordError {
    /// An error with this message.
    pub fn new(message: String) -> Self {
        RecordError(message)
    }
}

fn err(e: mcap::McapError) -> RecordError {
    RecordError(format!("writing the MCAP recording: {e}"))
}

impl<W: Write + Seek> McapRecorder<W> {
    /// Start a recording in `out` with every channel declared.
    pub fn new(out: W) -> Result<Self, RecordError> {
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(concat!("supine ", env!("CARGO_PKG_VERSION")));
        let mut writer = options.create(out).map_err(err)?;
        let mut channels = BTreeMap::new();
        for topic in Topic::ALL {
            let schema = writer
                .add_schema(
                    topic.schema_name(),
                    "jsonschema",
                    schemas::schema_text(topic).as_bytes(),
                )
                .map_err(err)?;
            let id = writer
                .add_channel(schema, topic.name(), "json", &BTreeMap::new())
                .map_err(err)?;
            channels.insert(topic, id);
        }
        Ok(McapRecorder {
            writer,
            channels,
            sequence: 0,
            last_log_ns: None,
        })
    }

    /// Append one frame's messages; a log time before the previous frame's is refused (the file would not seek).
    pub fn write(&mut self, frame: &FrameMessages) -> Result<(), RecordError> {
        if let Some(last) = self.last_log_ns
            && frame.log_ns < last
        {
            return Err(RecordError(format!(
                "log time {} ns is before the previous frame's {last} ns",
                frame.log_ns
            )));
        }
        for (topic, data) in &frame.items {
            let header = MessageHeader {
                channel_id: self.channels[topic],
                sequence: self.sequence,
                log_time: frame.log_ns,
                publish_time: frame.log_ns,
            };
            self.sequence = self.sequence.wrapping_add(1);
            self.writer.write_to_known_channel(&header, data).map_err(err)?;
        }
        self.last_log_ns = Some(frame.log_ns);
        Ok(())
    }

    /// Write the summary and footer and give the output back.
    pub fn finish(mut self) -> Result<W, RecordError> {
        self.writer.finish().map_err(err)?;
        Ok(self.writer.into_inner())
    }
}
