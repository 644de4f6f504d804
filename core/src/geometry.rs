//! The geometry vocabulary of supine: nalgebra's f32 types under the names every module uses, and [`Plane`].
//!
//! Points and vectors are in metres inside algorithms (millimetre integers only on the wire and in depth images).
//! Every point lives in a named frame (`camera`, `robot_base`, `torso`, `body`, `bed`; see [`crate::camera`]) and
//! every rigid transform is an [`Isometry3`] named `a_from_b`: it maps coordinates in frame `b` to frame `a`, so
//! `a_from_c = a_from_b * b_from_c` reads left to right. These are plain aliases, so nalgebra's whole API applies;
//! all of them are `Copy` and live on the stack. Bulk point buffers (mesh vertices, body-model rows) stay `[f32; 3]`
//! arrays, the flat layout of the model files and the renderer (the same memory as a [`Point3`]; convert with
//! `Point3::from`). A plane test costs four multiply-adds per point.

use serde::{Deserialize, Serialize};

/// A 2D point, e.g. pixel coordinates (u right, v down).
pub type Point2 = nalgebra::Point2<f32>;
/// A 3D point, metres, in a frame named by the variable (`tip_in_torso`, `p_camera`).
pub type Point3 = nalgebra::Point3<f32>;
/// A 3D vector (direction, offset or normal), metres where it has a length.
pub type Vector3 = nalgebra::Vector3<f32>;
/// A 3x3 matrix (rotations, covariances, normal equations of small solves).
pub type Matrix3 = nalgebra::Matrix3<f32>;
/// A rigid transform, named `a_from_b` (maps frame `b` coordinates to frame `a`).
pub type Isometry3 = nalgebra::Isometry3<f32>;
/// A unit quaternion (rotation part of an [`Isometry3`]).
pub type UnitQuaternion = nalgebra::UnitQuaternion<f32>;
/// A rotation matrix.
pub type Rotation3 = nalgebra::Rotation3<f32>;
/// A translation.
pub type Translation3 = nalgebra::Translation3<f32>;

/// A plane `n·p + d = 0` with unit normal `n`, pointing to the side that counts as above (up from the floor and the
/// mattress, toward the camera).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Plane {
    /// Unit normal.
    pub normal: [f32; 3],
    /// Offset: `n·p + d = 0` on the plane.
    pub d: f32,
}

impl Plane {
    /// The plane through `point` with unit `normal`.
    pub fn through(point: Vector3, normal: Vector3) -> Plane {
        Plane {
            normal: normal.into(),
            d: -normal.dot(&point),
        }
    }

    /// The unit normal as a vector.
    pub fn normal(&self) -> Vector3 {
        Vector3::from(self.normal)
    }

    /// Signed distance of `p` from the plane, positive on the side the normal points to.
    pub fn signed_distance(&self, p: &Point3) -> f32 {
        self.normal().dot(&p.coords) + self.d
    }

    /// This plane expressed in frame `a`, given `a_from_b` and the plane in frame `b`.
    pub fn transformed(&self, a_from_b: &Isometry3) -> Plane {
        let n = a_from_b.rotation * self.normal();
        Plane {
            normal: n.into(),
            d: self.d - n.dot(&a_from_b.translation.vector),
        }
    }
}

/// A rigid transform from a 4x4 row-major matrix (the JSON form of truth and config files); the rotation block is
/// taken as given (orthonormalised through the quaternion).
pub fn isometry_from_rows(m: &[[f32; 4]; 4]) -> Isometry3 {
    let r = Matrix3::new(
        m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
    );
    Isometry3::from_parts(
        Translation3::new(m[0][3], m[1][3], m[2][3]),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_distance_and_transform_agree() {
        let plane = Plane::through(Vector3::new(0.0, 0.0, 0.5), Vector3::z());
        let p = Point3::new(0.3, -0.2, 0.75);
        assert!((plane.signed_distance(&p) - 0.25).abs() < 1e-6);
        let a_from_b = Isometry3::new(Vector3::new(0.1, 2.0, -0.4), Vector3::new(0.3, -0.2, 0.9));
        let moved = plane.transformed(&a_from_b);
        let d = moved.signed_distance(&(a_from_b * p));
        assert!((d - 0.25).abs() < 1e-5, "distance {d} after the transform");
        assert!((moved.normal().norm() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn transforms_compose_left_to_right() {
        let a_from_b = Isometry3::translation(1.0, 0.0, 0.0);
        let b_from_c = Isometry3::rotation(Vector3::new(0.0, 0.0, core::f32::consts::FRAC_PI_2));
        let p_c = Point3::new(1.0, 0.0, 0.0);
        let p_a = (a_from_b * b_from_c) * p_c;
        assert!((p_a - Point3::new(1.0, 1.0, 0.0)).norm() < 1e-6);
    }
}
