//! Criterion benchmarks of every per-frame stage that exists, one core, on frame 30 of the committed demo recording
//! (`models/artifacts/demo/`, with the robot arm over the torso) and the committed default models: the clip (the
//! init phase's volume of interest over all pixels), the joint forest (sampling and tree descent, 512 samples), the
//! six mean-shifts (votes and modes), the canonical view, the subspace projection, one ICP iteration (torso surface
//! of the sequence's shape against the depth, 3 cm / 3° off the truth), probe mapping and packet encoding (pose,
//! salient points, probe). Run: `cargo bench -p supine-models --bench stages` (pin one core with `taskset -c 0`);
//! `tests/bench/run.sh` reads the medians from `target/criterion/stages/`.
//!
//! The whole frame is not here: it is the tracker's loop (a `frame` bench joins when the tracker lands).

use criterion::{Criterion, criterion_main};
use std::hint::black_box;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::forest::MAX_SAMPLES;
use supine_core::forest::infer::{InferConfig, Method, Workspace, estimate, reestimate, sample_and_descend};
use supine_core::forest::model::ForestView;
use supine_core::forest::sample::Clip;
use supine_core::geometry::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3, isometry_from_rows};
use supine_core::icp::{IcpParams, point_to_plane_step};
use supine_core::planes::{PlaneConfig, estimate_bed, scratch_points};
use supine_core::probe::map_tip;
use supine_core::salient::SalientPoint;
use supine_core::shape::ShapeModelView;
use supine_core::shape::canonical::{body_frame, canonical_view};
use supine_core::time::Timestamp;
use supine_core::torso::{TorsoBuffers, TorsoSurface};
use supine_core::wire::BodyRegion;
use supine_core::wire::message::Message;
use supine_core::wire::sample::MESSAGES;
use supine_models::body::BodyModel;
use supine_models::sequence::{FrameTruth, SequenceMeta};
use supine_tests::fixtures::{demo_dir, demo_frames};

/// The demo frame the stages run on (the arm is over the torso there).
const FRAME: usize = 30;

fn bench(c: &mut Criterion) {
    let k = Intrinsics::KINECT_V1;
    let frames = demo_frames(FRAME + 1);
    let depth = &frames[FRAME].depth_mm;
    let frame = DepthFrame::new(depth, k.width, k.height, Timestamp::default(), 0).expect("demo frame");
    let meta: SequenceMeta =
        serde_json::from_slice(&std::fs::read(demo_dir().join("sequence.json")).expect("demo meta"))
            .expect("demo meta parses");
    let truth: FrameTruth = serde_json::from_str(
        std::fs::read_to_string(demo_dir().join("truth.jsonl"))
            .expect("demo truth")
            .lines()
            .nth(FRAME)
            .expect("truth of the frame"),
    )
    .expect("truth parses");
    let mattress = meta.planes_camera[1];
    let mut g = c.benchmark_group("stages");

    // Clip: the init phase finds the bed once; every frame then tests every pixel against its volume.
    let pc = PlaneConfig::default();
    let n = scratch_points(k.width as usize, k.height as usize, pc.stride as usize);
    let (mut pts, mut labels) = (vec![Point3::origin(); n], vec![0u8; n]);
    let bed = estimate_bed(&frame, &k, &pc, None, &mut pts, &mut labels).expect("bed of the demo frame");
    g.bench_function("clip", |b| {
        b.iter(|| {
            let mut kept = 0u32;
            for (i, &d) in depth.iter().enumerate() {
                let (u, v) = ((i % 640) as u16, (i / 640) as u16);
                kept += bed.volume.keeps_pixel(&k, u, v, d) as u32;
            }
            black_box(kept)
        })
    });

    // Forest: 512 samples of the clip and their descent through every tree (the lockstep descent `estimate` runs);
    // then the votes and six mean-shifts from those leaves; then both (`estimate`).
    let fbytes =
        std::fs::read(supine_models::forest::cli::default_path()).expect("models/artifacts/joints.jfor");
    let forest = ForestView::parse(&fbytes).expect("valid default forest");
    let planes = [mattress, meta.planes_camera[2]];
    let clip = Clip::over_image(&planes, &k);
    let samples = forest.samples_per_frame().min(MAX_SAMPLES);
    let mut ws = Box::new(Workspace::new());
    let icfg = InferConfig {
        samples,
        seed: 7,
        method: Method::Refined,
    };
    let none = [None; SalientPoint::COUNT];
    g.bench_function("forest_sample_descend", |b| {
        b.iter(|| black_box(sample_and_descend(&forest, &frame, &k, &clip, &icfg, &mut ws)))
    });
    sample_and_descend(&forest, &frame, &k, &clip, &icfg, &mut ws);
    g.bench_function("mean_shift", |b| {
        b.iter(|| black_box(reestimate(&forest, Method::Refined, &none, &mut ws)))
    });
    g.bench_function("forest_total", |b| {
        b.iter(|| black_box(estimate(&forest, &frame, &k, &clip, &icfg, &none, &mut ws)))
    });

    // Shape: canonical view and subspace projection (the init phase's per-frame shape estimate).
    let sbytes =
        std::fs::read(supine_models::shape::default_artifact_path()).expect("models/artifacts/shape.ssm");
    let shape = ShapeModelView::parse(&sbytes).expect("valid shape model");
    let salient = truth.salient_camera.map(Point3::from);
    let camera_from_body = body_frame(&salient, &mattress.normal()).expect("body frame");
    let mut canonical = vec![0.0f32; shape.pixels()];
    g.bench_function("canonical_view", |b| {
        b.iter(|| {
            black_box(
                canonical_view(
                    &frame,
                    &k,
                    &camera_from_body,
                    &mattress,
                    shape.camera(),
                    &mut canonical,
                )
                .ok(),
            )
        })
    });
    canonical_view(
        &frame,
        &k,
        &camera_from_body,
        &mattress,
        shape.camera(),
        &mut canonical,
    )
    .expect("view");
    g.bench_function("subspace_projection", |b| {
        b.iter(|| black_box(shape.subspace().project(&canonical).ok()))
    });

    // ICP: one projective point-to-plane step of the shaped torso surface.
    let model = BodyModel::load_default().expect("body model");
    let body = model.view();
    let nv = body.counts().subset;
    let mut vertices = vec![Point3::origin(); nv];
    let mut normals = vec![Vector3::zeros(); nv];
    let mut regions = vec![BodyRegion::OffBody; nv];
    let surface = TorsoSurface::build(
        &body,
        &meta.shape,
        TorsoBuffers {
            vertices: &mut vertices,
            normals: &mut normals,
            regions: &mut regions,
        },
    )
    .expect("torso surface");
    let mp: Vec<[f32; 3]> = surface.vertices().iter().map(|p| p.coords.into()).collect();
    let mn: Vec<[f32; 3]> = surface.normals().iter().map(|v| (*v).into()).collect();
    let camera_from_torso = isometry_from_rows(&truth.camera_from_torso);
    let start = Isometry3::from_parts(
        Translation3::new(0.02, -0.015, 0.015),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.03, -0.03, 0.02)),
    ) * camera_from_torso;
    let params = IcpParams::new(mattress);
    g.bench_function("icp_iteration", |b| {
        b.iter(|| black_box(point_to_plane_step(&frame, &k, &mp, Some(&mn), 1, &start, &params).ok()))
    });

    // Probe mapping: the arm's tip (truth of the frame) onto the torso surface.
    let tip = truth
        .camera_from_probe
        .map(|m| isometry_from_rows(&m).translation.vector)
        .expect("the demo frame has the arm");
    let tip_torso = camera_from_torso.inverse_transform_point(&Point3::from(tip));
    g.bench_function("probe_mapping", |b| {
        b.iter(|| black_box(map_tip(&surface, &tip_torso)))
    });

    // Packets: the per-frame pose, salient points and probe messages, COBS-framed.
    let per_frame: Vec<Message> = MESSAGES[..3].to_vec();
    let mut buf = [0u8; 512];
    g.bench_function("packet_encode", |b| {
        b.iter(|| {
            let mut total = 0;
            for m in &per_frame {
                total += m.encode_serial(&mut buf).unwrap_or(0);
            }
            black_box(total)
        })
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
