//! Evaluation commands of `supine-models eval`: each reads generated data, runs the product's code on it and
//! reports figures against the ground truth (JSON keys in shared/design/cli.md).

pub mod calibration;
pub mod figure;
pub mod tracking;
pub mod tracking_plot;
pub mod tracking_truth;
