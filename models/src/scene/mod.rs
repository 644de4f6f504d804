//! The synthetic hospital room: floor, bed, patient, robot arm with ultrasound probe, and the robot head's camera.
//!
//! Frames (see `supine_core::camera`; transforms are named `a_from_b`):
//! - `robot_base` = the world frame here: metres, z up, origin on the floor at the robot's base. The bed stands
//!   beside the robot with its long axis along +x (head end at +x), its near edge at y = `bed.near_edge_y`.
//! - `bed`: origin on the mattress top at the mattress centre, z up, y toward the head end, x the patient's left
//!   (the body model's bed frame). `world_from_bed` rotates bed y onto world +x.
//! - `camera`: the Kinect's optical frame (x right, y down, z forward). The head sits beside the bed, 1.0–1.6 m above
//!   the mattress and 0.5–1.2 m to the side of the patient's midline, looking down at the torso; image right is the
//!   head end. The V views of one dataset body are random rotations of the head about two axes (yaw about world z and
//!   elevation about the horizontal axis across the view direction) around that nominal pose, both through the
//!   torso centre.
//!
//! Building a scene costs a few thousand vertices (bed, arm) on top of the body; rendering is [`crate::render`].

pub mod arm;
pub mod body;
pub mod model_body;
pub mod shapes;

use crate::body::PosedBody;
use crate::render::{DrawMesh, Label, Renderer};
use nalgebra::{Isometry3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use shapes::TriMesh;
use supine_core::geometry::Plane;

/// Bed geometry (metres, radians).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BedParams {
    /// Mattress length along the bed.
    pub length: f32,
    /// Mattress width.
    pub width: f32,
    /// Height of the mattress top above the floor.
    pub mattress_top: f32,
    /// Mattress thickness.
    pub mattress_thickness: f32,
    /// World x of the bed centre.
    pub centre_x: f32,
    /// World y of the bed's near (robot-side) long edge.
    pub near_edge_y: f32,
    /// Head-section raise angle (matches the body's).
    pub head_raise: f32,
    /// Bed-frame y of the head-section hinge.
    pub hinge_y: f32,
}

impl BedParams {
    /// A random hospital bed for a body lying with `head_raise` about a hinge at `hinge_y`.
    pub fn sample(rng: &mut ChaCha8Rng, head_raise: f32, hinge_y: f32) -> BedParams {
        BedParams {
            length: rng.gen_range(1.95..2.1),
            width: rng.gen_range(0.85..1.0),
            mattress_top: rng.gen_range(0.55..0.8),
            mattress_thickness: rng.gen_range(0.12..0.18),
            centre_x: rng.gen_range(-0.3..0.3),
            near_edge_y: rng.gen_range(0.25..0.45),
            head_raise,
            hinge_y,
        }
    }

    /// `world_from_bed`: bed y → world +x, bed z → world z, origin at the mattress top centre.
    pub fn world_from_bed(&self) -> Isometry3<f32> {
        let rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -std::f32::consts::FRAC_PI_2);
        Isometry3::from_parts(
            Translation3::new(
                self.centre_x,
                self.near_edge_y + 0.5 * self.width,
                self.mattress_top,
            ),
            rot,
        )
    }

    /// Bed frame → head section frame rotation about the hinge line (x axis through y = hinge, z = 0).
    fn bed_from_head_section(&self) -> Isometry3<f32> {
        let pivot = Vector3::new(0.0, self.hinge_y, 0.0);
        let rot = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.head_raise);
        Isometry3::from_parts(Translation3::from(pivot - rot * pivot), rot)
    }

    /// The bed as one mesh in the bed frame: frame, legs, flat mattress section, raised head section, head and
    /// foot boards.
    pub fn mesh(&self) -> TriMesh {
        let mut m = TriMesh::default();
        let (hl, hw, t) = (self.length * 0.5, self.width * 0.5, self.mattress_thickness);
        let top = self.mattress_top;
        // Mattress: flat from the foot end to the hinge, then the head section rotated about the hinge.
        m.add_aabb([-hw, -hl, -t], [hw, self.hinge_y, 0.0]);
        let mut head = TriMesh::default();
        head.add_aabb([-hw, self.hinge_y, -t], [hw, hl, 0.0]);
        m.append(&head, &self.bed_from_head_section());
        // Frame under the mattress and four legs down to the floor (z = −top in the bed frame).
        let frame_bottom = -t - 0.12;
        m.add_aabb([-hw + 0.03, -hl + 0.02, frame_bottom], [hw - 0.03, hl - 0.02, -t]);
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let (x, y) = (sx * (hw - 0.08), sy * (hl - 0.08));
            m.add_aabb([x - 0.03, y - 0.03, -top], [x + 0.03, y + 0.03, frame_bottom]);
        }
        // Head board (tall) and foot board (low), 4 cm thick.
        m.add_aabb([-hw, hl, -t - 0.15], [hw, hl + 0.04, 0.45]);
        m.add_aabb([-hw, -hl - 0.04, -t - 0.15], [hw, -hl, 0.12]);
        m
    }

    /// Planes of the mattress top (flat part) and of the head section's top, in the bed frame.
    pub fn planes(&self) -> (Plane, Plane) {
        let flat = Plane::through(Vector3::zeros(), Vector3::z());
        let hs = self.bed_from_head_section();
        let head = Plane::through(hs.translation.vector, hs.rotation * Vector3::z());
        (flat, head)
    }
}

/// Where the head (camera) is: the nominal pose of a body and the per-view rotations about it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ViewParams {
    /// Camera height above the mattress top, metres.
    pub height_above_mattress: f32,
    /// Horizontal distance from the patient's midline to the camera, metres.
    pub lateral_offset: f32,
    /// Camera position along the bed relative to the look-at point, metres.
    pub along_offset: f32,
    /// Yaw of this view about the vertical axis through the look-at point, radians.
    pub yaw: f32,
    /// Elevation change of this view about the horizontal axis across the view direction, radians.
    pub elevation: f32,
    /// Roll about the optical axis, radians.
    pub roll: f32,
    /// Look-at point in the world frame.
    pub target: [f32; 3],
}

impl ViewParams {
    /// A nominal head pose beside the bed looking at `target` (world), with no view rotation yet.
    pub fn sample_nominal(rng: &mut ChaCha8Rng, target: [f32; 3]) -> ViewParams {
        ViewParams {
            height_above_mattress: rng.gen_range(1.0..1.6),
            lateral_offset: rng.gen_range(0.5..1.2),
            along_offset: rng.gen_range(-0.15..0.15),
            yaw: 0.0,
            elevation: 0.0,
            roll: 0.0,
            target,
        }
    }

    /// One of the V random views about this nominal pose (yaw ±20°, elevation ±10°, roll ±3°).
    pub fn sample_view(&self, rng: &mut ChaCha8Rng) -> ViewParams {
        ViewParams {
            yaw: rng.gen_range(-0.35..0.35),
            elevation: rng.gen_range(-0.17..0.17),
            roll: rng.gen_range(-0.05..0.05),
            ..*self
        }
    }

    /// `camera_from_world` for this view; `midline_y` is the world y of the patient's midline, `mattress_z` the
    /// mattress height. The camera is on the −y (robot) side.
    pub fn camera_from_world(&self, midline_y: f32, mattress_z: f32) -> Isometry3<f32> {
        let target = Vector3::from(self.target);
        let nominal_eye = Vector3::new(
            target.x + self.along_offset,
            midline_y - self.lateral_offset,
            mattress_z + self.height_above_mattress,
        );
        let rel = nominal_eye - target;
        // Elevation about the horizontal axis perpendicular to the (horizontal) view direction, then yaw about z.
        let horiz = Vector3::new(rel.x, rel.y, 0.0).normalize();
        let across = Vector3::z().cross(&horiz);
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), self.yaw)
            * Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(across), -self.elevation);
        let eye = target + r * rel;
        look_at(eye, target, self.roll)
    }
}

/// `camera_from_world` of a camera at `eye` looking at `target`, image up toward world +z, rolled by `roll`.
pub fn look_at(eye: Vector3<f32>, target: Vector3<f32>, roll: f32) -> Isometry3<f32> {
    let z = (target - eye).normalize();
    let up = Vector3::z();
    let y = -(up - z * up.dot(&z)).normalize(); // image down
    let x = y.cross(&z);
    // Columns of world_from_camera's rotation are the camera axes in world coordinates.
    let world_from_cam_rot = Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[x, y, z]))
        * Rotation3::from_axis_angle(&Vector3::z_axis(), roll);
    let world_from_camera = Isometry3::from_parts(
        Translation3::from(eye),
        UnitQuaternion::from_rotation_matrix(&world_from_cam_rot),
    );
    world_from_camera.inverse()
}

/// A 4x4 row-major matrix of an isometry (for JSON ground truth).
pub fn matrix_rows(t: &Isometry3<f32>) -> [[f32; 4]; 4] {
    let m: Matrix4<f32> = t.to_homogeneous();
    [0, 1, 2, 3].map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)], m[(r, 3)]])
}

/// Everything in the room for one body, in the world frame, ready to render from any camera.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Bed geometry.
    pub bed: BedParams,
    /// Floor quad (world).
    pub floor: TriMesh,
    /// Bed mesh (world).
    pub bed_mesh: TriMesh,
    /// The patient in the world frame.
    pub body_vertices: Vec<[f32; 3]>,
    /// The patient's triangles.
    pub body_triangles: Vec<[u32; 3]>,
    /// Part id per body triangle.
    pub body_triangle_parts: Vec<u8>,
    /// Salient points in the world frame.
    pub salient_world: [[f32; 3]; 6],
    /// The robot arm and probe (world), if present.
    pub arm: Option<arm::ArmState>,
}

impl Scene {
    /// Put `body` (bed frame) on `bed` in the room.
    pub fn new(body: &PosedBody<'_>, bed: BedParams) -> Scene {
        let wfb = bed.world_from_bed();
        let to_world = |p: &[f32; 3]| {
            let q = wfb * Point3::from(*p);
            [q.x, q.y, q.z]
        };
        let mut floor = TriMesh::default();
        let (cx, cy) = (bed.centre_x, bed.near_edge_y + 0.5 * bed.width);
        floor.vertices = vec![
            [cx - 5.0, cy - 5.0, 0.0],
            [cx + 5.0, cy - 5.0, 0.0],
            [cx + 5.0, cy + 5.0, 0.0],
            [cx - 5.0, cy + 5.0, 0.0],
        ];
        floor.triangles = vec![[0, 1, 2], [0, 2, 3]];
        let bed_local = bed.mesh();
        let mut bed_mesh = TriMesh::default();
        bed_mesh.append(&bed_local, &wfb);
        Scene {
            bed,
            floor,
            bed_mesh,
            body_vertices: body.vertices.iter().map(to_world).collect(),
            body_triangles: body.triangles.to_vec(),
            body_triangle_parts: body.part_of_triangle(),
            salient_world: body.salient_points.map(|p| to_world(&p)),
            arm: None,
        }
    }

    /// World y of the patient's midline (the mattress centre line).
    pub fn midline_y(&self) -> f32 {
        self.bed.near_edge_y + 0.5 * self.bed.width
    }

    /// The torso centre (mean of shoulders and hips), where the head looks.
    pub fn torso_centre(&self) -> [f32; 3] {
        let s = &self.salient_world;
        let mut c = [0.0; 3];
        for p in [s[1], s[2], s[4], s[5]] {
            for k in 0..3 {
                c[k] += 0.25 * p[k];
            }
        }
        c
    }

    /// Floor, mattress (flat) and head-section planes in the world frame.
    pub fn planes_world(&self) -> [Plane; 3] {
        let wfb = self.bed.world_from_bed();
        let (flat, head) = self.bed.planes();
        [
            Plane {
                normal: [0.0, 0.0, 1.0],
                d: 0.0,
            },
            flat.transformed(&wfb),
            head.transformed(&wfb),
        ]
    }

    /// Render the scene from `camera_from_world` into `renderer` (cleared first).
    pub fn render(&self, renderer: &mut Renderer, camera_from_world: &Isometry3<f32>, with_arm: bool) {
        renderer.clear();
        renderer.draw(&mesh(&self.floor, Label::Floor), camera_from_world);
        renderer.draw(&mesh(&self.bed_mesh, Label::Bed), camera_from_world);
        renderer.draw(
            &DrawMesh {
                vertices: &self.body_vertices,
                triangles: &self.body_triangles,
                label: Label::Body,
                triangle_part: Some(&self.body_triangle_parts),
                cull_back_faces: true,
            },
            camera_from_world,
        );
        if with_arm && let Some(arm) = &self.arm {
            renderer.draw(&arm_draw(&arm.mesh), camera_from_world);
        }
    }
}

/// A draw call for a closed mesh without part ids (bed, floor, arm: all closed or seen from their front only).
fn mesh(m: &TriMesh, label: Label) -> DrawMesh<'_> {
    DrawMesh {
        vertices: &m.vertices,
        triangles: &m.triangles,
        label,
        triangle_part: None,
        cull_back_faces: true,
    }
}

/// The draw call of an arm mesh.
pub fn arm_draw(m: &TriMesh) -> DrawMesh<'_> {
    mesh(m, Label::Occluder)
}

/// Test fixture: a sampled mannequin on a sampled bed seen from a nominal view, drawn from `seed` in that order. The
/// scene, the view's `camera_from_world` and the rng after those draws.
#[cfg(test)]
pub(crate) fn mannequin_scene(seed: u64) -> (Scene, Isometry3<f32>, ChaCha8Rng) {
    use rand_chacha::rand_core::SeedableRng;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let patient = body::Mannequin::build(&body::Mannequin::sample_params(&mut rng));
    let bed = BedParams::sample(&mut rng, 0.0, 0.0);
    let scene = Scene::new(&patient.body, bed);
    let view = ViewParams::sample_nominal(&mut rng, scene.torso_centre());
    let cfw = view.camera_from_world(scene.midline_y(), bed.mattress_top);
    (scene, cfw, rng)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_chacha::rand_core::SeedableRng;

    #[test]
    fn look_at_points_the_optical_axis_at_the_target_with_image_right_along_x() {
        let eye = Vector3::new(0.2, -0.5, 2.0);
        let target = Vector3::new(0.0, 0.8, 0.7);
        let cfw = look_at(eye, target, 0.0);
        let t = cfw * Point3::from(target);
        assert!(t.x.abs() < 1e-5 && t.y.abs() < 1e-5 && t.z > 0.0);
        // World +x (head end) maps to image right; world up maps to image up (−y).
        let xdir = cfw.rotation * Vector3::x();
        assert!(xdir.x > 0.9);
        let up = cfw.rotation * Vector3::z();
        assert!(up.y < 0.0);
    }

    #[test]
    fn planes_transform_consistently() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let bed = BedParams::sample(&mut rng, 0.4, 0.1);
        let wfb = bed.world_from_bed();
        let (_, head) = bed.planes();
        let hw = head.transformed(&wfb);
        // A point on the raised head-section top: bed frame (0, hinge + 0.5 cos a, 0.5 sin a).
        let p_bed = Vector3::new(
            0.1,
            bed.hinge_y + 0.5 * bed.head_raise.cos(),
            0.5 * bed.head_raise.sin(),
        );
        let p_w = wfb * Point3::from(p_bed);
        let r = Vector3::from(hw.normal).dot(&p_w.coords) + hw.d;
        assert!(r.abs() < 1e-5, "residual {r}");
        let flat_w = bed.planes().0.transformed(&wfb);
        assert!((flat_w.d + bed.mattress_top).abs() < 1e-5);
    }
}
