//! Inference of the shape regression forest (paper §3.2): from the 20 subspace coefficients `c` to the 20 body
//! shape coefficients (in units of each component's σ), the mean of the trees' leaf vectors.
//!
//! Nodes are stored flat (sections `TREE`, `NFEA`, `NTHR`, `NCHL`, `LEAF`, `LSCL` of the shape model file): an
//! internal node sends `c` left when `c[feature] < threshold` and its children are `left` and `left + 1`; a leaf
//! (feature [`LEAF_FEATURE`]) names a row of `LEAF` (i16, one dequantisation scale per output). Validation makes
//! every child index larger than its parent's, so a walk ends in at most `n_nodes` steps whatever the bytes.
//! Cost: 16 trees × depth (about 12) comparisons plus 16 × 20 multiply-adds, a few µs; nothing allocates.

use crate::body_model::SHAPE_COMPONENTS;
use crate::model_file::LeSlice;

use super::subspace::SUBSPACE_DIM;

/// `NFEA` value of a leaf.
pub const LEAF_FEATURE: u16 = 0xFFFF;

/// The forest, borrowed from a validated shape model file.
#[derive(Debug, Clone, Copy)]
pub struct ShapeForest<'a> {
    pub(crate) roots: LeSlice<'a, u32>,
    pub(crate) feature: LeSlice<'a, u16>,
    pub(crate) threshold: LeSlice<'a, f32>,
    pub(crate) child: LeSlice<'a, u32>,
    pub(crate) leaves: LeSlice<'a, i16>,
    pub(crate) leaf_scale: LeSlice<'a, f32>,
}

/// Why the forest sections are inconsistent (checked once by [`ShapeForest::validate`]).
pub(crate) fn validate(f: &ShapeForest<'_>) -> Result<(), &'static str> {
    let n = f.feature.len();
    if f.threshold.len() != n || f.child.len() != n {
        return Err("node sections differ in length");
    }
    if f.roots.is_empty() || f.roots.iter().any(|r| r as usize >= n) {
        return Err("no trees, or a root outside the nodes");
    }
    if f.leaf_scale.len() != SHAPE_COMPONENTS || !f.leaves.len().is_multiple_of(SHAPE_COMPONENTS) {
        return Err("leaf sections do not hold 20 outputs");
    }
    if !f.leaf_scale.iter().all(|s| s.is_finite() && s >= 0.0) {
        return Err("leaf scales must be finite and non-negative");
    }
    let n_leaves = f.leaves.len() / SHAPE_COMPONENTS;
    for i in 0..n {
        let feat = f.feature.at(i);
        let c = f.child.at(i) as usize;
        if feat == LEAF_FEATURE {
            if c >= n_leaves {
                return Err("leaf index out of range");
            }
        } else if feat as usize >= SUBSPACE_DIM || !f.threshold.at(i).is_finite() || c <= i || c + 1 >= n {
            return Err("internal node with a bad feature, threshold or child");
        }
    }
    Ok(())
}

impl ShapeForest<'_> {
    /// Number of trees.
    pub fn tree_count(&self) -> usize {
        self.roots.len()
    }

    /// Number of nodes over all trees.
    pub fn node_count(&self) -> usize {
        self.feature.len()
    }

    /// Leaf row reached by `c` in tree `t`.
    fn leaf_of(&self, t: usize, c: &[f32; SUBSPACE_DIM]) -> usize {
        let mut i = self.roots.at(t) as usize;
        // Children are larger than parents (validated), so this ends; the bound is belt and braces.
        for _ in 0..self.feature.len() {
            let f = self.feature.at(i);
            if f == LEAF_FEATURE {
                break;
            }
            let left = self.child.at(i) as usize;
            i = if c[f as usize] < self.threshold.at(i) {
                left
            } else {
                left + 1
            };
        }
        self.child.at(i) as usize
    }

    /// The shape coefficients (σ units) predicted for subspace coefficients `c`.
    pub fn predict(&self, c: &[f32; SUBSPACE_DIM]) -> [f32; SHAPE_COMPONENTS] {
        let mut acc = [0i32; SHAPE_COMPONENTS];
        for t in 0..self.tree_count() {
            let base = self.leaf_of(t, c) * SHAPE_COMPONENTS;
            for (k, a) in acc.iter_mut().enumerate() {
                *a += self.leaves.at(base + k) as i32;
            }
        }
        let n = self.tree_count() as f32;
        let mut out = [0.0f32; SHAPE_COMPONENTS];
        for (k, o) in out.iter_mut().enumerate() {
            *o = acc[k] as f32 * self.leaf_scale.at(k) / n;
        }
        out
    }
}
