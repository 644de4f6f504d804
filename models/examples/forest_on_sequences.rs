//! Why the joint forest is worse on tracking-sequence frames than on its own dataset views: runs a forest on the
//! first frames of each sequence under several clips (the tracker's full-frame bed-plane clip, the same restricted to
//! the patient's box as the dataset crops it, that box with everything outside it read as no depth as in training, the
//! head section dropped, the tracker's volume of interest as clip planes, and the tracker's height ceiling)
//! and reports the forest's mean point error and where the samples fall (near the true torso surface or not).
//!
//! `cargo run --release -p supine-models --example forest_on_sequences -- SEQ_DIR_OR_PARENT [FOREST] [FRAMES] [MARGIN_PX] [CEILING_M]`
//! Cost: per frame and clip one forest estimate (~1 ms) and a nearest-vertex search per sample (~5 ms).

use anyhow::{Context, Result, bail};
use nalgebra::{Point3, Vector3};
use std::path::PathBuf;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::forest::feature::DepthImage;
use supine_core::forest::infer::{self, InferConfig, Method, Workspace};
use supine_core::forest::model::ForestView;
use supine_core::forest::sample::{
    CLIP_MARGIN_M, CLIP_MAX_DEPTH_MM, Ceiling, Clip, PixelRect, SamplePixel, sample_pixels,
};
use supine_core::geometry::Plane;
use supine_core::planes::{self, BedScene, PlaneConfig};
use supine_drivers::SourceErrorKind;
use supine_drivers::oni::OniReader;
use supine_models::eval::tracking_truth::{TrackingTruth, sequence_dirs};

/// Pixels outside `rect` read as no depth: what the trainer sees of a dataset crop.
struct Masked<'a> {
    frame: &'a DepthFrame<'a>,
    rect: PixelRect,
}

impl DepthImage for Masked<'_> {
    fn depth_at(&self, x: i32, y: i32) -> u16 {
        let r = self.rect;
        if x < r.u0 as i32 || y < r.v0 as i32 || x >= r.u1 as i32 || y >= r.v1 as i32 {
            return 0;
        }
        self.frame.depth_at(x, y)
    }
}

#[derive(Default, Clone, Copy)]
struct Tally {
    frames: u32,
    err_sum: f64,
    err_n: u32,
    missing: u32,
    samples: u64,
    near_torso: u64,
    in_box: u64,
    /// Wall time of the estimates, µs (an upper bound on a shared machine).
    us: f64,
    point_sum: [f64; 6],
}

/// The volume of interest as planes the clip keeps points above: mattress, head section, the footprint's four sides
/// and its top (the sides and top moved out by the clip's margin so the box is the volume itself).
fn voi_clip_planes(bed: &BedScene) -> [Plane; 7] {
    let v = &bed.volume;
    let camera_from_bed = v.bed_from_camera.inverse();
    let side = |axis: usize, sign: f32, at: f32| {
        let mut n = Vector3::zeros();
        n[axis] = sign;
        let n_cam = camera_from_bed.rotation * n;
        let mut p = Vector3::zeros();
        p[axis] = at - sign * 0.02;
        let p_cam = camera_from_bed * Point3::from(p);
        Plane {
            normal: n_cam.into(),
            d: -n_cam.dot(&p_cam.coords),
        }
    };
    let [mattress, head] = bed.clip_planes();
    [
        mattress,
        head,
        side(0, 1.0, v.min[0]),
        side(0, -1.0, v.max[0]),
        side(1, 1.0, v.min[1]),
        side(1, -1.0, v.max[1]),
        side(2, -1.0, v.max[2]),
    ]
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(root) = args.first() else {
        bail!("usage: forest_on_sequences SEQ_DIR_OR_PARENT [FOREST] [FRAMES] [MARGIN_PX] [CEILING_M]");
    };
    let forest_path = PathBuf::from(args.get(1).map_or("models/artifacts/joints.jfor", |s| s.as_str()));
    let frames: usize = args.get(2).map_or(Ok(10), |s| s.parse()).context("FRAMES")?;
    let margin: f32 = args.get(3).map_or(Ok(48.0), |s| s.parse()).context("MARGIN_PX")?;
    let height_m: f32 = args
        .get(4)
        .map_or(Ok(supine_core::tracker::FOREST_CEILING_M), |s| s.parse())
        .context("CEILING_M")?;
    let bytes = std::fs::read(&forest_path).with_context(|| format!("reading {}", forest_path.display()))?;
    let forest = ForestView::parse(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", forest_path.display()))?;
    let k = Intrinsics::KINECT_V1;
    let names = ["full", "box", "box_masked", "mattress_only", "voi", "ceiling"];
    let mut ws = Box::new(Workspace::new());
    let mut total = [Tally::default(); 6];
    println!("seq    {}", names.map(|n| format!("{n:>34}")).join(""));
    for dir in sequence_dirs(&PathBuf::from(root))? {
        let seq = TrackingTruth::load(&dir)?;
        let planes: [Plane; 2] = [seq.meta.planes_camera[1], seq.meta.planes_camera[2]];
        let mattress: [Plane; 2] = [seq.meta.planes_camera[1], seq.meta.planes_camera[1]];
        let mut reader = OniReader::open(dir.join("sequence.oni"))?;
        let up = seq
            .robot_base_from_camera()
            .map(|t| t.inverse().rotation * Vector3::z());
        let mut voi_planes: Option<Vec<Plane>> = None;
        let mut tally = [Tally::default(); 6];
        for f in 0..frames {
            let frame = match reader.read_frame() {
                Ok(fr) => fr,
                Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
                Err(e) => bail!("{}: {e}", dir.display()),
            };
            let t = &seq.frames[f];
            if voi_planes.is_none() {
                let cfg = PlaneConfig::default();
                let n =
                    planes::scratch_points(k.width as usize, k.height as usize, cfg.stride.max(1) as usize);
                let mut pts = vec![Point3::origin(); n];
                let mut labels = vec![0u8; n];
                // The tracker's init retries on later frames; here a frame without a bed falls back to the planes.
                voi_planes = match planes::estimate_bed(&frame, &k, &cfg, up.as_ref(), &mut pts, &mut labels)
                {
                    Ok(bed) => Some(voi_clip_planes(&bed).to_vec()),
                    Err(e) => {
                        eprintln!(
                            "{}: no bed on frame {f} ({e:?}): voi = the true planes",
                            dir.display()
                        );
                        Some(planes.to_vec())
                    }
                };
            }
            let voi = voi_planes.as_deref().unwrap_or(&[]);
            let torso = seq.torso.frame(f).context("torso frame")?;
            // The patient's box: salient pixels and the projected torso surface, plus the dataset's margin.
            let (mut u0, mut v0, mut u1, mut v1) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
            let mut grow = |u: f32, v: f32| {
                u0 = u0.min(u);
                v0 = v0.min(v);
                u1 = u1.max(u);
                v1 = v1.max(v);
            };
            for p in &t.salient_pixels {
                grow(p[0], p[1]);
            }
            for v in torso {
                if let Some(q) = k.project(&Point3::from(*v)) {
                    grow(q.x, q.y);
                }
            }
            let rect = PixelRect {
                u0: (u0 - margin).max(0.0) as u16,
                v0: (v0 - margin).max(0.0) as u16,
                u1: (u1 + margin).min(k.width as f32) as u16,
                v1: (v1 + margin).min(k.height as f32) as u16,
            };
            let full_rect = PixelRect {
                u0: 0,
                v0: 0,
                u1: k.width,
                v1: k.height,
            };
            let seed = 0x5EED_0000 + f as u64;
            for (i, tally) in tally.iter_mut().enumerate() {
                let clip = Clip {
                    above: match i {
                        3 => &mattress,
                        4 => voi,
                        _ => &planes,
                    },
                    margin_m: CLIP_MARGIN_M,
                    region: if i == 1 || i == 2 { rect } else { full_rect },
                    max_depth_mm: CLIP_MAX_DEPTH_MM,
                };
                let cfg = InferConfig {
                    samples: forest.samples_per_frame(),
                    seed,
                    method: Method::Refined,
                };
                let masked = Masked { frame: &frame, rect };
                // What the tracker's forest reads (`TrackerConfig::forest_ceiling_m`), here over the true planes.
                let ceiling = Ceiling::new(&frame, &k, &planes, height_m);
                let started = std::time::Instant::now();
                let est = if i == 2 {
                    infer::estimate(&forest, &masked, &k, &clip, &cfg, &[None; 6], &mut ws)
                } else if i == 5 {
                    infer::estimate(&forest, &ceiling, &k, &clip, &cfg, &[None; 6], &mut ws)
                } else {
                    infer::estimate(&forest, &frame, &k, &clip, &cfg, &[None; 6], &mut ws)
                };
                tally.us += started.elapsed().as_secs_f64() * 1e6;
                tally.frames += 1;
                for (j, (e, p)) in est.iter().zip(&t.salient_camera).enumerate() {
                    match e {
                        Some(e) => {
                            let mm = ((e.position.coords - Vector3::from(*p)).norm() * 1000.0) as f64;
                            tally.err_sum += mm;
                            tally.err_n += 1;
                            tally.point_sum[j] += mm;
                        }
                        None => tally.missing += 1,
                    }
                }
                // The same draw as estimate made, to see where the samples fall.
                let mut px = vec![SamplePixel::default(); cfg.samples];
                let n = if i == 5 {
                    sample_pixels(&ceiling, &k, &clip, seed, &mut px)
                } else {
                    sample_pixels(&frame, &k, &clip, seed, &mut px)
                };
                for s in &px[..n] {
                    let p = Vector3::from(s.p);
                    let near = torso
                        .iter()
                        .any(|v| (Vector3::from(*v) - p).norm_squared() < 0.05 * 0.05);
                    tally.samples += 1;
                    tally.near_torso += near as u64;
                    let inside = s.x >= rect.u0 && s.x < rect.u1 && s.y >= rect.v0 && s.y < rect.v1;
                    tally.in_box += inside as u64;
                }
            }
        }
        let name = dir
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        let cell = |t: &Tally| {
            format!(
                "{:>8.1} mm miss {:>3} torso {:>4.2} box {:>4.2}",
                t.err_sum / t.err_n.max(1) as f64,
                t.missing,
                t.near_torso as f64 / t.samples.max(1) as f64,
                t.in_box as f64 / t.samples.max(1) as f64
            )
        };
        println!(
            "{name:<6} {}",
            tally.iter().map(cell).collect::<Vec<_>>().join("")
        );
        let per_point = tally[0]
            .point_sum
            .map(|v| format!("{:.0}", v / tally[0].frames.max(1) as f64));
        eprintln!(
            "{name:<6} full clip, per point mm (head, l/r shoulder, belly, l/r hip): {}",
            per_point.join(" ")
        );
        for (a, b) in total.iter_mut().zip(&tally) {
            a.frames += b.frames;
            a.err_sum += b.err_sum;
            a.err_n += b.err_n;
            a.missing += b.missing;
            a.samples += b.samples;
            a.near_torso += b.near_torso;
            a.in_box += b.in_box;
            a.us += b.us;
        }
    }
    let mean_of_seq = |t: &Tally| t.err_sum / t.err_n.max(1) as f64;
    println!(
        "all    {}",
        total
            .iter()
            .map(|t| format!(
                "{:>8.1} mm miss {:>3} torso {:>4.2} box {:>4.2}",
                mean_of_seq(t),
                t.missing,
                t.near_torso as f64 / t.samples.max(1) as f64,
                t.in_box as f64 / t.samples.max(1) as f64
            ))
            .collect::<Vec<_>>()
            .join("")
    );
    let times: Vec<String> = names
        .iter()
        .zip(&total)
        .map(|(n, t)| format!("{n} {:.0}", t.us / t.frames.max(1) as f64))
        .collect();
    println!("estimate wall time per frame, us: {}", times.join(", "));
    Ok(())
}
