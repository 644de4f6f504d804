//! The linear shape regression (optional section `LINP`, or `LINR` in older files, of the shape model file): the
//! 20 body shape coefficients (σ units) as an affine function of the regression inputs, `s = Wᵀ x + b`, a ridge
//! regression learnt on the training bodies. The inputs ([`inputs`]) are the 20 subspace coefficients and, for
//! `LINP`, [`POINT_FEATURES`] distances between the salient points (shoulder width, hip width, torso length,
//! head to shoulders): the canonical view is built in a hip-centred frame and carries little of the body's size,
//! which the points' spacing does (on validation bodies with 30 mm noise on the points: 11.4 -> 9.8 mm; see
//! `docs/shape-eval.md`). On the validation bodies the linear map beats the forest on the coefficients: the map
//! from image coefficients to shape is close to linear and the trees' piecewise-constant leaves add variance.
//! Used by [`super::ShapeModelView::estimate`] in place of the forest when the file has it.
//! Cost: 500 multiply-adds; nothing allocates.

use crate::body_model::SHAPE_COMPONENTS;
use crate::geometry::Point3;
use crate::model_file::LeSlice;
use crate::salient::SalientPoint;

use super::subspace::SUBSPACE_DIM;

/// Bound of each predicted coefficient (σ units): an affine map extrapolates without limit on coefficients far
/// outside the training views (an arm or wrong salient points), while bodies lie within ±3σ (the bound beyond
/// which the issue rejects plain fits).
pub const LINEAR_BOUND: f32 = 3.0;

/// Distances between salient points among the regression inputs.
pub const POINT_FEATURES: usize = 4;

/// Regression inputs: the subspace coefficients, then the point features.
pub const LINEAR_INPUTS: usize = SUBSPACE_DIM + POINT_FEATURES;

/// Values of a `LINR` section (the coefficients only): `SUBSPACE_DIM` weight rows of `SHAPE_COMPONENTS` outputs,
/// then the bias row.
pub const LINEAR_LEN: usize = (SUBSPACE_DIM + 1) * SHAPE_COMPONENTS;

/// Values of a `LINP` section (coefficients and point features): `LINEAR_INPUTS` weight rows, then the bias row.
pub const LINEAR_POINTS_LEN: usize = (LINEAR_INPUTS + 1) * SHAPE_COMPONENTS;

/// The point features, metres: shoulder width, hip width, torso length (hip centre to shoulder centre) and head
/// to shoulder centre.
pub fn point_features(points: &[Point3; SalientPoint::COUNT]) -> [f32; POINT_FEATURES] {
    let p = |s: SalientPoint| points[s.index()];
    let shoulders = nalgebra::center(&p(SalientPoint::LeftShoulder), &p(SalientPoint::RightShoulder));
    let hips = nalgebra::center(&p(SalientPoint::LeftHip), &p(SalientPoint::RightHip));
    [
        (p(SalientPoint::LeftShoulder) - p(SalientPoint::RightShoulder)).norm(),
        (p(SalientPoint::LeftHip) - p(SalientPoint::RightHip)).norm(),
        (shoulders - hips).norm(),
        (p(SalientPoint::Head) - shoulders).norm(),
    ]
}

/// The regression inputs for subspace coefficients `c` of a view made with salient points `points`.
pub fn inputs(c: &[f32; SUBSPACE_DIM], points: &[Point3; SalientPoint::COUNT]) -> [f32; LINEAR_INPUTS] {
    let f = point_features(points);
    core::array::from_fn(|k| {
        if k < SUBSPACE_DIM {
            c[k]
        } else {
            f[k - SUBSPACE_DIM]
        }
    })
}

/// The affine map, borrowed from a validated shape model file: element (input `k`, output `j`) at `20 k + j`,
/// the bias of output `j` at `20 · inputs + j`.
#[derive(Debug, Clone, Copy)]
pub struct ShapeLinear<'a> {
    pub(crate) w: LeSlice<'a, f32>,
    /// Inputs read: `SUBSPACE_DIM` (`LINR`) or `LINEAR_INPUTS` (`LINP`).
    pub(crate) inputs: usize,
}

impl ShapeLinear<'_> {
    /// Whether the map reads the point features (a `LINP` section).
    pub fn uses_points(&self) -> bool {
        self.inputs > SUBSPACE_DIM
    }

    /// The shape coefficients (σ units) for regression inputs `x` ([`inputs`]; a `LINR` map reads only the
    /// coefficients), each clamped to ±[`LINEAR_BOUND`].
    pub fn predict(&self, x: &[f32; LINEAR_INPUTS]) -> [f32; SHAPE_COMPONENTS] {
        let mut out = [0.0f32; SHAPE_COMPONENTS];
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.w.at(self.inputs * SHAPE_COMPONENTS + j);
        }
        for (k, &xk) in x.iter().take(self.inputs).enumerate() {
            let base = k * SHAPE_COMPONENTS;
            for (j, o) in out.iter_mut().enumerate() {
                *o += self.w.at(base + j) * xk;
            }
        }
        for o in out.iter_mut() {
            *o = o.clamp(-LINEAR_BOUND, LINEAR_BOUND);
        }
        out
    }
}
