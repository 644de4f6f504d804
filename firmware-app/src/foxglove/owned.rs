//! [`OwnedFrame`]: a [`FrameRecord`] copied out of the frame loop's borrowed buffers, so that encoding and writing
//! happen on the outputs' own thread. Copying costs one pass over the depth image (0.6 MB at 640x480) and the torso
//! mesh; [`OwnedFrame::copy_from`] reuses the buffers of a spent frame, so a steady loop does not allocate.

use supine_core::camera::Intrinsics;
use supine_core::geometry::{Isometry3, Point3};
use supine_core::salient::SalientPoint;
use supine_core::time::Timestamp;
use supine_core::wire::{Message, TrackerState};

use super::{FrameRecord, ProbeOverlay};

/// The torso mesh placed in the camera frame, owned.
#[derive(Debug, Clone, Default)]
pub struct OwnedTorso {
    /// Vertices, `torso` frame.
    pub vertices: Vec<Point3>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[u32; 3]>,
    /// Where the torso frame is.
    pub camera_from_torso: Isometry3,
}

/// One frame's record, owned.
#[derive(Debug, Clone)]
pub struct OwnedFrame {
    /// Capture time.
    pub capture: Timestamp,
    /// Frame index as the source counts it.
    pub index: u32,
    /// Depth pixels, row-major mm.
    pub depth_mm: Vec<u16>,
    /// Width in pixels.
    pub width: u16,
    /// Height in pixels.
    pub height: u16,
    /// Depth camera intrinsics.
    pub intrinsics: Intrinsics,
    /// Salient points, camera frame.
    pub salient: Option<[Point3; SalientPoint::COUNT]>,
    /// The torso mesh, when present (`torso_buf` keeps its buffers when absent).
    pub torso: Option<OwnedTorso>,
    torso_buf: OwnedTorso,
    /// The probe.
    pub probe: Option<ProbeOverlay>,
    /// The frame's packets.
    pub packets: Vec<Message>,
    /// Tracker state.
    pub state: Option<TrackerState>,
}

impl Default for OwnedFrame {
    fn default() -> Self {
        OwnedFrame {
            capture: Timestamp::default(),
            index: 0,
            depth_mm: Vec::new(),
            width: 0,
            height: 0,
            intrinsics: Intrinsics::KINECT_V1,
            salient: None,
            torso: None,
            torso_buf: OwnedTorso::default(),
            probe: None,
            packets: Vec::new(),
            state: None,
        }
    }
}

impl OwnedFrame {
    /// Overwrite this frame with a copy of `record`, reusing its buffers.
    pub fn copy_from(&mut self, record: &FrameRecord<'_>) {
        self.capture = record.capture;
        self.index = record.depth.index;
        self.depth_mm.clear();
        self.depth_mm.extend_from_slice(record.depth.depth_mm());
        self.width = record.depth.width();
        self.height = record.depth.height();
        self.intrinsics = record.intrinsics;
        self.salient = record.salient.copied();
        let mut torso = self
            .torso
            .take()
            .unwrap_or_else(|| std::mem::take(&mut self.torso_buf));
        match &record.torso {
            Some(t) => {
                torso.vertices.clear();
                torso.vertices.extend_from_slice(t.surface.vertices());
                torso.triangles.clear();
                torso
                    .triangles
                    .extend((0..t.surface.triangle_count()).map(|i| t.surface.triangle(i).map(|v| v as u32)));
                torso.camera_from_torso = t.camera_from_torso;
                self.torso = Some(torso);
            }
            None => self.torso_buf = torso,
        }
        self.probe = record.probe;
        self.packets.clear();
        self.packets.extend_from_slice(record.packets);
        self.state = record.state;
    }
}
