//! What one frame of the service looks like to Foxglove: [`FrameRecord`] (the depth frame and what the tracker made
//! of it) encoded once into JSON messages on fixed channels ([`Topic`]), then written to an MCAP file
//! ([`mcap_out::McapRecorder`], `--record`) and/or served live ([`live::LiveView`], `--view`).
//!
//! Encoding is JSON with Foxglove's well-known schema names (`foxglove.RawImage`, `foxglove.CameraCalibration`,
//! `foxglove.SceneUpdate`, `foxglove.FrameTransforms`) and JSON schemas written for them here ([`schemas`]); packets
//! use the `supine wire decode` JSON form. Frames: `robot_base` (when calibrated) → `camera` → `torso`.
//!
//! Cost per frame, only when recording or viewing: the depth image is base64'd (about 0.8 MB of JSON at 640x480)
//! and the torso mesh is written out as JSON; a few ms on the host, allocation per message.

pub mod live;
pub mod mcap_out;
mod messages;
pub mod outputs;
pub mod owned;
pub mod schemas;

use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::{Isometry3, Point3};
use supine_core::salient::SalientPoint;
use supine_core::time::Timestamp;
use supine_core::torso::TorsoSurface;
use supine_core::wire::{Message, TrackerState};

pub use messages::encode_frame;

/// One frame as the recorder and the live view take it.
#[derive(Debug, Clone, Copy)]
pub struct FrameRecord<'a> {
    /// Capture time of the depth frame.
    pub capture: Timestamp,
    /// The depth frame.
    pub depth: DepthFrame<'a>,
    /// The depth camera's intrinsics.
    pub intrinsics: Intrinsics,
    /// Salient points in the camera frame, in [`SalientPoint::ALL`] order, when the tracker has them.
    pub salient: Option<&'a [Point3; SalientPoint::COUNT]>,
    /// The shaped torso and where it is, when the tracker has it.
    pub torso: Option<TorsoOverlay<'a>>,
    /// The probe, when its pose is known.
    pub probe: Option<ProbeOverlay>,
    /// The wire packets sent for this frame.
    pub packets: &'a [Message],
    /// The tracker's state after this frame (`None` before a tracker runs, as in a depth-only replay).
    pub state: Option<TrackerState>,
}

impl<'a> FrameRecord<'a> {
    /// A record with the depth frame only (tests build overlays on it).
    #[cfg(test)]
    pub fn depth_only(depth: DepthFrame<'a>, intrinsics: Intrinsics) -> Self {
        FrameRecord {
            capture: depth.capture,
            depth,
            intrinsics,
            salient: None,
            torso: None,
            probe: None,
            packets: &[],
            state: None,
        }
    }
}

/// The fitted torso surface placed in the camera frame.
#[derive(Debug, Clone, Copy)]
pub struct TorsoOverlay<'a> {
    /// Vertices and triangles in the `torso` frame.
    pub surface: TorsoSurface<'a>,
    /// Where the torso frame is.
    pub camera_from_torso: Isometry3,
}

/// The probe tip and the torso surface point it maps to, camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeOverlay {
    /// Probe tip.
    pub tip: Point3,
    /// The nearest point of the torso surface, when mapped.
    pub surface_point: Option<Point3>,
}

/// The channels every recording and live view carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Topic {
    /// `foxglove.RawImage`, 16UC1 millimetres.
    Depth,
    /// `foxglove.CameraCalibration` of the depth camera.
    Calibration,
    /// `foxglove.SceneUpdate`: torso mesh, salient points, probe.
    Scene,
    /// `foxglove.FrameTransforms`: robot_base → camera → torso.
    Transforms,
    /// One message per wire packet (`supine wire decode` JSON).
    Packets,
    /// Frame index, capture time and tracker state.
    Tracker,
}

impl Topic {
    /// Every topic, in channel-id order.
    pub const ALL: [Topic; 6] = [
        Topic::Depth,
        Topic::Calibration,
        Topic::Scene,
        Topic::Transforms,
        Topic::Packets,
        Topic::Tracker,
    ];

    /// The topic name.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Depth => "/depth",
            Topic::Calibration => "/depth/calibration",
            Topic::Scene => "/scene",
            Topic::Transforms => "/tf",
            Topic::Packets => "/packets",
            Topic::Tracker => "/tracker",
        }
    }

    /// The schema name Foxglove dispatches on.
    pub fn schema_name(self) -> &'static str {
        match self {
            Topic::Depth => "foxglove.RawImage",
            Topic::Calibration => "foxglove.CameraCalibration",
            Topic::Scene => "foxglove.SceneUpdate",
            Topic::Transforms => "foxglove.FrameTransforms",
            Topic::Packets => "supine.Packet",
            Topic::Tracker => "supine.TrackerStatus",
        }
    }

    /// 1-based channel id (the live view's; the MCAP writer assigns its own in the same order).
    pub fn id(self) -> u16 {
        self as u16 + 1
    }
}

/// One frame's messages, encoded once for every output.
#[derive(Debug, Clone, Default)]
pub struct FrameMessages {
    /// Log time in ns (monotonic across the run, see [`LogClock`]).
    pub log_ns: u64,
    /// (topic, JSON payload), several per topic for packets.
    pub items: Vec<(Topic, Vec<u8>)>,
}

/// Log times for the outputs: the capture time in ns, kept strictly increasing when the capture clock steps back
/// (a looping file, a sensor reopened) by shifting the rest of the run forward.
#[derive(Debug, Clone, Default)]
pub struct LogClock {
    offset_ns: u64,
    last_ns: Option<u64>,
}

impl LogClock {
    /// The log time for a frame captured at `capture`.
    pub fn log_ns(&mut self, capture: Timestamp) -> u64 {
        let raw = capture.as_us() * 1000;
        let mut t = raw + self.offset_ns;
        if let Some(last) = self.last_ns
            && t <= last
        {
            // One nominal frame period (30 Hz) after the previous frame.
            let next = last + 33_333_333;
            self.offset_ns += next - t;
            t = next;
        }
        self.last_ns = Some(t);
        t
    }
}

/// What the Foxglove outputs write for one tracked frame.
pub fn record_of<'a>(v: &'a crate::pipeline::FrameView<'a, 'a>, intrinsics: Intrinsics) -> FrameRecord<'a> {
    let r = v.report;
    let pose = r.camera_from_torso;
    FrameRecord {
        capture: v.frame.capture,
        depth: *v.frame,
        intrinsics,
        salient: r.salient_camera.as_ref(),
        torso: pose
            .zip(v.surface)
            .map(|(camera_from_torso, surface)| TorsoOverlay {
                surface,
                camera_from_torso,
            }),
        probe: pose.zip(r.probe).map(|(p, m)| ProbeOverlay {
            tip: p * m.tip,
            surface_point: Some(p * m.nearest),
        }),
        packets: &r.packets,
        state: Some(r.state),
    }
}

#[cfg(test)]
mod tests;
