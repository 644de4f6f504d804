//! Per-frame cost of shape estimation on one core (criterion medians): the subspace estimate (canonical view, Eq. 1,
//! forest) and the combined refinement (alternating ICP + Eq. 7), with the committed default models on a frame of
//! the statistical body model. Run: `cargo bench -p supine-models --bench shape`.

use criterion::{Criterion, criterion_main};
use std::hint::black_box;
use supine_core::depth::DepthFrame;
use supine_core::fit::{AXIS_STARTS_M, FitParams, fit_shape, fit_shape_along_axis, initial_pose};
use supine_core::icp::IcpParams;
use supine_core::shape::ShapeModelView;
use supine_core::time::Timestamp;
use supine_models::body::BodyModel;
use supine_models::shape::data::{frames_of, intrinsics, small_dataset};

fn bench(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("supine-shape-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    // Two bodies: the dataset generator refuses a split that leaves the train or the test part empty.
    let ds = small_dataset(&dir, 2, 2, 4).expect("bench frame");
    let bytes =
        std::fs::read(supine_models::shape::default_artifact_path()).expect("models/artifacts/shape.ssm");
    let shape = ShapeModelView::parse(&bytes).expect("valid shape model");
    let model = BodyModel::load_default().expect("body model");
    let body = model.view();
    let k = intrinsics(&ds);
    let rec = ds.read_body(0).expect("body 0");
    let f = frames_of(&rec, &k, 1, 0.03).into_iter().next().expect("a view");
    let frame = DepthFrame::new(&f.depth, k.width, k.height, Timestamp::default(), 0).expect("frame");
    let mut canonical = vec![0.0f32; shape.pixels()];
    let mut points = vec![[0.0f32; 3]; body.counts().subset];
    let mut normals = points.clone();
    c.bench_function("shape/subspace_estimate", |b| {
        b.iter(|| {
            black_box(
                shape
                    .estimate(&frame, &k, &f.noisy_points, &f.mattress, &mut canonical)
                    .ok(),
            )
        })
    });
    let est = shape
        .estimate(&frame, &k, &f.noisy_points, &f.mattress, &mut canonical)
        .expect("estimate");
    let params = FitParams::combined(IcpParams::new(f.mattress), &[0, 3]);
    let pose = initial_pose(&body, &est.shape, &f.noisy_points, &f.mattress.normal()).expect("pose");
    c.bench_function("shape/combined_refinement", |b| {
        b.iter(|| {
            black_box(
                fit_shape(
                    &body,
                    &frame,
                    &k,
                    &est.shape,
                    pose,
                    &params,
                    &mut points,
                    &mut normals,
                )
                .ok(),
            )
        })
    });
    c.bench_function("shape/combined_along_axis", |b| {
        b.iter(|| {
            black_box(
                fit_shape_along_axis(
                    &body,
                    &frame,
                    &k,
                    &est.shape,
                    pose,
                    &AXIS_STARTS_M,
                    &params,
                    &mut points,
                    &mut normals,
                )
                .ok(),
            )
        })
    });
    let _ = std::fs::remove_dir_all(&dir);
}

// criterion's macro defines an undocumented `benches` function.
#[allow(missing_docs)]
mod group {
    criterion::criterion_group!(benches, super::bench);
}
use group::benches;
criterion_main!(benches);
