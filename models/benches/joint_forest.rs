//! One frame's joint-forest inference on one core (the target: at most 0.5 ms median): sampling 512 kept
//! pixels, descending the trees, votes and the six mean-shifts, with the committed default forest
//! (`models/artifacts/joints.jfor`) on views rendered here with the body model (seeded; the mannequin stands in
//! when the body model artifact is missing). Run: `cargo bench -p supine-models --bench joint_forest`
//! (criterion reports the median; pin one core with `taskset -c 0`; `SUPINE_JOINT_FOREST=FILE` times another forest). The `_cpu` variants time the same frames in
//! the thread's CPU time (`/proc/thread-self/schedstat`, Linux), which a shared machine's load does not inflate.
// criterion's macros define an undocumented `pub fn benches`.
#![allow(missing_docs)]

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Duration;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::forest::infer::{InferConfig, Method, Workspace, estimate};
use supine_core::forest::model::ForestView;
use supine_core::forest::sample::Clip;
use supine_core::salient::SalientPoint;
use supine_core::time::Timestamp;
use supine_models::dataset::{Dataset, DatasetConfig, generate};
use supine_models::forest::cli::default_path;
use supine_models::forest::data::view_planes;
use supine_models::scene::model_body::{BodyKind, open_source};

/// This thread's CPU time so far, if the kernel tells it (the yield makes the scheduler bring it up to date).
fn thread_cpu() -> Option<Duration> {
    std::thread::yield_now();
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: u64 = s.split_whitespace().next()?.parse().ok()?;
    Some(Duration::from_nanos(ns))
}

fn bench(c: &mut Criterion) {
    // SUPINE_JOINT_FOREST=FILE times another forest file (a candidate before it is committed).
    let path = std::env::var_os("SUPINE_JOINT_FOREST").map_or_else(default_path, std::path::PathBuf::from);
    let bytes = std::fs::read(&path).expect("the committed default forest models/artifacts/joints.jfor");
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
        ..DatasetConfig::default()
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
    let mut frame_i = 0u64;
    let mut one = |method: Method| {
        let (depth, planes) = &frames[(frame_i % frames.len() as u64) as usize];
        let frame = DepthFrame::new(depth, 640, 480, Timestamp::default(), 0).unwrap();
        let clip = Clip::over_image(planes, &k);
        let cfg = InferConfig {
            samples: view.samples_per_frame(),
            seed: frame_i,
            method,
        };
        frame_i += 1;
        black_box(estimate(&view, &frame, &k, &clip, &cfg, &none, &mut ws));
    };
    for (name, method) in [("refined", Method::Refined), ("baseline", Method::Baseline)] {
        c.bench_function(&format!("joint_forest_frame_{name}_512"), |b| {
            b.iter(|| one(method))
        });
        if thread_cpu().is_some() {
            c.bench_function(&format!("joint_forest_frame_{name}_512_cpu"), |b| {
                b.iter_custom(|iters| {
                    let t0 = thread_cpu().unwrap_or_default();
                    for _ in 0..iters {
                        one(method);
                    }
                    thread_cpu().unwrap_or_default().saturating_sub(t0)
                })
            });
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench);
criterion_main!(benches);
