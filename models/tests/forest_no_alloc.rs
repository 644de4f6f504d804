//! One frame's joint-forest inference never touches the heap: a counting global allocator watches this thread
//! while a trained forest (tiny, trained here) estimates the six points on generated frames, with and without
//! priors, for both vote methods, and re-estimates from the kept leaves without them (equal to the plain estimate),
//! and must see zero allocations.
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::forest::infer::{InferConfig, Method, Workspace, estimate, reestimate};
use supine_core::forest::meanshift::Prior;
use supine_core::forest::model::ForestView;
use supine_core::forest::sample::Clip;
use supine_core::salient::SalientPoint;
use supine_core::time::Timestamp;
use supine_models::dataset::{Dataset, DatasetConfig, generate};
use supine_models::forest::data::view_planes;
use supine_models::forest::refine::RefineParams;
use supine_models::forest::train::{TrainConfig, train};
use supine_models::forest::tree::TreeParams;
use supine_models::scene::body::Mannequin;
use supine_tests::alloc_count::{Counting, count_allocations, counter_is_installed};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn inference_allocates_nothing() {
    let dir = std::env::temp_dir().join(format!("supine-forest-noalloc-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let cfg = DatasetConfig {
        bodies: 4,
        views: 2,
        seed: 9,
        occluder_fraction: 0.5,
        train_fraction: 0.75,
        previews: 0,
        ..DatasetConfig::default()
    };
    generate(&Mannequin, &cfg, &dir, &|| {}).unwrap();
    let ds = Dataset::open(&dir).unwrap();
    let tc = TrainConfig {
        trees: 3,
        samples_per_image: 256,
        tree: TreeParams {
            max_depth: 8,
            candidates: 16,
            min_split: 20,
            ..TreeParams::default()
        },
        validation_fraction: 0.34,
        refine: RefineParams {
            epochs: 2,
            ..RefineParams::default()
        },
        ..TrainConfig::default()
    };
    let (forest, _) = train(&ds, &tc, false).unwrap();
    let bytes = forest.to_file_bytes("{}").unwrap();
    let view = ForestView::parse(&bytes).unwrap();
    let rec = ds.read_body(ds.test[0]).unwrap();
    let k = Intrinsics::KINECT_V1;
    let mut ws = Box::new(Workspace::new());
    let frames: Vec<(Vec<u16>, _)> = rec
        .views
        .iter()
        .map(|v| (v.full_depth(640, 480), view_planes(&v.truth)))
        .collect();
    let prior = Prior {
        mean: rec.views[0].truth.salient_camera[0],
        sigma_m: [0.1; 3],
    };
    let priors = [Some(prior); SalientPoint::COUNT];
    let none = [None; SalientPoint::COUNT];
    let mut found = 0;
    assert!(counter_is_installed());
    let ((), n) = count_allocations(|| {
        for (depth, planes) in &frames {
            let frame = DepthFrame::new(depth, 640, 480, Timestamp::default(), 0).unwrap();
            let clip = Clip::over_image(planes, &k);
            for (seed, method) in [(1, Method::Refined), (2, Method::Baseline)] {
                let cfg = InferConfig {
                    samples: 512,
                    seed,
                    method,
                };
                let plain = estimate(&view, &frame, &k, &clip, &cfg, &none, &mut ws);
                let primed = estimate(&view, &frame, &k, &clip, &cfg, &priors, &mut ws);
                found += plain.iter().flatten().count() + primed.iter().flatten().count();
                // The same samples' votes again without the prior (the tracker's second look): the plain estimate.
                assert_eq!(reestimate(&view, method, &none, &mut ws), plain);
            }
        }
    });
    assert!(found > 0, "the forest found points");
    assert_eq!(n, 0, "inference allocated {n} times");
}
