//! ROS 2 depth bags (MCAP files written by rosbag2) as a [`DepthSource`]: `sensor_msgs/msg/Image` messages of
//! encoding 16UC1 (mm) or 32FC1 (metres, converted to mm), CDR-encoded, zstd-compressed or plain chunks.
//!
//! # Topic
//! [`McapSource::open`] plays the topic it is given, else the bag's only image topic (when there are several, the
//! only one whose name contains `depth`); otherwise it fails listing the image topics. Intrinsics come from the
//! `sensor_msgs/msg/CameraInfo` beside the topic (`<namespace>/camera_info`, or the bag's only camera info topic),
//! else the Kinect v1 field of view at the image's size.
//!
//! # Time
//! A frame's capture time is its header stamp (the message's log time when the stamp is unset) relative to the
//! first frame's: ROS stamps are Unix times, which do not fit the 48-bit capture clock. [`McapSource::origin_ns`]
//! gives the first stamp back. A stamp earlier than the previous frame's is a corrupt frame.
//!
//! # Errors and cost
//! A frame that does not decode (wrong size, truncated payload, colour encoding) is a [`SourceErrorKind::CorruptData`]
//! or `Unsupported` error for that frame and the source goes on with the next message; a damaged file (bad record,
//! truncated chunk) ends the stream with a `CorruptData` error, then [`SourceErrorKind::EndOfStream`]. Per frame:
//! one CDR pass over the pixels into the source's buffer; the `mcap` crate allocates per chunk when decompressing
//! (host-side replay, not the head's live path).

mod cdr;
mod stream;
#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};
use std::time::Duration;

use mcap::records::Record;
use supine_core::camera::{Intrinsics, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD};
use supine_core::depth::DepthFrame;

pub use cdr::{
    DepthEncoding, ImageInfo, decode_camera_info, decode_depth_image, encode_camera_info, encode_image_16uc1,
    encode_image_32fc1,
};
pub use stream::ChannelInfo;

use crate::source::{DepthSource, SourceError, SourceErrorKind, capture_time};
use stream::Stream;

/// The ROS 2 schema of images.
pub const IMAGE_SCHEMA: &str = "sensor_msgs/msg/Image";
/// The ROS 2 schema of camera intrinsics.
pub const CAMERA_INFO_SCHEMA: &str = "sensor_msgs/msg/CameraInfo";

/// A depth topic of a ROS 2 MCAP bag, frame by frame.
pub struct McapSource {
    stream: Stream,
    name: String,
    topic: String,
    channel: u16,
    frames: Option<u64>,
    intrinsics: Intrinsics,
    encoding: DepthEncoding,
    pixels: Vec<u16>,
    /// The frame decoded at open (for its size) is lent first.
    pending: Option<(u64, u32)>,
    origin_ns: u64,
    last_ns: u64,
    images: u32,
    done: bool,
}

/// A message of the image channel as read: its stamp (or log time) and pixel metadata, or why it is bad.
type Decoded = Result<(u64, ImageInfo), SourceError>;

impl McapSource {
    /// Open `path` and play `topic`, or the bag's only depth-like topic when `None` (see the module docs).
    pub fn open(path: impl AsRef<Path>, topic: Option<&str>) -> Result<Self, SourceError> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let channels = stream::inventory(path, &name)?;
        let image = choose_topic(&name, &channels, topic)?;
        let info_channel = camera_info_channel(&channels, &image.topic);

        let mut stream = Stream::open(path, &name)?;
        let mut pixels = Vec::new();
        let mut intrinsics_seen = None;
        // The first image fixes the frame size; camera info published before it is taken on the way.
        let first = loop {
            let decoded = stream.next_with(|record| match record {
                Record::Message { header, data } if header.channel_id == image.id => {
                    Some(Some(decode(&data, header.log_time, &mut pixels)))
                }
                Record::Message { header, data } if Some(header.channel_id) == info_channel => {
                    if intrinsics_seen.is_none() {
                        intrinsics_seen = decode_camera_info(&data).ok();
                    }
                    Some(None)
                }
                _ => None,
            })?;
            match decoded {
                None => {
                    return Err(SourceError::new(
                        SourceErrorKind::EndOfStream,
                        format!("{name}: topic {} holds no image message", image.topic),
                    ));
                }
                Some(None) => continue,
                Some(Some(result)) => break result.map_err(|e| e.context(format!("{name}: first image")))?,
            }
        };
        let (stamp, info) = first;
        if intrinsics_seen.is_none()
            && let Some(id) = info_channel
        {
            intrinsics_seen = first_camera_info(path, &name, id);
        }
        let intrinsics = match intrinsics_seen {
            Some(k) if k.width == info.width && k.height == info.height => k,
            Some(k) => {
                tracing::warn!(
                    "{name}: camera info is {}x{}, the images {}x{}; using the Kinect field of view",
                    k.width,
                    k.height,
                    info.width,
                    info.height
                );
                Intrinsics::from_fov(info.width, info.height, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD)
            }
            None => Intrinsics::from_fov(info.width, info.height, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD),
        };
        Ok(McapSource {
            stream,
            name,
            topic: image.topic.clone(),
            channel: image.id,
            frames: image.messages,
            intrinsics,
            encoding: info.encoding,
            pixels,
            pending: Some((stamp, 0)),
            origin_ns: stamp,
            last_ns: stamp,
            images: 1,
            done: false,
        })
    }

    /// The channels of the bag at `path` (for listings and error messages).
    pub fn channels(path: impl AsRef<Path>) -> Result<Vec<ChannelInfo>, SourceError> {
        let path = path.as_ref();
        stream::inventory(path, &path.display().to_string())
    }

    /// Image messages on the topic, when the bag's statistics (or the open scan) counted them.
    pub fn frame_count(&self) -> Option<u64> {
        self.frames
    }

    /// The topic being played.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// The first frame's stamp in ns since the Unix epoch: capture times count from it.
    pub fn origin_ns(&self) -> u64 {
        self.origin_ns
    }

    /// The pixel encoding of the first frame.
    pub fn encoding(&self) -> DepthEncoding {
        self.encoding
    }

    fn lend(&self, stamp_ns: u64, index: u32) -> Result<DepthFrame<'_>, SourceError> {
        let capture = capture_time((stamp_ns - self.origin_ns) / 1000)?;
        DepthFrame::new(
            &self.pixels,
            self.intrinsics.width,
            self.intrinsics.height,
            capture,
            index,
        )
        .map_err(|e| SourceError::new(SourceErrorKind::CorruptData, format!("{}: {e}", self.name)))
    }
}

/// Decode one image message; the stamp falls back to the log time when the header's is unset.
fn decode(data: &[u8], log_time: u64, pixels: &mut Vec<u16>) -> Decoded {
    let info = decode_depth_image(data, pixels)?;
    let stamp = if info.stamp_ns != 0 {
        info.stamp_ns
    } else {
        log_time
    };
    Ok((stamp, info))
}

impl DepthSource for McapSource {
    fn next_frame(&mut self, _timeout: Duration) -> Result<DepthFrame<'_>, SourceError> {
        if let Some((stamp, index)) = self.pending.take() {
            return self.lend(stamp, index);
        }
        if self.done {
            return Err(SourceError::end_of_stream());
        }
        let channel = self.channel;
        let pixels = &mut self.pixels;
        let next = self.stream.next_with(|record| match record {
            Record::Message { header, data } if header.channel_id == channel => {
                Some(decode(&data, header.log_time, pixels))
            }
            _ => None,
        });
        let decoded = match next {
            Ok(Some(d)) => d,
            Ok(None) => {
                self.done = true;
                return Err(SourceError::end_of_stream());
            }
            Err(e) => {
                self.done = true;
                return Err(e);
            }
        };
        let index = self.images;
        self.images = self.images.saturating_add(1);
        let bad = |why: String| {
            SourceError::new(
                SourceErrorKind::CorruptData,
                format!("{}: image {index} of {}: {why}", self.name, self.topic),
            )
        };
        let (stamp, info) = match decoded {
            Ok(d) => d,
            Err(e) => {
                return Err(SourceError::new(
                    e.kind(),
                    format!("{}: image {index} of {}: {}", self.name, self.topic, e.message()),
                ));
            }
        };
        if (info.width, info.height) != (self.intrinsics.width, self.intrinsics.height) {
            return Err(bad(format!(
                "{}x{}, the topic started at {}x{}",
                info.width, info.height, self.intrinsics.width, self.intrinsics.height
            )));
        }
        if stamp < self.last_ns {
            return Err(bad(format!(
                "stamp {stamp} ns is earlier than the previous frame's {} ns",
                self.last_ns
            )));
        }
        self.last_ns = stamp;
        self.lend(stamp, index)
    }

    fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn describe(&self) -> String {
        let frames = match self.frames {
            Some(n) => format!("{n} frames"),
            None => "frame count unknown".into(),
        };
        format!(
            "mcap:{}#{} (ROS 2 {} {}x{}, {frames})",
            self.name,
            self.topic,
            self.encoding.as_str(),
            self.intrinsics.width,
            self.intrinsics.height
        )
    }
}

/// The image channel to play: `topic` when given, else the only (depth-named) image topic.
fn choose_topic<'a>(
    name: &str,
    channels: &'a [ChannelInfo],
    topic: Option<&str>,
) -> Result<&'a ChannelInfo, SourceError> {
    let images: Vec<&ChannelInfo> = channels
        .iter()
        .filter(|c| c.schema == IMAGE_SCHEMA && c.encoding == "cdr")
        .collect();
    let list = |cs: &[&ChannelInfo]| {
        if cs.is_empty() {
            return "none".to_owned();
        }
        cs.iter()
            .map(|c| match c.messages {
                Some(n) => format!("{} ({n} messages)", c.topic),
                None => c.topic.clone(),
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some(want) = topic {
        return match channels.iter().find(|c| c.topic == want) {
            Some(c) if images.iter().any(|i| i.id == c.id) => Ok(c),
            Some(c) => Err(SourceError::new(
                SourceErrorKind::InvalidArgument,
                format!(
                    "{name}: topic {want} carries {} ({}), not CDR {IMAGE_SCHEMA}; image topics: {}",
                    if c.schema.is_empty() {
                        "no schema"
                    } else {
                        &c.schema
                    },
                    c.encoding,
                    list(&images)
                ),
            )),
            None => Err(SourceError::new(
                SourceErrorKind::InvalidArgument,
                format!("{name}: no topic {want}; image topics: {}", list(&images)),
            )),
        };
    }
    let depth: Vec<&ChannelInfo> = images
        .iter()
        .copied()
        .filter(|c| c.topic.contains("depth"))
        .collect();
    match (images.as_slice(), depth.as_slice()) {
        ([only], _) | (_, [only]) => Ok(only),
        ([], _) => {
            let all: Vec<&ChannelInfo> = channels.iter().collect();
            Err(SourceError::new(
                SourceErrorKind::InvalidArgument,
                format!("{name}: no CDR {IMAGE_SCHEMA} topic; the bag has: {}", list(&all)),
            ))
        }
        _ => Err(SourceError::new(
            SourceErrorKind::InvalidArgument,
            format!(
                "{name}: {} image topics, choose one with --topic (or mcap:PATH#TOPIC): {}",
                images.len(),
                list(&images)
            ),
        )),
    }
}

/// The camera info channel for `image_topic`: `<namespace>/camera_info`, else the only one.
fn camera_info_channel(channels: &[ChannelInfo], image_topic: &str) -> Option<u16> {
    let infos: Vec<&ChannelInfo> = channels
        .iter()
        .filter(|c| c.schema == CAMERA_INFO_SCHEMA && c.encoding == "cdr")
        .collect();
    let sibling = image_topic
        .rsplit_once('/')
        .map(|(ns, _)| format!("{ns}/camera_info"));
    infos
        .iter()
        .find(|c| Some(&c.topic) == sibling.as_ref())
        .or(match infos.as_slice() {
            [only] => Some(only),
            _ => None,
        })
        .map(|c| c.id)
}

/// The first decodable camera info on channel `id` (a separate pass: it may come after the first image).
fn first_camera_info(path: &Path, name: &str, id: u16) -> Option<Intrinsics> {
    let mut stream = Stream::open(path, name).ok()?;
    stream
        .next_with(|record| match record {
            Record::Message { header, data } if header.channel_id == id => decode_camera_info(&data).ok(),
            _ => None,
        })
        .ok()
        .flatten()
}

/// Whether `path` names an MCAP file by its extension (`file:` sources pick the reader by it).
pub fn is_mcap_path(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// A `PathBuf` helper for the spec parser: `PATH#/topic` split at the last `#` followed by `/`.
pub(crate) fn split_topic(rest: &str) -> (PathBuf, Option<String>) {
    match rest.rsplit_once('#') {
        Some((path, topic)) if topic.starts_with('/') && !path.is_empty() => {
            (PathBuf::from(path), Some(topic.to_owned()))
        }
        _ => (PathBuf::from(rest), None),
    }
}
