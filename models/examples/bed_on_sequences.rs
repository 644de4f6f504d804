//! Why the init phase misses or invents a raised head section, or takes something else for the mattress: runs
//! `supine_core::planes::estimate_bed` on the first frames of each sequence as the tracker draws its RANSAC seed, and
//! prints against the sequence's true planes what it found (mattress error, section angle) and, per labelled plane
//! that is not vertical, what its points are: how many, their share on the true section, their tilt from up, the
//! 1st percentile of their height above the true and the found mattress (a section's bottom), their spread along the
//! plane's level lines (5th-95th percentile: a section spans the bed), how many of their local normals agree with the
//! plane's (`flat a/t`, the one-surface test), and the points within the plane's inlier band at the found mattress
//! (the hinge test).
//!
//! `cargo run --release -p supine-models --example bed_on_sequences -- SEQ_DIR_OR_PARENT [FRAMES [TRACKER_SEED]]`
//! (`TRACKER_SEED`: the tracker's `seed`, its default when left out).
//! Cost: per sequence and frame one plane search (a few ms) and a few passes over its 8 k points.

use anyhow::{Context, Result, bail};
use nalgebra::{Matrix3, Point3, Vector3};
use std::path::PathBuf;
use supine_core::camera::Intrinsics;
use supine_core::geometry::Plane;
use supine_core::planes::{self, BedScene, PlaneConfig};
use supine_core::rng::mix_seed;
use supine_core::tracker::{TrackerConfig, bed_vote};
use supine_drivers::oni::OniReader;
use supine_models::eval::tracking_truth::{TrackingTruth, sequence_dirs};

fn degrees_between(a: &Vector3<f32>, b: &Vector3<f32>) -> f32 {
    a.dot(b).abs().min(1.0).acos().to_degrees()
}

/// The `q` quantile of `v`, sorted.
fn quantile(v: &[f32], q: f32) -> f32 {
    v[((v.len() - 1) as f32 * q) as usize]
}

/// `f` of each point, sorted.
fn sorted(points: &[Point3<f32>], f: impl Fn(&Point3<f32>) -> f32) -> Vec<f32> {
    let mut v: Vec<f32> = points.iter().map(f).collect();
    v.sort_by(f32::total_cmp);
    v
}

/// One line per non-vertical labelled plane of `bed`'s search.
#[allow(clippy::too_many_arguments)] // the search's points and labels, its result, the truth, the frame and settings
fn describe_planes(
    pts: &[Point3<f32>],
    labels: &[u8],
    bed: Option<&BedScene>,
    truth: &[Plane; 2],
    raised: bool,
    up: &Vector3<f32>,
    cfg: &PlaneConfig,
    surface: Option<(&supine_core::depth::DepthFrame<'_>, &Intrinsics)>,
) {
    let [mattress_t, section_t] = truth;
    for l in 1..=6u8 {
        let own: Vec<Point3<f32>> = pts
            .iter()
            .zip(labels)
            .filter(|(_, x)| **x == l)
            .map(|(p, _)| *p)
            .collect();
        if own.len() < 3 {
            continue;
        }
        // The least-squares plane of its inliers: the smallest eigenvector of their covariance.
        let c = own.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / own.len() as f32;
        let cov = own.iter().fold(Matrix3::zeros(), |s, p| {
            s + (p.coords - c) * (p.coords - c).transpose()
        });
        let e = cov.symmetric_eigen();
        let normal: Vector3<f32> = e.eigenvectors.column(e.eigenvalues.imin()).into();
        let tilt = degrees_between(&normal, up);
        if tilt >= 70.0 {
            continue;
        }
        let on_section = own
            .iter()
            .filter(|p| raised && section_t.signed_distance(p).abs() < 0.02)
            .count();
        let h_true = sorted(&own, |p| mattress_t.signed_distance(p));
        let level = normal.cross(up).try_normalize(1e-6).unwrap_or(Vector3::x());
        let along = sorted(&own, |p| level.dot(&p.coords));
        let spread = quantile(&along, 0.95) - quantile(&along, 0.05);
        let mut line = format!(
            "    plane {l}: {:5} pts, {:3.0}% on the true section, tilt {tilt:2.0} deg, bottom {:+.3} m above the true \
             mattress, spread {spread:.2} m",
            own.len(),
            100.0 * on_section as f32 / own.len() as f32,
            quantile(&h_true, 0.01),
        );
        if let Some((f, k)) = surface {
            let plane = Plane::through(c, normal);
            let (tested, agree) = planes::surface_agreement(f, k, &plane, pts, labels, l);
            line += &format!(", flat {agree}/{tested}");
        }
        if let Some(bed) = bed {
            let h_found = sorted(&own, |p| bed.mattress.signed_distance(p));
            let d = -normal.dot(&c);
            let hinge = pts
                .iter()
                .filter(|p| (normal.dot(&p.coords) + d).abs() < cfg.inlier_m)
                .filter(|p| bed.mattress.signed_distance(p) < 0.03)
                .count();
            line += &format!(
                ", bottom {:+.3} above the found one, {hinge} band points at it",
                quantile(&h_found, 0.01)
            );
        }
        println!("{line}");
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(root) = args.first() else {
        bail!("usage: bed_on_sequences SEQ_DIR_OR_PARENT [FRAMES [TRACKER_SEED]]");
    };
    let frames: u64 = args.get(1).map_or(Ok(1), |s| s.parse()).context("FRAMES")?;
    let tracker_seed: u64 = args
        .get(2)
        .map_or(Ok(TrackerConfig::default().seed), |s| s.parse())
        .context("TRACKER_SEED")?;
    let k = Intrinsics::KINECT_V1;
    for dir in sequence_dirs(&PathBuf::from(root))? {
        let seq = TrackingTruth::load(&dir)?;
        let truth = [seq.meta.planes_camera[1], seq.meta.planes_camera[2]];
        let raise = degrees_between(&truth[0].normal(), &truth[1].normal());
        let mut reader = OniReader::open(dir.join("sequence.oni"))?;
        let Some(up) = seq
            .robot_base_from_camera()
            .map(|t| t.inverse().rotation * Vector3::z())
        else {
            bail!("{}: no robot_base_from_camera in sequence.json", dir.display());
        };
        let name = dir
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        println!("{name}: true head raise {raise:.0} deg");
        let mut beds = Vec::new();
        for f in 0..frames {
            let frame = reader
                .read_frame()
                .map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
            // The tracker's draw: its seed mixed with the frame count.
            let mut cfg = PlaneConfig::default();
            cfg.seed = mix_seed(cfg.seed ^ tracker_seed, f);
            let n = planes::scratch_points(k.width as usize, k.height as usize, cfg.stride.max(1) as usize);
            let mut pts = vec![Point3::origin(); n];
            let mut labels = vec![0u8; n];
            let result = planes::estimate_bed(&frame, &k, &cfg, Some(&up), &mut pts, &mut labels);
            match &result {
                Err(e) => println!("  frame {f}: no bed ({e:?})"),
                Ok(bed) => {
                    println!("  frame {f}: {}", against_truth(bed, &truth[0]));
                    beds.push(*bed);
                }
            }
            describe_planes(
                &pts,
                &labels,
                result.as_ref().ok(),
                &truth,
                raise > 1.0,
                &up,
                &cfg,
                Some((&frame, &k)),
            );
        }
        // What the tracker keeps with `bed_frames` = FRAMES (when every frame found a bed; the tracker votes on the
        // frames it tried).
        if let Some(first) = beds.first() {
            let kept = bed_vote::replacement(&beds, first).unwrap_or(*first);
            println!("  voted over {frames}: {}", against_truth(&kept, &truth[0]));
        }
    }
    Ok(())
}

/// The mattress's error against the true mattress `truth`, and the section's angle.
fn against_truth(bed: &BedScene, truth: &Plane) -> String {
    format!(
        "mattress off {:.1} deg / {:.0} mm ({:+.0} mm high), section {}",
        degrees_between(&bed.mattress.normal(), &truth.normal()),
        (bed.mattress.d - truth.d).abs() * 1000.0,
        (truth.d - bed.mattress.d) * 1000.0,
        bed.head_section.map_or("none".into(), |h| format!(
            "{:.0} deg",
            degrees_between(&h.normal(), &bed.mattress.normal())
        ))
    )
}
