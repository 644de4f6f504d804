//! Depth through libOpenNI2 (feature `openni2`): live devices and .oni playback by the real OpenNI2 stack.
//!
//! Live Kinect v1 needs libfreenect's OpenNI2 driver (`libFreenectDriver.so` in `.../OpenNI2/Drivers`; Debian ships
//! only PS1080, PSLink, OniFile and DummyDevice). The source asks for DEPTH_1_MM 640x480@30 and takes the intrinsics
//! from the stream's FOV properties (principal point at the image centre, as OpenNI's own world conversion).
//!
//! .oni files (`openni2:PATH`) play with PLAYBACK_SPEED = -1 (manual: exactly one frame per read, none dropped) and
//! repeat off; the end is detected by a frame count (NUMBER_OF_FRAMES) and, failing that, by
//! `oniWaitForAnyStream` timing out. Seeking is never used: it crashes the Debian build's player thread. Nor is a
//! file's stream destroyed before its device closes: the player thread reads the stream list unlocked (`sys.rs`,
//! `Deferred`). Known and left: closing a file while its player still has frames to deliver is slow (about a second)
//! and, closed that way 60 times in one process, libOniFile still crashed in 7 of 19 runs (2026-12-05; another race
//! in the player, not found yet). The pure-Rust reader (`file:PATH`) has no player thread.
//!
//! # Timing and cost
//! `next_frame` waits in `oniWaitForAnyStream` for at most the timeout (files: at least [`FILE_EOF_WAIT`], since a
//! timeout there means end of file), then copies the frame row by row into a buffer allocated at open and releases
//! OpenNI's frame at once: one 600 kB copy, no allocation.

mod sys;

use std::time::Duration;

use supine_core::camera::{Intrinsics, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD};
use supine_core::depth::DepthFrame;

pub use sys::DeviceInfo;
use sys::{Context, Device, OniError, OniVideoMode, Recorder, Stream};

use crate::source::{DepthSource, SourceError, SourceErrorKind, capture_time};

/// How long an .oni playback may take to produce the next frame before it counts as the end of the file.
pub const FILE_EOF_WAIT: Duration = Duration::from_millis(2000);

fn to_source_error(e: OniError, context: &str) -> SourceError {
    let kind = match e.status {
        sys::STATUS_NO_DEVICE => SourceErrorKind::NoDevice,
        sys::STATUS_TIME_OUT => SourceErrorKind::Timeout,
        sys::STATUS_NOT_SUPPORTED => SourceErrorKind::Unsupported,
        _ => SourceErrorKind::Other,
    };
    SourceError::new(kind, format!("{context}: {e}"))
}

/// The devices OpenNI2 enumerates (files are never listed).
pub fn list_devices() -> Result<Vec<DeviceInfo>, SourceError> {
    let ctx = Context::acquire().map_err(|e| to_source_error(e, "initialising OpenNI2"))?;
    ctx.devices()
        .map_err(|e| to_source_error(e, "listing OpenNI2 devices"))
}

/// A depth stream from libOpenNI2: a live device or an .oni file it plays.
pub struct OpenNi2Source {
    // Drop order: recorder, stream, device, context (a file's stream is destroyed by the device, after its close).
    recorder: Option<Recorder>,
    stream: Stream,
    device: Device,
    ctx: Context,
    label: String,
    frames_in_file: Option<u32>,
    frames_read: u32,
    mode: OniVideoMode,
    intrinsics: Intrinsics,
    depth: Vec<u16>,
    ended: bool,
}

impl std::fmt::Debug for OpenNi2Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OpenNi2Source")
            .field("label", &self.label)
            .field("mode", &self.mode)
            .finish()
    }
}

impl OpenNi2Source {
    /// Open `uri` (a device URI or an .oni path); `None` opens the first device and fails with
    /// [`SourceErrorKind::NoDevice`] if there is none.
    pub fn open(uri: Option<&str>) -> Result<Self, SourceError> {
        let ctx = Context::acquire().map_err(|e| to_source_error(e, "initialising OpenNI2"))?;
        if uri.is_none() {
            let devices = ctx
                .devices()
                .map_err(|e| to_source_error(e, "listing OpenNI2 devices"))?;
            if devices.is_empty() {
                return Err(SourceError::new(
                    SourceErrorKind::NoDevice,
                    "no OpenNI2 device found (is the Kinect plugged in, and libFreenectDriver.so installed in \
                     the OpenNI2 Drivers directory? Debian's OpenNI2 has no Kinect v1 driver)",
                ));
            }
        }
        let label = uri.map_or_else(|| "openni2".to_owned(), |u| format!("openni2:{u}"));
        let device = Device::open(&ctx, uri).map_err(|e| to_source_error(e, &format!("opening {label}")))?;
        let is_file = device.is_playback();
        if is_file {
            device
                .set_f32(sys::DEVICE_PROPERTY_PLAYBACK_SPEED, -1.0)
                .map_err(|e| to_source_error(e, &format!("{label}: manual playback speed")))?;
            device
                .set_i32(sys::DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED, 0)
                .map_err(|e| to_source_error(e, &format!("{label}: playback repeat off")))?;
        }
        let mut stream = device
            .create_depth_stream()
            .map_err(|e| to_source_error(e, &format!("{label}: depth stream")))?;
        if !is_file {
            let wanted = OniVideoMode {
                pixel_format: sys::PIXEL_FORMAT_DEPTH_1_MM,
                resolution_x: 640,
                resolution_y: 480,
                fps: 30,
            };
            if let Err(e) = stream.set_video_mode(wanted) {
                let modes: Vec<String> = device
                    .depth_modes()
                    .iter()
                    .map(|m| {
                        format!(
                            "{}x{}@{} fmt {}",
                            m.resolution_x, m.resolution_y, m.fps, m.pixel_format
                        )
                    })
                    .collect();
                return Err(SourceError::new(
                    SourceErrorKind::Unsupported,
                    format!(
                        "{label}: DEPTH_1_MM 640x480@30 refused ({e}); the device offers {}",
                        modes.join(", ")
                    ),
                ));
            }
        }
        let mode = stream
            .video_mode()
            .map_err(|e| to_source_error(e, &format!("{label}: video mode")))?;
        if mode.pixel_format != sys::PIXEL_FORMAT_DEPTH_1_MM
            && mode.pixel_format != sys::PIXEL_FORMAT_DEPTH_100_UM
        {
            return Err(SourceError::new(
                SourceErrorKind::Unsupported,
                format!(
                    "{label}: depth pixel format {} is not in millimetres",
                    mode.pixel_format
                ),
            ));
        }
        let (w, h) = (mode.resolution_x, mode.resolution_y);
        if !(1..=1600).contains(&w) || !(1..=1200).contains(&h) {
            return Err(SourceError::new(
                SourceErrorKind::CorruptData,
                format!("{label}: implausible video mode {w}x{h}"),
            ));
        }
        let hfov = stream
            .get_f32(sys::STREAM_PROPERTY_HORIZONTAL_FOV)
            .unwrap_or(KINECT_V1_HFOV_RAD);
        let vfov = stream
            .get_f32(sys::STREAM_PROPERTY_VERTICAL_FOV)
            .unwrap_or(KINECT_V1_VFOV_RAD);
        let intrinsics = Intrinsics::from_fov(w as u16, h as u16, hfov, vfov);
        let frames_in_file = if is_file {
            stream
                .get_i32(sys::STREAM_PROPERTY_NUMBER_OF_FRAMES)
                .ok()
                .filter(|&n| n > 0)
                .map(|n| n as u32)
        } else {
            None
        };
        stream
            .start()
            .map_err(|e| to_source_error(e, &format!("{label}: starting the depth stream")))?;
        tracing::info!(
            "{label}: depth {w}x{h}@{} format {}, file: {is_file}",
            mode.fps,
            mode.pixel_format
        );
        Ok(OpenNi2Source {
            recorder: None,
            stream,
            device,
            ctx,
            label,
            frames_in_file,
            frames_read: 0,
            mode,
            intrinsics,
            depth: vec![0; (w * h) as usize],
            ended: false,
        })
    }

    /// Whether this is an .oni file played by OpenNI2 (rather than a live device).
    pub fn is_file(&self) -> bool {
        self.device.is_playback()
    }

    /// The device's description from OpenNI2.
    pub fn device_info(&self) -> Result<DeviceInfo, SourceError> {
        self.device.info().map_err(|e| to_source_error(e, &self.label))
    }

    /// Start OpenNI2's own Recorder on this stream, writing `path` (a `16zT` .oni, as OpenNI writes it); every frame
    /// read afterwards is recorded. The file is completed by [`OpenNi2Source::stop_openni2_recording`] or on drop.
    pub fn start_openni2_recording(&mut self, path: &str) -> Result<(), SourceError> {
        self.recorder = None;
        let rec = Recorder::start(&self.ctx, path, &self.stream)
            .map_err(|e| to_source_error(e, &format!("{}: recording to {path}", self.label)))?;
        self.recorder = Some(rec);
        Ok(())
    }

    /// Stop and destroy the OpenNI2 Recorder, which finishes its file.
    pub fn stop_openni2_recording(&mut self) {
        self.recorder = None;
    }
}

impl DepthSource for OpenNi2Source {
    fn next_frame(&mut self, timeout: Duration) -> Result<DepthFrame<'_>, SourceError> {
        if self.ended || self.frames_in_file.is_some_and(|n| self.frames_read >= n) {
            self.ended = true;
            return Err(SourceError::end_of_stream());
        }
        let wait = if self.is_file() {
            timeout.max(FILE_EOF_WAIT)
        } else {
            timeout
        };
        let ms = wait.as_millis().min(i32::MAX as u128) as i32;
        match self.stream.wait(ms) {
            Ok(true) => {}
            Ok(false) if self.is_file() => {
                self.ended = true;
                return Err(SourceError::end_of_stream());
            }
            Ok(false) => return Err(SourceError::timeout()),
            Err(e) => {
                return Err(SourceError::new(
                    SourceErrorKind::Disconnected,
                    format!("{}: {e}", self.label),
                ));
            }
        }
        let (w, h) = (self.mode.resolution_x, self.mode.resolution_y);
        let label = &self.label;
        let frame = self
            .stream
            .read_frame()
            .map_err(|e| SourceError::new(SourceErrorKind::Disconnected, format!("{label}: {e}")))?;
        let (fw, fh, stride, ts, index, format) = frame.meta();
        if (fw, fh) != (w, h) {
            return Err(SourceError::new(
                SourceErrorKind::CorruptData,
                format!("{label}: frame is {fw}x{fh}, the stream mode is {w}x{h}"),
            ));
        }
        let data = frame.data();
        let row_bytes = w as usize * 2;
        let stride = if stride > 0 { stride as usize } else { row_bytes };
        if stride < row_bytes || data.len() < stride * (h as usize - 1) + row_bytes {
            return Err(SourceError::new(
                SourceErrorKind::CorruptData,
                format!(
                    "{label}: frame holds {} bytes, too few for {w}x{h} (stride {stride})",
                    data.len()
                ),
            ));
        }
        for (row, out) in self.depth.chunks_exact_mut(w as usize).enumerate() {
            let src = &data[row * stride..row * stride + row_bytes];
            for (d, s) in out.iter_mut().zip(src.chunks_exact(2)) {
                *d = u16::from_le_bytes([s[0], s[1]]);
            }
        }
        drop(frame);
        if format == sys::PIXEL_FORMAT_DEPTH_100_UM {
            for d in &mut self.depth {
                *d = ((*d as u32 + 5) / 10) as u16;
            }
        }
        self.frames_read += 1;
        DepthFrame::new(
            &self.depth,
            w as u16,
            h as u16,
            capture_time(ts)?,
            index.max(0) as u32,
        )
        .map_err(|e| SourceError::new(SourceErrorKind::Other, e.to_string()))
    }

    fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn describe(&self) -> String {
        let kind = if self.is_file() {
            "file played by libOpenNI2"
        } else {
            "live"
        };
        format!(
            "{} ({kind}, {}x{}@{})",
            self.label, self.mode.resolution_x, self.mode.resolution_y, self.mode.fps
        )
    }
}
