//! The joint forest (paper Sect. 3.3): a Girshick et al. 2011 regression forest whose leaves are refined globally
//! (Eq. 2-4), evaluated per frame to give the six salient points with a confidence each.
//!
//! - [`feature`]: depth-difference features with depth-normalised offsets (Shotton et al.), in integer millimetres
//!   so that training and inference take exactly the same branches.
//! - [`model`]: the [`model::ForestModel`] trait inference runs on, and [`model::ForestView`], the validated
//!   borrowed view of a quantised `JFOR` model file.
//! - [`sample`]: seeded pixel sampling from a clipped frame (a set of planes and a pixel region).
//! - [`meanshift`]: weighted mean-shift over 3D votes, with an optional Gaussian prior per point.
//! - [`infer`]: one frame's estimate (sampling, trees, votes with Eq. 5 and Eq. 6, mean-shift) in a caller-owned
//!   [`infer::Workspace`].
//!
//! Cost per frame (512 samples, 3 trees of depth 24): about 40 k node tests and 6 mean-shifts over at most 512
//! votes each; no allocation. The trainer, the quantiser and the evaluation live in `supine-models`
//! (`models/src/forest`).
// Axes of 3-vectors and the per-point arrays are indexed in step with each other; index loops read best here.
#![allow(clippy::needless_range_loop)]

pub mod feature;
pub mod infer;
pub mod meanshift;
pub mod model;
pub mod sample;

/// Most trees a forest may have (inference buffers are sized for it).
pub const MAX_TREES: usize = 4;
/// Most samples one frame's inference draws.
pub const MAX_SAMPLES: usize = 1024;
/// Vote modes per leaf and point in the baseline (Girshick) leaves.
pub const MODES: usize = 2;
/// Most votes per point: every sample, tree and mode of the baseline.
pub const MAX_VOTES: usize = MAX_SAMPLES * MAX_TREES * MODES;
