//! Writer of `SHAP` model files (layout: [`supine_core::shape`]): canonical camera, mean image, quantised
//! eigen-images with their priors, and the quantised forest. Leaves and eigen-images are i16 with one scale per
//! output/component (max |value| / 32767), so the rounding error is at most half a step.

use anyhow::{Result, ensure};
use nalgebra::DMatrix;
use supine_core::model_file::{ElemType, SectionData, encoded_len, write};
use supine_core::shape::canonical::CanonicalCamera;
use supine_core::shape::forest::LEAF_FEATURE;
use supine_core::shape::linear::{LINEAR_LEN, LINEAR_POINTS_LEN};
use supine_core::shape::subspace::SUBSPACE_DIM;
use supine_core::shape::{FORMAT_VERSION, KIND};

use super::forest::{DIM, Forest, Node};

fn le<T: Copy, const N: usize>(xs: &[T], f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
    xs.iter().flat_map(|&x| f(x)).collect()
}

fn scales(values: impl Iterator<Item = (usize, f32)>, k: usize) -> Vec<f32> {
    let mut s = vec![0.0f32; k];
    for (i, v) in values {
        s[i] = s[i].max(v.abs() / 32767.0);
    }
    s.iter().map(|&x| if x > 0.0 { x } else { 1.0 }).collect()
}

fn q(x: f32, s: f32) -> i16 {
    (x / s).round().clamp(-32767.0, 32767.0) as i16
}

/// Encode a shape model: `eigen` is P × 20 (columns = eigen-images), `prior` the Eq. 1 prior weight per
/// coefficient, `info` JSON provenance.
pub fn write_shape_model(
    cam: &CanonicalCamera,
    mean: &[f32],
    eigen: &DMatrix<f32>,
    prior: &[f32; SUBSPACE_DIM],
    forest: &Forest,
    info: &str,
) -> Result<Vec<u8>> {
    write_shape_model_with_linear(cam, mean, eigen, prior, forest, &[], info)
}

/// [`write_shape_model`] with linear shape regressions (layout [`supine_core::shape::linear::ShapeLinear`],
/// unquantised), which the estimate then uses: `LINR` for 21 · 20 values (the coefficients), `LINP` for 25 · 20
/// (the coefficients and the salient points' distances); at most one of each.
pub fn write_shape_model_with_linear(
    cam: &CanonicalCamera,
    mean: &[f32],
    eigen: &DMatrix<f32>,
    prior: &[f32; SUBSPACE_DIM],
    forest: &Forest,
    linear: &[&[f32]],
    info: &str,
) -> Result<Vec<u8>> {
    for len in [LINEAR_LEN, LINEAR_POINTS_LEN] {
        ensure!(
            linear.iter().filter(|l| l.len() == len).count() <= 1,
            "at most one linear regression of {len} values"
        );
    }
    ensure!(
        linear
            .iter()
            .all(|l| l.len() == LINEAR_LEN || l.len() == LINEAR_POINTS_LEN),
        "linear regression must hold {LINEAR_LEN} or {LINEAR_POINTS_LEN} values"
    );
    let p = cam.pixels();
    ensure!(
        mean.len() == p && eigen.nrows() == p && eigen.ncols() == SUBSPACE_DIM,
        "subspace size mismatch"
    );
    let escl = scales(
        (0..p)
            .flat_map(|i| (0..SUBSPACE_DIM).map(move |k| (i, k)))
            .map(|(i, k)| (k, eigen[(i, k)])),
        SUBSPACE_DIM,
    );
    let mut eigs = Vec::with_capacity(p * SUBSPACE_DIM);
    for i in 0..p {
        for k in 0..SUBSPACE_DIM {
            eigs.push(q(eigen[(i, k)], escl[k]));
        }
    }
    let mut roots = Vec::new();
    let (mut feat, mut thr, mut child, mut leaves) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::<[f32; DIM]>::new());
    for t in &forest.trees {
        let base = feat.len() as u32;
        roots.push(base);
        for n in t {
            match n {
                Node::Split {
                    feature,
                    threshold,
                    left,
                } => {
                    feat.push(*feature);
                    thr.push(*threshold);
                    child.push(base + *left as u32);
                }
                Node::Leaf(v) => {
                    feat.push(LEAF_FEATURE);
                    thr.push(0.0);
                    child.push(leaves.len() as u32);
                    leaves.push(*v);
                }
            }
        }
    }
    let lscl = scales(leaves.iter().flat_map(|l| l.iter().copied().enumerate()), DIM);
    let leaf_q: Vec<i16> = leaves
        .iter()
        .flat_map(|l| (0..DIM).map(|k| q(l[k], lscl[k])).collect::<Vec<_>>())
        .collect();
    let head = [
        cam.width as u32,
        cam.height as u32,
        cam.stride as u32,
        forest.trees.len() as u32,
    ];
    let camr = [
        cam.focal_px,
        cam.cx,
        cam.cy,
        cam.distance_m,
        cam.half_width_m,
        cam.below_hip_m,
        cam.above_hip_m,
        cam.max_height_m,
        cam.below_mattress_m,
    ];
    let mut bufs: Vec<(&[u8; 4], ElemType, Vec<u8>)> = vec![
        (b"HEAD", ElemType::U32, le(&head, u32::to_le_bytes)),
        (b"CAMR", ElemType::F32, le(&camr, f32::to_le_bytes)),
        (b"MEAN", ElemType::F32, le(mean, f32::to_le_bytes)),
        (b"EIGS", ElemType::I16, le(&eigs, i16::to_le_bytes)),
        (b"ESCL", ElemType::F32, le(&escl, f32::to_le_bytes)),
        (b"EPRI", ElemType::F32, le(prior, f32::to_le_bytes)),
        (b"TREE", ElemType::U32, le(&roots, u32::to_le_bytes)),
        (b"NFEA", ElemType::U16, le(&feat, u16::to_le_bytes)),
        (b"NTHR", ElemType::F32, le(&thr, f32::to_le_bytes)),
        (b"NCHL", ElemType::U32, le(&child, u32::to_le_bytes)),
        (b"LEAF", ElemType::I16, le(&leaf_q, i16::to_le_bytes)),
        (b"LSCL", ElemType::F32, le(&lscl, f32::to_le_bytes)),
        (
            b"CREF",
            ElemType::U32,
            le(&[cam.height_reference.code()], u32::to_le_bytes),
        ),
        (b"INFO", ElemType::U8, info.as_bytes().to_vec()),
    ];
    for l in linear {
        let tag = if l.len() == LINEAR_POINTS_LEN {
            b"LINP"
        } else {
            b"LINR"
        };
        bufs.push((tag, ElemType::F32, le(l, f32::to_le_bytes)));
    }
    let sections: Vec<SectionData<'_>> = bufs
        .iter()
        .map(|(t, e, b)| SectionData {
            tag: **t,
            elem: *e,
            bytes: b,
        })
        .collect();
    let mut out = vec![0u8; encoded_len(&sections)];
    let n = write(KIND, FORMAT_VERSION, &sections, &mut out).map_err(|e| anyhow::anyhow!("{e}"))?;
    out.truncate(n);
    Ok(out)
}
