//! The patient's shaped torso surface in the `torso` frame, built once at the end of the init phase into caller
//! buffers and then read every frame by ICP and probe mapping: the body model's torso subset shaped with the
//! estimated coefficients, area-weighted vertex normals over the subset's triangles, and a wire body region per
//! vertex.
//!
//! The `torso` frame (named in [`crate::camera`]): origin at the hip centre, y toward the shoulder centre, x the
//! patient's left, z out of the chest; [`a_from_torso`] builds it from the six salient points in any frame `a`.
//!
//! Cost: building is `3·n·K` multiply-adds for the shape plus one pass over the triangles (about 0.1 ms for the
//! default model's 1250-vertex subset); nothing per frame, nothing allocated.

use crate::body_model::{BodyModelView, BodyPart};
use crate::error::BufferLenError;
use crate::geometry::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use crate::model_file::LeSlice;
use crate::salient::SalientPoint;
use crate::wire::BodyRegion;

/// `a_from_torso` from the six salient points given in frame `a`; `None` when hips and shoulders coincide or the
/// left-right direction is parallel to the body axis.
pub fn a_from_torso(salient: &[Point3; SalientPoint::COUNT]) -> Option<Isometry3> {
    let p = |s: SalientPoint| salient[s.index()].coords;
    let hip = (p(SalientPoint::LeftHip) + p(SalientPoint::RightHip)) * 0.5;
    let shoulder = (p(SalientPoint::LeftShoulder) + p(SalientPoint::RightShoulder)) * 0.5;
    let y = (shoulder - hip).try_normalize(1e-6)?;
    let left = (p(SalientPoint::LeftShoulder) - p(SalientPoint::RightShoulder))
        + (p(SalientPoint::LeftHip) - p(SalientPoint::RightHip));
    let x = (left - y * left.dot(&y)).try_normalize(1e-6)?;
    let z = x.cross(&y);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Some(Isometry3::from_parts(
        Translation3::from(hip),
        UnitQuaternion::from_rotation_matrix(&rot),
    ))
}

/// Area-weighted outward vertex normals of `vertices` over `triangles` (index triples, counter-clockwise seen from
/// outside); a vertex of no triangle gets `lone`. Triangles naming a vertex past the slices are skipped. One routine
/// for the torso model ([`Point3`] / [`Vector3`]) and the fit's shaped subset (`[f32; 3]`).
pub fn vertex_normals<P, N>(triangles: LeSlice<'_, u16>, vertices: &[P], normals: &mut [N], lone: Vector3)
where
    P: Copy + Into<Point3>,
    N: Copy + From<Vector3> + Into<Vector3>,
{
    let n = vertices.len().min(normals.len());
    normals.fill(N::from(Vector3::zeros()));
    for t in 0..triangles.len() / 3 {
        let [a, b, c] = [0, 1, 2].map(|i| triangles.at(3 * t + i) as usize);
        if a >= n || b >= n || c >= n {
            continue;
        }
        let [pa, pb, pc] = [a, b, c].map(|i| vertices[i].into());
        // Counter-clockwise seen from outside: the cross product points out, with twice the area as length.
        let face = (pb - pa).cross(&(pc - pa));
        for i in [a, b, c] {
            normals[i] = N::from(normals[i].into() + face);
        }
    }
    for nrm in normals.iter_mut() {
        *nrm = N::from((*nrm).into().try_normalize(1e-12).unwrap_or(lone));
    }
}

/// Caller buffers for a [`TorsoSurface`], one entry per torso-subset vertex.
#[derive(Debug)]
pub struct TorsoBuffers<'a> {
    /// Vertex positions, `torso` frame.
    pub vertices: &'a mut [Point3],
    /// Unit outward vertex normals, `torso` frame.
    pub normals: &'a mut [Vector3],
    /// Body region of each vertex.
    pub regions: &'a mut [BodyRegion],
}

/// The shaped torso surface: vertices, normals and regions in the `torso` frame, triangles from the model.
#[derive(Debug, Clone, Copy)]
pub struct TorsoSurface<'a> {
    vertices: &'a [Point3],
    normals: &'a [Vector3],
    regions: &'a [BodyRegion],
    triangles: LeSlice<'a, u16>,
    body_from_torso: Isometry3,
}

impl<'a> TorsoSurface<'a> {
    /// Shape the body model's torso subset with coefficients `s` into `buf` (each slice exactly as long as the
    /// subset), in the `torso` frame of that shaped body at rest.
    pub fn build(view: &BodyModelView<'a>, s: &[f32], buf: TorsoBuffers<'a>) -> Result<Self, BufferLenError> {
        let n = view.counts().subset;
        for len in [buf.vertices.len(), buf.normals.len(), buf.regions.len()] {
            if len != n {
                return Err(BufferLenError {
                    expected: n,
                    found: len,
                });
            }
        }
        let salient = view.salient_points(s).map(Point3::from);
        // A model whose salient points are degenerate still gets a surface, in the body frame.
        let body_from_torso = a_from_torso(&salient).unwrap_or_else(Isometry3::identity);
        let torso_from_body = body_from_torso.inverse();
        let subset = view.torso_subset();
        for (out, v) in buf.vertices.iter_mut().zip(subset.iter()) {
            *out = torso_from_body * Point3::from(view.shape_vertex(v as usize, s));
        }
        let triangles = view.torso_subset_triangles();
        vertex_normals(triangles, buf.vertices, buf.normals, Vector3::z());
        // Torso half-width: the widest chest or abdomen vertex from the midline.
        let half_width = subset
            .iter()
            .zip(buf.vertices.iter())
            .filter(|(v, _)| {
                matches!(
                    view.part_of_vertex(*v as usize),
                    BodyPart::Chest | BodyPart::Abdomen
                )
            })
            .map(|(_, p)| libm::fabsf(p.x))
            .fold(0.0f32, f32::max)
            .max(1e-3);
        for ((r, v), p) in buf.regions.iter_mut().zip(subset.iter()).zip(buf.vertices.iter()) {
            *r = view.part_of_vertex(v as usize).region_at(p.x / half_width);
        }
        Ok(TorsoSurface {
            vertices: buf.vertices,
            normals: buf.normals,
            regions: buf.regions,
            triangles,
            body_from_torso,
        })
    }

    /// The surface over buffers a [`TorsoSurface::build`] filled earlier (a tracker keeps the buffers and takes
    /// this view per frame); `None` when the slices' lengths differ.
    pub fn from_parts(
        view: &BodyModelView<'a>,
        vertices: &'a [Point3],
        normals: &'a [Vector3],
        regions: &'a [BodyRegion],
        body_from_torso: Isometry3,
    ) -> Option<Self> {
        (vertices.len() == view.counts().subset
            && normals.len() == vertices.len()
            && regions.len() == vertices.len())
        .then(|| TorsoSurface {
            vertices,
            normals,
            regions,
            triangles: view.torso_subset_triangles(),
            body_from_torso,
        })
    }

    /// Vertex positions, `torso` frame.
    pub fn vertices(&self) -> &'a [Point3] {
        self.vertices
    }

    /// Unit outward vertex normals, `torso` frame.
    pub fn normals(&self) -> &'a [Vector3] {
        self.normals
    }

    /// Body region of each vertex.
    pub fn regions(&self) -> &'a [BodyRegion] {
        self.regions
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len() / 3
    }

    /// Vertex indices of triangle `t` (counter-clockwise seen from outside).
    pub fn triangle(&self, t: usize) -> [usize; 3] {
        [0, 1, 2].map(|i| self.triangles.at(3 * t + i) as usize)
    }

    /// Where the torso frame sits in the body model's frame (for drawing the model, and for ground truth).
    pub fn body_from_torso(&self) -> Isometry3 {
        self.body_from_torso
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torso_frame_from_salient_points() {
        // A patient supine on a bed (world z up), head toward +y: the patient's left is +x.
        let p = |x: f32, y: f32, z: f32| Point3::new(x, y, z);
        let salient = [
            p(0.0, 0.75, 0.2),
            p(0.2, 0.5, 0.15),
            p(-0.2, 0.5, 0.15),
            p(0.0, 0.2, 0.25),
            p(0.1, 0.0, 0.1),
            p(-0.1, 0.0, 0.1),
        ];
        let w_from_t = a_from_torso(&salient).unwrap();
        let origin = w_from_t * Point3::origin();
        assert!((origin - p(0.0, 0.0, 0.1)).norm() < 1e-6);
        let y = w_from_t * Vector3::y();
        assert!((y - Vector3::new(0.0, 1.0, 0.1).normalize()).norm() < 1e-5);
        assert!((w_from_t * Vector3::x() - Vector3::x()).norm() < 1e-5);
        // z out of the chest: up, for a supine patient.
        assert!((w_from_t * Vector3::z()).z > 0.99);
        assert!(a_from_torso(&[p(0.0, 0.0, 0.0); 6]).is_none());
    }
}
