//! Body shape from one depth frame (paper §3.2) and its refinement by fitting (§3.4), host side: data access,
//! randomised SVD, the shape forest trainer, the `SHAP` file writer, `train shape` and `eval shape` (Fig. 5).
//! The per-frame code they drive lives in `supine_core::shape` and `supine_core::fit`.

pub mod chart;
pub mod cli;
pub mod data;
pub mod eval;
pub mod file;
pub mod forest;
pub mod ridge;
pub mod rsvd;
pub mod train;

/// Default shape model artifact, relative to the workspace root.
pub const DEFAULT_ARTIFACT: &str = "models/artifacts/shape.ssm";

/// Absolute path of the committed default shape model.
pub fn default_artifact_path() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("artifacts")
        .join("shape.ssm")
}
