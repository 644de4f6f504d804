//! `supine info`: what this build and this machine offer: models, depth devices, links.
//!
//! Read-only and quick: it opens device nodes only to query them (no streaming).

use std::fmt::Write as _;
use std::path::Path;

use clap::Args;

use crate::failure::Failure;

/// Arguments of `supine info`.
#[derive(Args, Debug)]
pub struct InfoArgs {
    /// Directory with the model files (default: the first of $SUPINE_MODELS, models/artifacts,
    /// /usr/share/supine/models that exists, as `supine demo` searches them).
    #[arg(long)]
    pub models: Option<std::path::PathBuf>,
}

/// Run `supine info`: print the sections to stdout. Exit 1 (after printing) when a model file is invalid.
pub fn run(args: InfoArgs) -> Result<(), Failure> {
    let dir = match args.models {
        Some(dir) if dir.is_dir() => dir,
        Some(dir) => {
            let what = if dir.exists() {
                "not a directory"
            } else {
                "no such directory"
            };
            return Err(anyhow::anyhow!("--models {}: {what}", dir.display()).into());
        }
        None => {
            let dirs = crate::model_dirs::model_dirs();
            dirs.iter()
                .find(|d| d.is_dir())
                .cloned()
                .unwrap_or_else(|| dirs[0].clone())
        }
    };
    let (models, invalid) = models_section(&dir);
    let mut out = models;
    out.push_str(&devices_section());
    out.push_str(&links_section());
    crate::console::out(&out)?;
    if !invalid.is_empty() {
        return Err(anyhow::anyhow!(
            "invalid model file(s) in {}: {}",
            dir.display(),
            invalid.join(", ")
        )
        .into());
    }
    Ok(())
}

/// The model files present (name and size), "none yet" when the directory is missing or empty, and the names of
/// the files that are supine model files but do not validate.
fn models_section(dir: &Path) -> (String, Vec<String>) {
    let mut invalid = Vec::new();
    let mut s = format!("models ({}):\n", dir.display());
    let mut files: Vec<std::path::PathBuf> = match std::fs::read_dir(dir) {
        Ok(entries) => entries
            .filter_map(|e| e.ok())
            .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
            .map(|e| e.path())
            .collect(),
        Err(_) => Vec::new(),
    };
    files.sort();
    if files.is_empty() {
        s.push_str("  none yet\n");
    }
    for path in files {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let line = match std::fs::read(&path) {
            Ok(bytes) => {
                let (what, valid) = describe_model(&bytes);
                if !valid {
                    invalid.push(name.clone());
                }
                format!("{} bytes, {what}", bytes.len())
            }
            Err(e) => {
                invalid.push(name.clone());
                format!("unreadable: {e}")
            }
        };
        let _ = writeln!(s, "  {name}  {line}");
    }
    (s, invalid)
}

/// What a model file is and whether it validates (magic, versions, sizes, checksum), as core would load it.
fn describe_model(bytes: &[u8]) -> (String, bool) {
    use crate::models::ModelCheck;
    match crate::models::check(bytes) {
        ModelCheck::NotAModel => ("not a supine model file".to_owned(), true),
        ModelCheck::UnknownKind(kind) => (format!("model kind {kind:?}: not known to this build"), true),
        ModelCheck::Valid { what, .. } => (what, true),
        ModelCheck::Invalid { kind, error } => (
            format!("INVALID {} model: {error}", crate::models::kind_name(kind)),
            false,
        ),
    }
}

/// Depth devices visible to each backend of this build.
fn devices_section() -> String {
    let mut s = String::from("devices:\n");
    s.push_str(&openni2_devices());
    s.push_str(&freenect_devices());
    let v4l2 = supine_drivers::v4l2::list_devices();
    if v4l2.is_empty() {
        s.push_str("  v4l2: no /dev/video* nodes\n");
    }
    for d in v4l2 {
        let y10b = if d.offers_y10b {
            "offers Y10B (Kinect depth)"
        } else {
            "no Y10B"
        };
        let _ = writeln!(
            s,
            "  v4l2: {}  driver {}  card {:?}  {y10b}",
            d.path.display(),
            d.driver,
            d.card
        );
    }
    s
}

#[cfg(feature = "openni2")]
fn openni2_devices() -> String {
    match supine_drivers::openni2::list_devices() {
        Ok(list) if list.is_empty() => "  openni2: no devices\n".into(),
        Ok(list) => list
            .iter()
            .map(|d| {
                format!(
                    "  openni2: {}  {} {}  usb {:04x}:{:04x}\n",
                    d.uri, d.vendor, d.name, d.usb_vendor_id, d.usb_product_id
                )
            })
            .collect(),
        Err(e) => format!("  openni2: error: {e}\n"),
    }
}

#[cfg(not(feature = "openni2"))]
fn openni2_devices() -> String {
    "  openni2: not compiled in (build with --features openni2)\n".into()
}

#[cfg(feature = "freenect")]
fn freenect_devices() -> String {
    match supine_drivers::freenect::device_count() {
        Ok(n) => format!("  freenect: {n} Kinect(s)\n"),
        Err(e) => format!("  freenect: error: {e}\n"),
    }
}

#[cfg(not(feature = "freenect"))]
fn freenect_devices() -> String {
    "  freenect: not compiled in (build with --features freenect)\n".into()
}

/// The packet links this build speaks and the serial ports and CAN interfaces visible (see `crate::links`).
/// Kept as its own function so that the depth-source and link halves of `supine info` can change independently.
fn links_section() -> String {
    crate::links::info_text()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn models_section_lists_files_or_says_none() {
        let dir = std::env::temp_dir().join(format!("supine-info-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert!(models_section(&dir).0.contains("none yet"));
        std::fs::write(dir.join("joints.forest"), [0u8; 12]).unwrap();
        let (s, invalid) = models_section(&dir);
        assert!(invalid.is_empty(), "{invalid:?}");
        assert!(
            s.contains("joints.forest  12 bytes, not a supine model file"),
            "{s}"
        );
        let mut body = std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../models/artifacts/body.sbm"
        ))
        .unwrap();
        std::fs::write(dir.join("body.sbm"), &body).unwrap();
        let (s, invalid) = models_section(&dir);
        assert!(s.contains("body model v1, 13380 vertices, valid"), "{s}");
        assert!(invalid.is_empty(), "{invalid:?}");
        let last = body.len() - 1;
        body[last] ^= 0xFF;
        std::fs::write(dir.join("body.sbm"), &body).unwrap();
        let (s, invalid) = models_section(&dir);
        assert!(s.contains("INVALID body model"), "{s}");
        assert_eq!(invalid, ["body.sbm"]);
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(
            models_section(Path::new("/nonexistent/supine"))
                .0
                .contains("none yet")
        );
    }

    #[test]
    fn devices_section_names_every_backend() {
        let s = devices_section();
        assert!(
            s.contains("openni2:") && s.contains("freenect:") && s.contains("v4l2:"),
            "{s}"
        );
    }
}
