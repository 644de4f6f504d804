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
    /// Directory with the model files (default: models/artifacts).
    #[arg(long, default_value = "models/artifacts")]
    pub models: std::path::PathBuf,
}

/// Run `supine info`: print the sections to stdout.
pub fn run(args: InfoArgs) -> Result<(), Failure> {
    let mut out = String::new();
    out.push_str(&models_section(&args.models));
    out.push_str(&devices_section());
    out.push_str(&links_section());
    print!("{out}");
    Ok(())
}

/// The model files present (name and size); "none yet" when the directory is missing or empty.
fn models_section(dir: &Path) -> String {
    let mut s = format!("models ({}):\n", dir.display());
    let mut files: Vec<(String, u64)> = match std::fs::read_dir(dir) {
        Ok(entries) => entries
            .filter_map(|e| e.ok())
            .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
            .map(|e| {
                (
                    e.file_name().to_string_lossy().into_owned(),
                    e.metadata().map(|m| m.len()).unwrap_or(0),
                )
            })
            .collect(),
        Err(_) => Vec::new(),
    };
    files.sort();
    if files.is_empty() {
        s.push_str("  none yet\n");
    }
    for (name, size) in files {
        let _ = writeln!(s, "  {name}  {size} bytes");
    }
    s
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
        assert!(models_section(&dir).contains("none yet"));
        std::fs::write(dir.join("joints.forest"), [0u8; 12]).unwrap();
        let s = models_section(&dir);
        assert!(s.contains("joints.forest  12 bytes"), "{s}");
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(models_section(Path::new("/nonexistent/supine")).contains("none yet"));
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
