//! The ground truth of a tracking sequence directory (`supine-models sequence`), loaded for `eval tracking` and
//! replay, and the scores against it: torso surface error (each estimated torso vertex to the true posed torso
//! surface), salient-point error and probe-mapping error (the mapped surface point and the signed distance).
//!
//! Loading checks every file against `sequence.json` (frame counts, vertex and triangle counts, indices, the arm
//! states' count) and names the file and what is wrong when one is missing, truncated or corrupt.
//!
//! Cost: loading reads 12 bytes per torso vertex per frame (3 MB for 300 frames of the default model's 837-vertex
//! subset); a torso surface score is one exact nearest-point query per estimated vertex ([`SurfaceQuery`]), ~10 ms
//! for 837 vertices against 1542 triangles; the other scores are a few flops.

use crate::eval::calibration::read_arm_capture;
use crate::sequence::episodes::Episodes;
use crate::sequence::torso_truth::{self, SurfaceQuery};
use crate::sequence::{FrameTruth, SequenceMeta, arm_stream};
use anyhow::{Context, Result, bail, ensure};
use nalgebra::{Isometry3, Point3, Vector3};
use std::path::{Path, PathBuf};
use supine_core::calib::ArmSample;
use supine_core::calib::solve::{Pair, kabsch};
use supine_core::probe::ProbeMapping;
use supine_core::salient::SalientPoint;
use supine_core::wire::BodyRegion;

/// The true torso surface of every frame (`torso.bin`).
#[derive(Debug, Clone, PartialEq)]
pub struct TorsoTruth {
    /// Triangles, indices into one frame's vertices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// Body region of each vertex.
    pub regions: Vec<BodyRegion>,
    vertices: Vec<[f32; 3]>,
    per_frame: usize,
}

impl TorsoTruth {
    /// Read and validate `torso.bin`.
    pub fn read(path: &Path) -> Result<TorsoTruth> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        TorsoTruth::parse(&bytes).with_context(|| format!("invalid {}", path.display()))
    }

    /// Parse a `torso.bin` image (layout in [`crate::sequence::torso_truth`]).
    pub fn parse(bytes: &[u8]) -> Result<TorsoTruth> {
        ensure!(
            bytes.len() >= torso_truth::HEADER_LEN,
            "{} bytes, shorter than the {}-byte header",
            bytes.len(),
            torso_truth::HEADER_LEN
        );
        ensure!(
            &bytes[..8] == torso_truth::MAGIC,
            "not a torso surface file (bad magic)"
        );
        let word =
            |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]) as usize;
        let (frames, n, m) = (word(8), word(12), word(16));
        ensure!(n > 0 && m > 0, "empty surface: {n} vertices, {m} triangles");
        let tri_len = m.checked_mul(12).context("triangle count overflows")?;
        let region_len = n.div_ceil(4) * 4;
        let frame_len = n.checked_mul(12).context("vertex count overflows")?;
        let expected = frames
            .checked_mul(frame_len)
            .and_then(|v| v.checked_add(torso_truth::HEADER_LEN + tri_len + region_len))
            .context("file size overflows")?;
        if bytes.len() != expected {
            let body = bytes
                .len()
                .saturating_sub(torso_truth::HEADER_LEN + tri_len + region_len);
            bail!(
                "{} bytes where the header ({frames} frames of {n} vertices, {m} triangles) needs {expected}: {} \
                 whole frames present (truncated or corrupt)",
                bytes.len(),
                body / frame_len
            );
        }
        let mut at = torso_truth::HEADER_LEN;
        let mut triangles = Vec::with_capacity(m);
        for t in 0..m {
            let tri = [word(at), word(at + 4), word(at + 8)];
            ensure!(
                tri.iter().all(|&i| i < n),
                "triangle {t} has a vertex index beyond the {n} vertices"
            );
            triangles.push(tri.map(|i| i as u32));
            at += 12;
        }
        let mut regions = Vec::with_capacity(n);
        for (i, &r) in bytes[at..at + n].iter().enumerate() {
            regions.push(
                BodyRegion::from_u8(r).with_context(|| format!("vertex {i} has no body region ({r})"))?,
            );
        }
        at += region_len;
        let vertices: Vec<[f32; 3]> = bytes[at..]
            .chunks_exact(12)
            .map(|c| {
                let f = |k: usize| f32::from_le_bytes([c[k], c[k + 1], c[k + 2], c[k + 3]]);
                [f(0), f(4), f(8)]
            })
            .collect();
        ensure!(
            vertices.iter().flatten().all(|v| v.is_finite()),
            "a vertex position is not finite"
        );
        Ok(TorsoTruth {
            triangles,
            regions,
            vertices,
            per_frame: n,
        })
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.vertices.len() / self.per_frame
    }

    /// Vertices per frame.
    pub fn vertex_count(&self) -> usize {
        self.per_frame
    }

    /// The true torso vertices of frame `f`, camera frame, metres.
    pub fn frame(&self, f: usize) -> Option<&[[f32; 3]]> {
        self.vertices.get(f * self.per_frame..(f + 1) * self.per_frame)
    }
}

/// Salient-point error of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointError {
    /// Distance per point ([`SalientPoint`] order), mm.
    pub per_point_mm: [f32; SalientPoint::COUNT],
    /// Their mean, mm.
    pub mean_mm: f32,
}

/// Probe-mapping error of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeError {
    /// Distance from the estimated nearest surface point to the true one, mm.
    pub position_mm: f32,
    /// Absolute difference of the signed distances, mm.
    pub signed_distance_mm: f32,
    /// Whether the estimated region is the true one.
    pub region_correct: bool,
    /// The true signed distance of the tip from the skin, mm (how far the probe hovers).
    pub true_distance_mm: f32,
}

/// Everything a sequence directory holds as truth.
#[derive(Debug, Clone)]
pub struct TrackingTruth {
    /// The directory.
    pub dir: PathBuf,
    /// `sequence.json`.
    pub meta: SequenceMeta,
    /// `truth.jsonl`, one entry per frame.
    pub frames: Vec<FrameTruth>,
    /// `torso.bin`.
    pub torso: TorsoTruth,
    /// `arm.cobs` decoded, when the sequence has an arm.
    pub arm: Option<Vec<ArmSample>>,
}

impl TrackingTruth {
    /// Load and cross-check the truth of the sequence in `dir`.
    pub fn load(dir: &Path) -> Result<TrackingTruth> {
        let meta_path = dir.join("sequence.json");
        let meta_bytes = std::fs::read(&meta_path)
            .with_context(|| format!("reading {} (not a sequence directory?)", meta_path.display()))?;
        let meta: SequenceMeta = serde_json::from_slice(&meta_bytes)
            .with_context(|| format!("invalid {}", meta_path.display()))?;
        ensure!(
            meta.calibration.is_none(),
            "{} is a calibration sequence, not a tracking one",
            dir.display()
        );
        let n = meta.config.frames as usize;
        let truth_path = dir.join("truth.jsonl");
        let text = std::fs::read_to_string(&truth_path)
            .with_context(|| format!("reading {}", truth_path.display()))?;
        let mut frames = Vec::with_capacity(n);
        for (i, line) in text.lines().enumerate() {
            let t: FrameTruth = serde_json::from_str(line)
                .with_context(|| format!("{} line {}: not a frame's truth", truth_path.display(), i + 1))?;
            ensure!(
                t.frame as usize == i,
                "{} line {}: frame {} out of order",
                truth_path.display(),
                i + 1,
                t.frame
            );
            frames.push(t);
        }
        ensure!(
            frames.len() == n,
            "{}: {} frames where sequence.json says {n} (truncated?)",
            truth_path.display(),
            frames.len()
        );
        let surface = meta.torso_surface.as_ref().with_context(|| {
            format!(
                "{} has no torso_surface: regenerate the sequence with this version of `supine-models sequence`",
                meta_path.display()
            )
        })?;
        let torso_path = dir.join(&surface.file);
        let torso = TorsoTruth::read(&torso_path)?;
        ensure!(
            torso.frame_count() == n
                && torso.vertex_count() == surface.vertices as usize
                && torso.triangles.len() == surface.triangles as usize,
            "{}: {} frames of {} vertices and {} triangles where sequence.json says {n} of {} and {}",
            torso_path.display(),
            torso.frame_count(),
            torso.vertex_count(),
            torso.triangles.len(),
            surface.vertices,
            surface.triangles
        );
        let arm = match &meta.arm {
            None => None,
            Some(stream) => Some(read_arm(dir, stream)?),
        };
        Ok(TrackingTruth {
            dir: dir.to_path_buf(),
            meta,
            frames,
            torso,
            arm,
        })
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// The full-occlusion and motion episodes.
    pub fn episodes(&self) -> &Episodes {
        &self.meta.episodes
    }

    /// The true `robot_base_from_camera`.
    pub fn robot_base_from_camera(&self) -> Option<Isometry3<f32>> {
        self.meta.robot_base_from_camera.map(|e| e.to_isometry())
    }

    fn frame(&self, f: u32) -> Result<&FrameTruth> {
        self.frames
            .get(f as usize)
            .with_context(|| format!("frame {f} beyond the sequence's {} frames", self.frames.len()))
    }

    /// Mean distance (mm) from each estimated torso vertex (camera frame, metres) to the true posed torso surface
    /// of frame `f`.
    pub fn torso_surface_error_mm(&self, estimated_camera: &[[f32; 3]], f: u32) -> Result<f32> {
        self.frame(f)?;
        ensure!(!estimated_camera.is_empty(), "no estimated torso vertex to score");
        let vertices = self.torso.frame(f as usize).context("torso frame missing")?;
        let query = SurfaceQuery::new(vertices, &self.torso.triangles);
        let mut sum = 0.0f64;
        for (i, v) in estimated_camera.iter().enumerate() {
            let near = query
                .nearest(&Point3::from(*v))
                .with_context(|| format!("estimated torso vertex {i} is not finite: {v:?}"))?;
            sum += near.distance as f64;
        }
        Ok((sum / estimated_camera.len() as f64 * 1000.0) as f32)
    }

    /// The rigid pose that best fits `model` (torso vertices in any frame, the truth's vertices in its order) to
    /// frame `f`'s true posed torso, vertex for vertex (Kabsch); `None` when the counts differ.
    pub fn rigid_best(&self, model: &[Point3<f32>], f: u32) -> Result<Option<Isometry3<f32>>> {
        let posed = self.torso.frame(f as usize).context("torso frame missing")?;
        if posed.len() != model.len() {
            return Ok(None);
        }
        let pairs: Vec<Pair> = model
            .iter()
            .zip(posed)
            .map(|(m, p)| Pair {
                robot_base: Point3::from(*p),
                camera: *m,
            })
            .collect();
        Ok(kabsch(&pairs, |_| 1.0))
    }

    /// The torso surface error (mm) of `model` at its best rigid pose ([`TrackingTruth::rigid_best`]): the error left
    /// by the model's shape and by the posture of the true body (the spine's bend and twist, the neck), which no
    /// rigid pose removes. A tracker's torso error above it is its pose's. `None` when the counts differ.
    pub fn rigid_floor_mm(&self, model: &[Point3<f32>], f: u32) -> Result<Option<f32>> {
        let Some(best) = self.rigid_best(model, f)? else {
            return Ok(None);
        };
        self.torso_error_at_mm(model, &best, f).map(Some)
    }

    /// [`TrackingTruth::torso_surface_error_mm`] of `model` (torso vertices) placed in the camera frame by `pose`.
    pub fn torso_error_at_mm(&self, model: &[Point3<f32>], pose: &Isometry3<f32>, f: u32) -> Result<f32> {
        let placed: Vec<[f32; 3]> = model.iter().map(|v| (pose * v).coords.into()).collect();
        self.torso_surface_error_mm(&placed, f)
    }

    /// Salient-point error of frame `f` for estimated points in the camera frame (metres, [`SalientPoint`] order).
    pub fn point_error_mm(
        &self,
        estimated_camera: &[[f32; 3]; SalientPoint::COUNT],
        f: u32,
    ) -> Result<PointError> {
        let t = self.frame(f)?;
        let mut per_point_mm = [0.0f32; SalientPoint::COUNT];
        for (k, e) in per_point_mm.iter_mut().enumerate() {
            *e = (Vector3::from(estimated_camera[k]) - Vector3::from(t.salient_camera[k])).norm() * 1000.0;
        }
        ensure!(
            per_point_mm.iter().all(|e| e.is_finite()),
            "an estimated salient point is not finite"
        );
        let mean_mm = per_point_mm.iter().sum::<f32>() / SalientPoint::COUNT as f32;
        Ok(PointError {
            per_point_mm,
            mean_mm,
        })
    }

    /// Whether frame `f`'s probe is scored: the arm is present and its tip is near the body.
    pub fn probe_scored(&self, f: u32) -> bool {
        self.frames
            .get(f as usize)
            .and_then(|t| t.probe_truth.as_ref())
            .is_some_and(|p| p.near_body)
    }

    /// Probe-mapping error of frame `f` for an estimated nearest surface point (camera frame, metres), signed
    /// distance (metres) and region; `None` where the frame's probe is not scored ([`Self::probe_scored`]).
    pub fn probe_error(
        &self,
        nearest_camera: [f32; 3],
        signed_distance_m: f32,
        region: BodyRegion,
        f: u32,
    ) -> Result<Option<ProbeError>> {
        let t = self.frame(f)?;
        let Some(p) = t.probe_truth.as_ref().filter(|p| p.near_body) else {
            return Ok(None);
        };
        let position_mm = (Vector3::from(nearest_camera) - Vector3::from(p.nearest_camera)).norm() * 1000.0;
        let signed_distance_mm = (signed_distance_m - p.signed_distance_m).abs() * 1000.0;
        ensure!(
            position_mm.is_finite() && signed_distance_mm.is_finite(),
            "the estimated probe mapping is not finite"
        );
        Ok(Some(ProbeError {
            position_mm,
            signed_distance_mm,
            region_correct: region.name() == p.region,
            true_distance_mm: p.signed_distance_m * 1000.0,
        }))
    }

    /// [`Self::probe_error`] of core's mapping (torso frame) under the estimated `camera_from_torso`.
    pub fn probe_error_of_mapping(
        &self,
        mapping: &ProbeMapping,
        camera_from_torso: &Isometry3<f32>,
        f: u32,
    ) -> Result<Option<ProbeError>> {
        let nearest = camera_from_torso * mapping.nearest;
        self.probe_error(nearest.coords.into(), mapping.signed_distance, mapping.region, f)
    }
}

/// The sequence directories `--data` names: `path` itself when it holds a `sequence.json`, else its subdirectories
/// that do, sorted by name; an error when there is none.
pub fn sequence_dirs(path: &Path) -> Result<Vec<PathBuf>> {
    if path.join("sequence.json").is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    let dirs = subdirectories(path, |p| p.join("sequence.json").is_file())?;
    ensure!(
        !dirs.is_empty(),
        "{} holds no sequence (no sequence.json in it or its subdirectories)",
        path.display()
    );
    Ok(dirs)
}

/// `path`'s subdirectories that `keep` accepts, sorted by name.
pub fn subdirectories(path: &Path, keep: impl Fn(&Path) -> bool) -> Result<Vec<PathBuf>> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(path)
        .with_context(|| format!("reading {}", path.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| keep(p))
        .collect();
    dirs.sort();
    Ok(dirs)
}

/// The subdirectories of `path` that hold a sequence's frames or truth but no `sequence.json` (a generation that did
/// not finish): [`sequence_dirs`] leaves them out, and the evaluation says so.
pub fn incomplete_sequence_dirs(path: &Path) -> Vec<PathBuf> {
    if path.join("sequence.json").is_file() {
        return Vec::new();
    }
    subdirectories(path, |p| {
        !p.join("sequence.json").is_file()
            && (p.join("sequence.oni").is_file() || p.join("truth.jsonl").is_file())
    })
    .unwrap_or_default()
}

fn read_arm(dir: &Path, stream: &arm_stream::ArmStream) -> Result<Vec<ArmSample>> {
    let path = dir.join(&stream.file);
    ensure!(
        path.exists(),
        "{} missing (sequence.json lists {} arm states)",
        path.display(),
        stream.samples
    );
    let (arm, errors) = read_arm_capture(&path)?;
    ensure!(
        errors == 0 && arm.len() == stream.samples as usize,
        "{}: {} arm states decoded ({errors} undecodable frames) where sequence.json says {} (truncated or corrupt)",
        path.display(),
        arm.len(),
        stream.samples
    );
    Ok(arm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::body::Mannequin;
    use crate::sequence::episodes::{EpisodeFrames, MotionKind};
    use crate::sequence::{SequenceConfig, generate};

    /// 20 frames with the sweep, a 4-frame park and a 4-frame roll: every episode, a few seconds to generate.
    fn tiny(name: &str, seed: u64) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("supine-track-truth-{name}-{}", std::process::id()));
        let cfg = SequenceConfig {
            full_occlusion: true,
            motion: Some(MotionKind::Roll),
            episode_frames: EpisodeFrames {
                transit: 2,
                full_occlusion: 4,
                motion: 4,
            },
            sweep_period_s: 0.5,
            ..SequenceConfig::new(20, seed, true)
        };
        generate(&Mannequin, &cfg, &dir, &mut |_, _| {}).unwrap();
        dir
    }

    #[test]
    fn a_tiny_sequence_loads_and_scores_its_own_truth_as_zero() {
        let dir = tiny("score", 3);
        let t = TrackingTruth::load(&dir).unwrap();
        assert_eq!(t.frame_count(), 20);
        assert_eq!(t.torso.frame_count(), 20);
        let o = t.episodes().full_occlusion.unwrap();
        assert_eq!((o.approach_start, o.start, o.end, o.leave_end), (6, 8, 12, 14));
        assert!(
            o.torso_occluded_fraction_min > 0.9,
            "parked arm hides {}",
            o.torso_occluded_fraction_min
        );
        for f in o.start..o.end {
            assert!(t.frames[f as usize].torso_occluded_fraction >= o.torso_occluded_fraction_min);
        }
        let m = t.episodes().motion.unwrap();
        assert_eq!((m.start, m.end), (14, 18));
        // The roll shows in the torso pose: frames before and after differ by about the roll angle.
        let rot = |f: usize| {
            let r = t.frames[f].camera_from_torso;
            nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::new(
                r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2],
            ))
        };
        let turned = rot(13).rotation_to(&rot(19)).angle().to_degrees();
        assert!(
            (turned - m.roll_deg.abs()).abs() < 3.0,
            "{turned}° vs {}°",
            m.roll_deg
        );
        let base = t.robot_base_from_camera().unwrap();
        let arm = t.arm.as_ref().unwrap();
        assert!(arm.len() > 40, "{} arm states", arm.len());
        // An arm state's tip, through the true extrinsic, lands near the true tip of its (late) frame.
        let s = &arm[30];
        let latency = t.meta.arm.as_ref().unwrap().latency_us as f32 * 1e-6;
        let f = ((s.time.as_us() as f32 * 1e-6 - latency) * 30.0).round() as usize;
        let m = t.frames[f].camera_from_probe.unwrap();
        let tip_camera = base.inverse() * s.tip_robot_base;
        let truth = Point3::new(m[0][3], m[1][3], m[2][3]);
        assert!(
            (tip_camera - truth).norm() < 0.03,
            "{:?} vs {truth:?}",
            tip_camera
        );

        let mut scored = 0;
        for f in 0..20u32 {
            let v = t.torso.frame(f as usize).unwrap();
            assert!(t.torso_surface_error_mm(v, f).unwrap() < 1e-3);
            // Every vertex 5 mm farther from the camera: at most 5 mm from the surface, and not much less.
            let pushed: Vec<[f32; 3]> = v.iter().map(|p| [p[0], p[1], p[2] + 0.005]).collect();
            let e = t.torso_surface_error_mm(&pushed, f).unwrap();
            assert!(e > 1.5 && e <= 5.0 + 1e-3, "frame {f}: {e} mm");
            let sal = t.frames[f as usize].salient_camera;
            assert!(t.point_error_mm(&sal, f).unwrap().mean_mm < 1e-6);
            let off = sal.map(|p| [p[0] + 0.01, p[1], p[2]]);
            assert!((t.point_error_mm(&off, f).unwrap().mean_mm - 10.0).abs() < 1e-3);
            if t.probe_scored(f) {
                scored += 1;
                let p = t.frames[f as usize].probe_truth.clone().unwrap();
                let region = BodyRegion::from_name(&p.region).unwrap();
                let e = t
                    .probe_error(p.nearest_camera, p.signed_distance_m, region, f)
                    .unwrap()
                    .unwrap();
                assert!(e.position_mm < 1e-6 && e.signed_distance_mm < 1e-6 && e.region_correct);
                // On its sweep (not moving to or from the park) the tip rests 3 mm outside the skin.
                if f < o.approach_start || f >= o.leave_end {
                    assert!(
                        p.signed_distance_m > -0.005 && p.signed_distance_m < 0.03,
                        "frame {f}: {}",
                        p.signed_distance_m
                    );
                }
                let q = [
                    p.nearest_camera[0],
                    p.nearest_camera[1] + 0.004,
                    p.nearest_camera[2],
                ];
                let e = t
                    .probe_error(q, p.signed_distance_m - 0.002, region, f)
                    .unwrap()
                    .unwrap();
                assert!((e.position_mm - 4.0).abs() < 1e-2 && (e.signed_distance_mm - 2.0).abs() < 1e-2);
            }
        }
        assert!(scored >= 8, "{scored} frames with the probe on the body");
        for f in o.start..o.end {
            assert!(!t.probe_scored(f), "the parked probe is off the body");
        }
        assert!(t.torso_surface_error_mm(&[], 0).is_err());
        assert!(t.torso_surface_error_mm(&[[f32::NAN, 0.0, 1.0]], 0).is_err());
        assert!(t.point_error_mm(&[[0.0; 3]; 6], 20).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn missing_truncated_and_corrupt_files_are_named() {
        let dir = tiny("corrupt", 5);
        let err = |dir: &Path| format!("{:#}", TrackingTruth::load(dir).unwrap_err());
        let copy = std::env::temp_dir().join(format!("supine-track-truth-copy-{}", std::process::id()));
        let reset = || {
            std::fs::remove_dir_all(&copy).ok();
            std::fs::create_dir_all(&copy).unwrap();
            for f in ["sequence.json", "truth.jsonl", "torso.bin", "arm.cobs"] {
                std::fs::copy(dir.join(f), copy.join(f)).unwrap();
            }
        };
        reset();
        assert!(TrackingTruth::load(&copy).is_ok());
        let torso = std::fs::read(dir.join("torso.bin")).unwrap();
        std::fs::write(copy.join("torso.bin"), &torso[..torso.len() - 100]).unwrap();
        let e = err(&copy);
        assert!(e.contains("torso.bin") && e.contains("truncated"), "{e}");
        let mut bad = torso.clone();
        bad[0] = b'X';
        std::fs::write(copy.join("torso.bin"), &bad).unwrap();
        assert!(err(&copy).contains("bad magic"));
        let mut bad = torso.clone();
        bad[torso_truth::HEADER_LEN..torso_truth::HEADER_LEN + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        std::fs::write(copy.join("torso.bin"), &bad).unwrap();
        assert!(err(&copy).contains("vertex index"), "{}", err(&copy));
        std::fs::write(copy.join("torso.bin"), &torso[..10]).unwrap();
        assert!(err(&copy).contains("header"));

        reset();
        let text = std::fs::read_to_string(dir.join("truth.jsonl")).unwrap();
        let short: String = text.lines().take(12).map(|l| format!("{l}\n")).collect();
        std::fs::write(copy.join("truth.jsonl"), short).unwrap();
        assert!(err(&copy).contains("truncated"));
        std::fs::write(copy.join("truth.jsonl"), format!("{}{{\"frame\":", &text)).unwrap();
        assert!(err(&copy).contains("line 21"), "{}", err(&copy));

        reset();
        let arm = std::fs::read(dir.join("arm.cobs")).unwrap();
        std::fs::write(copy.join("arm.cobs"), &arm[..arm.len() / 2]).unwrap();
        assert!(err(&copy).contains("arm.cobs"));
        std::fs::remove_file(copy.join("arm.cobs")).unwrap();
        assert!(err(&copy).contains("missing"));

        reset();
        assert_eq!(sequence_dirs(&copy).unwrap(), vec![copy.clone()]);
        assert!(sequence_dirs(copy.parent().unwrap()).unwrap().contains(&copy));
        assert!(!incomplete_sequence_dirs(copy.parent().unwrap()).contains(&copy));
        std::fs::remove_file(copy.join("sequence.json")).unwrap();
        assert!(err(&copy).contains("not a sequence directory"));
        // Frames without their sequence.json: left out of the folder's sequences, and named as incomplete.
        assert!(
            !sequence_dirs(copy.parent().unwrap())
                .unwrap_or_default()
                .contains(&copy)
        );
        assert!(incomplete_sequence_dirs(copy.parent().unwrap()).contains(&copy));
        assert!(
            sequence_dirs(&copy)
                .unwrap_err()
                .to_string()
                .contains("no sequence")
        );
        std::fs::remove_dir_all(&copy).ok();
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn the_same_seed_gives_the_same_bytes() {
        let a = tiny("det-a", 11);
        let b = tiny("det-b", 11);
        for f in [
            "sequence.oni",
            "truth.jsonl",
            "torso.bin",
            "arm.cobs",
            "sequence.json",
        ] {
            assert!(
                std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(),
                "{f} differs"
            );
        }
        std::fs::remove_dir_all(&a).ok();
        std::fs::remove_dir_all(&b).ok();
    }
}
