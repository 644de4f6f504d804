//! Model files and recordings the cross-crate tests load: core's fixture model files (written with
//! `model_file::write`, see `supine_core::fixture`) as owned bytes, and the committed demo recording with its
//! ground truth, read through the same `DepthSource` a live Kinect uses.

use std::path::PathBuf;

use supine_core::fixture;
use supine_drivers::DepthSource;
use supine_drivers::oni::OniReader;

/// The tiny body-model fixture as a file image.
pub fn tiny_body_model() -> Vec<u8> {
    let mut buf = vec![0u8; fixture::TINY_BODY_LEN];
    let n = fixture::tiny_body_model(&mut buf).expect("the fixture fits its documented length");
    buf.truncate(n);
    buf
}

/// The workspace root (the parent of this crate's folder).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// Folder of the committed demo recording (`sequence.oni`, `truth.jsonl`, `sequence.json`).
pub fn demo_dir() -> PathBuf {
    workspace_root().join("models/artifacts/demo")
}

/// One frame of a recording, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnedFrame {
    /// Depth, mm, row-major, 0 = no depth.
    pub depth_mm: Vec<u16>,
    /// Width in pixels.
    pub width: u16,
    /// Height in pixels.
    pub height: u16,
    /// Capture time, µs.
    pub capture_us: u64,
    /// Frame index as the file numbers it.
    pub index: u32,
}

/// The first `max` frames of an .oni recording (all of them if it has fewer), read with the pure-Rust reader.
pub fn load_frames(path: &std::path::Path, max: usize) -> Result<Vec<OwnedFrame>, String> {
    let mut reader = OniReader::open(path).map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    while out.len() < max {
        match reader.next_frame(std::time::Duration::ZERO) {
            Ok(f) => out.push(OwnedFrame {
                depth_mm: f.depth_mm().to_vec(),
                width: f.width(),
                height: f.height(),
                capture_us: f.capture.as_us(),
                index: f.index,
            }),
            Err(e) if e.kind() == supine_drivers::SourceErrorKind::EndOfStream => break,
            Err(e) => return Err(format!("{}: {e}", path.display())),
        }
    }
    Ok(out)
}

/// The committed demo recording's frames (up to `max`).
pub fn demo_frames(max: usize) -> Vec<OwnedFrame> {
    load_frames(&demo_dir().join("sequence.oni"), max).expect("the committed demo recording reads")
}
