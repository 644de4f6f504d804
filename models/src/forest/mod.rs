//! The joint forest's host side (paper Sect. 3.3): training ([`train`]: tree growing for body-part
//! classification, Girshick baseline leaves, the global refinement of Eq. 2-4, validation choices), the float
//! forest and its quantisation to a `JFOR` model file ([`float`]), the evaluation on held-out bodies ([`eval`]) and
//! the `train joints` / `eval joints` commands ([`cli`]). Inference itself is `supine_core::forest`.
// Axes of 3-vectors and the per-point arrays are indexed in step with each other; index loops read best here.
#![allow(clippy::needless_range_loop)]

pub mod chart;
pub mod cli;
pub mod data;
pub mod encode;
pub mod eval;
pub mod float;
pub mod leaves;
pub mod refine;
pub mod sidecar;
pub mod train;
pub mod tree;
