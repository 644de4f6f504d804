//! The statistical body model on the host: build it from the MakeHuman assets, load it from its model file, shape and
//! pose it.
//!
//! # Using it (renderer, dataset and sequence generators)
//! ```no_run
//! use supine_models::body::{BodyModel, Shape};
//! use supine_models::pose::{BedPoseSampler, Pose};
//! use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
//!
//! let model = BodyModel::load_default()?;          // models/artifacts/body.sbm (committed)
//! let mut rng = ChaCha8Rng::seed_from_u64(7);
//! let shape = model.sample_shape(&mut rng);        // a body of the calibrated adult population
//! let bed = BedPoseSampler::new(&model).sample(&mut rng); // one of ~750 sub-pose combinations + lying variation
//! let posed = model.pose(&shape, &bed.pose);       // LBS; body frame
//! let bed_from_body = bed.lying.bed_from_body(&posed); // rigid: supine on the mattress plane z = 0
//! let on_bed = posed.transformed(&bed_from_body);
//! // on_bed.vertices, on_bed.triangles, on_bed.part_of_vertex / part_of_triangle(), on_bed.salient_points
//! # Ok::<(), anyhow::Error>(())
//! ```
//!
//! * [`BodyModel`]: loaded (and dequantised) from a `BODY` model file, see [`supine_core::body_model`] for the
//!   layout. Cheap to share (`&BodyModel` is all posing needs).
//! * [`Shape`]: the 20 PCA coefficients (raw, metres along unit directions; [`BodyModel::sigma`] normalises).
//! * [`crate::pose::Pose`]: per-bone Euler XYZ rotations (Blender pose-bone convention) of the 36-bone rig.
//! * [`PosedBody`]: skin vertices (metres), triangles, per-vertex [`BodyPart`] ids, the 6 salient points and the
//!   joints, all in the same frame.
//!
//! Frames: the **body frame** is the MakeHuman/Blender frame: metres, z up (head), the body faces -y, x is the body's
//! left; the rest pose is MakeHuman's A-pose, soles near z = -0.82, pelvis near z = 0.06. The **bed frame**
//! ([`crate::pose::Lying`]): z up from the mattress, y toward the head end, x the patient's left when supine. Lying
//! variations (side tilt, raised head end) are rigid transforms from body to bed frame plus, for the raised head
//! end, a hip flexion inside the pose: that is the split between the pose and the scene.
//!
//! Building (`supine-models body`): [`build`] samples a calibrated population ([`population`]), blends MakeHuman
//! targets ([`phenotype`]), measures ([`measure`]), runs PCA ([`pca`]), derives the reduced rig ([`rig`]) and writes
//! the file ([`mod@file`]).

pub mod build;
pub mod cli;
pub mod figure;
pub mod file;
pub mod measure;
pub mod pca;
pub mod phenotype;
pub mod population;
pub mod rig;

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use supine_core::body_model::BodyModelView;

pub use supine_core::body_model::BodyPart;
pub use supine_core::salient::SalientPoint;

use crate::pose::{Pose, pose_body};

/// Number of shape components of the model (the paper's 20).
pub const COMPONENTS: usize = 20;
/// Default artifact path, relative to the workspace root.
pub const DEFAULT_ARTIFACT: &str = "models/artifacts/body.sbm";

/// Absolute path of the committed default body model (`<workspace>/models/artifacts/body.sbm`).
pub fn default_artifact_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("artifacts")
        .join("body.sbm")
}

/// Shape coefficients: `M + V s` gives the rest-pose body.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Shape {
    /// Raw PCA coefficients (metres along unit-norm directions of the 3·rows-dimensional shape space).
    pub coeffs: [f32; COMPONENTS],
}

impl Shape {
    /// The mean body.
    pub const MEAN: Shape = Shape {
        coeffs: [0.0; COMPONENTS],
    };

    /// From coefficients in units of each component's standard deviation (paper §4.2 normalisation).
    pub fn from_normalised(model: &BodyModel, z: &[f32]) -> Shape {
        let mut coeffs = [0.0; COMPONENTS];
        for (k, c) in coeffs.iter_mut().enumerate() {
            *c = z.get(k).copied().unwrap_or(0.0) * model.sigma[k];
        }
        Shape { coeffs }
    }

    /// Coefficients in units of each component's standard deviation.
    pub fn normalised(&self, model: &BodyModel) -> [f32; COMPONENTS] {
        let mut z = [0.0; COMPONENTS];
        for (k, v) in z.iter_mut().enumerate() {
            *v = if model.sigma[k] > 0.0 {
                self.coeffs[k] / model.sigma[k]
            } else {
                0.0
            };
        }
        z
    }
}

/// One bone of the posing rig.
#[derive(Clone, Debug, PartialEq)]
pub struct Bone {
    /// Blender name in the MakeHuman default rig (`spine03`, `upperarm01.L`, ...).
    pub name: String,
    /// Parent bone index (`None` for the root, bone 0); parents precede children.
    pub parent: Option<usize>,
    /// Joint index of the bone head.
    pub head: usize,
    /// Joint index of the bone tail.
    pub tail: usize,
    /// Blender roll (radians).
    pub roll: f32,
}

/// A training-population member as stored in the model file (for sampling realistic bodies).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PopulationMember {
    /// Shape coefficients of the member's PCA projection.
    pub shape: Shape,
    /// 0 = female, 1 = male.
    pub male: bool,
    /// Age in years.
    pub age_years: f32,
    /// Standing height (z extent of the skin), metres.
    pub height_m: f32,
    /// Body-mass index (mesh volume × 985 kg/m³ / height²).
    pub bmi: f32,
    /// Waist circumference (MakeHuman waist vertex loop), metres.
    pub waist_m: f32,
}

/// The body model, loaded and dequantised for host-side work.
#[derive(Clone, Debug)]
pub struct BodyModel {
    bytes: Vec<u8>,
    /// Number of skin vertices.
    pub n_vertices: usize,
    /// Number of rig joints.
    pub n_joints: usize,
    /// Mean position of every row (vertices, joints, salient points).
    pub mean: Vec<[f32; 3]>,
    /// Dequantised basis, `basis[(3·row + c)·COMPONENTS + k]`.
    pub basis: Vec<f32>,
    /// Standard deviation of each coefficient over the training population.
    pub sigma: [f32; COMPONENTS],
    /// Skin triangles (counter-clockwise seen from outside).
    pub triangles: Vec<[u32; 3]>,
    /// Body part id ([`BodyPart`] as u8) of each skin vertex.
    pub part_of_vertex: Vec<u8>,
    /// Bones of the posing rig, parents first.
    pub bones: Vec<Bone>,
    /// Joint names (`joint-l-shoulder`, `v8057+17023`, ...).
    pub joint_names: Vec<String>,
    /// Skinning influences per vertex: (bone, weight), weights summing to 1.
    pub skin: Vec<Vec<(u16, f32)>>,
    /// Torso ICP subset (skin vertex indices).
    pub torso_subset: Vec<u32>,
    /// Training population (coefficients and measurements), when the file has it.
    pub population: Vec<PopulationMember>,
}

impl BodyModel {
    /// Load a body model file.
    pub fn load(path: &Path) -> Result<BodyModel> {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read body model {}", path.display()))?;
        BodyModel::from_bytes(bytes).with_context(|| format!("invalid body model {}", path.display()))
    }

    /// Load the committed default model ([`default_artifact_path`]).
    pub fn load_default() -> Result<BodyModel> {
        let p = default_artifact_path();
        if !p.exists() {
            bail!(
                "default body model {} is missing; build it with `supine-models body`",
                p.display()
            );
        }
        BodyModel::load(&p)
    }

    /// Validate (through [`BodyModelView::parse`]) and dequantise a model file image.
    pub fn from_bytes(bytes: Vec<u8>) -> Result<BodyModel> {
        let view = BodyModelView::parse(&bytes).map_err(|e| anyhow::anyhow!("{e}"))?;
        let c = view.counts();
        if c.components != COMPONENTS {
            bail!(
                "body model has {} shape components, this build uses {COMPONENTS}",
                c.components
            );
        }
        let rows = c.rows();
        let mean = (0..rows).map(|r| view.mean_row(r)).collect();
        let mut basis = vec![0.0f32; 3 * rows * COMPONENTS];
        for r in 0..rows {
            for ci in 0..3 {
                for k in 0..COMPONENTS {
                    basis[(3 * r + ci) * COMPONENTS + k] = view.basis(r, ci, k);
                }
            }
        }
        let mut sigma = [0.0; COMPONENTS];
        for (k, s) in sigma.iter_mut().enumerate() {
            *s = view.sigma(k);
        }
        let t = view.triangles();
        let triangles = (0..c.triangles)
            .map(|i| [t.at(3 * i) as u32, t.at(3 * i + 1) as u32, t.at(3 * i + 2) as u32])
            .collect();
        let part_of_vertex = (0..c.vertices).map(|v| view.part_of_vertex(v) as u8).collect();
        let bones = (0..c.bones)
            .map(|b| {
                let (head, tail) = view.bone_joints(b);
                Bone {
                    name: view.bone_name(b).to_string(),
                    parent: view.bone_parent(b),
                    head,
                    tail,
                    roll: view.bone_roll(b),
                }
            })
            .collect();
        let joint_names = (0..c.joints).map(|j| view.joint_name(j).to_string()).collect();
        let skin = (0..c.vertices)
            .map(|v| {
                let mut inf: Vec<(u16, f32)> = (0..c.max_influences)
                    .map(|i| view.skin_influence(v, i))
                    .filter(|&(_, w)| w > 0.0)
                    .map(|(b, w)| (b as u16, w))
                    .collect();
                let sum: f32 = inf.iter().map(|x| x.1).sum();
                for x in &mut inf {
                    x.1 /= sum;
                }
                inf
            })
            .collect();
        let torso_subset = view.torso_subset().iter().map(u32::from).collect();
        let population = file::read_population(view.file())?;
        Ok(BodyModel {
            n_vertices: c.vertices,
            n_joints: c.joints,
            mean,
            basis,
            sigma,
            triangles,
            part_of_vertex,
            bones,
            joint_names,
            skin,
            torso_subset,
            population,
            bytes,
        })
    }

    /// The file image this model was loaded from.
    pub fn file_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The core view of the same file (what the head computer uses).
    pub fn view(&self) -> BodyModelView<'_> {
        // The bytes were validated in `from_bytes` and are immutable since.
        BodyModelView::parse(&self.bytes).expect("validated at load")
    }

    /// Row `row` for `shape`.
    #[inline]
    pub fn row(&self, row: usize, shape: &Shape) -> [f32; 3] {
        let mut p = self.mean[row];
        for (c, pc) in p.iter_mut().enumerate() {
            let b = &self.basis[(3 * row + c) * COMPONENTS..(3 * row + c + 1) * COMPONENTS];
            *pc += b.iter().zip(&shape.coeffs).map(|(x, s)| x * s).sum::<f32>();
        }
        p
    }

    /// Rest-pose skin vertices for `shape`.
    pub fn rest_vertices(&self, shape: &Shape) -> Vec<[f32; 3]> {
        (0..self.n_vertices).map(|v| self.row(v, shape)).collect()
    }

    /// Rest-pose joints for `shape`.
    pub fn rest_joints(&self, shape: &Shape) -> Vec<[f32; 3]> {
        (0..self.n_joints)
            .map(|j| self.row(self.n_vertices + j, shape))
            .collect()
    }

    /// Rest-pose salient points for `shape`, in [`SalientPoint::ALL`] order.
    pub fn rest_salient_points(&self, shape: &Shape) -> [[f32; 3]; SalientPoint::COUNT] {
        SalientPoint::ALL.map(|p| self.row(self.n_vertices + self.n_joints + p as usize, shape))
    }

    /// Index of the bone called `name`.
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    /// Index of the joint called `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joint_names.iter().position(|b| b == name)
    }

    /// Pose the body of `shape` with `pose` (linear blend skinning), in the body frame.
    pub fn pose(&self, shape: &Shape, pose: &Pose) -> PosedBody<'_> {
        pose_body(self, shape, pose)
    }

    /// A random body of the calibrated adult population: a training member drawn uniformly, plus Gaussian jitter of
    /// 0.15 σ per component, so bodies are realistic (not the Gaussian approximation) yet never exact repeats.
    /// Falls back to N(0, σ²) clipped to ±3σ when the file has no population.
    pub fn sample_shape<R: Rng>(&self, rng: &mut R) -> Shape {
        let mut coeffs = [0.0; COMPONENTS];
        if self.population.is_empty() {
            for (k, c) in coeffs.iter_mut().enumerate() {
                let z: f32 = rng.sample::<f32, _>(StandardNormal).clamp(-3.0, 3.0);
                *c = z * self.sigma[k];
            }
        } else {
            let m = &self.population[rng.gen_range(0..self.population.len())];
            for (k, c) in coeffs.iter_mut().enumerate() {
                let z: f32 = StandardNormal.sample(rng);
                *c = m.shape.coeffs[k] + 0.15 * z * self.sigma[k];
            }
        }
        Shape { coeffs }
    }
}

/// A posed body: what the renderer draws and what the ground truth records, from the statistical model or the
/// mannequin. Vertices and points share one frame (the body frame from [`BodyModel::pose`], or whatever
/// [`PosedBody::transformed`] or the scene moved them to). Triangles and part ids are borrowed from the model when
/// posing it, owned by bodies that carry them themselves (the mannequin, a scene's patient).
#[derive(Clone, Debug)]
pub struct PosedBody<'m> {
    /// Skin vertex positions, metres.
    pub vertices: Vec<[f32; 3]>,
    /// Skin triangles (counter-clockwise seen from outside).
    pub triangles: Cow<'m, [[u32; 3]]>,
    /// Part id of each vertex: a [`BodyPart`] for the statistical model, an index into the source's part names
    /// otherwise (see [`crate::scene::body::BodySource::part_names`]).
    pub part_of_vertex: Cow<'m, [u8]>,
    /// The six salient points, in [`SalientPoint::ALL`] order, posed.
    pub salient_points: [[f32; 3]; SalientPoint::COUNT],
    /// Rig joints, posed (empty for bodies without a rig, such as the mannequin).
    pub joints: Vec<[f32; 3]>,
}

impl PosedBody<'_> {
    /// The same body owning its triangles and part ids (a copy of them when they were borrowed).
    pub fn into_owned(self) -> PosedBody<'static> {
        PosedBody {
            vertices: self.vertices,
            triangles: Cow::Owned(self.triangles.into_owned()),
            part_of_vertex: Cow::Owned(self.part_of_vertex.into_owned()),
            salient_points: self.salient_points,
            joints: self.joints,
        }
    }

    /// Body part id of each triangle: the part of its first vertex (a triangle never spans more than two parts, and
    /// the first-vertex rule keeps labels stable and deterministic).
    pub fn part_of_triangle(&self) -> Vec<u8> {
        self.triangles
            .iter()
            .map(|t| self.part_of_vertex[t[0] as usize])
            .collect()
    }

    /// The same body moved by a rigid transform (vertices, salient points and joints).
    pub fn transformed(&self, t: &nalgebra::Isometry3<f32>) -> Self {
        let f = |p: &[f32; 3]| -> [f32; 3] {
            let q = t * nalgebra::Point3::new(p[0], p[1], p[2]);
            [q.x, q.y, q.z]
        };
        PosedBody {
            vertices: self.vertices.iter().map(f).collect(),
            triangles: self.triangles.clone(),
            part_of_vertex: self.part_of_vertex.clone(),
            salient_points: self.salient_points.map(|p| f(&p)),
            joints: self.joints.iter().map(f).collect(),
        }
    }

    /// Axis-aligned bounds (min, max) of the vertices.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for v in &self.vertices {
            for c in 0..3 {
                lo[c] = lo[c].min(v[c]);
                hi[c] = hi[c].max(v[c]);
            }
        }
        (lo, hi)
    }
}
