//! Adapter from the statistical body model ([`crate::body`], [`crate::pose`]) to the scene's [`BodySource`]: shape
//! from the calibrated population, pose from the bed-pose generator (750 sub-pose combinations plus lying
//! variation), LBS, then the body model's bed frame (hips at the origin) shifted onto this crate's bed frame
//! (origin at the mattress centre).
//!
//! Cost per sample: one LBS of the MakeHuman mesh (~10 ms) and a copy of its triangles; a sequence frame
//! (`sample_motion`) poses pose `a` too, to place the body, once per patient.

use super::body::{BodySource, Patient};
use crate::body::{BodyModel, BodyPart, PosedBody, Shape};
use crate::pose::bed::pose_on_bed;
use crate::pose::{BedPose, BedPoseSampler, Rest};
use anyhow::{Context, Result};
use nalgebra::Isometry3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use std::path::Path;
use std::sync::{Mutex, PoisonError};

/// Bed-frame y of the hip joints (and so of the head-section hinge, which the body model puts through the hips).
pub const HIP_Y: f32 = 0.0;

/// The MakeHuman/PCA body model with its bed-pose sampler.
pub struct ModelBodySource {
    model: BodyModel,
    sampler: BedPoseSampler,
    /// `sample_motion`'s placement of its last patient, keyed by (shape seed, pose seed `a`): a sequence asks for
    /// the same patient on every frame, and the placement costs an LBS of pose `a` of its own.
    placement: Mutex<Option<Placement>>,
}

/// A patient's (shape seed, pose seed) and where its pose lies on the bed.
type Placement = ((u64, u64), Isometry3<f32>);

impl ModelBodySource {
    /// Load the body model from `path`, or the committed default artifact.
    pub fn load(path: Option<&Path>) -> Result<Self> {
        let model = match path {
            Some(p) => BodyModel::load(p).with_context(|| format!("loading body model {}", p.display()))?,
            None => BodyModel::load_default()
                .context("loading the default body model (models/artifacts/body.sbm)")?,
        };
        Ok(ModelBodySource {
            sampler: BedPoseSampler::new(&model),
            model,
            placement: Mutex::new(None),
        })
    }

    /// `posed` (on the body model's bed frame) as a patient on this crate's bed frame.
    fn placed(
        &self,
        posed: PosedBody<'_>,
        shape: &Shape,
        bed: &BedPose,
        pose_json: serde_json::Value,
    ) -> Patient {
        let body = posed
            .transformed(&Isometry3::translation(0.0, HIP_Y, 0.0))
            .into_owned();
        Patient {
            body,
            part_names: self.part_names(),
            shape: shape.normalised(&self.model).to_vec(),
            pose: pose_json,
            head_raise_rad: bed.lying.head_raise_rad,
            hinge_y_m: HIP_Y,
        }
    }
}

impl BodySource for ModelBodySource {
    fn name(&self) -> String {
        "makehuman-pca".into()
    }

    fn part_names(&self) -> Vec<String> {
        (0..BodyPart::COUNT as u8)
            .map(|i| BodyPart::from_u8(i).map_or("unknown", |p| p.name()).to_string())
            .collect()
    }

    fn sample(&self, rng: &mut ChaCha8Rng, rest: Rest) -> Result<Patient> {
        let shape = self.model.sample_shape(rng);
        let bed = self.sampler.sample(rng);
        let json = serde_json::to_value(&bed)?;
        Ok(self.placed(pose_on_bed(&self.model, &shape, &bed, rest), &shape, &bed, json))
    }

    /// Pose `a`'s sub-pose combination and lying, blended toward the same combination with other arm sub-poses
    /// (drawn from `b`): the trunk and legs stay where pose `a` rests on its back
    /// ([`crate::pose::Lying::bed_from_trunk`]), the arms move.
    fn sample_motion(&self, shape_seed: u64, a: u64, b: u64, t: f32) -> Result<Patient> {
        let shape = self
            .model
            .sample_shape(&mut ChaCha8Rng::seed_from_u64(shape_seed));
        let first = self.sampler.sample(&mut ChaCha8Rng::seed_from_u64(a));
        let mut rb = ChaCha8Rng::seed_from_u64(b);
        // Combination index = trunk·125 + left arm·25 + right arm·5 + legs: replace both arm digits.
        let c = first.combination;
        let other = (c / 125) * 125 + rb.gen_range(0..5) * 25 + rb.gen_range(0..5) * 5 + c % 5;
        let pa = self.sampler.canonical(c, first.lying);
        let pb = self.sampler.canonical(other, first.lying);
        let mut blended = pa.clone();
        for (r, (x, y)) in blended
            .pose
            .rotations
            .iter_mut()
            .zip(pa.pose.rotations.iter().zip(&pb.pose.rotations))
        {
            for k in 0..3 {
                r[k] = x[k] + (y[k] - x[k]) * t;
            }
        }
        let json = serde_json::json!({ "from_combination": c, "to_combination": other, "t": t, "lying": first.lying, "pose": blended.pose });
        // The body rests on its back where pose `a` puts it: placed by each blend's lowest vertex, a hand rising from
        // under the head or beside a raised back would let the patient sink with it (2-4 cm in a second).
        let key = (shape_seed, a);
        let known = *self.placement.lock().unwrap_or_else(PoisonError::into_inner);
        let bed_from_body = match known {
            Some((k, placement)) if k == key => placement,
            _ => {
                let placement = pa.lying.bed_from_trunk(&self.model.pose(&shape, &pa.pose));
                *self.placement.lock().unwrap_or_else(PoisonError::into_inner) = Some((key, placement));
                placement
            }
        };
        let posed = self.model.pose(&shape, &blended.pose).transformed(&bed_from_body);
        Ok(self.placed(posed, &shape, &blended, json))
    }

    fn torso_subset(&self) -> Option<Vec<u32>> {
        Some(self.model.torso_subset.clone())
    }
}

/// Which body source a command uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BodyKind {
    /// The statistical MakeHuman/PCA body model with the bed-pose generator (the real thing).
    Model,
    /// The procedural mannequin (tests, or before the body model is built).
    Mannequin,
}

/// Open the body source of `kind` (`model_path` overrides the default body model artifact).
pub fn open_source(kind: BodyKind, model_path: Option<&Path>) -> Result<Box<dyn BodySource>> {
    Ok(match kind {
        BodyKind::Model => Box::new(ModelBodySource::load(model_path)?),
        BodyKind::Mannequin => Box::new(super::body::Mannequin),
    })
}
