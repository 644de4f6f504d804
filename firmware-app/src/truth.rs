//! Ground truth beside a synthetic recording (`supine-models sequence` writes it): `sequence.json` for what is
//! constant (the patient's shape, the camera's pose in `robot_base`) and `truth.jsonl` with one line per frame.
//! Only the fields that scoring needs are read; the rest of each record is ignored. Read once, before the loop.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, ensure};
use supine_core::geometry::{Isometry3, Point3, isometry_from_rows};

/// One frame's truth.
#[derive(Debug, Clone, serde::Deserialize)]
pub struct TruthFrame {
    /// Salient points in the camera frame, metres.
    pub salient_camera: [[f32; 3]; 6],
    /// The torso pose, 4x4 row-major.
    pub camera_from_torso: [[f32; 4]; 4],
    /// The probe tip's pose in `robot_base`, when the arm is in the scene.
    pub world_from_probe: Option<[[f32; 4]; 4]>,
}

#[derive(Debug, Clone, serde::Deserialize)]
struct Meta {
    shape: Vec<f32>,
    camera_from_world: [[f32; 4]; 4],
    #[serde(default)]
    episodes: Option<Episodes>,
}

#[derive(Debug, Clone, serde::Deserialize)]
struct Episodes {
    full_occlusion: Option<FullOcclusion>,
}

/// The episode where the arm parks over the whole torso (`sequence --full-occlusion`).
#[derive(Debug, Clone, Copy, serde::Deserialize)]
pub struct FullOcclusion {
    /// First parked frame.
    pub start: u32,
    /// First frame after the park (recovery counts from here).
    pub end: u32,
}

/// The truth of one recording.
#[derive(Debug, Clone)]
pub struct Truth {
    /// The patient's shape, σ units.
    pub shape: Vec<f32>,
    /// Where the camera sits in `robot_base` (the sequences' world frame).
    pub robot_base_from_camera: Isometry3,
    /// One entry per frame, in order.
    pub frames: Vec<TruthFrame>,
    /// The full-occlusion episode, when the sequence has one.
    pub full_occlusion: Option<FullOcclusion>,
}

impl Truth {
    /// Read `truth` (a truth.jsonl) and the sequence.json beside it.
    pub fn load(truth: &Path) -> Result<Self> {
        let meta_path: PathBuf = truth.with_file_name("sequence.json");
        let meta: Meta = serde_json::from_slice(
            &std::fs::read(&meta_path).with_context(|| format!("reading {}", meta_path.display()))?,
        )
        .with_context(|| format!("parsing {}", meta_path.display()))?;
        let text = std::fs::read_to_string(truth).with_context(|| format!("reading {}", truth.display()))?;
        let frames = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
            .map(|(i, l)| {
                serde_json::from_str::<TruthFrame>(l)
                    .with_context(|| format!("{} line {}", truth.display(), i + 1))
            })
            .collect::<Result<Vec<_>>>()?;
        ensure!(!frames.is_empty(), "{} holds no frames", truth.display());
        Ok(Truth {
            shape: meta.shape,
            robot_base_from_camera: isometry_from_rows(&meta.camera_from_world).inverse(),
            frames,
            full_occlusion: meta.episodes.and_then(|e| e.full_occlusion),
        })
    }

    /// The truth of frame `i` (by position in the recording).
    pub fn frame(&self, i: usize) -> Option<&TruthFrame> {
        self.frames.get(i)
    }
}

impl TruthFrame {
    /// The true salient points.
    pub fn salient(&self) -> [Point3; 6] {
        self.salient_camera.map(Point3::from)
    }
}
