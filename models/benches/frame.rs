//! Criterion benchmark of the whole tracking frame: `supine_core::tracker::Tracker::process` (joint forest with the
//! feedback prior, torso ICP, probe mapping, packets) on the committed demo recording with the committed default
//! models, after the init phase, one core. Each iteration is the next frame of the recording played forth and back
//! (so the motion stays continuous); the arm state is the truth's probe tip. `tests/bench/run.sh` reads the p50 and
//! p99 over criterion's samples. Run: `taskset -c 0 cargo bench -p supine-models --bench frame`.

use criterion::{Criterion, criterion_main};
use std::hint::black_box;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::geometry::{Point3, isometry_from_rows};
use supine_core::time::{Timestamp, VirtualClock};
use supine_core::tracker::{ArmSample, ScratchSizes, Tracker};
use supine_core::wire::TrackerState;
use supine_drivers::tracker_host::{ModelFiles, TrackerScratch};
use supine_models::eval::tracking::SequenceData;
use supine_tests::fixtures::{demo_dir, demo_frames};

fn bench(c: &mut Criterion) {
    let k = Intrinsics::KINECT_V1;
    let frames = demo_frames(60);
    let seq = SequenceData::load(&demo_dir()).expect("demo truth");
    let files = ModelFiles::load(&demo_dir().join("..")).expect("committed models");
    let models = files.views().expect("models parse");
    let rb = seq.robot_base_from_camera();
    let mut cfg = supine_core::tracker::TrackerConfig {
        robot_base_from_camera: rb,
        ..Default::default()
    };
    cfg.up_camera = Some(rb.inverse().rotation * supine_core::geometry::Vector3::z());
    let mut store = TrackerScratch::new(&ScratchSizes::of(&models, &k, &cfg.planes));
    let mut tracker = Tracker::new(models, k, cfg, store.scratch()).expect("tracker");
    let clock = VirtualClock::new(Timestamp::from_us(1).unwrap());
    let arm: Vec<Option<ArmSample>> = seq
        .truth
        .iter()
        .map(|t| {
            t.world_from_probe.as_ref().map(|m| {
                let p = isometry_from_rows(m);
                ArmSample {
                    time: Timestamp::default(),
                    tip_robot_base: Point3::from(p.translation.vector),
                    robot_base_from_probe: p.rotation,
                }
            })
        })
        .collect();
    let mut i = 0usize;
    let mut step = |tracker: &mut Tracker<'_, '_>| {
        let period = 2 * (frames.len() - 1);
        let j = if i % period < frames.len() {
            i % period
        } else {
            period - i % period
        };
        let t = Timestamp::from_us(1 + i as u64 * 33_333).unwrap();
        clock.set(t);
        let f = DepthFrame::new(&frames[j].depth_mm, k.width, k.height, t, i as u32).unwrap();
        i += 1;
        tracker.process(&f, arm[j].as_ref(), &clock)
    };
    for _ in 0..90 {
        if !matches!(
            tracker.state(),
            TrackerState::Initialising | TrackerState::Acquiring
        ) {
            break;
        }
        step(&mut tracker);
    }
    assert!(
        !matches!(
            tracker.state(),
            TrackerState::Initialising | TrackerState::Acquiring
        ),
        "the tracker did not acquire the demo patient in 90 frames"
    );
    let mut g = c.benchmark_group("frame");
    g.bench_function("tracking", |b| {
        b.iter(|| black_box(step(&mut tracker).packets.len()))
    });
    g.finish();
}

// criterion's macro defines an undocumented `benches` function.
#[allow(missing_docs)]
mod group {
    criterion::criterion_group!(benches, super::bench);
}
use group::benches;
criterion_main!(benches);
