//! supine-core: everything that runs per frame on the head computer, and the wire protocol to the arm controller.
//!
//! `#![no_std]` without `alloc`, in the manner of smoltcp and postcard: models are borrowed views over bytes that were
//! validated once, working memory is caller-provided with capacities fixed at compile time, and nothing here reads a
//! clock, a file or the environment (time, frames and model bytes are inputs), so every replay is deterministic.
//!
//! Layers:
//! - [`crc`]: the checksums shared by the wire protocol and the model files.
//! - [`camera`]: pinhole intrinsics of the Kinect v1 depth camera and the named coordinate frames.
//! - [`depth`]: a borrowed 640x480 millimetre depth frame, as every depth source lends it.
//! - [`wire`]: the protocol to the arm controller (serial COBS/postcard/CRC-32C, CAN with E2E, SLCAN, candump).
//! - [`model_file`]: the versioned, checksummed container every model file uses (validated once, borrowed views).
//! - [`body_model`]: the statistical body model (mean + shape basis, joints, salient points, torso ICP subset).
#![no_std]
#![cfg_attr(not(test), deny(clippy::std_instead_of_core))]

pub mod body_model;
pub mod camera;
pub mod crc;
pub mod depth;
pub mod model_file;
pub mod wire;
