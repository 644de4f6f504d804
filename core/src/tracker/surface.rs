//! Surface adaptation: once the tracked torso model has settled, its front surface is moved along its normals
//! onto what the camera sees of this patient. The body model's 20 coefficients cannot hold every
//! patient's front (the estimate stays about 1 σ from the truth per coefficient) nor the posture the patient lies
//! in; over a few well-seen tracked frames each torso vertex collects its distance to the observed surface, and
//! the mean, smoothed over the mesh, becomes its displacement. Vertices the camera never saw keep the shape
//! model's position (or take their seen neighbours' displacement through the smoothing).
//!
//! Cost: [`accumulate`] is one projective association of the torso vertices (about 20-40 µs for the default
//! model's 837 vertices); [`apply`] runs once, `smooth` passes over the subset's triangles plus the normals (about
//! 0.1 ms). Nothing allocates: the sums live in caller buffers.

use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::{Isometry3, Point3, Vector3};
use crate::icp::{self, IcpParams};
use crate::model_file::LeSlice;
use crate::torso;

/// How the surface is adapted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceConfig {
    /// Tracked frames whose observations are averaged per round (0: off).
    pub frames: u16,
    /// Rounds: each adds what its frames saw to the displacement so far.
    pub rounds: u8,
    /// Good tracked frames with the current torso model before a frame counts (the pose settles first).
    pub settle_frames: u16,
    /// A frame counts only when its fit sees at least this share of the front-facing torso.
    pub min_visible: f32,
    /// Observations farther than this from the model along its normal are not the patient's surface (the arm
    /// just in front of it, a hand on the chest), metres; also the largest total displacement.
    pub max_m: f32,
    /// A vertex needs observations in at least this share of a round's frames to be moved by its own.
    pub min_share: f32,
    /// ... and their standard deviation at most this, metres: the arm passing just in front of the skin, or a
    /// pose still sliding, gives observations that disagree from frame to frame; the skin does not.
    pub max_sd_m: f32,
    /// Smoothing passes per round (each averages a vertex with its mesh neighbours).
    pub smooth: u8,
    /// Vertices within this distance of the probe tip collect nothing (the probe and its holder lie on the skin
    /// where they touch it), metres.
    pub probe_clear_m: f32,
}

impl Default for SurfaceConfig {
    fn default() -> Self {
        SurfaceConfig {
            frames: 8,
            rounds: 2,
            settle_frames: 3,
            min_visible: 0.5,
            max_m: 0.03,
            min_share: 0.3,
            max_sd_m: 0.006,
            smooth: 2,
            probe_clear_m: 0.12,
        }
    }
}

/// One torso vertex's sums: this round's observed displacements along its normal, and the total of the rounds
/// applied so far.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct VertexSums {
    /// Sum of this round's displacements, metres.
    pub sum: f32,
    /// Sum of their squares, m².
    pub sum_sq: f32,
    /// How many.
    pub count: f32,
    /// Total displacement of the rounds applied so far, metres.
    pub total: f32,
}

impl VertexSums {
    /// No observation and no displacement.
    pub const ZERO: VertexSums = VertexSums {
        sum: 0.0,
        sum_sq: 0.0,
        count: 0.0,
        total: 0.0,
    };

    /// Forget this round's observations, keep the total.
    pub fn new_round(&mut self) {
        *self = VertexSums {
            total: self.total,
            ..VertexSums::ZERO
        };
    }
}

/// Add this frame's observations to `sums` ([`VertexSums`]): the torso `vertices` and `normals` (torso frame) at `camera_from_torso` paired projectively
/// with the frame. Vertices within `cfg.probe_clear_m` of `probe_tip` (torso frame) are skipped. Returns the
/// number of vertices that collected an observation.
#[allow(clippy::too_many_arguments)] // the frame, its camera, the model, its pose and the caller's sums
pub fn accumulate(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    vertices: &[Point3],
    normals: &[Vector3],
    camera_from_torso: &Isometry3,
    params: &IcpParams,
    probe_tip: Option<&Point3>,
    cfg: &SurfaceConfig,
    sums: &mut [VertexSums],
) -> usize {
    let mut used = 0;
    let clear2 = cfg.probe_clear_m * cfg.probe_clear_m;
    icp::associate(
        frame,
        k,
        vertices,
        Some(normals),
        1,
        camera_from_torso,
        params,
        |i, p, o, n| {
            if probe_tip.is_some_and(|t| (vertices[i] - t).norm_squared() < clear2) {
                return;
            }
            let Some(s) = sums.get_mut(i) else {
                return;
            };
            // The distance along the model normal to the observed tangent plane.
            let m = camera_from_torso.rotation * normals[i];
            let cos = n.dot(&m);
            if cos < 0.5 {
                return;
            }
            let d = n.dot(&(o - p)) / cos;
            if d.abs() < cfg.max_m {
                s.sum += d;
                s.sum_sq += d * d;
                s.count += 1.0;
                used += 1;
            }
        },
    );
    used
}

/// End a round: the smoothed mean of this round's observations in `sums` over `frames` frames is added to each
/// vertex's total (held within `cfg.max_m`), `vertices` move by it along `normals`, the normals are recomputed
/// over `triangles` (the torso subset's), and a new round starts. `tmp` (as long as `vertices`) is working
/// memory. Returns the number of vertices moved by their own observations.
pub fn apply(
    triangles: LeSlice<'_, u16>,
    vertices: &mut [Point3],
    normals: &mut [Vector3],
    sums: &mut [VertexSums],
    tmp: &mut [[f32; 3]],
    frames: u16,
    cfg: &SurfaceConfig,
) -> usize {
    let n = vertices.len().min(normals.len()).min(sums.len()).min(tmp.len());
    let min_count = (cfg.min_share * f32::from(frames)).max(1.0);
    let mut own = 0;
    // From here on a vertex's `sum` is this round's displacement and `count` its weight (1: known, 0: not).
    for s in sums[..n].iter_mut() {
        let mean = s.sum / s.count.max(1.0);
        let var = s.sum_sq / s.count.max(1.0) - mean * mean;
        let seen = s.count >= min_count && var <= cfg.max_sd_m * cfg.max_sd_m;
        own += seen as usize;
        (s.sum, s.count) = if seen { (mean, 1.0) } else { (0.0, 0.0) };
    }
    for _ in 0..cfg.smooth {
        // tmp[i] = (weighted displacement, weight) over the vertex and its mesh neighbours.
        for (t, s) in tmp[..n].iter_mut().zip(sums.iter()) {
            *t = [s.sum * s.count, s.count, 0.0];
        }
        for f in 0..triangles.len() / 3 {
            let [a, b, c] = [0, 1, 2].map(|i| triangles.at(3 * f + i) as usize);
            if a >= n || b >= n || c >= n {
                continue;
            }
            for (x, y) in [(a, b), (b, c), (c, a), (b, a), (c, b), (a, c)] {
                tmp[x][0] += sums[y].sum * sums[y].count;
                tmp[x][1] += sums[y].count;
            }
        }
        for (s, t) in sums[..n].iter_mut().zip(tmp.iter()) {
            (s.sum, s.count) = if t[1] > 0.0 {
                (t[0] / t[1], 1.0)
            } else {
                (0.0, 0.0)
            };
        }
    }
    for ((v, nrm), s) in vertices[..n].iter_mut().zip(normals.iter()).zip(sums.iter_mut()) {
        let total = (s.total + s.sum).clamp(-cfg.max_m, cfg.max_m);
        *v += nrm * (total - s.total);
        s.total = total;
        s.new_round();
    }
    torso::vertex_normals(triangles, &vertices[..n], &mut normals[..n], Vector3::z());
    own
}

/// Move freshly built `vertices` along their `normals` by the totals in `sums` and recompute the normals (a torso
/// model rebuilt with a new shape keeps what the rounds so far found). Does nothing while every total is zero.
pub fn displace(
    triangles: LeSlice<'_, u16>,
    vertices: &mut [Point3],
    normals: &mut [Vector3],
    sums: &[VertexSums],
) {
    if sums.iter().all(|s| s.total == 0.0) {
        return;
    }
    let n = vertices.len().min(normals.len()).min(sums.len());
    for ((v, nrm), s) in vertices[..n].iter_mut().zip(normals.iter()).zip(sums.iter()) {
        *v += nrm * s.total;
    }
    torso::vertex_normals(triangles, &vertices[..n], &mut normals[..n], Vector3::z());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Intrinsics, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD};
    use crate::geometry::{Plane, Translation3, UnitQuaternion};
    use crate::model_file::{ElemType, Section};
    use crate::time::Timestamp;

    const WIDTH: u16 = 160;
    const HEIGHT: u16 = 120;

    /// The Kinect's field of view at a quarter of its resolution, looking at the torso frame's origin from 1 m
    /// along its +z (the patch faces the camera).
    fn camera() -> (Intrinsics, Isometry3) {
        let k = Intrinsics::from_fov(WIDTH, HEIGHT, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD);
        let camera_from_torso = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), core::f32::consts::PI),
        );
        (k, camera_from_torso)
    }

    /// The association of the tracker's fit, with the mattress 1 m behind the patch.
    fn params() -> IcpParams {
        IcpParams::new(Plane::through(
            Vector3::new(0.0, 0.0, 2.0),
            Vector3::new(0.0, 0.0, -1.0),
        ))
    }

    /// One frame of a flat surface `depth_mm` from the camera, added to `sums`.
    fn observe_flat(
        depth_mm: u16,
        v: &[Point3],
        n: &[Vector3],
        tip: Option<&Point3>,
        cfg: &SurfaceConfig,
        sums: &mut [VertexSums],
    ) -> usize {
        let (k, camera_from_torso) = camera();
        let depth = [depth_mm; WIDTH as usize * HEIGHT as usize];
        let frame = DepthFrame::new(&depth, WIDTH, HEIGHT, Timestamp::default(), 0).expect("sized");
        accumulate(&frame, &k, v, n, &camera_from_torso, &params(), tip, cfg, sums)
    }

    /// A flat patch of `w` x `h` vertices 2 cm apart in the torso frame's x-y plane, facing +z, and its triangles.
    fn patch<const N: usize, const T: usize>(w: usize, h: usize) -> ([Point3; N], [Vector3; N], [u16; T]) {
        let mut v = [Point3::origin(); N];
        let mut tri = [0u16; T];
        for y in 0..h {
            for x in 0..w {
                v[y * w + x] = Point3::new(x as f32 * 0.02 - 0.1, y as f32 * 0.02 - 0.1, 0.0);
            }
        }
        let mut t = 0;
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                let i = (y * w + x) as u16;
                let (r, d, rd) = (i + 1, i + w as u16, i + w as u16 + 1);
                tri[t..t + 6].copy_from_slice(&[i, r, rd, i, rd, d]);
                t += 6;
            }
        }
        (v, [Vector3::z(); N], tri)
    }

    /// `tri` as the little-endian view a model file gives, written into `bytes`.
    fn le<'a>(tri: &[u16], bytes: &'a mut [u8]) -> LeSlice<'a, u16> {
        for (c, t) in bytes.chunks_exact_mut(2).zip(tri) {
            c.copy_from_slice(&t.to_le_bytes());
        }
        let section = Section {
            tag: *b"TRIS",
            elem: ElemType::U16,
            count: tri.len(),
            bytes,
        };
        section.view().expect("u16")
    }

    #[test]
    fn a_patch_seen_1_cm_nearer_the_camera_than_the_model_moves_out_by_1_cm_except_by_the_probe() {
        const W: usize = 11;
        let (mut v, mut n, tri) = patch::<{ W * W }, { 6 * (W - 1) * (W - 1) }>(W, W);
        // The probe clears the corner vertex and its three neighbours (2.8 cm away at most).
        let cfg = SurfaceConfig {
            probe_clear_m: 0.03,
            ..SurfaceConfig::default()
        };
        let mut sums = [VertexSums::ZERO; W * W];
        let tip = v[0];
        // One round's frames, all alike: the plane 1 cm in front of the patch (0.99 m from the camera).
        let observe = |v: &[Point3], n: &[Vector3], sums: &mut [VertexSums]| -> usize {
            (0..cfg.frames)
                .map(|_| observe_flat(990, v, n, Some(&tip), &cfg, sums))
                .sum()
        };
        assert!(observe(&v, &n, &mut sums) > 0);
        // The corner under the probe collected nothing; a middle vertex collected every frame, 1 cm each.
        for i in [0, 1, W, W + 1] {
            assert_eq!(sums[i].count, 0.0);
        }
        let mid = sums[W * W / 2];
        assert_eq!(mid.count, f32::from(cfg.frames));
        assert!((mid.sum / mid.count - 0.01).abs() < 2e-3, "{mid:?}");
        let mut bytes = [0u8; 2 * 6 * (W - 1) * (W - 1)];
        let triangles = le(&tri, &mut bytes);
        let mut tmp = [[0.0f32; 3]; W * W];
        let own = apply(triangles, &mut v, &mut n, &mut sums, &mut tmp, cfg.frames, &cfg);
        assert_eq!(own, W * W - 4);
        for (i, (p, s)) in v.iter().zip(&sums).enumerate() {
            // The unobserved corner took its neighbours' displacement through the smoothing.
            assert!((p.z - 0.01).abs() < 2e-3, "vertex {i} at {}", p.z);
            assert_eq!((s.sum, s.sum_sq, s.count), (0.0, 0.0, 0.0));
            assert!((s.total - p.z).abs() < 1e-6);
        }
        for nrm in &n {
            assert!((nrm - Vector3::z()).norm() < 1e-3);
        }
        // A second round sees the moved patch on the surface and adds nothing.
        observe(&v, &n, &mut sums);
        apply(triangles, &mut v, &mut n, &mut sums, &mut tmp, cfg.frames, &cfg);
        assert!(sums.iter().all(|s| (s.total - 0.01).abs() < 2e-3));
        // A model built afresh takes the totals.
        let (mut fresh, mut fresh_n, _) = patch::<{ W * W }, { 6 * (W - 1) * (W - 1) }>(W, W);
        displace(triangles, &mut fresh, &mut fresh_n, &sums);
        for (p, q) in fresh.iter().zip(&v) {
            assert!((p - q).norm() < 1e-6);
        }
    }

    #[test]
    fn observations_that_disagree_from_frame_to_frame_move_nothing() {
        const W: usize = 5;
        let (mut v, mut n, tri) = patch::<{ W * W }, { 6 * (W - 1) * (W - 1) }>(W, W);
        let cfg = SurfaceConfig::default();
        let mut sums = [VertexSums::ZERO; W * W];
        // Something passing in front of the skin: 2.5 cm out on odd frames, on the skin on even ones (mean 1.25
        // cm, standard deviation 1.25 cm).
        for f in 0..cfg.frames {
            observe_flat(if f % 2 == 1 { 975 } else { 1000 }, &v, &n, None, &cfg, &mut sums);
        }
        assert_eq!(sums[W * W / 2].count, f32::from(cfg.frames));
        let mut bytes = [0u8; 2 * 6 * (W - 1) * (W - 1)];
        let mut tmp = [[0.0f32; 3]; W * W];
        let own = apply(
            le(&tri, &mut bytes),
            &mut v,
            &mut n,
            &mut sums,
            &mut tmp,
            cfg.frames,
            &cfg,
        );
        assert_eq!(own, 0);
        assert!(v.iter().all(|p| p.z == 0.0));
    }

    #[test]
    fn observations_beyond_the_window_are_not_the_surface() {
        const W: usize = 5;
        let (v, n, _) = patch::<{ W * W }, { 6 * (W - 1) * (W - 1) }>(W, W);
        // The arm 3.5 cm in front of the patch: inside the occluder margin, outside the window.
        let mut sums = [VertexSums::ZERO; W * W];
        let cfg = SurfaceConfig::default();
        assert_eq!(observe_flat(965, &v, &n, None, &cfg, &mut sums), 0);
        assert!(sums.iter().all(|s| s.count == 0.0));
    }
}
