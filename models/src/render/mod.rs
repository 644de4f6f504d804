//! CPU z-buffer rasteriser: triangle meshes in the `robot_base` (world) frame → a 640x480 depth image in the `camera`
//! frame with per-pixel ground truth (what the pixel sees, which body part, which triangle).
//!
//! Why a CPU rasteriser: the dataset generator renders tens of thousands of images on a 2-core build machine without a
//! GPU, and every byte must be deterministic for a seed. Design:
//! - vertices are transformed once per draw call into the camera frame (a reused scratch buffer), triangles are
//!   clipped against a near plane (Sutherland–Hodgman on a fixed-size polygon, no allocation) and projected;
//! - screen coordinates are snapped to 1/256 px and edge functions are evaluated exactly in `i64`, so the top-left
//!   fill rule holds bit-exactly (two triangles sharing an edge never both cover, nor both miss, a pixel centre);
//! - pixel centres sit at integer coordinates (`Intrinsics` convention); each row of the clamped bounding box is
//!   walked over the span solved from the three edge equations (narrow triangles test per pixel instead), with
//!   incremental edge values; closed meshes may skip back faces;
//! - depth is perspective-correct: 1/z is affine in screen space, interpolated from the barycentrics and stored as
//!   the z-buffer value (larger = nearer), so a plane at 2 m renders 1/z = 0.5 exactly.
//!
//! Cost: one rigid transform per vertex, a few integer adds per covered pixel plus a little per row and triangle; a
//! frame with the ~27k-triangle MakeHuman body, bed, floor and arm takes ~3 ms on one core. Buffers live in
//! [`Renderer`] and are reused between frames; nothing is allocated per triangle.

pub mod effects;
pub mod noise;

use nalgebra::{Isometry3, Point3, Vector3};
use supine_core::camera::Intrinsics;

/// What a pixel sees (ground-truth class), stored per pixel as a `u8`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[repr(u8)]
pub enum Label {
    /// Nothing was rendered at this pixel (no surface within the far plane).
    None = 0,
    /// The room floor.
    Floor = 1,
    /// The bed: frame, legs, mattress, head section, head board.
    Bed = 2,
    /// The patient's skin.
    Body = 3,
    /// The robot arm and its ultrasound probe.
    Occluder = 4,
}

impl Label {
    /// The label for a stored byte; unknown bytes map to `None`.
    pub fn from_u8(v: u8) -> Label {
        match v {
            1 => Label::Floor,
            2 => Label::Bed,
            3 => Label::Body,
            4 => Label::Occluder,
            _ => Label::None,
        }
    }
}

/// Part id stored for pixels that are not on the body.
pub const NO_PART: u8 = 255;
/// Triangle id stored for pixels where nothing was rendered.
pub const NO_TRIANGLE: u32 = u32::MAX;
/// Near clipping distance in metres (the Kinect sees nothing closer than ~0.5 m; this only keeps projection finite).
pub const NEAR_M: f32 = 0.1;
/// Projected coordinates beyond this many pixels from the image are rejected (keeps the i64 edge maths exact).
const GUARD_PX: f32 = 1.0e6;
/// Sub-pixel precision: screen coordinates are snapped to 1/256 px.
const SUBPIX_BITS: u32 = 8;
const SUBPIX: f32 = (1u32 << SUBPIX_BITS) as f32;

/// One mesh to draw: vertices in the world frame, triangles, the label its pixels get, and optional per-triangle
/// part ids (body parts) written to the part buffer.
#[derive(Debug, Clone, Copy)]
pub struct DrawMesh<'a> {
    /// Vertex positions in the world frame, metres.
    pub vertices: &'a [[f32; 3]],
    /// Triangles as vertex indices.
    pub triangles: &'a [[u32; 3]],
    /// Label written to covered pixels.
    pub label: Label,
    /// Per-triangle part id (same length as `triangles`), or `None` to write [`NO_PART`].
    pub triangle_part: Option<&'a [u8]>,
    /// Skip triangles facing away from the camera: only for closed meshes wound counter-clockwise seen from
    /// outside (their back faces are always hidden by front faces), where it halves the work.
    pub cull_back_faces: bool,
}

/// Per-pixel output of one rendered frame, row-major `width * height`.
#[derive(Debug, Clone)]
pub struct RenderBuffers {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// 1/z in 1/metres along the optical axis; 0 where nothing was rendered.
    pub inv_z: Vec<f32>,
    /// [`Label`] of the nearest surface, as `u8`.
    pub label: Vec<u8>,
    /// Body-part id of the nearest surface ([`NO_PART`] off the body).
    pub part: Vec<u8>,
    /// Global triangle id of the nearest surface (index into [`RenderBuffers::normals`]); [`NO_TRIANGLE`] if none.
    pub triangle: Vec<u32>,
    /// Unit normal of every triangle drawn since the last clear, in the camera frame, in draw order.
    pub normals: Vec<[f32; 3]>,
}

impl RenderBuffers {
    /// Depth in metres at pixel index `i`, or `None` where nothing was rendered.
    pub fn z_at(&self, i: usize) -> Option<f32> {
        let iz = self.inv_z[i];
        if iz > 0.0 { Some(1.0 / iz) } else { None }
    }

    /// Clean depth image in millimetres (rounded, 0 where empty or beyond `u16`), written into `out`.
    pub fn depth_mm_into(&self, out: &mut [u16]) {
        for (o, &iz) in out.iter_mut().zip(&self.inv_z) {
            *o = if iz > 0.0 {
                (1000.0 / iz).round().min(65535.0) as u16
            } else {
                0
            };
        }
    }

    /// Number of pixels carrying `label`.
    pub fn count_label(&self, label: Label) -> usize {
        self.label.iter().filter(|&&l| l == label as u8).count()
    }
}

/// A z-buffer rasteriser with reusable buffers (see the module docs for the design).
#[derive(Debug, Clone)]
pub struct Renderer {
    intrinsics: Intrinsics,
    buffers: RenderBuffers,
    /// Scratch: vertices of the current draw call in the camera frame.
    cam_vertices: Vec<[f32; 3]>,
}

/// A clipped, projected vertex: screen position (pixels) and 1/z.
#[derive(Debug, Clone, Copy, Default)]
struct ScreenVertex {
    x: f32,
    y: f32,
    inv_z: f32,
}

impl Renderer {
    /// A renderer for `intrinsics` (usually [`Intrinsics::KINECT_V1`]); buffers are allocated once here.
    pub fn new(intrinsics: Intrinsics) -> Self {
        let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
        let n = w * h;
        Renderer {
            intrinsics,
            buffers: RenderBuffers {
                width: w,
                height: h,
                inv_z: vec![0.0; n],
                label: vec![Label::None as u8; n],
                part: vec![NO_PART; n],
                triangle: vec![NO_TRIANGLE; n],
                normals: Vec::with_capacity(1 << 16),
            },
            cam_vertices: Vec::with_capacity(1 << 15),
        }
    }

    /// The camera intrinsics this renderer projects with.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// Reset every buffer to "nothing rendered" (keeps capacity).
    pub fn clear(&mut self) {
        let b = &mut self.buffers;
        b.inv_z.fill(0.0);
        b.label.fill(Label::None as u8);
        b.part.fill(NO_PART);
        b.triangle.fill(NO_TRIANGLE);
        b.normals.clear();
    }

    /// The buffers rendered so far.
    pub fn buffers(&self) -> &RenderBuffers {
        &self.buffers
    }

    /// Draw `mesh` seen from a camera at `camera_from_world`; nearer surfaces win (z-buffer). Triangles are not culled
    /// by facing, so open meshes and either winding render correctly.
    pub fn draw(&mut self, mesh: &DrawMesh<'_>, camera_from_world: &Isometry3<f32>) {
        self.cam_vertices.clear();
        self.cam_vertices.extend(mesh.vertices.iter().map(|v| {
            let p = camera_from_world * Point3::new(v[0], v[1], v[2]);
            [p.x, p.y, p.z]
        }));
        let label = mesh.label as u8;
        for (ti, t) in mesh.triangles.iter().enumerate() {
            let a = self.cam_vertices[t[0] as usize];
            let b = self.cam_vertices[t[1] as usize];
            let c = self.cam_vertices[t[2] as usize];
            // Triangle id = index into `normals`, so the noise model can look the surface normal up per pixel.
            let id = self.buffers.normals.len() as u32;
            let n = Vector3::from(b) - Vector3::from(a);
            let n = n.cross(&(Vector3::from(c) - Vector3::from(a)));
            let len = n.norm();
            let n = if len > 0.0 {
                n / len
            } else {
                Vector3::new(0.0, 0.0, -1.0)
            };
            self.buffers.normals.push([n.x, n.y, n.z]);
            // Facing away from the camera at the origin: the ray to any vertex runs along the normal.
            if mesh.cull_back_faces && n.dot(&Vector3::from(a)) > 0.0 {
                continue;
            }
            let part = mesh.triangle_part.map_or(NO_PART, |p| p[ti]);
            self.triangle_clipped([a, b, c], label, part, id);
        }
    }

    /// Clip a camera-frame triangle against z = NEAR_M and rasterise the result (0, 1 or 2 triangles).
    fn triangle_clipped(&mut self, tri: [[f32; 3]; 3], label: u8, part: u8, id: u32) {
        let inside = tri.map(|p| p[2] >= NEAR_M);
        if !inside.iter().any(|&i| i) {
            return;
        }
        // Sutherland–Hodgman against one plane: a triangle becomes at most a quad.
        let mut poly = [[0.0f32; 3]; 4];
        let mut n = 0;
        if inside.iter().all(|&i| i) {
            poly[..3].copy_from_slice(&tri);
            n = 3;
        } else {
            for i in 0..3 {
                let p = tri[i];
                let q = tri[(i + 1) % 3];
                let (pin, qin) = (inside[i], inside[(i + 1) % 3]);
                if pin {
                    poly[n] = p;
                    n += 1;
                }
                if pin != qin {
                    let t = (NEAR_M - p[2]) / (q[2] - p[2]);
                    poly[n] = [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]), NEAR_M];
                    n += 1;
                }
            }
        }
        let k = &self.intrinsics;
        let mut sv = [ScreenVertex::default(); 4];
        for i in 0..n {
            let p = poly[i];
            let iz = 1.0 / p[2];
            sv[i] = ScreenVertex {
                x: k.fx * p[0] * iz + k.cx,
                y: k.fy * p[1] * iz + k.cy,
                inv_z: iz,
            };
            if !(sv[i].x.abs() < GUARD_PX && sv[i].y.abs() < GUARD_PX) {
                return;
            }
        }
        self.raster(sv[0], sv[1], sv[2], label, part, id);
        if n == 4 {
            self.raster(sv[0], sv[2], sv[3], label, part, id);
        }
    }

    /// Rasterise one projected triangle with the top-left fill rule and a 1/z depth test.
    fn raster(&mut self, v0: ScreenVertex, v1: ScreenVertex, v2: ScreenVertex, label: u8, part: u8, id: u32) {
        let fix = |v: f32| (v * SUBPIX).round() as i64;
        let (mut x0, mut y0, mut z0) = (fix(v0.x), fix(v0.y), v0.inv_z);
        let (mut x1, mut y1, mut z1) = (fix(v1.x), fix(v1.y), v1.inv_z);
        let (x2, y2, z2) = (fix(v2.x), fix(v2.y), v2.inv_z);
        let mut area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0);
        if area == 0 {
            return;
        }
        if area < 0 {
            // Orient every triangle the same way so one fill rule applies.
            std::mem::swap(&mut x0, &mut x1);
            std::mem::swap(&mut y0, &mut y1);
            std::mem::swap(&mut z0, &mut z1);
            area = -area;
        }
        let (w, h) = (self.buffers.width as i64, self.buffers.height as i64);
        let one = 1i64 << SUBPIX_BITS;
        // Pixel centres are at integer coordinates: covered pixels lie in [ceil(min), floor(max)].
        let umin = (x0.min(x1).min(x2) + one - 1).div_euclid(one).max(0);
        let umax = x0.max(x1).max(x2).div_euclid(one).min(w - 1);
        let vmin = (y0.min(y1).min(y2) + one - 1).div_euclid(one).max(0);
        let vmax = y0.max(y1).max(y2).div_euclid(one).min(h - 1);
        if umin > umax || vmin > vmax {
            return;
        }
        // Edge function of a→b at p: (b−a)×(p−a); with area > 0 the interior is where all three are positive.
        // Top-left rule (y down, this orientation): an edge owns its boundary iff dy < 0, or dy == 0 and dx > 0.
        struct Edge {
            a: i64,
            b: i64,
            row: i64,
        }
        let edge = |ax: i64, ay: i64, bx: i64, by: i64| {
            let (dx, dy) = (bx - ax, by - ay);
            let bias = if dy < 0 || (dy == 0 && dx > 0) { 0 } else { -1 };
            let px = umin * one;
            let py = vmin * one;
            // E(p) = dx*(py-ay) - dy*(px-ax); stepping +1 px in u adds -dy*one, in v adds dx*one.
            Edge {
                a: -dy * one,
                b: dx * one,
                row: dx * (py - ay) - dy * (px - ax) + bias,
            }
        };
        let mut e0 = edge(x1, y1, x2, y2); // weight of v0
        let mut e1 = edge(x2, y2, x0, y0); // weight of v1
        let mut e2 = edge(x0, y0, x1, y1); // weight of v2
        // Barycentric weights are the unbiased edge values / area; the bias (0 or −1 in 1/65536 px²) is far below
        // f32 resolution of the weights, so it is ignored in the interpolation.
        let inv_area = 1.0 / area as f64;
        let (iz0, iz1, iz2) = (
            (z0 as f64 * inv_area) as f32,
            (z1 as f64 * inv_area) as f32,
            (z2 as f64 * inv_area) as f32,
        );
        let width = self.buffers.width;
        let last = umax - umin;
        for v in vmin..=vmax {
            // The covered span of this row, solved per edge from E_row + a·k >= 0 (k = u − umin): no per-pixel
            // inside test, so large triangles (floor, bed) cost only their covered pixels.
            let (mut lo, mut hi) = (0i64, last);
            // Narrow triangles (most of a body mesh) skip the three divisions: a per-pixel test is cheaper there.
            let narrow = last < 12;
            for e in [&e0, &e1, &e2] {
                if narrow {
                    break;
                }
                if e.a > 0 {
                    if e.row < 0 {
                        lo = lo.max((-e.row + e.a - 1) / e.a);
                    }
                } else if e.a < 0 {
                    if e.row < 0 {
                        hi = -1;
                    } else {
                        hi = hi.min(e.row / -e.a);
                    }
                } else if e.row < 0 {
                    hi = -1;
                }
            }
            if lo <= hi {
                let (mut w0, mut w1, mut w2) = (e0.row + e0.a * lo, e1.row + e1.a * lo, e2.row + e2.a * lo);
                let base = v as usize * width + umin as usize;
                for k in lo..=hi {
                    if (w0 | w1 | w2) < 0 {
                        w0 += e0.a;
                        w1 += e1.a;
                        w2 += e2.a;
                        continue;
                    }
                    let inv_z = w0 as f32 * iz0 + w1 as f32 * iz1 + w2 as f32 * iz2;
                    let i = base + k as usize;
                    if inv_z > self.buffers.inv_z[i] {
                        self.buffers.inv_z[i] = inv_z;
                        self.buffers.label[i] = label;
                        self.buffers.part[i] = part;
                        self.buffers.triangle[i] = id;
                    }
                    w0 += e0.a;
                    w1 += e1.a;
                    w2 += e2.a;
                }
            }
            e0.row += e0.b;
            e1.row += e1.b;
            e2.row += e2.b;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn quad(z: f32, half: f32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        (
            vec![
                [-half, -half, z],
                [half, -half, z],
                [half, half, z],
                [-half, half, z],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn fronto_parallel_plane_renders_exact_depth() {
        let mut r = Renderer::new(Intrinsics::KINECT_V1);
        let (v, t) = quad(2.0, 10.0);
        r.draw(
            &DrawMesh {
                vertices: &v,
                triangles: &t,
                label: Label::Floor,
                triangle_part: None,
                cull_back_faces: false,
            },
            &Isometry3::identity(),
        );
        let mut mm = vec![0u16; 640 * 480];
        r.buffers().depth_mm_into(&mut mm);
        assert!(mm.iter().all(|&d| d == 2000), "every pixel at exactly 2000 mm");
        assert_eq!(r.buffers().count_label(Label::Floor), 640 * 480);
    }

    #[test]
    fn tilted_plane_matches_ray_intersection() {
        // Plane through (0,0,1.5) with normal (0, -0.6, -0.8): z varies across the image; compare with ray casting.
        let rot = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.6435); // tilt ~36.9°
        let pose = Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.5), rot);
        let (v, t) = quad(0.0, 3.0);
        let mut r = Renderer::new(Intrinsics::KINECT_V1);
        r.draw(
            &DrawMesh {
                vertices: &v,
                triangles: &t,
                label: Label::Bed,
                triangle_part: None,
                cull_back_faces: false,
            },
            &pose,
        );
        let n = rot * Vector3::z();
        let p0 = Vector3::new(0.0, 0.0, 1.5);
        let k = Intrinsics::KINECT_V1;
        let mut checked = 0;
        for vpx in (0..480).step_by(7) {
            for upx in (0..640).step_by(7) {
                let ray = Vector3::new((upx as f32 - k.cx) / k.fx, (vpx as f32 - k.cy) / k.fy, 1.0);
                let z = n.dot(&p0) / n.dot(&ray);
                let got = r.buffers().z_at(vpx * 640 + upx).expect("plane covers the image");
                // Vertex snapping to 1/256 px moves the plane by a few µm at most.
                assert!((got - z).abs() < 1e-5 * z, "pixel ({upx},{vpx}): {got} vs {z}");
                let mm = (z * 1000.0).round();
                if ((z * 1000.0).fract() - 0.5).abs() > 0.05 {
                    assert_eq!((got * 1000.0).round(), mm, "millimetre value at ({upx},{vpx})");
                }
                checked += 1;
            }
        }
        assert!(checked > 5000);
    }

    #[test]
    fn shared_edge_pixels_are_covered_exactly_once() {
        // A fan of triangles around a centre, with vertices on pixel centres and half-pixel positions: every pixel
        // inside the fan is covered exactly once (top-left rule), none twice.
        let k = Intrinsics::KINECT_V1;
        let z = 1.0;
        let to_world = |u: f32, v: f32| [(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z];
        let centre = to_world(100.0, 100.0);
        let ring: Vec<[f32; 3]> = [
            (60.0, 60.0),
            (140.5, 60.0),
            (140.5, 140.0),
            (100.0, 160.5),
            (60.0, 140.0),
        ]
        .iter()
        .map(|&(u, v)| to_world(u, v))
        .collect();
        let mut counts = vec![0u32; 640 * 480];
        for i in 0..ring.len() {
            let verts = [centre, ring[i], ring[(i + 1) % ring.len()]];
            let mut r = Renderer::new(k);
            r.draw(
                &DrawMesh {
                    vertices: &verts,
                    triangles: &[[0, 1, 2]],
                    label: Label::Body,
                    triangle_part: None,
                    cull_back_faces: false,
                },
                &Isometry3::identity(),
            );
            for (c, &l) in counts.iter_mut().zip(&r.buffers().label) {
                *c += (l == Label::Body as u8) as u32;
            }
        }
        assert!(counts.iter().all(|&c| c <= 1), "no pixel covered twice");
        // Interior pixel centres, including those exactly on shared edges (e.g. the row v = 100 and column u = 100).
        for (u, v) in [
            (100, 100),
            (100, 70),
            (70, 100),
            (130, 100),
            (100, 130),
            (61, 61),
            (120, 150),
        ] {
            assert_eq!(counts[v * 640 + u], 1, "pixel ({u},{v}) covered once");
        }
        // A pixel centre exactly on the fan's left boundary edge u = 60 (a left edge) is covered; on the right
        // boundary u = 140.5 it cannot be (not a centre); the top edge v = 60 is covered, the bottom-left edge not.
        assert_eq!(counts[80 * 640 + 60], 1, "left edge owns its pixels");
        assert_eq!(counts[60 * 640 + 80], 1, "top edge owns its pixels");
    }

    #[test]
    fn axis_aligned_square_covers_fill_rule_pixels() {
        // Square from pixel 10 to 20 in both axes: top-left rule covers u, v in [10, 20), i.e. exactly 100 pixels.
        let k = Intrinsics::KINECT_V1;
        let z = 1.25;
        let w = |u: f32, v: f32| [(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z];
        let verts = [w(10.0, 10.0), w(20.0, 10.0), w(20.0, 20.0), w(10.0, 20.0)];
        let mut r = Renderer::new(k);
        r.draw(
            &DrawMesh {
                vertices: &verts,
                triangles: &[[0, 1, 2], [0, 2, 3]],
                label: Label::Bed,
                triangle_part: None,
                cull_back_faces: false,
            },
            &Isometry3::identity(),
        );
        let b = r.buffers();
        assert_eq!(b.count_label(Label::Bed), 100);
        assert_eq!(b.label[10 * 640 + 10], Label::Bed as u8);
        assert_eq!(b.label[19 * 640 + 19], Label::Bed as u8);
        assert_eq!(b.label[20 * 640 + 15], Label::None as u8);
        assert_eq!(b.label[15 * 640 + 20], Label::None as u8);
    }

    #[test]
    fn depth_buffer_keeps_nearest_in_any_draw_order() {
        let (far_v, t) = quad(3.0, 5.0);
        let (near_v, _) = quad(1.0, 0.2);
        let part = [7u8, 7];
        for near_first in [false, true] {
            let mut r = Renderer::new(Intrinsics::KINECT_V1);
            let far = DrawMesh {
                vertices: &far_v,
                triangles: &t,
                label: Label::Floor,
                triangle_part: None,
                cull_back_faces: false,
            };
            let near = DrawMesh {
                vertices: &near_v,
                triangles: &t,
                label: Label::Body,
                triangle_part: Some(&part),
                cull_back_faces: false,
            };
            if near_first {
                r.draw(&near, &Isometry3::identity());
                r.draw(&far, &Isometry3::identity());
            } else {
                r.draw(&far, &Isometry3::identity());
                r.draw(&near, &Isometry3::identity());
            }
            let b = r.buffers();
            let centre = 240 * 640 + 320;
            assert_eq!(b.label[centre], Label::Body as u8);
            assert_eq!(b.part[centre], 7);
            assert!((b.z_at(centre).unwrap() - 1.0).abs() < 1e-6);
            assert_eq!(b.label[10 * 640 + 10], Label::Floor as u8);
            assert!((b.z_at(10 * 640 + 10).unwrap() - 3.0).abs() < 1e-5);
            // Near quad spans ±0.2 m at 1 m: ±114 px around the centre.
            let body = b.count_label(Label::Body);
            assert!((220 * 220..=230 * 230).contains(&body), "body pixels {body}");
        }
    }

    #[test]
    fn back_face_culling_of_closed_meshes_changes_nothing_visible() {
        let mut m = crate::scene::shapes::TriMesh::default();
        m.add_ellipsoid(&Isometry3::translation(0.1, -0.05, 1.4), [0.3, 0.2, 0.25], 16, 24);
        m.add_aabb([-0.5, 0.1, 1.2], [0.2, 0.4, 1.9]);
        let render = |cull| {
            let mut r = Renderer::new(Intrinsics::KINECT_V1);
            let pose = Isometry3::rotation(Vector3::new(0.3, 0.5, 0.1));
            r.draw(
                &DrawMesh {
                    vertices: &m.vertices,
                    triangles: &m.triangles,
                    label: Label::Bed,
                    triangle_part: None,
                    cull_back_faces: cull,
                },
                &pose,
            );
            r.buffers().clone()
        };
        let (all, culled) = (render(false), render(true));
        assert_eq!(all.inv_z, culled.inv_z);
        assert_eq!(all.triangle, culled.triangle);
        assert!(all.count_label(Label::Bed) > 20_000);
    }

    #[test]
    fn triangles_crossing_the_near_plane_are_clipped() {
        // A floor-like quad extending behind the camera still renders its visible part with correct depth.
        let verts = [
            [-5.0, 1.0, -2.0],
            [5.0, 1.0, -2.0],
            [5.0, 1.0, 8.0],
            [-5.0, 1.0, 8.0],
        ];
        let mut r = Renderer::new(Intrinsics::KINECT_V1);
        r.draw(
            &DrawMesh {
                vertices: &verts,
                triangles: &[[0, 1, 2], [0, 2, 3]],
                label: Label::Floor,
                triangle_part: None,
                cull_back_faces: false,
            },
            &Isometry3::identity(),
        );
        let b = r.buffers();
        let k = Intrinsics::KINECT_V1;
        // Row v = 400 sees the plane y = 1 at z = fy / (v − cy).
        let z = b.z_at(400 * 640 + 320).unwrap();
        assert!((z - k.fy / (400.0 - k.cy)).abs() < 1e-4, "z {z}");
        assert_eq!(
            b.label[100 * 640 + 320],
            Label::None as u8,
            "above the horizon sees nothing"
        );
    }
}
