//! Where the commands look for model files and the demo recording: one list, so `supine info` reports the
//! directory `supine demo` (and later `supine run`) would load from.

use std::path::PathBuf;

/// Where the Debian package installs the default models (cross/package).
pub const INSTALLED: &str = "/usr/share/supine/models";

/// The model directories searched, in order: `$SUPINE_MODELS`, `models/artifacts` (a checkout), the installed ones.
pub fn model_dirs() -> Vec<PathBuf> {
    let mut dirs = Vec::new();
    if let Some(dir) = std::env::var_os("SUPINE_MODELS") {
        dirs.push(PathBuf::from(dir));
    }
    dirs.push(PathBuf::from("models/artifacts"));
    dirs.push(PathBuf::from(INSTALLED));
    dirs
}
