//! Body shape from one depth frame (paper §3.2): canonical view → masked subspace projection (Eq. 1) → shape
//! regression forest, all from one validated, borrowed `SHAP` model file.
//!
//! Sections of kind `SHAP`, format version [`FORMAT_VERSION`] (element type, count), P = width · height:
//! ```text
//! HEAD u32  4        width, height, stride, n_trees
//! CAMR f32  9        focal_px, cx, cy, distance_m, half_width_m, below_hip_m, above_hip_m, max_height_m,
//!                    below_mattress_m                               (see canonical::CanonicalCamera)
//! MEAN f32  P        mean canonical image (metres above the hip centre)
//! EIGS i16  P·20     eigen-images, pixel-major: element (pixel i, component k) at 20 i + k
//! ESCL f32  20       dequantisation scale of each eigen-image
//! EPRI f32  20       prior weight σ_n² / var_k of each subspace coefficient (Eq. 1's regulariser)
//! TREE u32  n_trees  root node of each tree
//! NFEA u16  n_nodes  split feature (subspace coefficient index), 0xFFFF for a leaf
//! NTHR f32  n_nodes  split threshold (left when c[f] < threshold)
//! NCHL u32  n_nodes  left child (right = left + 1) of an internal node, the leaf row of a leaf
//! LEAF i16  L·20     leaf shape vectors (σ units), quantised
//! LSCL f32  20       dequantisation scale of each output
//! CREF u32  1        optional: canonical height reference (0 hip centre, 1 mattress; absent = 0)
//! LINR f32  21·20    optional: linear shape regression on the coefficients (see linear::ShapeLinear); when
//!                    present the estimate uses it instead of the forest
//! LINP f32  25·20    optional: the same on the coefficients and the salient points' distances
//!                    (linear::point_features); preferred over LINR
//! ```
//! Host-only sections (`INFO`: the training report) are ignored here.
//!
//! Per-frame cost (one desktop core, default 112x80 canonical view, stride 2): canonical view ~1 ms, projection
//! ~1.5 ms, forest ~5 µs (linear regression under 1 µs). The caller lends the canonical image buffer
//! ([`ShapeModelView::pixels`] f32).

pub mod canonical;
pub mod combine;
pub mod forest;
pub mod linear;
pub mod subspace;

use crate::body_model::SHAPE_COMPONENTS;
use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::geometry::{Isometry3, Plane, Point3};
use crate::model_file::{ModelFile, ModelFileError, Tag};
use crate::salient::SalientPoint;
use canonical::{CanonicalCamera, DegenerateFrame, HeightReference};
use forest::ShapeForest;
use linear::{LINEAR_INPUTS, LINEAR_LEN, LINEAR_POINTS_LEN, ShapeLinear};
use subspace::{ProjectError, SUBSPACE_DIM, Subspace};

/// Kind tag of shape model files.
pub const KIND: Tag = *b"SHAP";
/// Format version of the `SHAP` kind that this build reads.
pub const FORMAT_VERSION: u16 = 1;

/// A validated, borrowed shape model (canonical camera, subspace, forest).
#[derive(Debug, Clone, Copy)]
pub struct ShapeModelView<'a> {
    file: ModelFile<'a>,
    camera: CanonicalCamera,
    subspace: Subspace<'a>,
    forest: ShapeForest<'a>,
    linear: Option<ShapeLinear<'a>>,
    /// The `LINR` map (coefficients only), kept for [`ShapeModelView::coefficients_only`].
    linear_coeffs: Option<ShapeLinear<'a>>,
}

fn invalid(tag: &[u8; 4], what: &'static str) -> ModelFileError {
    ModelFileError::InvalidData { tag: *tag, what }
}

impl<'a> ShapeModelView<'a> {
    /// Validate `bytes` as a shape model: container checks, then sizes, floats and the forest's node links.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, ModelFileError> {
        let file = ModelFile::parse(bytes, KIND, FORMAT_VERSION)?;
        let head = file.typed::<u32>(*b"HEAD", Some(4))?;
        let (w, h, stride, n_trees) = (head.at(0), head.at(1), head.at(2), head.at(3));
        if w == 0
            || h == 0
            || w > 1024
            || h > 1024
            || stride == 0
            || stride > 16
            || n_trees == 0
            || n_trees > 256
        {
            return Err(invalid(
                b"HEAD",
                "canonical size, stride or tree count out of range",
            ));
        }
        let pixels = (w * h) as usize;
        let cam = file.typed::<f32>(*b"CAMR", Some(9))?;
        if !cam.iter().all(f32::is_finite) || cam.at(0) <= 0.0 || cam.at(3) <= 0.0 {
            return Err(invalid(
                b"CAMR",
                "canonical camera must be finite with positive focal and distance",
            ));
        }
        let camera = CanonicalCamera {
            width: w as u16,
            height: h as u16,
            focal_px: cam.at(0),
            cx: cam.at(1),
            cy: cam.at(2),
            distance_m: cam.at(3),
            half_width_m: cam.at(4),
            below_hip_m: cam.at(5),
            above_hip_m: cam.at(6),
            max_height_m: cam.at(7),
            below_mattress_m: cam.at(8),
            stride: stride as u16,
            height_reference: match file.typed::<u32>(*b"CREF", Some(1)) {
                Err(ModelFileError::MissingSection { .. }) => HeightReference::HipCentre,
                Err(e) => return Err(e),
                Ok(c) => HeightReference::from_code(c.at(0))
                    .ok_or(invalid(b"CREF", "unknown canonical height reference"))?,
            },
        };
        let mean = file.typed::<f32>(*b"MEAN", Some(pixels))?;
        let basis = file.typed::<i16>(*b"EIGS", Some(pixels * SUBSPACE_DIM))?;
        let scale = file.typed::<f32>(*b"ESCL", Some(SUBSPACE_DIM))?;
        let prior_s = file.typed::<f32>(*b"EPRI", Some(SUBSPACE_DIM))?;
        if !mean.iter().all(f32::is_finite)
            || !scale.iter().all(|s| s.is_finite() && s >= 0.0)
            || !prior_s.iter().all(|s| s.is_finite() && s >= 0.0)
        {
            return Err(invalid(b"MEAN", "non-finite mean, scale or prior"));
        }
        let mut prior = [0.0f32; SUBSPACE_DIM];
        for (k, p) in prior.iter_mut().enumerate() {
            *p = prior_s.at(k);
        }
        let forest = ShapeForest {
            roots: file.typed::<u32>(*b"TREE", Some(n_trees as usize))?,
            feature: file.typed::<u16>(*b"NFEA", None)?,
            threshold: file.typed::<f32>(*b"NTHR", None)?,
            child: file.typed::<u32>(*b"NCHL", None)?,
            leaves: file.typed::<i16>(*b"LEAF", None)?,
            leaf_scale: file.typed::<f32>(*b"LSCL", Some(SHAPE_COMPONENTS))?,
        };
        forest::validate(&forest).map_err(|what| invalid(b"NFEA", what))?;
        let linear_section = |tag: Tag, len: usize, inputs: usize| match file.typed::<f32>(tag, Some(len)) {
            Err(ModelFileError::MissingSection { .. }) => Ok(None),
            Err(e) => Err(e),
            Ok(w) if !w.iter().all(f32::is_finite) => {
                Err(invalid(&tag, "non-finite linear regression weight"))
            }
            Ok(w) => Ok(Some(ShapeLinear { w, inputs })),
        };
        let linear_points = linear_section(*b"LINP", LINEAR_POINTS_LEN, LINEAR_INPUTS)?;
        let linear_coeffs = linear_section(*b"LINR", LINEAR_LEN, SUBSPACE_DIM)?;
        Ok(ShapeModelView {
            file,
            camera,
            subspace: Subspace {
                mean,
                basis,
                scale,
                prior,
            },
            forest,
            linear: linear_points.or(linear_coeffs),
            linear_coeffs,
        })
    }

    /// This model with the regression on the coefficients alone (`LINR`, else the forest) in place of the one on
    /// the coefficients and the salient points (`LINP`): for callers whose salient points are much worse than the
    /// ones it was trained with, whose spacing would then mislead it.
    pub fn coefficients_only(&self) -> Self {
        ShapeModelView {
            linear: self.linear_coeffs,
            ..*self
        }
    }

    /// The validated container.
    pub fn file(&self) -> &ModelFile<'a> {
        &self.file
    }

    /// The canonical camera the subspace was learnt for.
    pub fn camera(&self) -> &CanonicalCamera {
        &self.camera
    }

    /// Pixels of the canonical image (the length of the buffer [`Self::estimate`] borrows).
    pub fn pixels(&self) -> usize {
        self.camera.pixels()
    }

    /// The eigen-image subspace.
    pub fn subspace(&self) -> &Subspace<'a> {
        &self.subspace
    }

    /// The shape regression forest.
    pub fn forest(&self) -> &ShapeForest<'a> {
        &self.forest
    }

    /// The linear shape regression, if the file has one (then [`Self::estimate`] uses it, not the forest).
    pub fn linear(&self) -> Option<&ShapeLinear<'a>> {
        self.linear.as_ref()
    }

    /// The shape coefficients (σ units) for subspace coefficients `c` of a view made with salient points
    /// `points`: the linear regression if present, else the forest (which reads `c` only).
    pub fn regress(
        &self,
        c: &[f32; SUBSPACE_DIM],
        points: &[Point3; SalientPoint::COUNT],
    ) -> [f32; SHAPE_COMPONENTS] {
        match &self.linear {
            Some(l) => l.predict(&linear::inputs(c, points)),
            None => self.forest.predict(c),
        }
    }

    /// Shape from one frame: the canonical view of `frame` for the salient points (camera frame) and the mattress
    /// plane (camera frame, normal up), its masked projection and the regression's prediction ([`Self::regress`]).
    /// `canonical` is the caller's scratch of [`Self::pixels`] values (it holds the canonical image afterwards).
    pub fn estimate(
        &self,
        frame: &DepthFrame<'_>,
        k: &Intrinsics,
        points: &[Point3; SalientPoint::COUNT],
        mattress: &Plane,
        canonical: &mut [f32],
    ) -> Result<ShapeEstimate, ShapeError> {
        let camera_from_body = canonical::body_frame(points, &mattress.normal())?;
        canonical::canonical_view(frame, k, &camera_from_body, mattress, &self.camera, canonical)
            .map_err(|e| ShapeError::Project(ProjectError::Size(e)))?;
        let (c, visible) = self.subspace.project(canonical).map_err(ShapeError::Project)?;
        Ok(ShapeEstimate {
            shape: self.regress(&c, points),
            subspace: c,
            visible,
            camera_from_body,
        })
    }
}

/// What [`ShapeModelView::estimate`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeEstimate {
    /// Shape coefficients in units of each component's σ (multiply by `BodyModelView::sigma` for raw ones).
    pub shape: [f32; SHAPE_COMPONENTS],
    /// Subspace coefficients of the canonical image (Eq. 1).
    pub subspace: [f32; SUBSPACE_DIM],
    /// Canonical pixels that were visible.
    pub visible: usize,
    /// The body frame the canonical view was built in.
    pub camera_from_body: Isometry3,
}

/// Why a shape estimate failed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ShapeError {
    /// The salient points do not define a body frame.
    Frame(DegenerateFrame),
    /// The masked projection failed.
    Project(ProjectError),
}

impl From<DegenerateFrame> for ShapeError {
    fn from(e: DegenerateFrame) -> Self {
        ShapeError::Frame(e)
    }
}

impl core::fmt::Display for ShapeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ShapeError::Frame(e) => e.fmt(f),
            ShapeError::Project(e) => e.fmt(f),
        }
    }
}

impl core::error::Error for ShapeError {}

#[cfg(test)]
mod tests;
