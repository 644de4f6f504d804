//! The real-time tracker (`supine_core::tracker`) on the committed demo recording with the committed default
//! models: it initialises and tracks, allocates nothing per frame, replays bit-identically, ICP converges back from
//! a known perturbation, the shape refit on lock (in rounds) moves the shape toward the truth and fits the frame it
//! was chosen on though the next frame runs it, the shape modes keep the shape or go on refitting it (and a known
//! shape is never doubted), and bad frames (empty, wrong size, no patient) lead to defined states.

use std::path::Path;
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::fit::BedContact;
use supine_core::geometry::{Isometry3, Translation3, UnitQuaternion, Vector3};
use supine_core::time::{Timestamp, VirtualClock};
use supine_core::tracker::budget::Stopwatch;
use supine_core::tracker::torso_icp::{self, TorsoIcpConfig};
use supine_core::tracker::{FrameReport, Models, ScratchSizes, Tracker, TrackerConfig};
use supine_core::wire::{Body, Message, ShapeMode, TrackerState};
use supine_drivers::SourceErrorKind;
use supine_drivers::oni::OniReader;
use supine_drivers::tracker_host::{ModelFiles, TrackerScratch};
use supine_models::eval::tracking::{SequenceData, isometry_of};
use supine_tests::alloc_count::{Counting, count_allocations, counter_is_installed};

#[global_allocator]
static ALLOC: Counting = Counting;

fn demo_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("artifacts/demo")
}

fn models() -> ModelFiles {
    ModelFiles::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("artifacts")).expect("committed models")
}

/// The demo's frames, decoded once: depth and capture time.
fn frames() -> Vec<(Vec<u16>, Timestamp)> {
    let mut r = OniReader::open(demo_dir().join("sequence.oni")).expect("demo recording");
    let mut out = Vec::new();
    loop {
        match r.read_frame() {
            Ok(f) => out.push((f.depth_mm().to_vec(), f.capture)),
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) => panic!("demo recording: {e}"),
        }
    }
    assert_eq!(out.len(), 60);
    out
}

fn config(seq: &SequenceData) -> TrackerConfig {
    let mut cfg = TrackerConfig {
        robot_base_from_camera: seq.robot_base_from_camera(),
        ..TrackerConfig::default()
    };
    cfg.up_camera = Some(cfg.robot_base_from_camera.inverse().rotation * Vector3::z());
    cfg
}

/// A tracker on `models` with `cfg` (the Kinect's intrinsics), handed to `f` with a virtual clock at 1 µs.
fn with_tracker<R>(
    models: &Models<'_>,
    cfg: TrackerConfig,
    f: impl FnOnce(&mut Tracker<'_, '_>, &VirtualClock) -> R,
) -> R {
    let k = Intrinsics::KINECT_V1;
    let mut store = TrackerScratch::new(&ScratchSizes::of(models, &k, &cfg.planes));
    let mut tracker = Tracker::new(*models, k, cfg, store.scratch()).unwrap();
    let clock = VirtualClock::new(Timestamp::from_us(1).unwrap());
    f(&mut tracker, &clock)
}

/// A tracker on the committed models with the demo's configuration, handed to `f` with the demo recording's frames
/// and a virtual clock.
fn with_demo_tracker<R>(
    f: impl FnOnce(&mut Tracker<'_, '_>, &[(Vec<u16>, Timestamp)], &VirtualClock) -> R,
) -> R {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    let frames = frames();
    with_tracker(&models, config(&seq), |tracker, clock| f(tracker, &frames, clock))
}

fn frame(depth: &[u16], t: Timestamp, index: u32) -> DepthFrame<'_> {
    DepthFrame::new(depth, 640, 480, t, index).unwrap()
}

/// The depth of the demo played forth and back (0..59, 58..1, 0..59, ... so the motion stays continuous) at step
/// `i`, and its capture time at 30 Hz.
fn forth_and_back(frames: &[(Vec<u16>, Timestamp)], i: usize) -> (&[u16], Timestamp) {
    let period = 2 * (frames.len() - 1);
    let j = i % period;
    let j = if j < frames.len() { j } else { period - j };
    (&frames[j].0, Timestamp::from_us(1 + i as u64 * 33_333).unwrap())
}

/// The frames the init phase took: the index of the first frame that ended in another state.
fn init_frames(states: &[TrackerState]) -> usize {
    states
        .iter()
        .position(|s| *s != TrackerState::Initialising)
        .expect("init finished")
}

/// What [`run`] saw.
struct Run {
    packets: Vec<Message>,
    states: Vec<TrackerState>,
    /// Each frame's tracked pose.
    poses: Vec<Option<Isometry3>>,
    /// Frames after the init phase on which the forest ran (it gave points).
    forest_frames: usize,
    /// Allocations made by `process` after the init phase.
    allocations: u64,
    /// The frame whose processing applied the first surface adaptation round.
    surface_adapted: Option<usize>,
}

/// Run `n` frames (the demo played forth and back).
fn run(models: &Models<'_>, cfg: TrackerConfig, frames: &[(Vec<u16>, Timestamp)], n: usize) -> Run {
    with_tracker(models, cfg, |tracker, clock| {
        let mut packets = Vec::with_capacity(n * 5);
        let mut states = Vec::with_capacity(n);
        let mut poses = Vec::with_capacity(n);
        let mut forest_frames = 0;
        let mut allocations = 0;
        let mut surface_adapted = None;
        for i in 0..n {
            let (depth, t) = forth_and_back(frames, i);
            let f = frame(depth, t, i as u32);
            clock.set(t);
            let initialised = tracker.state() != TrackerState::Initialising;
            let (r, a) = count_allocations(|| tracker.process(&f, None, clock));
            if initialised {
                allocations += a;
                forest_frames += usize::from(r.forest_points.iter().any(Option::is_some));
            }
            states.push(r.state);
            poses.push(r.camera_from_torso);
            packets.extend(r.packets.iter().copied());
            if surface_adapted.is_none() && tracker.surface_rounds() > 0 {
                surface_adapted = Some(i);
            }
        }
        Run {
            packets,
            states,
            poses,
            forest_frames,
            allocations,
            surface_adapted,
        }
    })
}

#[test]
fn tracks_the_demo_without_allocating_and_replays_bit_identically() {
    assert!(counter_is_installed());
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    let frames = frames();
    let cfg = config(&seq);
    let Run {
        packets,
        states,
        allocations,
        surface_adapted,
        ..
    } = run(&models, cfg, &frames, 1000);
    assert_eq!(allocations, 0, "the tracker allocated after init");
    // The surface adaptation ran inside the allocation count and early enough for the replays below to cover it.
    let adapted = surface_adapted.expect("the surface adaptation never ran");
    assert!(adapted < 300, "the surface adaptation ran at frame {adapted}");
    let init = init_frames(&states);
    assert!(init <= 90, "init took {init} frames (3 s)");
    let tracked = states[init..].iter().filter(|s| s.has_pose()).count();
    assert!(
        tracked as f32 >= 0.9 * (states.len() - init) as f32,
        "tracked {tracked} of {} frames after init",
        states.len() - init
    );
    // Every frame ends with a health packet; sequence numbers count up by one.
    for w in packets.windows(2) {
        assert_eq!(w[1].seq, w[0].seq.wrapping_add(1));
    }
    // Replay: the same frames give the same packets, also from inside thread pools of other sizes.
    let again = run(&models, cfg, &frames, 300).packets;
    assert_eq!(&packets[..again.len()], &again[..]);
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let p = pool.install(|| run(&models, cfg, &frames, 120)).packets;
        assert_eq!(&packets[..p.len()], &p[..], "{threads} threads");
    }
}

#[test]
fn the_forest_runs_only_where_its_start_is_needed_and_the_poses_are_those_of_running_it_every_frame() {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    let frames = frames();
    let lazy = config(&seq);
    assert!(!lazy.forest_every_frame, "the default");
    let every = TrackerConfig {
        forest_every_frame: true,
        ..lazy
    };
    let (a, b) = (
        run(&models, lazy, &frames, 300),
        run(&models, every, &frames, 300),
    );
    assert_eq!(a.states, b.states);
    assert_eq!(a.poses, b.poses);
    assert_eq!(a.packets, b.packets);
    let init = init_frames(&a.states);
    let tracked = a.states[init..].iter().filter(|s| s.has_pose()).count();
    assert!(tracked > 200, "tracked {tracked} frames");
    let after_init = a.states.len() - init;
    assert!(
        b.forest_frames * 20 >= after_init * 19,
        "every-frame forest on {} of {after_init}",
        b.forest_frames
    );
    assert!(
        a.forest_frames * 4 < after_init,
        "the forest ran on {} of {after_init} frames",
        a.forest_frames
    );
}

/// The first frame after the init phase that has a tracked pose, and the init phase's last frame.
fn first_tracked(
    models: &Models<'_>,
    cfg: TrackerConfig,
    frames: &[(Vec<u16>, Timestamp)],
) -> (usize, usize) {
    let states = run(models, cfg, frames, 40).states;
    let init = init_frames(&states);
    let first = states.iter().position(|s| s.has_pose()).expect("acquired");
    (first, init)
}

#[test]
fn the_init_fit_lets_the_first_acquisition_confirm_a_frame_sooner() {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    let frames = frames();
    // No fit is sure enough to skip the confirmation over frames (the demo's first fits are), so without the init
    // fit the first acquisition needs a second frame.
    let mut on = TrackerConfig {
        acquire_from_init: true,
        ..config(&seq)
    };
    on.icp.acquire_max_rms_m = 0.0;
    let off = TrackerConfig {
        acquire_from_init: false,
        ..on
    };
    let (first_on, init_on) = first_tracked(&models, on, &frames);
    let (first_off, init_off) = first_tracked(&models, off, &frames);
    assert_eq!(init_on, init_off, "the init phase does not depend on it");
    assert_eq!(
        first_on,
        init_on + 1,
        "on: tracked from the first frame after the init phase"
    );
    assert_eq!(
        first_off,
        first_on + 1,
        "off: the first acquisition waits for a second frame"
    );
}

/// The init phase's last frame and its bed when the first frame is seen `shift_mm` farther away (the whole scene).
fn init_with_first_frame_shifted(
    models: &Models<'_>,
    cfg: TrackerConfig,
    frames: &[(Vec<u16>, Timestamp)],
    shift_mm: u16,
) -> (usize, supine_core::planes::BedScene) {
    with_tracker(models, cfg, |tracker, clock| {
        for (i, (depth, t)) in frames.iter().enumerate() {
            let shifted: Vec<u16> = depth
                .iter()
                .map(|&d| if d == 0 { 0 } else { d + shift_mm })
                .collect();
            let depth = if i == 0 { &shifted } else { depth };
            clock.set(*t);
            tracker.process(&frame(depth, *t, i as u32), None, clock);
            if tracker.state() != TrackerState::Initialising {
                return (i, *tracker.bed().expect("a bed once initialised"));
            }
        }
        panic!("the init phase did not end");
    })
}

#[test]
fn a_first_frames_bed_that_the_next_frames_outvote_is_replaced() {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    let frames = frames();
    let voted = config(&seq);
    assert!(voted.bed_frames > 1, "the default votes");
    let first = TrackerConfig {
        bed_frames: 1,
        ..voted
    };
    let (init_true, bed_true) = init_with_first_frame_shifted(&models, voted, &frames, 0);
    let (init_first, _) = init_with_first_frame_shifted(&models, first, &frames, 0);
    assert_eq!(
        init_true, init_first,
        "the demo's beds agree: the vote changes nothing"
    );
    // Frame 0 seen 15 cm farther: its mattress lies 15 cm low, the next four frames' where it is.
    let (init_kept, bed_kept) = init_with_first_frame_shifted(&models, first, &frames, 150);
    let (init_voted, bed_voted) = init_with_first_frame_shifted(&models, voted, &frames, 150);
    let centre = bed_true.volume.bed_from_camera.inverse() * supine_core::geometry::Point3::origin();
    let off = |b: &supine_core::planes::BedScene| b.mattress.signed_distance(&centre);
    assert!(off(&bed_kept) > 0.1, "one frame's bed kept: {} m", off(&bed_kept));
    assert!(off(&bed_voted).abs() < 0.02, "voted: {} m", off(&bed_voted));
    assert_eq!(init_kept, init_first);
    assert_eq!(
        init_voted,
        init_first + (voted.bed_frames as usize - 1),
        "the shape frames start again with the voted bed"
    );
}

/// The init phase's shape and the shape after `lock_refits` refits in `rounds` rounds (with `bed`, the refits' bed
/// contact) on the demo's first `n` frames, as distances (σ units, all 20 coefficients) to the recording's true
/// shape, and the body-shape revisions sent.
fn shape_after(
    models: &Models<'_>,
    seq: &SequenceData,
    (lock_refits, rounds): (u8, u8),
    bed: Option<BedContact>,
    n: usize,
) -> (f32, f32, Vec<u8>) {
    let cfg = TrackerConfig {
        lock_refits,
        refit_rounds: rounds.saturating_sub(1),
        refit_bed_contact: bed,
        ..config(seq)
    };
    let dist = |z: &[f32; 20]| {
        z.iter()
            .zip(&seq.meta.shape)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f32>()
            .sqrt()
    };
    let mut init = None;
    let mut last = None;
    let mut revisions = Vec::new();
    track_demo(models, cfg, n, None, |_, tracker, r| {
        if init.is_none() {
            init = tracker.shape().map(dist);
        }
        last = tracker.shape().map(dist);
        for p in r.packets.iter() {
            if let Body::BodyShape(b) = p.body
                && revisions.last() != Some(&b.revision)
            {
                revisions.push(b.revision);
            }
        }
    });
    (
        init.expect("init finished"),
        last.expect("init finished"),
        revisions,
    )
}

/// The demo's first `n` frames, in order, through a tracker with `cfg`, frame `blank` (if any) replaced by one
/// without depth; `each(frame index, tracker, report)` after every frame.
fn track_demo(
    models: &Models<'_>,
    cfg: TrackerConfig,
    n: usize,
    blank: Option<usize>,
    mut each: impl FnMut(usize, &Tracker<'_, '_>, &FrameReport),
) {
    let frames = frames();
    let empty = vec![0u16; 640 * 480];
    with_tracker(models, cfg, |tracker, clock| {
        for (i, (d, t)) in frames.iter().enumerate().take(n) {
            clock.set(*t);
            let d = if blank == Some(i) { &empty } else { d };
            let r = tracker.process(&frame(d, *t, i as u32), None, clock);
            each(i, tracker, &r);
        }
    })
}

#[test]
fn shape_refit_on_lock_moves_the_shape_toward_the_truth() {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    let (init, off, revisions) = shape_after(&models, &seq, (0, 1), None, 40);
    assert_eq!(off, init, "no refit: the init phase's shape stays");
    assert_eq!(revisions, [1]);
    let (init3, refit, revisions) = shape_after(&models, &seq, (3, 1), None, 40);
    assert_eq!(init3, init, "the init phase does not depend on the refits");
    // Measured: 4.08 -> 3.32 σ (4.29 -> 3.39 with the joint forest before 2026-12-04's); the refit's mean shape
    // becomes revision 2, announced at once.
    assert!(refit < 0.9 * init, "refit {refit} vs init {init}");
    assert_eq!(revisions, [1, 2]);
    // The bed contact (off by default) changes what the refits find; measured here 5.75 σ against the free refit's
    // 3.32 (on held-out sequences it also lost, docs/tracking.md).
    let (_, on_bed, revisions) = shape_after(&models, &seq, (3, 1), Some(BedContact::default()), 40);
    assert_ne!(on_bed, refit);
    assert_eq!(revisions, [1, 2]);
    // Later rounds wait for the tracker to settle with the new shape, then refit from there: each announces a
    // revision, and the default's three rounds stay as close to the truth as one, within 5 %. Their gain is an
    // average over the validation sequences (docs/tracking.md, ninth round), not a law of every sequence: on this
    // one they measured 3.34 against 3.39 σ with the joint forest before 2026-12-04's, 3.35 against 3.32 σ after.
    let rounds = TrackerConfig::default().refit_rounds + 1;
    let (_, later, revisions) = shape_after(&models, &seq, (3, rounds), None, 60);
    assert_eq!(revisions.len(), 1 + rounds as usize);
    assert!(later <= 1.05 * refit, "{rounds} rounds {later} vs one {refit}");
    assert!(later < 0.9 * init, "{rounds} rounds {later} vs init {init}");
}

/// The body-shape packets (frame, revision, coefficients) of the demo's first `n` frames with the default
/// tracker, frame `blank` (if any) replaced by one without depth.
fn shape_packets(
    models: &Models<'_>,
    seq: &SequenceData,
    n: usize,
    blank: Option<usize>,
) -> Vec<(usize, u8, [i16; 20])> {
    let mut out = Vec::new();
    track_demo(models, config(seq), n, blank, |i, _, r| {
        for p in r.packets.iter() {
            if let Body::BodyShape(b) = p.body {
                out.push((i, b.revision, b.coefficients_milli));
            }
        }
    });
    out
}

#[test]
fn a_lock_refit_chosen_on_a_frame_fits_that_frames_pixels_on_the_next_frame() {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    let all = shape_packets(&models, &seq, 60, None);
    // Revision 1 is the init phase's shape; 2 the first round of lock refits, adopted when the frame after the
    // round's last refit was chosen arrives (the refit runs first), and announced by that frame.
    let &(adopted, revision, shape) = all
        .iter()
        .find(|p| p.1 == 2)
        .expect("the lock refits adopted a shape");
    // That frame's own pixels do not enter the refit: without depth it announces the same shape.
    let blanked = shape_packets(&models, &seq, adopted + 1, Some(adopted));
    assert_eq!(blanked.last(), Some(&(adopted, revision, shape)));
    // The frame the refit was chosen on does: without depth it chooses none, and the next frame adopts nothing.
    let unchosen = shape_packets(&models, &seq, adopted + 1, Some(adopted - 1));
    assert!(
        unchosen.iter().all(|p| p.1 < 2),
        "the refit ran without its frame: {unchosen:?}"
    );
}

#[test]
fn icp_converges_back_from_a_known_perturbation() {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    let frames = frames();
    let k = Intrinsics::KINECT_V1;
    let cfg = TrackerConfig {
        known_shape: Some({
            let mut z = [0.0; 20];
            z.iter_mut().zip(&seq.meta.shape).for_each(|(o, s)| *o = *s);
            z
        }),
        ..config(&seq)
    };
    with_tracker(&models, cfg, |tracker, clock| {
        let mut converged: Option<Isometry3> = None;
        for (i, (d, t)) in frames.iter().enumerate().take(20) {
            let r = tracker.process(&frame(d, *t, i as u32), None, clock);
            converged = r.camera_from_torso.or(converged);
        }
        let converged = converged.expect("the tracker found the torso");
        // The converged pose lies near the truth of the frame it came from.
        let truth = isometry_of(&seq.truth[19].camera_from_torso);
        assert!((converged.translation.vector - truth.translation.vector).norm() < 0.05);
        let (d, t) = &frames[19];
        let f = frame(d, *t, 19);
        let surface = tracker.surface().unwrap();
        let bed = tracker.bed().unwrap();
        let icp = TorsoIcpConfig::default();
        let params = torso_icp::icp_params(&icp, bed);
        let budget = tracker.config().budget;
        let (again, _) = torso_icp::fit_torso(
            &f,
            &k,
            surface.vertices(),
            surface.normals(),
            converged,
            &icp,
            &params,
            &budget,
            0,
            clock,
            &Stopwatch::start(clock),
        );
        for (dt, angle) in [
            (Vector3::new(0.03, 0.0, 0.0), 0.0),
            (Vector3::new(0.0, 0.02, -0.02), 0.05),
            (Vector3::zeros(), -0.08),
        ] {
            // Shifted in the camera frame, turned about the torso's own long axis.
            let start = Isometry3::from_parts(Translation3::from(dt), UnitQuaternion::identity())
                * again
                * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), angle);
            let (back, fit) = torso_icp::fit_torso(
                &f,
                &k,
                surface.vertices(),
                surface.normals(),
                start,
                &icp,
                &params,
                &budget,
                0,
                clock,
                &Stopwatch::start(clock),
            );
            let dp = (back.translation.vector - again.translation.vector).norm();
            let da = back.rotation.angle_to(&again.rotation);
            assert!(
                dp < 0.005 && da < 0.02,
                "from {dt:?} / {angle} rad: {dp} m, {da} rad off ({fit:?})"
            );
        }
    })
}

#[test]
fn bad_frames_lead_to_defined_states() {
    with_demo_tracker(|tracker, frames, clock| {
        let k = Intrinsics::KINECT_V1;
        let empty = vec![0u16; 640 * 480];
        let t0 = Timestamp::from_us(1).unwrap();
        // An empty frame during init: no bed, still initialising, a health packet says so.
        let r = tracker.process(&frame(&empty, t0, 0), None, clock);
        assert_eq!(r.state, TrackerState::Initialising);
        assert!(
            matches!(r.packets.last().unwrap().body, Body::Health(h) if h.state == TrackerState::Initialising)
        );
        // A frame of the wrong size is rejected unprocessed.
        let small = vec![1000u16; 320 * 240];
        let r = tracker.process(&DepthFrame::new(&small, 320, 240, t0, 1).unwrap(), None, clock);
        assert!(r.rejected);
        assert_eq!(r.state, TrackerState::Initialising);
        for (i, (d, t)) in frames.iter().enumerate().take(30) {
            tracker.process(&frame(d, *t, i as u32), None, clock);
        }
        assert!(tracker.state().has_pose());
        // The patient leaves the bed: every pixel above the mattress now sees the mattress behind.
        let bed = *tracker.bed().unwrap();
        let (d, t) = &frames[30];
        let mut gone = d.clone();
        for (i, z) in gone.iter_mut().enumerate() {
            let (u, v) = ((i % 640) as f32, (i / 640) as f32);
            let p = k.unproject(u, v, *z as f32 * 0.001);
            if *z != 0 && bed.mattress.signed_distance(&p) > 0.02 {
                // The mattress plane along this pixel's ray: signed distance is affine in the depth.
                let s0 = bed.mattress.signed_distance(&k.unproject(u, v, 0.0));
                let s1 = bed.mattress.signed_distance(&k.unproject(u, v, 1.0));
                *z = (-s0 / (s1 - s0) * 1000.0).round() as u16;
            }
        }
        let mut states = Vec::new();
        for i in 0..10 {
            states.push(tracker.process(&frame(&gone, *t, 30 + i), None, clock).state);
        }
        assert!(states.contains(&TrackerState::Lost), "{states:?}");
        assert_eq!(*states.last().unwrap(), TrackerState::Reacquiring);
        // Empty frames keep it re-acquiring; the patient back, it tracks again.
        for i in 0..3 {
            assert_eq!(
                tracker.process(&frame(&empty, *t, 40 + i), None, clock).state,
                TrackerState::Reacquiring
            );
        }
        let mut back = TrackerState::Reacquiring;
        for (i, (d, t)) in frames.iter().enumerate().skip(30).take(5) {
            back = tracker.process(&frame(d, *t, 50 + i as u32), None, clock).state;
        }
        assert!(
            matches!(back, TrackerState::Tracking | TrackerState::Degraded),
            "{back:?}"
        );
        // A sensor fault, then the re-initialise command.
        tracker.sensor_fault();
        assert_eq!(tracker.state(), TrackerState::SensorFault);
        tracker.reinitialise();
        assert_eq!(
            tracker
                .process(&frame(&frames[0].0, frames[0].1, 99), None, clock)
                .state,
            TrackerState::Initialising
        );
    });
}

#[test]
fn a_known_shape_is_never_doubted_or_refitted() {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    // Every good tracked frame's residual over the doubt's bar: the doubt fires as soon as it counts.
    let doubting = TrackerConfig {
        doubt_rms_m: 0.0,
        ..config(&seq)
    };
    let lost_after_tracking = |states: &[TrackerState]| {
        let first = states.iter().position(|s| *s == TrackerState::Tracking);
        first.is_some_and(|i| states[i..].contains(&TrackerState::Lost))
    };
    // The control: an estimated shape is doubted once its refits are in, and the lock is dropped.
    let (revisions, states, _) = shape_revisions(&models, doubting, 60, None);
    assert!(lost_after_tracking(&states), "{states:?}");
    assert!(revisions.len() > 1, "{revisions:?}");
    // A known shape (a frozen one kept over a re-initialise) plans no lock refits, so it is never doubted: the
    // refits the doubt would start replaced it before 2026-12-07.
    let mut known = [0.0; 20];
    known
        .iter_mut()
        .zip(&seq.meta.shape)
        .for_each(|(o, s)| *o = *s + 0.5);
    let known_cfg = TrackerConfig {
        known_shape: Some(known),
        ..doubting
    };
    let (revisions, states, shape) = shape_revisions(&models, known_cfg, 60, None);
    assert!(states.contains(&TrackerState::Tracking), "{states:?}");
    assert!(!lost_after_tracking(&states), "{states:?}");
    assert_eq!(revision_numbers(&revisions), [1]);
    assert_eq!(shape, known);
}

/// The revision numbers of [`shape_revisions`]' list, without their frames.
fn revision_numbers(r: &[(usize, u8)]) -> Vec<u8> {
    r.iter().map(|&(_, v)| v).collect()
}

/// What a run of `n` demo frames (forth and back) with `cfg` did to the shape: the frame each new body-shape
/// revision was first sent on, the states, and the shape at the end; `switch` sets a shape mode before the given
/// frame.
fn shape_revisions(
    models: &Models<'_>,
    cfg: TrackerConfig,
    n: usize,
    switch: Option<(usize, ShapeMode)>,
) -> (Vec<(usize, u8)>, Vec<TrackerState>, [f32; 20]) {
    let frames = frames();
    with_tracker(models, cfg, |tracker, clock| {
        let (mut revisions, mut states) = (Vec::new(), Vec::new());
        for i in 0..n {
            if let Some((at, mode)) = switch
                && at == i
            {
                tracker.set_shape_mode(mode);
            }
            let (depth, t) = forth_and_back(&frames, i);
            clock.set(t);
            let r = tracker.process(&frame(depth, t, i as u32), None, clock);
            states.push(r.state);
            for p in r.packets.iter() {
                if let Body::BodyShape(b) = p.body
                    && revisions.last().map(|&(_, v)| v) != Some(b.revision)
                {
                    revisions.push((i, b.revision));
                }
            }
        }
        (revisions, states, *tracker.shape().expect("init finished"))
    })
}

#[test]
fn shape_modes_keep_the_shape_or_go_on_refitting_it() {
    let bytes = models();
    let models = bytes.views().unwrap();
    let seq = SequenceData::load(&demo_dir()).unwrap();
    // Once (the default): the init phase's shape, then one revision per round of lock refits, then no more.
    let rounds = usize::from(TrackerConfig::default().refit_rounds) + 1;
    let (once, ..) = shape_revisions(&models, config(&seq), 240, None);
    assert_eq!(revision_numbers(&once).len(), 1 + rounds, "{once:?}");
    // Continuous: further rounds, each after at least `continuous_refit_frames` good tracked frames.
    let every = 40;
    let continuous = TrackerConfig {
        shape_mode: ShapeMode::Continuous,
        continuous_refit_frames: every,
        ..config(&seq)
    };
    let (more, states, _) = shape_revisions(&models, continuous, 240, None);
    assert_eq!(
        more[..=rounds],
        once[..=rounds],
        "the configured rounds as in once"
    );
    assert!(more.len() >= 1 + rounds + 2, "{more:?} {states:?}");
    for w in more[rounds..].windows(2) {
        assert!(w[1].0 - w[0].0 > usize::from(every), "{more:?}");
    }
    // Frozen from the start: the init phase's shape, never revised.
    let frozen = TrackerConfig {
        shape_mode: ShapeMode::Frozen,
        ..config(&seq)
    };
    let (kept, states, _) = shape_revisions(&models, frozen, 240, None);
    assert_eq!(revision_numbers(&kept), [1]);
    assert!(states.contains(&TrackerState::Tracking));
    // Frozen once tracking has begun: a round under way is dropped, not adopted.
    let first_refit = once[1].0;
    let (dropped, ..) = shape_revisions(
        &models,
        config(&seq),
        240,
        Some((first_refit - 1, ShapeMode::Frozen)),
    );
    assert_eq!(revision_numbers(&dropped), [1]);
    // Frozen just after the first round is in, with every residual over the doubt's bar: the doubt does not judge
    // (firing, it would put the init phase's shape back and refit it).
    let doubting = TrackerConfig {
        doubt_rms_m: 0.0,
        ..config(&seq)
    };
    let switched = once[1].0 + 1;
    let (after, states, _) = shape_revisions(&models, doubting, 240, Some((switched, ShapeMode::Frozen)));
    assert_eq!(revision_numbers(&after), [1, 2]);
    assert!(!states[switched..].contains(&TrackerState::Lost), "{states:?}");
    // Continuous switched on after the configured rounds are over starts a further round.
    let (on, ..) = shape_revisions(
        &models,
        config(&seq),
        240,
        Some((once[rounds].0 + 1, ShapeMode::Continuous)),
    );
    assert_eq!(on[..=rounds], once[..=rounds]);
    assert!(on.len() > 1 + rounds, "{on:?}");
}

#[test]
fn a_reinitialise_keeps_a_frozen_shape_and_estimates_the_shape_again_otherwise() {
    with_demo_tracker(|tracker, frames, clock| {
        let mut i = 0;
        let mut run = |tracker: &mut Tracker<'_, '_>, n: usize| {
            let mut states = Vec::new();
            for _ in 0..n {
                let (depth, t) = forth_and_back(frames, i);
                clock.set(t);
                states.push(tracker.process(&frame(depth, t, i as u32), None, clock).state);
                i += 1;
            }
            states
        };
        // The init phase's estimate, then the lock refits' first round.
        run(tracker, 12);
        let estimated = *tracker.shape().expect("init finished");
        run(tracker, 60);
        let refitted = *tracker.shape().unwrap();
        assert_ne!(refitted, estimated, "a round of lock refits was adopted");
        // Frozen, re-initialised twice (the second time before the init phase is over): the refitted shape stays.
        tracker.set_shape_mode(ShapeMode::Frozen);
        tracker.reinitialise();
        run(tracker, 1);
        tracker.reinitialise();
        let states = run(tracker, 60);
        assert!(states.contains(&TrackerState::Tracking), "{states:?}");
        assert_eq!(*tracker.shape().unwrap(), refitted);
        // Once again: a re-initialise estimates the shape afresh, and the frozen one is gone.
        tracker.set_shape_mode(ShapeMode::Once);
        tracker.reinitialise();
        run(tracker, 12);
        assert_ne!(*tracker.shape().expect("init finished"), refitted);
    });
}
