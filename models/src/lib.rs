//! supine-models: the host-only toolchain that produces everything `supine-core` reads.
//!
//! MakeHuman assets → statistical body model → posed, rendered synthetic Kinect data → trained and quantised models
//! → evaluation reports. Runs on a workstation (rayon for parallel work); never on the head computer.

pub mod assets;
pub mod bench;
pub mod body;
pub mod dataset;
pub mod eval;
pub mod forest;
pub mod noise_report;
pub mod pose;
pub mod provenance;
pub mod render;
pub mod scene;
pub mod sequence;
pub mod shape;
