//! supine-core: everything that runs per frame on the head computer, and the wire protocol to the arm controller.
//!
//! `#![no_std]` without `alloc`, in the manner of smoltcp and postcard: models are borrowed views over bytes that were
//! validated once, working memory is caller-provided with capacities fixed at compile time, and nothing here reads a
//! clock, a file or the environment (time, frames and model bytes are inputs), so every replay is deterministic.
//!
//! Vocabulary (every module speaks it; look here before adding a type):
//! - [`geometry`]: points, vectors and isometries (nalgebra f32, transforms named `a_from_b`) and [`geometry::Plane`].
//! - [`time`]: [`time::Timestamp`] (µs, 48 bits) and the [`time::Clock`] the tracker takes.
//! - [`salient`]: the six salient points, one enum for the model, the forest, the wire and the reports.
//! - [`body_model::SHAPE_COMPONENTS`]: the shape size (20); [`body_model::BodyPart`] and its wire region.
//! - [`rng`]: the seeded generator (SplitMix64) behind sampling, RANSAC and fault schedules.
//! - [`error`]: small errors shared by several modules ([`error::RangeError`], [`error::BufferLenError`]).
//!
//! Layers:
//! - [`crc`]: the checksums shared by the wire protocol and the model files.
//! - [`camera`]: pinhole intrinsics of the Kinect v1 depth camera and the named coordinate frames.
//! - [`depth`]: a borrowed 640x480 millimetre depth frame, as every depth source lends it.
//! - [`wire`]: the protocol to the arm controller (serial COBS/postcard/CRC-32C, CAN with E2E, SLCAN, candump).
//! - [`model_file`]: the versioned, checksummed container every model file uses (validated once, borrowed views).
//! - [`body_model`]: the statistical body model (mean + shape basis, joints, salient points, torso ICP subset).
//! - [`calib`]: camera-to-robot calibration (probe-tip detection, time pairing, Kabsch/RANSAC solver).
//! - `fixture` (tests, or the `fixtures` feature): tiny model files written with [`model_file::write`].
//!
//! Where the tracker's parts go as they land (each a module of its own, named after what it holds):
//! - `forest/`: the joint forest's model-file view, depth-difference features, inference, weighted mean-shift.
//! - `shape/`: canonical view, masked subspace projection (Eq. 1), shape regression forest (reusing `forest`).
//! - [`planes`]: RANSAC floor and mattress planes, the volume of interest, clipping (the init phase's scene part).
//! - [`torso`]: the `torso` frame from the salient points and the shaped torso surface (vertices, normals, regions).
//! - `icp`: projective point-to-plane ICP with fixed iterations; `fit`: alternating rigid ICP and shape fitting
//!   (Eq. 7).
//! - [`probe`]: probe mapping onto the torso surface (tip, nearest point, normal, signed distance, region).
//! - [`tracker`]: the real-time loop: state machine, frame budget, caller-sized scratch, `process(frame, arm, clock)`,
//!   and the accuracy figures it is scored by.
//!
//! Their trainers, quantisers and evaluations live in `supine-models` (`models/src/forest`, `models/src/shape`,
//! `models/src/eval`).
#![no_std]
#![cfg_attr(not(test), deny(clippy::std_instead_of_core))]

pub mod body_model;
pub mod calib;
pub mod camera;
pub mod crc;
pub mod depth;
pub mod error;
pub mod fit;
#[cfg(any(test, feature = "fixtures"))]
pub mod fixture;
pub mod forest;
pub mod geometry;
pub mod icp;
pub mod model_file;
pub mod normal_memo;
pub mod planes;
pub mod probe;
pub mod rng;
pub mod salient;
pub mod shape;
pub mod spd;
pub mod time;
pub mod torso;
pub mod tracker;
pub mod wire;
