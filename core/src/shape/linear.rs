//! The linear shape regression (optional section `LINR` of the shape model file): the 20 body shape coefficients
//! (σ units) as an affine function of the 20 subspace coefficients, `s = Wᵀ c + b`, a ridge regression learnt on
//! the training bodies. On the validation bodies it beats the forest on these inputs (see `docs/shape-eval.md`):
//! the map from image coefficients to shape is close to linear and the trees' piecewise-constant leaves add
//! variance. Used by [`super::ShapeModelView::estimate`] in place of the forest when the file has it.
//! Cost: 400 multiply-adds; nothing allocates.

use crate::body_model::SHAPE_COMPONENTS;
use crate::model_file::LeSlice;

use super::subspace::SUBSPACE_DIM;

/// Bound of each predicted coefficient (σ units): an affine map extrapolates without limit on coefficients far
/// outside the training views (an arm or wrong salient points), while bodies lie within ±3σ (the bound beyond
/// which the issue rejects plain fits).
pub const LINEAR_BOUND: f32 = 3.0;

/// Values of a `LINR` section: `SUBSPACE_DIM` weight rows of `SHAPE_COMPONENTS` outputs, then the bias row.
pub const LINEAR_LEN: usize = (SUBSPACE_DIM + 1) * SHAPE_COMPONENTS;

/// The affine map, borrowed from a validated shape model file: element (input `k`, output `j`) at `20 k + j`,
/// the bias of output `j` at `20 · 20 + j`.
#[derive(Debug, Clone, Copy)]
pub struct ShapeLinear<'a> {
    pub(crate) w: LeSlice<'a, f32>,
}

impl ShapeLinear<'_> {
    /// The shape coefficients (σ units) for subspace coefficients `c`, each clamped to ±[`LINEAR_BOUND`].
    pub fn predict(&self, c: &[f32; SUBSPACE_DIM]) -> [f32; SHAPE_COMPONENTS] {
        let mut out = [0.0f32; SHAPE_COMPONENTS];
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.w.at(SUBSPACE_DIM * SHAPE_COMPONENTS + j);
        }
        for (k, &ck) in c.iter().enumerate() {
            let base = k * SHAPE_COMPONENTS;
            for (j, o) in out.iter_mut().enumerate() {
                *o += self.w.at(base + j) * ck;
            }
        }
        for o in out.iter_mut() {
            *o = o.clamp(-LINEAR_BOUND, LINEAR_BOUND);
        }
        out
    }
}
