//! The depth-source contract: every backend (OpenNI2, libfreenect, V4L2, .oni replay, wrappers) lends frames the same way.
//!
//! # Design
//! A [`DepthSource`] owns one depth buffer, allocated when the source is opened. [`DepthSource::next_frame`] fills it
//! and lends it as a [`DepthFrame`] that borrows the source mutably: the frame must be dropped before the next call,
//! which the borrow checker enforces. Nothing is allocated per frame (the same lending idea as smoltcp's `RxToken`,
//! expressed with a plain borrow instead of a closure so that callers can use `?` freely).
//!
//! # Timing
//! `next_frame(timeout)` blocks the calling thread until a frame is available or `timeout` has passed, then returns
//! [`SourceErrorKind::Timeout`]. `Duration::ZERO` polls. Live sources deliver at the sensor rate (30 Hz for a Kinect v1) and
//! keep at most one frame queued: a caller that falls behind gets the newest frame and sees the gap in
//! [`DepthFrame::index`]. File sources never wait: they return the next recorded frame immediately (no pacing to the
//! recorded rate; pace with the timestamps if needed) and [`SourceErrorKind::EndOfStream`] after the last one.
//!
//! # Errors
//! [`SourceError`] carries an [`SourceErrorKind`] (what a caller branches on, like embedded-hal's `SourceErrorKind`) and a message
//! for people. Messages for the frequent kinds (timeouts) are static strings, so even the error path does not allocate.
//!
//! # Opening by name
//! [`SourceSpec`] parses the CLI strings `openni2[:URI]`, `freenect[:INDEX]`, `v4l2:/dev/videoN`, `file:PATH` (an .oni
//! recording, or a ROS 2 bag when PATH ends in `.mcap`) and `mcap:PATH[#/TOPIC]` (a ROS 2 bag's depth topic);
//! [`open`] turns a spec into a boxed source, with a clear error when a backend was not compiled in.

use std::borrow::Cow;
use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;

use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::time::Timestamp;

/// What went wrong, coarsely: the part of an error that callers branch on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum SourceErrorKind {
    /// No device answered (none plugged in, wrong index or URI, file missing).
    NoDevice,
    /// The device was there and went away (unplugged, USB reset, stream stopped by the driver).
    Disconnected,
    /// No frame arrived within the timeout; the source is still usable.
    Timeout,
    /// Data arrived but is malformed (bad record, truncated file, wrong frame size, undecodable payload).
    CorruptData,
    /// A file or finite source has no more frames.
    EndOfStream,
    /// The backend, format, codec or mode is not supported (or not compiled in).
    Unsupported,
    /// An operating-system I/O error (open, read, write, ioctl, mmap).
    Io,
    /// The caller passed something invalid (malformed source string, out-of-range value).
    InvalidArgument,
    /// Anything else; the message says what.
    Other,
}

impl SourceErrorKind {
    /// A short lowercase name, e.g. for counters and JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            SourceErrorKind::NoDevice => "no device",
            SourceErrorKind::Disconnected => "disconnected",
            SourceErrorKind::Timeout => "timeout",
            SourceErrorKind::CorruptData => "corrupt data",
            SourceErrorKind::EndOfStream => "end of stream",
            SourceErrorKind::Unsupported => "unsupported",
            SourceErrorKind::Io => "i/o error",
            SourceErrorKind::InvalidArgument => "invalid argument",
            SourceErrorKind::Other => "other",
        }
    }
}

impl fmt::Display for SourceErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An error from a depth source, a recording or a file: a kind plus a message naming what failed.
#[derive(Debug)]
pub struct SourceError {
    kind: SourceErrorKind,
    message: Cow<'static, str>,
    io: Option<std::io::Error>,
}

impl SourceError {
    /// An error of `kind` with a message.
    pub fn new(kind: SourceErrorKind, message: impl Into<Cow<'static, str>>) -> Self {
        SourceError {
            kind,
            message: message.into(),
            io: None,
        }
    }

    /// An [`SourceErrorKind::Io`] error (or `NoDevice` for a missing file/device node) wrapping `err`, with context.
    pub fn io(context: impl Into<Cow<'static, str>>, err: std::io::Error) -> Self {
        let kind = match err.kind() {
            std::io::ErrorKind::NotFound => SourceErrorKind::NoDevice,
            std::io::ErrorKind::UnexpectedEof => SourceErrorKind::CorruptData,
            std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock => SourceErrorKind::Timeout,
            _ => SourceErrorKind::Io,
        };
        SourceError {
            kind,
            message: context.into(),
            io: Some(err),
        }
    }

    /// The timeout error: static message, no allocation.
    pub fn timeout() -> Self {
        SourceError::new(SourceErrorKind::Timeout, "no depth frame within the timeout")
    }

    /// The end-of-stream error: static message, no allocation.
    pub fn end_of_stream() -> Self {
        SourceError::new(SourceErrorKind::EndOfStream, "end of stream: no more frames")
    }

    /// The coarse kind of this error.
    pub fn kind(&self) -> SourceErrorKind {
        self.kind
    }

    /// The human-readable message (without the kind and the I/O cause).
    pub fn message(&self) -> &str {
        &self.message
    }

    /// The same error with `context: ` prepended to its message.
    pub fn context(mut self, context: impl fmt::Display) -> Self {
        self.message = Cow::Owned(format!("{context}: {}", self.message));
        self
    }
}

impl fmt::Display for SourceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)?;
        if let Some(io) = &self.io {
            write!(f, ": {io}")?;
        }
        Ok(())
    }
}

impl std::error::Error for SourceError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.io.as_ref().map(|e| e as &(dyn std::error::Error + 'static))
    }
}

/// A source of depth frames (live sensor, file replay, or a wrapper around another source).
///
/// See the [module documentation](self) for the lending, timing and error contract.
pub trait DepthSource {
    /// Block until the next frame is available (at most `timeout`) and lend it.
    ///
    /// The frame borrows the source's internal buffer; it is valid until the next call. Errors of kind
    /// [`SourceErrorKind::Timeout`] leave the source usable; [`SourceErrorKind::EndOfStream`] and [`SourceErrorKind::Disconnected`] are
    /// final for this source. Never allocates on success.
    fn next_frame(&mut self, timeout: Duration) -> Result<DepthFrame<'_>, SourceError>;

    /// The pinhole intrinsics of the frames this source lends (from the device or file FOV, or the Kinect default).
    fn intrinsics(&self) -> Intrinsics;

    /// A short description for logs and `supine info`, e.g. `file:/data/a.oni (16zT, 300 frames)`.
    fn describe(&self) -> String;
}

impl<S: DepthSource + ?Sized> DepthSource for Box<S> {
    fn next_frame(&mut self, timeout: Duration) -> Result<DepthFrame<'_>, SourceError> {
        (**self).next_frame(timeout)
    }
    fn intrinsics(&self) -> Intrinsics {
        (**self).intrinsics()
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
}

/// A parsed source string, as given to `supine record --source` and in the config.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// `openni2` (first device) or `openni2:URI` (a device URI from `supine info`, or a path to an .oni file played by
    /// libOpenNI2).
    OpenNi2 {
        /// Device URI or .oni path; `None` = any device.
        uri: Option<String>,
    },
    /// `freenect` (device 0) or `freenect:INDEX`.
    Freenect {
        /// Device index as counted by libfreenect.
        index: u32,
    },
    /// `v4l2:/dev/videoN`: gspca_kinect in depth mode (Y10B, uncalibrated disparity, see [`crate::kinect_raw`]).
    V4l2 {
        /// Device node path.
        path: PathBuf,
    },
    /// `file:PATH`: an .oni recording read by the pure-Rust reader ([`crate::oni::OniReader`]).
    File {
        /// File path.
        path: PathBuf,
    },
    /// `mcap:PATH[#/TOPIC]` (or `file:PATH.mcap`): a depth topic of a ROS 2 bag ([`crate::ros_bag::McapSource`]).
    Mcap {
        /// File path.
        path: PathBuf,
        /// The image topic; `None` = the bag's only depth-like topic.
        topic: Option<String>,
    },
}

impl SourceSpec {
    /// The file a file source reads (`file:` and `mcap:`), `None` for devices.
    pub fn file_path(&self) -> Option<&std::path::Path> {
        match self {
            SourceSpec::File { path } | SourceSpec::Mcap { path, .. } => Some(path),
            _ => None,
        }
    }
}

impl FromStr for SourceSpec {
    type Err = SourceError;

    fn from_str(s: &str) -> Result<Self, SourceError> {
        let (scheme, rest) = match s.split_once(':') {
            Some((scheme, rest)) => (scheme, Some(rest)),
            None => (s, None),
        };
        let bad = |why: &str| {
            SourceError::new(
                SourceErrorKind::InvalidArgument,
                format!(
                    "bad source {s:?}: {why} (expected openni2[:URI], freenect[:INDEX], v4l2:/dev/videoN, file:PATH \
                     or mcap:PATH[#/TOPIC])"
                ),
            )
        };
        match scheme {
            "openni2" => Ok(SourceSpec::OpenNi2 {
                uri: rest.filter(|r| !r.is_empty()).map(str::to_owned),
            }),
            "freenect" => match rest {
                None | Some("") => Ok(SourceSpec::Freenect { index: 0 }),
                Some(idx) => idx
                    .parse::<u32>()
                    .map(|index| SourceSpec::Freenect { index })
                    .map_err(|_| bad("the freenect index must be a non-negative integer")),
            },
            "v4l2" => match rest {
                Some(path) if !path.is_empty() => Ok(SourceSpec::V4l2 {
                    path: PathBuf::from(path),
                }),
                _ => Err(bad("v4l2 needs a device path, e.g. v4l2:/dev/video0")),
            },
            "file" => match rest {
                Some(path) if !path.is_empty() && crate::ros_bag::is_mcap_path(path.as_ref()) => {
                    Ok(SourceSpec::Mcap {
                        path: PathBuf::from(path),
                        topic: None,
                    })
                }
                Some(path) if !path.is_empty() => Ok(SourceSpec::File {
                    path: PathBuf::from(path),
                }),
                _ => Err(bad("file needs a path, e.g. file:recording.oni")),
            },
            "mcap" => match rest {
                Some(rest) if !rest.is_empty() && !rest.starts_with('#') => {
                    let (path, topic) = crate::ros_bag::split_topic(rest);
                    Ok(SourceSpec::Mcap { path, topic })
                }
                _ => Err(bad(
                    "mcap needs a path, e.g. mcap:bag.mcap or mcap:bag.mcap#/camera/depth/image_raw",
                )),
            },
            "" => Err(bad("empty source")),
            other => Err(bad(&format!("unknown source type {other:?}"))),
        }
    }
}

impl fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SourceSpec::OpenNi2 { uri: None } => f.write_str("openni2"),
            SourceSpec::OpenNi2 { uri: Some(uri) } => write!(f, "openni2:{uri}"),
            SourceSpec::Freenect { index } => write!(f, "freenect:{index}"),
            SourceSpec::V4l2 { path } => write!(f, "v4l2:{}", path.display()),
            SourceSpec::File { path } => write!(f, "file:{}", path.display()),
            SourceSpec::Mcap { path, topic: None } => write!(f, "mcap:{}", path.display()),
            SourceSpec::Mcap {
                path,
                topic: Some(topic),
            } => write!(f, "mcap:{}#{topic}", path.display()),
        }
    }
}

/// Options for [`open_with`] that some backends need.
#[derive(Debug, Clone, Default)]
pub struct OpenOptions {
    /// Raw→mm calibration for `v4l2:` sources (10-bit disparity); `None` uses the nominal, uncalibrated curve and
    /// logs a warning. See [`crate::kinect_raw::DisparityCalibration`].
    pub v4l2_calibration: Option<crate::kinect_raw::DisparityCalibration>,
}

/// Open the source named by `spec` with default options.
pub fn open(spec: &SourceSpec) -> Result<Box<dyn DepthSource>, SourceError> {
    open_with(spec, &OpenOptions::default())
}

/// Open the source named by `spec`.
///
/// Fails with [`SourceErrorKind::Unsupported`] naming the cargo feature when the backend was not compiled in.
pub fn open_with(spec: &SourceSpec, options: &OpenOptions) -> Result<Box<dyn DepthSource>, SourceError> {
    match spec {
        SourceSpec::File { path } => Ok(Box::new(crate::oni::OniReader::open(path)?)),
        SourceSpec::Mcap { path, topic } => Ok(Box::new(crate::ros_bag::McapSource::open(
            path,
            topic.as_deref(),
        )?)),
        SourceSpec::V4l2 { path } => {
            let calibration = options
                .v4l2_calibration
                .unwrap_or(crate::kinect_raw::DisparityCalibration::NOMINAL_10BIT);
            let source = crate::v4l2::V4l2Source::open(path, calibration)?;
            if options.v4l2_calibration.is_none() {
                tracing::warn!(
                    "v4l2 source {} uses the nominal 10-bit disparity curve; calibrate it (drivers/README.md)",
                    path.display()
                );
            }
            Ok(Box::new(source))
        }
        #[cfg(feature = "openni2")]
        SourceSpec::OpenNi2 { uri } => Ok(Box::new(crate::openni2::OpenNi2Source::open(uri.as_deref())?)),
        #[cfg(not(feature = "openni2"))]
        SourceSpec::OpenNi2 { .. } => Err(SourceError::new(
            SourceErrorKind::Unsupported,
            "openni2 support not compiled in: build with --features openni2 (needs libopenni2-dev)",
        )),
        #[cfg(feature = "freenect")]
        SourceSpec::Freenect { index } => Ok(Box::new(crate::freenect::FreenectSource::open(*index)?)),
        #[cfg(not(feature = "freenect"))]
        SourceSpec::Freenect { .. } => Err(SourceError::new(
            SourceErrorKind::Unsupported,
            "freenect support not compiled in: build with --features freenect (needs libfreenect-dev)",
        )),
    }
}

/// A device or recording timestamp in µs as a [`Timestamp`]; one of 2^48 µs (8.9 years) or more is corrupt data.
pub fn capture_time(us: u64) -> Result<Timestamp, SourceError> {
    Timestamp::from_us(us).ok_or_else(|| {
        SourceError::new(
            SourceErrorKind::CorruptData,
            format!("capture timestamp {us} µs is out of range (at most 2^48 - 1)"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_scheme() {
        assert_eq!(
            "openni2".parse::<SourceSpec>().unwrap(),
            SourceSpec::OpenNi2 { uri: None }
        );
        assert_eq!(
            "openni2:/tmp/a.oni".parse::<SourceSpec>().unwrap(),
            SourceSpec::OpenNi2 {
                uri: Some("/tmp/a.oni".into())
            }
        );
        assert_eq!(
            "freenect".parse::<SourceSpec>().unwrap(),
            SourceSpec::Freenect { index: 0 }
        );
        assert_eq!(
            "freenect:2".parse::<SourceSpec>().unwrap(),
            SourceSpec::Freenect { index: 2 }
        );
        assert_eq!(
            "v4l2:/dev/video1".parse::<SourceSpec>().unwrap(),
            SourceSpec::V4l2 {
                path: "/dev/video1".into()
            }
        );
        // Paths may contain colons.
        assert_eq!(
            "file:a:b.oni".parse::<SourceSpec>().unwrap(),
            SourceSpec::File {
                path: "a:b.oni".into()
            }
        );
    }

    #[test]
    fn mcap_specs_by_scheme_or_extension() {
        assert_eq!(
            "file:bags/a.MCAP".parse::<SourceSpec>().unwrap(),
            SourceSpec::Mcap {
                path: "bags/a.MCAP".into(),
                topic: None
            }
        );
        assert_eq!(
            "mcap:a#1.mcap#/cam/depth".parse::<SourceSpec>().unwrap(),
            SourceSpec::Mcap {
                path: "a#1.mcap".into(),
                topic: Some("/cam/depth".into())
            }
        );
        // A `#` not followed by a topic's leading `/` belongs to the path.
        assert_eq!(
            "mcap:a#b.mcap".parse::<SourceSpec>().unwrap(),
            SourceSpec::Mcap {
                path: "a#b.mcap".into(),
                topic: None
            }
        );
    }

    #[test]
    fn display_round_trips() {
        for s in [
            "openni2",
            "openni2:freenect://0",
            "freenect:1",
            "v4l2:/dev/video0",
            "file:x.oni",
            "mcap:x.mcap",
            "mcap:a#b.mcap#/camera/depth/image_raw",
        ] {
            assert_eq!(s.parse::<SourceSpec>().unwrap().to_string(), s);
        }
    }

    #[test]
    fn bad_specs_name_the_problem() {
        for (s, needle) in [
            ("freenect:x", "index"),
            ("v4l2", "device path"),
            ("file:", "needs a path"),
            ("kinect:0", "unknown source type \"kinect\""),
            ("", "empty"),
            ("mcap:", "mcap needs a path"),
            ("mcap:#/depth", "mcap needs a path"),
        ] {
            let e = s.parse::<SourceSpec>().unwrap_err();
            assert_eq!(e.kind(), SourceErrorKind::InvalidArgument);
            assert!(e.to_string().contains(needle), "{s:?}: {e}");
        }
    }

    #[cfg(not(feature = "openni2"))]
    #[test]
    fn missing_backend_says_which_feature() {
        let e = open(&SourceSpec::OpenNi2 { uri: None }).err().unwrap();
        assert_eq!(e.kind(), SourceErrorKind::Unsupported);
        assert!(e.to_string().contains("--features openni2"), "{e}");
    }

    #[cfg(not(feature = "freenect"))]
    #[test]
    fn missing_freenect_says_which_feature() {
        let e = open(&SourceSpec::Freenect { index: 0 }).err().unwrap();
        assert!(e.to_string().contains("--features freenect"), "{e}");
    }

    #[test]
    fn missing_file_is_no_device() {
        let e = open(&SourceSpec::File {
            path: "/nonexistent/x.oni".into(),
        })
        .err()
        .unwrap();
        assert_eq!(e.kind(), SourceErrorKind::NoDevice);
        assert!(e.to_string().contains("/nonexistent/x.oni"), "{e}");
    }

    #[test]
    fn io_errors_map_to_kinds() {
        let e = SourceError::io(
            "reading",
            std::io::Error::from(std::io::ErrorKind::PermissionDenied),
        );
        assert_eq!(e.kind(), SourceErrorKind::Io);
        assert!(std::error::Error::source(&e).is_some());
        assert_eq!(SourceError::timeout().kind(), SourceErrorKind::Timeout);
        assert_eq!(
            SourceError::end_of_stream().context("file:x").message(),
            "file:x: end of stream: no more frames"
        );
    }
}
