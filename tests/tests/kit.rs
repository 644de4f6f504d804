//! The test kit itself: the allocation counter counts (and counts nothing for allocation-free work), the fixture
//! model file loads in core's view exactly as core's own tests expect, and the committed recording loads.

use supine_core::body_model::BodyModelView;
use supine_core::fixture;
use supine_tests::alloc_count::{Counting, count_allocations, counter_is_installed};
use supine_tests::fixtures;

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_counter_sees_allocations_and_only_those() {
    assert!(counter_is_installed());
    let (sum, n) = count_allocations(|| (0..1000u32).map(std::hint::black_box).sum::<u32>());
    assert_eq!((sum, n), (499_500, 0));
    let (v, n) = count_allocations(|| vec![0u8; std::hint::black_box(4096)]);
    assert_eq!((v.len(), n), (4096, 1));
}

#[test]
fn parsing_the_fixture_model_allocates_nothing() {
    let bytes = fixtures::tiny_body_model();
    let (view, n) = count_allocations(|| BodyModelView::parse(&bytes).map(|v| v.salient_points(&[0.3, 0.1])));
    assert_eq!(n, 0, "parsing and shaping allocated");
    let points = view.expect("the fixture is a valid body model");
    let rows = fixture::VERTICES + fixture::JOINTS;
    let want = fixture::shaped(rows, &[0.3, 0.1]);
    assert!(
        (0..3).all(|c| (points[0][c] - want[c]).abs() < 1e-6),
        "{points:?} vs {want:?}"
    );
}

#[test]
fn the_demo_recording_loads() {
    let frames = fixtures::demo_frames(5);
    assert_eq!(frames.len(), 5);
    for w in frames.windows(2) {
        assert!(w[1].capture_us > w[0].capture_us, "timestamps increase");
    }
    assert!(
        frames
            .iter()
            .all(|f| f.depth_mm.len() == f.width as usize * f.height as usize)
    );
    assert!(fixtures::load_frames(&fixtures::demo_dir().join("missing.oni"), 1).is_err());
}

/// The fuzz seed of the model-file target is the tiny fixture, byte for byte: a golden file of the container and
/// body-model layouts, and the starting point from which the fuzzer reaches the semantic checks.
/// `SUPINE_BLESS=1` rewrites it after a deliberate format change.
#[test]
fn the_model_file_fuzz_seed_is_the_fixture() {
    let path = fixtures::workspace_root().join("fuzz/seeds/model_file/tiny_body.smf");
    let bytes = fixtures::tiny_body_model();
    if std::env::var_os("SUPINE_BLESS").is_some() {
        std::fs::write(&path, &bytes).unwrap();
    }
    let seed = std::fs::read(&path).expect("the committed fuzz seed");
    assert_eq!(seed, bytes, "{} differs from the fixture", path.display());
}
