//! How far the tracker's shape is from the patient's, per sequence of `eval tracking` reports: the mean upper-body
//! vertex error of `forest_icp_feedback`'s shape against the true shape, both in the body model's rest pose, raw
//! (no alignment) and translation-aligned (the pure shape error `eval shape` reports as `aligned`), beside the mean
//! shape's raw error and the sequence's torso surface error.
//!
//! `cargo run --release -p supine-models --example shape_in_tracking -- REPORT.json [REPORT.json ...]`
//! Cost: one posing of the body model per sequence.

use anyhow::{Context, Result};
use serde_json::Value;
use supine_models::body::{BodyModel, Shape};
use supine_models::pose::Pose;
use supine_models::shape::eval::{upper_body, vertex_errors};

fn coefficients(v: &Value) -> Option<[f32; 20]> {
    let a = v.as_array()?;
    let mut z = [0.0; 20];
    for (o, x) in z.iter_mut().zip(a) {
        *o = x.as_f64()? as f32;
    }
    Some(z)
}

fn mean_mm(x: &[f32]) -> f64 {
    x.iter().map(|&v| f64::from(v)).sum::<f64>() / x.len().max(1) as f64 * 1000.0
}

fn main() -> Result<()> {
    let model = BodyModel::load_default()?;
    let mask: Vec<bool> = model.part_of_vertex.iter().map(|&p| upper_body(p)).collect();
    let pose = Pose::rest_for(&model);
    for path in std::env::args().skip(1) {
        let report: Value =
            serde_json::from_str(&std::fs::read_to_string(&path).with_context(|| path.clone())?)?;
        let sequences = report["sequences"]
            .as_array()
            .context("no `sequences` in the report")?;
        let (mut raw_sum, mut aligned_sum, mut n) = (0.0, 0.0, 0usize);
        for s in sequences {
            let v = &s["variants"]["forest_icp_feedback"];
            let (Some(est), Some(truth)) =
                (coefficients(&v["shape_estimate"]), coefficients(&v["shape_true"]))
            else {
                continue;
            };
            let posed = model.pose(&Shape::from_normalised(&model, &truth), &pose);
            let e = vertex_errors(&model, &pose, &est, &posed, &mask);
            let mean_shape = vertex_errors(&model, &pose, &[0.0; 20], &posed, &mask);
            println!(
                "{} raw {:.1} aligned {:.1} mm (mean shape raw {:.1}); torso {:.1} mm",
                s["sequence"].as_str().unwrap_or("?"),
                mean_mm(&e.raw),
                mean_mm(&e.aligned),
                mean_mm(&mean_shape.raw),
                v["torso_surface_error_mm_mean"].as_f64().unwrap_or(f64::NAN)
            );
            raw_sum += mean_mm(&e.raw);
            aligned_sum += mean_mm(&e.aligned);
            n += 1;
        }
        println!(
            "{path}: {n} sequences, mean raw {:.1} mm, aligned {:.1} mm",
            raw_sum / n.max(1) as f64,
            aligned_sum / n.max(1) as f64
        );
    }
    Ok(())
}
