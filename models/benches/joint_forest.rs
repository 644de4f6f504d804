//! One frame's joint-forest inference on one core (the target: at most 0.5 ms median): sampling 512 kept
//! pixels, descending the trees, votes and the six mean-shifts, with the committed default forest
//! (`models/artifacts/joints.jfor`) on views rendered here with the body model (seeded; the mannequin stands in
//! when the body model artifact is missing). Run: `cargo bench -p supine-models --bench joint_forest`
//! (criterion reports the median; pin one core with `taskset -c 0`).
// criterion's macros define an undocumented `pub fn benches`.
#![allow(missing_docs)]

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::forest::infer::{InferConfig, Method, Workspace, estimate};
use supine_core::forest::model::ForestView;
use supine_core::salient::SalientPoint;
use supine_core::time::Timestamp;
use supine_models::dataset::{Dataset, DatasetConfig, generate};
use supine_models::forest::cli::default_path;
use supine_models::forest::data::{clip_for, view_planes};
use supine_models::render::noise::KinectNoise;
use supine_models::scene::model_body::{BodyKind, open_source};

fn bench(c: &mut Criterion) {
    let bytes =
        std::fs::read(default_path()).expect("the committed default forest models/artifacts/joints.jfor");
    let view = ForestView::parse(&bytes).expect("valid default forest");
    let dir = std::env::temp_dir().join(format!("supine-forest-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let cfg = DatasetConfig {
        bodies: 2,
        views: 4,
        seed: 77,
        occluder_fraction: 0.3,
        train_fraction: 0.5,
        previews: 0,
        noise: KinectNoise::default(),
        view_distance_scale: 1.0,
    };
    let source = open_source(BodyKind::Model, None).or_else(|_| open_source(BodyKind::Mannequin, None));
    generate(source.expect("a body source").as_ref(), &cfg, &dir, &|| {}).expect("bench views");
    let ds = Dataset::open(&dir).expect("bench dataset");
    let rec = ds.read_body(0).expect("bench body");
    let frames: Vec<_> = rec
        .views
        .iter()
        .map(|v| (v.full_depth(640, 480), view_planes(&v.truth)))
        .collect();
    let k = Intrinsics::KINECT_V1;
    let mut ws = Box::new(Workspace::new());
    let none = [None; SalientPoint::COUNT];
    for (name, method) in [("refined", Method::Refined), ("baseline", Method::Baseline)] {
        let mut i = 0u64;
        c.bench_function(&format!("joint_forest_frame_{name}_512"), |b| {
            b.iter(|| {
                let (depth, planes) = &frames[(i % frames.len() as u64) as usize];
                let frame = DepthFrame::new(depth, 640, 480, Timestamp::default(), 0).unwrap();
                let clip = clip_for(planes, &k);
                let cfg = InferConfig {
                    samples: view.samples_per_frame(),
                    seed: i,
                    method,
                };
                i += 1;
                black_box(estimate(&view, &frame, &k, &clip, &cfg, &none, &mut ws))
            })
        });
    }
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
