//! The tracker's host side: its three model files read and validated once at start-up ([`ModelFiles`]) and its
//! working memory allocated once, before the first frame ([`TrackerScratch`]), for every program that runs
//! `supine_core::tracker` (the service, replay, the demo, the evaluation). Nothing here runs per frame.

use std::path::{Path, PathBuf};
use supine_core::body_model::{BodyModelView, SHAPE_COMPONENTS};
use supine_core::error::BufferLenError;
use supine_core::forest::infer::Workspace;
use supine_core::forest::model::ForestView;
use supine_core::geometry::{Isometry3, Point3, Vector3};
use supine_core::model_file::ModelFileError;
use supine_core::normal_memo::MemoCell;
use supine_core::shape::ShapeModelView;
use supine_core::torso::{TorsoBuffers, TorsoSurface};
use supine_core::tracker::surface::VertexSums;
use supine_core::tracker::{Models, Scratch, ScratchSizes};
use supine_core::wire::BodyRegion;

/// File names of the three models in a model directory.
pub const MODEL_FILES: [&str; 3] = ["body.sbm", "joints.jfor", "shape.ssm"];

/// Why the model files could not be loaded: which file, and what was wrong with it.
#[derive(Debug)]
pub struct ModelLoadError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong (the OS error, or core's validation error).
    pub reason: String,
}

impl std::fmt::Display for ModelLoadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "model file {}: {}", self.path.display(), self.reason)
    }
}

impl std::error::Error for ModelLoadError {}

/// The three model files, read once and validated.
pub struct ModelFiles {
    /// The body model (body.sbm).
    pub body: Vec<u8>,
    /// The joint forest (joints.jfor).
    pub joints: Vec<u8>,
    /// The shape model (shape.ssm).
    pub shape: Vec<u8>,
}

impl ModelFiles {
    /// Read the three files ([`MODEL_FILES`]) from `dir`.
    pub fn load(dir: &Path) -> Result<Self, ModelLoadError> {
        let [b, j, s] = MODEL_FILES.map(|n| dir.join(n));
        Self::load_files(&b, &j, &s)
    }

    /// Read the three files from their paths and check that each parses as its kind.
    pub fn load_files(body: &Path, joints: &Path, shape: &Path) -> Result<Self, ModelLoadError> {
        let read = |p: &Path| {
            std::fs::read(p).map_err(|e| ModelLoadError {
                path: p.to_path_buf(),
                reason: e.to_string(),
            })
        };
        let files = ModelFiles {
            body: read(body)?,
            joints: read(joints)?,
            shape: read(shape)?,
        };
        let bad = |p: &Path, e: ModelFileError| ModelLoadError {
            path: p.to_path_buf(),
            reason: e.to_string(),
        };
        BodyModelView::parse(&files.body).map_err(|e| bad(body, e))?;
        ForestView::parse(&files.joints).map_err(|e| bad(joints, e))?;
        ShapeModelView::parse(&files.shape).map_err(|e| bad(shape, e))?;
        Ok(files)
    }

    /// The validated views the tracker reads.
    pub fn views(&self) -> Result<Models<'_>, ModelFileError> {
        Ok(Models {
            body: BodyModelView::parse(&self.body)?,
            joints: ForestView::parse(&self.joints)?,
            shape: ShapeModelView::parse(&self.shape)?,
        })
    }
}

/// Owned scratch for a tracker (allocated once, before the first frame).
pub struct TrackerScratch {
    plane_points: Vec<Point3>,
    plane_labels: Vec<u8>,
    canonical: Vec<f32>,
    fit_points: Vec<[f32; 3]>,
    fit_normals: Vec<[f32; 3]>,
    surface_sums: Vec<VertexSums>,
    torso_vertices: Vec<Point3>,
    torso_normals: Vec<Vector3>,
    torso_regions: Vec<BodyRegion>,
    forest: Box<Workspace>,
    normal_memo: Vec<MemoCell>,
    refit_depth: Vec<u16>,
}

impl TrackerScratch {
    /// Buffers of the sizes `sizes` asks for.
    pub fn new(sizes: &ScratchSizes) -> Self {
        TrackerScratch {
            plane_points: vec![Point3::origin(); sizes.plane_points],
            plane_labels: vec![0; sizes.plane_points],
            canonical: vec![0.0; sizes.canonical],
            fit_points: vec![[0.0; 3]; sizes.torso],
            fit_normals: vec![[0.0; 3]; sizes.torso],
            surface_sums: vec![VertexSums::ZERO; sizes.torso],
            torso_vertices: vec![Point3::origin(); sizes.torso],
            torso_normals: vec![Vector3::zeros(); sizes.torso],
            torso_regions: vec![BodyRegion::OffBody; sizes.torso],
            forest: Box::new(Workspace::new()),
            normal_memo: vec![MemoCell::EMPTY; sizes.pixels],
            refit_depth: vec![0; sizes.pixels],
        }
    }

    /// The tracker's view of the buffers.
    pub fn scratch(&mut self) -> Scratch<'_> {
        Scratch {
            plane_points: &mut self.plane_points,
            plane_labels: &mut self.plane_labels,
            canonical: &mut self.canonical,
            fit_points: &mut self.fit_points,
            fit_normals: &mut self.fit_normals,
            surface_sums: &mut self.surface_sums,
            torso_vertices: &mut self.torso_vertices,
            torso_normals: &mut self.torso_normals,
            torso_regions: &mut self.torso_regions,
            forest: &mut self.forest,
            normal_memo: &mut self.normal_memo,
            refit_depth: &mut self.refit_depth,
        }
    }
}

/// A shaped torso surface in owned buffers (the true torso of a sequence, for scoring).
pub struct OwnedTorso {
    vertices: Vec<Point3>,
    normals: Vec<Vector3>,
    regions: Vec<BodyRegion>,
    body_from_torso: Isometry3,
}

impl OwnedTorso {
    /// The body model's torso subset shaped with `shape_sigma` (σ units; missing coefficients are 0).
    pub fn new(body: &BodyModelView<'_>, shape_sigma: &[f32]) -> Result<Self, BufferLenError> {
        let n = body.counts().subset;
        let mut raw = [0.0f32; SHAPE_COMPONENTS];
        for (i, r) in raw.iter_mut().enumerate() {
            *r = shape_sigma.get(i).copied().unwrap_or(0.0) * body.sigma(i);
        }
        let mut t = OwnedTorso {
            vertices: vec![Point3::origin(); n],
            normals: vec![Vector3::zeros(); n],
            regions: vec![BodyRegion::OffBody; n],
            body_from_torso: Isometry3::identity(),
        };
        let s = TorsoSurface::build(
            body,
            &raw,
            TorsoBuffers {
                vertices: &mut t.vertices,
                normals: &mut t.normals,
                regions: &mut t.regions,
            },
        )?;
        t.body_from_torso = s.body_from_torso();
        Ok(t)
    }

    /// The surface view (`None` for a body model other than the one it was built from).
    pub fn surface<'a>(&'a self, body: &BodyModelView<'a>) -> Option<TorsoSurface<'a>> {
        TorsoSurface::from_parts(
            body,
            &self.vertices,
            &self.normals,
            &self.regions,
            self.body_from_torso,
        )
    }
}
