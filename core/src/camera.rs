//! Pinhole intrinsics of the depth camera and the coordinate frames supine names.
//!
//! Frames (transforms are named `a_from_b`: they map coordinates in frame `b` to frame `a`):
//! - `camera`: the depth camera's optical frame, metres, x right, y down, z forward along the optical axis
//!   (OpenCV convention; OpenNI's "world" coordinates have y up and are converted at the driver boundary).
//! - `robot_base`: the robot's base frame, metres, z up; `robot_base_from_camera` comes from the head calibration.
//! - `torso`: the patient's torso frame estimated by the tracker (origin at the hip centre, see the tracker docs).
//! - `body`: the statistical body model's frame (metres, z up, the body facing -y, as in MakeHuman/Blender).
//!
//! Projection costs a handful of flops per point; nothing here allocates.

use crate::geometry::{Point2, Point3};

/// Pinhole intrinsics in pixels for an image of `width` x `height`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f32,
    /// Focal length along y, pixels.
    pub fy: f32,
    /// Principal point x, pixels (pixel centres are at integer coordinates).
    pub cx: f32,
    /// Principal point y, pixels.
    pub cy: f32,
    /// Image width, pixels.
    pub width: u16,
    /// Image height, pixels.
    pub height: u16,
}

/// Kinect v1 horizontal field of view as reported by OpenNI2's FreenectDriver (58.5 degrees).
pub const KINECT_V1_HFOV_RAD: f32 = 58.5 * core::f32::consts::PI / 180.0;
/// Kinect v1 vertical field of view as reported by OpenNI2's FreenectDriver (45.6 degrees).
pub const KINECT_V1_VFOV_RAD: f32 = 45.6 * core::f32::consts::PI / 180.0;

impl Intrinsics {
    /// The Kinect v1 depth camera at 640x480 as OpenNI2 models it: fx = 320 / tan(58.5°/2) = 571.4 px,
    /// principal point at the image centre (OpenNI's world conversion puts it exactly at W/2, H/2).
    pub const KINECT_V1: Intrinsics = Intrinsics {
        fx: 571.401,
        fy: 571.401,
        cx: 320.0,
        cy: 240.0,
        width: 640,
        height: 480,
    };

    /// Intrinsics from horizontal and vertical fields of view (radians), principal point at the image centre.
    pub fn from_fov(width: u16, height: u16, hfov_rad: f32, vfov_rad: f32) -> Self {
        let fx = width as f32 * 0.5 / libm::tanf(hfov_rad * 0.5);
        let fy = height as f32 * 0.5 / libm::tanf(vfov_rad * 0.5);
        Intrinsics {
            fx,
            fy,
            cx: width as f32 * 0.5,
            cy: height as f32 * 0.5,
            width,
            height,
        }
    }

    /// Horizontal field of view in radians.
    pub fn hfov_rad(&self) -> f32 {
        2.0 * libm::atanf(self.width as f32 * 0.5 / self.fx)
    }

    /// Vertical field of view in radians.
    pub fn vfov_rad(&self) -> f32 {
        2.0 * libm::atanf(self.height as f32 * 0.5 / self.fy)
    }

    /// Project a point in the `camera` frame (metres) to pixel coordinates; `None` behind or on the image plane.
    pub fn project(&self, p: &Point3) -> Option<Point2> {
        if p.z <= 0.0 {
            return None;
        }
        Some(Point2::new(
            self.fx * p.x / p.z + self.cx,
            self.fy * p.y / p.z + self.cy,
        ))
    }

    /// Back-project pixel (u, v) at depth `z` metres to a point in the `camera` frame.
    pub fn unproject(&self, u: f32, v: f32, z: f32) -> Point3 {
        Point3::new((u - self.cx) * z / self.fx, (v - self.cy) * z / self.fy, z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinect_constant_matches_openni_fov() {
        let k = Intrinsics::from_fov(640, 480, KINECT_V1_HFOV_RAD, KINECT_V1_VFOV_RAD);
        assert!((k.fx - Intrinsics::KINECT_V1.fx).abs() < 0.01, "fx {}", k.fx);
        assert!((k.fy - 570.9).abs() < 0.1, "fy {}", k.fy);
        assert!((Intrinsics::KINECT_V1.hfov_rad() - KINECT_V1_HFOV_RAD).abs() < 1e-5);
    }

    #[test]
    fn project_unproject_round_trip() {
        let k = Intrinsics::KINECT_V1;
        let p = Point3::new(0.31, -0.12, 1.7);
        let uv = k.project(&p).unwrap();
        let q = k.unproject(uv.x, uv.y, p.z);
        assert!((p - q).norm() < 1e-5);
        assert_eq!(k.project(&Point3::new(0.0, 0.0, -1.0)), None);
    }

    #[test]
    fn openni_world_conversion_agrees() {
        // OpenNI: X = (u/W - 0.5) * Z * 2 tan(hfov/2); pixel (0, 0) at 1000 mm gave X = -560.0 mm with 58.5°.
        let p = Intrinsics::KINECT_V1.unproject(0.0, 0.0, 1.0);
        assert!((p.x + 0.5600).abs() < 0.0005, "x {}", p.x);
    }
}
