//! The shape-basis figure (paper Fig. 2): the mean body and ±3σ along each of the first components, front and side
//! views, normal-shaded, rendered with the crate's z-buffer renderer ([`crate::render`]) into a greyscale PNG.
//!
//! Layout: one column pair (front, side) per component; rows −3σ, mean, +3σ. Cameras are 6 m away with a long
//! focal length, so the views are nearly orthographic and bodies of different sizes compare directly.

use std::path::Path;

use anyhow::{Context, Result};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use supine_core::camera::Intrinsics;

use super::{BodyModel, COMPONENTS, Shape};
use crate::render::{DrawMesh, Label, NO_TRIANGLE, Renderer};

const PANEL_W: usize = 170;
const PANEL_H: usize = 300;
const DISTANCE_M: f32 = 6.0;
const FOCAL_PX: f32 = 780.0;

/// Camera looking at the body from the front (`side = false`, from -y) or from its left (`side = true`, from +x).
fn camera_from_body(side: bool, centre_z: f32) -> Isometry3<f32> {
    // Camera frame: x right, y down, z forward.
    let m = if side {
        // Looking along -x (from the body's left): image right = body +y (the back), down = -z.
        Matrix3::new(0.0, 1.0, 0.0, 0.0, 0.0, -1.0, -1.0, 0.0, 0.0)
    } else {
        // Looking along +y: image right = body +x (the body's left, as when facing a person), down = -z.
        Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0)
    };
    let r = Rotation3::from_matrix_unchecked(m);
    let t = r * Vector3::new(0.0, 0.0, -centre_z) + Vector3::new(0.0, 0.0, DISTANCE_M);
    Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_rotation_matrix(&r))
}

/// Render one panel: Lambert shading from a light near the camera, white background.
fn panel(
    renderer: &mut Renderer,
    vertices: &[[f32; 3]],
    model: &BodyModel,
    side: bool,
    centre_z: f32,
) -> Vec<u8> {
    renderer.clear();
    let mesh = DrawMesh {
        vertices,
        triangles: &model.triangles,
        label: Label::Body,
        triangle_part: None,
        cull_back_faces: true,
    };
    renderer.draw(&mesh, &camera_from_body(side, centre_z));
    let b = renderer.buffers();
    let light = Vector3::new(-0.3f32, -0.5, -1.0).normalize();
    (0..PANEL_W * PANEL_H)
        .map(|i| {
            let t = b.triangle[i];
            if t == NO_TRIANGLE {
                return 255;
            }
            let n = b.normals[t as usize];
            let lambert = (n[0] * light.x + n[1] * light.y + n[2] * light.z).abs();
            (30.0 + 200.0 * lambert).clamp(0.0, 255.0) as u8
        })
        .collect()
}

/// Draw the figure for the first `components` components into `path`.
pub fn shape_basis_figure(model: &BodyModel, components: usize, path: &Path) -> Result<()> {
    let components = components.min(COMPONENTS);
    let intr = Intrinsics {
        fx: FOCAL_PX,
        fy: FOCAL_PX,
        cx: PANEL_W as f32 * 0.5,
        cy: PANEL_H as f32 * 0.5,
        width: PANEL_W as u16,
        height: PANEL_H as u16,
    };
    let mut renderer = Renderer::new(intr);
    let width = 2 * PANEL_W * components;
    let height = 3 * PANEL_H;
    let mut img = vec![255u8; width * height];
    // Centre every panel on the mean body's mid-height so size differences stay visible.
    let rest = model.rest_vertices(&Shape::MEAN);
    let (lo, hi) = rest
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), v| (lo.min(v[2]), hi.max(v[2])));
    let centre_z = 0.5 * (lo + hi);
    for k in 0..components {
        for (row, z) in [-3.0f32, 0.0, 3.0].into_iter().enumerate() {
            let mut s = Shape::MEAN;
            s.coeffs[k] = z * model.sigma[k];
            let v = model.rest_vertices(&s);
            for (col, side) in [false, true].into_iter().enumerate() {
                let p = panel(&mut renderer, &v, model, side, centre_z);
                let x0 = (2 * k + col) * PANEL_W;
                let y0 = row * PANEL_H;
                for y in 0..PANEL_H {
                    img[(y0 + y) * width + x0..(y0 + y) * width + x0 + PANEL_W]
                        .copy_from_slice(&p[y * PANEL_W..(y + 1) * PANEL_W]);
                }
            }
        }
    }
    // Thin separators between components.
    for k in 1..components {
        for y in 0..height {
            img[y * width + 2 * k * PANEL_W] = 160;
        }
    }
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).with_context(|| format!("cannot create {}", parent.display()))?;
    }
    let file = std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width as u32, height as u32);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().context("PNG header")?;
    w.write_image_data(&img).context("PNG data")?;
    Ok(())
}
