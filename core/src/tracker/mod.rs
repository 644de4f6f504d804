//! The real-time tracker (paper Fig. 1) as one allocation-free loop: `Tracker::process(frame, arm, clock)`.
//!
//! Init phase (state `initialising`, first frames with the patient still): the bed's planes and volume of interest
//! ([`crate::planes`]) from the first frame, voted over the first `bed_frames` ([`bed_vote`]: a voted bed that differs
//! restarts the shape frames); then the joint forest's points and the subspace shape estimate on each of
//! `shape_frames` frames, averaged; then one refinement by model fitting ([`crate::fit`], Eq. 7) unless the
//! budget forbids it; then the shaped torso model ([`crate::torso`]) built once into the caller's buffers.
//!
//! Per frame after init: the forest's six points (with a Gaussian prior around the last refined points in the
//! feedback variant, paper Sect. 3.4) give the torso frame; rigid point-to-plane ICP of the torso model refines it
//! ([`torso_icp`]: robust, occluder-aware, with what lies low over the bed taken as the patient rather than the arm,
//! a fixed iteration count cut by the [`budget`]); the refined pose and points feed the next frame's prior; probe
//! mapping ([`crate::probe`]) maps the newest arm state onto the surface; the [`state`] machine decides what the
//! health message says; packets are stamped with the frame's capture time. With a pose to fit from, the fit from that
//! pose (the temporal start) runs first and the forest only when its start is needed (the temporal fit neither good
//! nor followed while occluded): the forest's points would go unused on the other frames, so the poses are those of
//! running it every frame ([`TrackerConfig::forest_every_frame`]) without its millisecond on most tracked frames.
//!
//! A fit is good when its residual is small, most pairs lie within the shape's mismatch and the camera does not
//! see through the model ([`torso_icp::TorsoFit::support`]). Without a pose (acquiring, re-acquiring) the fit starts
//! from the forest's pose, that pose turned about the body axis, and the torso laid on the bed around it
//! ([`bed_search`]); a good fit is trusted at once only when its residual is very low, otherwise once consecutive
//! frames agree on it, and a fit good but for its residual once four frames in a row agree on it
//! ([`TorsoIcpConfig::near_confirm`]: an init shape far off keeps even the right pose over the bar); while
//! tracking, a good fit from a start other than the temporal one that lands far from it is not trusted (the patient
//! does not jump), unless the pose's own fit is not good and the far fit sees clearly more of the torso on two frames
//! in a row: then the pose was a wrong lock ([`TorsoIcpConfig::switch_margin`]).
//! When the pose's own fit sees a clear view of the torso that it does not match (enough of it seen, too little
//! support), the frame looks again as an acquisition would, from the forest without the prior, and a far fit with
//! clearly more support replaces the pose on two frames in a row ([`TorsoIcpConfig::clear_view_min_support`]).
//! Pixels without depth over the torso count as hidden, so a torso under the arm's shadow coasts as occluded
//! instead of being lost. While occluded, the pose follows a clean fit from the temporal start that stays near it,
//! with that fit's rotation held where the little it sees does not fix it
//! ([`TorsoIcpConfig::follow_occluded`], [`TrackerConfig::occluded_hold_rotation`]).
//!
//! The torso model is revised on the first tracked frames: lock refits of the shape (Eq. 7 from the tracked pose,
//! [`TrackerConfig::lock_refits`], in [`TrackerConfig::refit_rounds`]), then the [`surface`] adaptation, which moves
//! the model's front along its normals onto what a few well-seen frames show of this patient
//! ([`TrackerConfig::surface`]). A lock refit chosen on a frame runs when the next frame arrives, on a copy of the
//! chosen frame's depth ([`Scratch::refit_depth`]): the frame that locks has paid for the acquisition's fits.
//! A lock whose fit keeps a high residual once the first round of refits is in is doubted ([`doubt`]): the init
//! phase's shape goes back into the torso model and the tracker re-acquires, once per init phase. The shape mode
//! ([`TrackerConfig::shape_mode`], the arm controller's command) keeps the shape as it is (frozen) or goes on
//! refitting it every few seconds while tracking (continuous).
//!
//! Three variants share the loop, for the evaluation of the paper's claim: [`Variant::Forest`] (the forest's points
//! alone give the pose), [`Variant::ForestIcp`] (ICP from the forest each frame, no prior), and
//! [`Variant::ForestIcpFeedback`] (the product).
//!
//! Memory: the models are borrowed views, all scratch is the caller's ([`Scratch`], sized by [`ScratchSizes`]);
//! nothing allocates. Cost per tracking frame: up to `icp_iterations` ICP iterations (20-40 µs each), probe mapping
//! (tens of µs) and five packets, and the forest (about 1 ms) on the frames that need its start (every frame without
//! a pose); an acquiring frame adds the bed search's screening (0.5-1 ms) and up to six full fits, and a second look
//! a second mean-shift and three fits.

pub mod accuracy;
pub mod bed_search;
pub mod bed_vote;
pub mod budget;
pub mod doubt;
pub mod state;
pub mod surface;
pub mod torso_icp;

use core::cell::Cell;

use crate::body_model::{BodyModelView, SHAPE_COMPONENTS};
pub use crate::calib::ArmSample;
use crate::calib::solve::{Pair, kabsch};
use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::fit::{self, FitParams};
use crate::forest::infer::{self, InferConfig, Method, PointEstimate, Workspace};
use crate::forest::meanshift::Prior;
use crate::forest::model::ForestView;
use crate::geometry::{Isometry3, Point3, UnitQuaternion, Vector3};
use crate::icp;
use crate::normal_memo::{MemoCell, MemoStamp};
use crate::planes::{self, BedScene, PlaneConfig};
use crate::probe::{self, ProbeMapping};
use crate::rng::mix_seed;
use crate::salient::SalientPoint;
use crate::shape::ShapeModelView;
use crate::shape::combine::{MAX_SHAPE_FRAMES, ShapeCombine};
use crate::time::{Clock, Timestamp};
use crate::torso::{self, TorsoBuffers, TorsoSurface};
use crate::wire::{
    self, BodyRegion, BodyShape, Confidence, Health, Message, SalientPointReport, SalientPoints, ShapeMode,
    TorsoPose, TrackerState, UnitQuatQ14,
};
use budget::{BudgetConfig, BudgetCounters, Stage, StageTimes, Stopwatch};
use state::{FitQuality, StateLimits, StateMachine};
use surface::{SurfaceConfig, VertexSums};
use torso_icp::{TorsoFit, TorsoIcpConfig};

const P: usize = SalientPoint::COUNT;
/// Default [`TrackerConfig::forest_ceiling_m`]: chosen on the validation sequences (`docs/joint-forest.md`, 0.4 m cut
/// parts of some patients, 0.5 m none measurably); a patient lying on the bed stays well below it, the arm's upper
/// links do not.
pub const FOREST_CEILING_M: f32 = 0.6;

/// Which parts of the loop run (the evaluation compares them; the product is [`Variant::ForestIcpFeedback`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    /// The forest's points alone give the torso pose.
    Forest,
    /// ICP refines the forest's pose every frame; no prior.
    ForestIcp,
    /// ICP refines, and the refined points are the next frame's forest prior.
    ForestIcpFeedback,
}

impl Variant {
    /// Every variant.
    pub const ALL: [Variant; 3] = [Variant::Forest, Variant::ForestIcp, Variant::ForestIcpFeedback];

    /// Name used in reports (`forest`, `forest_icp`, `forest_icp_feedback`).
    pub const fn name(self) -> &'static str {
        match self {
            Variant::Forest => "forest",
            Variant::ForestIcp => "forest_icp",
            Variant::ForestIcpFeedback => "forest_icp_feedback",
        }
    }
}

/// Tracker settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerConfig {
    /// Which parts of the loop run.
    pub variant: Variant,
    /// Frame budget and ICP iteration count.
    pub budget: BudgetConfig,
    /// Frames whose shape estimates the init phase combines (at most [`MAX_SHAPE_FRAMES`]). 10: 30 was measured on
    /// 2026-12-05 (146 validation and 100 fresh sequences): torso 12.22 -> 11.24 and 15.91 -> 14.78 mm, but probe
    /// 10.96 -> 11.58 and 15.34 -> 15.83 mm and fewer frames tracked (0.979 -> 0.975, 0.986 -> 0.975), the init
    /// shape's rigid floor unchanged (9.2-9.5 mm): the frames' forest points err alike, so more of them add little.
    pub shape_frames: u16,
    /// Frames whose bed estimates the init phase votes on ([`bed_vote`]; at most [`MAX_BED_FRAMES`]): the first bed
    /// found serves the shape frames, and when the vote over the first `bed_frames` frames tried replaces it the
    /// shape frames start again (1: the first bed found is kept). 5 since 2026-12-05: under the tracker's seed,
    /// which the earlier rounds' bed rules were tuned on, the choice sets barely moved (146 validation sequences
    /// torso 10.31 -> 10.31 mm, 70001-70200 12.54 -> 12.58 mm); under seeds 1 and 2 a first bed 78 or 218 mm off put
    /// a whole sequence 0.5-0.6 m off (s29009 616 mm, s70105 502 mm), and over the three seeds the vote took the
    /// torso means from 12.07 to 10.68 mm and 13.10 to 12.26 mm (probe 12.85 -> 11.34, 13.14 -> 11.81 mm); fresh
    /// held-out 43001-43096, three seeds: 13.18 -> 13.13 mm, tracked 96.42 -> 96.77 % (docs/tracking.md,
    /// twenty-fourth round).
    pub bed_frames: u8,
    /// How the init phase combines its frames' shape estimates: the mean. The per-coefficient median (the shape
    /// evaluation's multi-frame estimate) was measured on 2026-12-05 and left the init shape's rigid floor as it was
    /// (9.19 -> 9.12 mm on the 146 validation sequences; torso 12.22 -> 12.46 mm there, 15.91 -> 15.33 mm on 100
    /// fresh ones: the acquisitions re-drawn, docs/tracking.md, seventeenth round).
    pub shape_combine: ShapeCombine,
    /// Whether the init phase refines the shape by model fitting.
    pub refine_shape: bool,
    /// Whether the init phase's shape estimate reads the salient points' spacing (the shape model's `LINP`
    /// regression) or the canonical view's coefficients alone (`LINR`). Off: the forest's points on the tracking
    /// sequences are 50-300 mm off, far worse than the 30 mm the regression was trained with, and on the 46
    /// validation sequences reading them moved the torso error 10.09 / 6.21 -> 11.07 / 5.87 mm (mean / median) and
    /// the probe error 8.87 -> 11.08 mm (docs/shape-eval.md, "The salient points' spacing").
    pub shape_point_features: bool,
    /// A shape known beforehand (σ units; a frozen shape kept over a re-initialise, or a diagnostic): the init
    /// phase then finds only the bed.
    pub known_shape: Option<[f32; SHAPE_COMPONENTS]>,
    /// Shape coefficients that carry the torso (Eq. 7's weak prior on them; the rest are held near the estimate).
    pub torso_coeffs: [bool; SHAPE_COMPONENTS],
    /// Eq. 7's Λ on `torso_coeffs` in the init phase's refinement: 1e-3. The shape evaluation's choice
    /// ([`fit::FREE_PRIOR_WEIGHT`], 0.1) was a wash here on the 20 validation sequences with figures (torso 17.08 ->
    /// 17.44 mm, probe 13.18 -> 12.75 mm; docs/tracking.md), so the tracker keeps the value it was tuned with.
    pub shape_free_weight: f32,
    /// Whether the shape refinement starts from a rigid registration of the estimated torso (the forest's pose and
    /// the [`bed_search`] grid, best support) instead of the forest's points alone. Off by default: on validation
    /// sequences it tracked more frames (0.745 against 0.717) but with a larger torso error (20.9 against 16.2 mm;
    /// docs/tracking.md).
    pub search_shape_start: bool,
    /// Whether the init phase's refinement, which registers the body model to the frame that ends the init phase,
    /// hands its torso pose to the first acquisition: as a start (as a re-acquisition starts from the last good
    /// pose) and as the first of [`TorsoIcpConfig::acquire_confirm`]'s consistent frames, so a first fit that agrees
    /// with it is trusted a frame sooner. On by default since 2026-12-04: on the 146 validation sequences the tracked
    /// share rose 0.9745 -> 0.9801 (early misses 399 -> 331 on 29001-29100) with the torso error 10.43 -> 10.49 mm
    /// and the probe error unchanged (docs/tracking.md, fifteenth round).
    pub acquire_from_init: bool,
    /// Shape refits (Eq. 7, plain: no prior but λ's) on the first frames tracked after the init phase that see enough
    /// of the torso ([`TrackerConfig::refit_min_visible`]), averaged and then built into the torso model (0: off).
    /// The init phase's refinement starts from the forest's points, which on a view with the arm can be 15-25 cm
    /// off, so it barely moves the shape; a refit from a confirmed tracked pose starts where ICP already holds the
    /// torso (docs/tracking.md, "Shape refit on lock").
    pub lock_refits: u8,
    /// A lock refit waits for a tracked frame whose fit sees at least this share of the front-facing torso (0: the
    /// first good fits): a refit on a half-hidden torso fits the shape to what hides it. On the 22 validation
    /// sequences 0.5 took the torso error from 15.2 to 13.6 mm (val2; s619 33.0 -> 18.2) and moved no sequence up by
    /// more than 0.5 mm (docs/tracking.md, "The bed's head section, and lock refits on a visible torso").
    pub refit_min_visible: f32,
    /// After this many frames with a pose and lock refits still waiting, they take a fit that sees
    /// [`TrackerConfig::refit_late_min_visible`] of the torso instead (0: never). A patient whose own arms hide half
    /// the torso for the whole sequence never shows half of it: without this the init phase's estimate stays, which
    /// on the validation sequences where it happened was 10-20 mm worse than a refit (s4012 24.6 mm, s5007 28.7 mm).
    pub refit_late_frames: u16,
    /// Further rounds of lock refits after the first: once a round's shape is adopted and the tracker has settled
    /// with it ([`TrackerConfig::refit_settle_frames`]), the same number of refits run again from the pose it
    /// settled into, starting from that shape (0: one round only). A first round from a pose still 10-25 mm off
    /// fits part of that error into the shape; from the pose the new shape settles into, the next round fits it
    /// out. On the 46 validation sequences (settling 10 frames) 2 rounds moved the torso error 10.90 / 6.86 ->
    /// 10.27 / 6.40 mm (mean / median) and the probe error 9.27 -> 9.05 mm, 14 sequences gaining more than 0.5 mm
    /// and 3 losing (s402 +2.4 mm); 1 round gave 10.38 / 6.54 and 9.15, 4 rounds 10.29 / 6.41 and 9.13 with s402
    /// +4.1 mm (docs/tracking.md, "Lock refits in rounds").
    pub refit_rounds: u8,
    /// A further round of lock refits ([`TrackerConfig::refit_rounds`]) waits for this many consecutive good
    /// tracked frames with the adopted shape: 10. On the validation sequences with one further round: 3 gave 10.95
    /// mm (s4004 refit from a pose still sliding: +21 mm), 10 gave 10.38, 20 gave 10.44, 30 gave 10.70 mm.
    pub refit_settle_frames: u16,
    /// What the tracker does with the shape after the init phase (the wire's shape mode, set by the arm controller's
    /// command): [`ShapeMode::Once`], the default, runs the lock refits' rounds and then keeps the shape;
    /// [`ShapeMode::Frozen`] keeps the shape it has (no further refits, no doubt; [`Tracker::reinitialise`] keeps
    /// it over the new init phase, as [`TrackerConfig::known_shape`]; the [`surface`] adaptation's rounds still
    /// run: they move the model's front, not the shape); [`ShapeMode::Continuous`] goes on with a round of lock
    /// refits every [`TrackerConfig::continuous_refit_frames`] good tracked frames after the configured rounds.
    pub shape_mode: ShapeMode,
    /// In [`ShapeMode::Continuous`], the consecutive good tracked frames with the current shape a further round of
    /// lock refits waits for: 90 (3 s at 30 Hz), so a revision is sent at most every few seconds.
    pub continuous_refit_frames: u16,
    /// The lock refits' visibility gate once [`TrackerConfig::refit_late_frames`] have passed: 0.4. On the 46
    /// validation sequences, after 30 frames, 0.4 moved the torso error 11.28 -> 10.90 mm and the probe error 9.46 ->
    /// 9.27 mm, four sequences gaining more than 0.5 mm and none losing; 0.3 and 0.35 refit s619 on its own arms
    /// (+6.8 mm), as did 0.4 after 15 frames (+4.5 mm); after 60 frames 0.4 helped two sequences (docs/tracking.md).
    pub refit_late_min_visible: f32,
    /// The lock refits hold the torso's lowest point on the mattress ([`fit::fit_shape_on_bed`]; `None`, the
    /// default: free). The front surface alone cannot tell a thick patient from a thin one nearer the camera, and the
    /// bed pins the back; but it helped on validation (torso 17.1 -> 16.2 mm) and hurt on held-out sequences (8.2 ->
    /// 9.7 mm), so it is not the default (docs/tracking.md). Measured again once every sequence's patient lay with
    /// the back on the mattress (83a1d85; choice set 73021-73220): torso 8.53 -> 8.74 mm, tracked 99.17 -> 98.96 %
    /// (forty-first round).
    pub refit_bed_contact: Option<fit::BedContact>,
    /// Eq. 7's λ (pull toward the mean body) in the lock refits: 0.01, a tenth of the shape evaluation's 0.1. From
    /// a tracked pose the fit sees the chest and belly well, and 0.1 shrank what it found toward the mean body. On
    /// the 46 validation sequences λ 0.1 / 0.03 / 0.01 / 0.003 / 0.001 gave a torso error of 14.8 / 13.0 / 12.9 /
    /// 12.9 / 13.2 mm (medians 8.1 / 6.8 / 6.6 / 5.9 / 5.8) and a probe error of 12.7 / 11.2 / 11.2 / 11.3 / 11.4 mm;
    /// at 0.01, 30 sequences gained more than 0.5 mm and 3 lost (docs/tracking.md, "Lock refits with a weaker pull").
    pub refit_lambda: f32,
    /// The lock refits use every `refit_stride`-th vertex of the body model's subset (1: all). 2 since
    /// 2026-12-04: a refit then takes 1.8 ms instead of 2.8 (medians), so the frames that run one stay under 4 ms,
    /// and on the 146 validation sequences the frame p99 fell 4.94 -> 3.96 ms (all frames after the init phase)
    /// with the torso error 10.49 -> 10.41 mm and the probe error 10.71 -> 10.72 mm; 3 gave 3.91 ms, 10.55 mm and
    /// 10.78 mm (docs/tracking.md, "Lock refits on every second vertex").
    pub refit_stride: u16,
    /// Doubt of a lock ([`doubt`]): once the first round of lock refits has run, this many good tracked frames in
    /// a row with a fit residual over [`TrackerConfig::doubt_rms_m`] drop the lock, once per init phase: the torso
    /// model goes back to the init phase's shape and the tracker re-acquires (0: off). A known shape
    /// ([`TrackerConfig::known_shape`]) runs no refits and is never doubted. 8 since 2026-12-06:
    /// after its refits a wrong lock keeps fitting at 6-13 mm while a right one settles at 3-5 mm; on the choice sets
    /// 34001-34100 / 70001-70200 / 72001-72250's 61 raised beds the torso error went 11.78 / 11.98 / 12.37 -> 11.29 /
    /// 11.72 / 11.69 mm, the probe error 11.16 / 12.21 / 12.71 -> 11.03 / 12.02 / 12.34 mm, and the frames tracked
    /// more than 30 mm off 11-14 % fewer; the tracked share fell 0.1-0.5 % (a dropped lock re-acquires, sometimes
    /// only after the full occlusion). Under tracker seed 1 smaller and mixed (torso +0.11 / -0.17 / -0.23 mm,
    /// tracked -0.3 to -1.1 %); docs/tracking.md, thirty-third round.
    pub doubt_frames: u16,
    /// The residual of [`TrackerConfig::doubt_frames`], metres: 7.5 mm (8.5 mm gained as much on 72001-72250's 61 and
    /// 0.2 mm less on 34001-34100; 6 mm counted only once every refit round was in fired late, on right tracks during
    /// the patient's motion, and gained nothing).
    pub doubt_rms_m: f32,
    /// The screening of the bed grid's starts ([`bed_search`], in acquisitions and the init phase's shape fit)
    /// uses every `screen_stride`-th torso vertex (1: all); the starts it keeps are refined on every vertex. 4 since
    /// 2026-12-05: the screening was most of an acquisition frame's ICP time, and acquisitions were most of the
    /// frames over 4 ms. On the 146 validation sequences 1 / 2 / 4 / 8 gave a torso error of 10.63 / 10.67 / 10.52 /
    /// 10.36 mm, a probe error of 10.37 / 10.65 / 10.04 / 10.07 mm and recovery within 5 frames on 124 / 123 / 123
    /// / 123; on 34001-34100 1 / 4 / 8 gave 11.86 / 12.15 / 13.08 mm (probe 11.22 / 11.27 / 11.87 mm). At 4 the frame
    /// p99 fell 5.49 -> 4.24 ms on validation (acquisition frames' median 3.91 -> 2.77 ms; docs/tracking.md,
    /// nineteenth round).
    pub screen_stride: u16,
    /// [`TorsoIcpConfig::hold_rotation_weight`] of the fit from the temporal start while occluded (0: off): the
    /// last pose's rotation is held where the little the frame shows of the torso does not fix it, so that a
    /// followed pose ([`TorsoIcpConfig::follow_occluded`]) does not turn away a few degrees a frame. 0.3: on the 46
    /// validation sequences 0.1 / 0.3 / 1 gave a torso error of 11.2 / 11.3 / 11.0 mm and a probe error of 9.9 / 9.5
    /// / 10.0 mm, against 13.0 / 10.1 mm following without it (0.3: the lowest probe error, the torso error within
    /// 0.3 mm of the lowest). Held while tracking too: 12.2 / 11.3 mm at 0.1 / 0.3, probe 11.6 / 10.0 mm. Holding the
    /// translation too was worse (0.3: 12.1 mm): the patient shifts under the arm.
    pub occluded_hold_rotation: f32,
    /// The surface adaptation ([`surface`]; `frames` 0: off): once the torso model has been tracked for `settle_frames`
    /// good frames, `frames` frames that see at least half the torso are averaged per vertex and the model's front
    /// moves onto them (within 3 cm, observations within 6 mm SD); each of `rounds` rounds adds to the displacement so
    /// far. A torso model adopted later (a lock refit round) keeps the displacement found. Two rounds of 8 frames after
    /// 3 settling frames since 2026-12-06: one round of 15 frames after 10 was reached only after the full occlusion
    /// (frames 108-148 of 150 on 34001-34100, in 57 of the 100 sequences), so most frames were tracked without it; the
    /// shorter rounds finish between the lock refit rounds (the first from frame 23 on, in 80 of the 100, 66 of them
    /// before the full occlusion). On the choice sets 34001-34100 / 70001-70200 the torso error went 12.31 / 12.27 ->
    /// 11.81 / 11.98 mm and the probe error 11.27 / 12.42 -> 11.18 / 12.21 mm; over the sequences within 20 mm the
    /// torso error fell 0.57 / 0.57 mm on average (39 / 70 sequences gaining more than 0.5 mm, 2 / 6 losing), the
    /// tracked share within 0.1 % and the recoveries within one sequence. One round of 8 frames gave 11.98 / 12.02 mm,
    /// of 5 frames 11.91 / 12.01 mm, three rounds of 8 11.74 / 11.88 mm (more losers on 70001-70200; docs/tracking.md,
    /// twenty-ninth round); adapting only after the last refit round gave 12.10 mm on 34001-34100. When introduced
    /// (2026-12-04, one round of 15 after 10) it moved the 46 validation sequences 10.28 / 6.40 -> 10.09 / 6.21 mm
    /// (mean / median), and three rounds of 5 frames let a slid pose drift further on a held-out roll (s25001; "The
    /// surface adaptation").
    pub surface: SurfaceConfig,
    /// Bed-plane search.
    pub planes: PlaneConfig,
    /// Up in the camera frame when known (from the calibration), for the bed search.
    pub up_camera: Option<Vector3>,
    /// Forest samples per frame (0: the model's own).
    pub forest_samples: u16,
    /// The forest reads pixels higher than this above the mattress and head section as no depth (the arm's links
    /// over the patient), metres; 0 or less: off.
    pub forest_ceiling_m: f32,
    /// Run the forest on every tracked frame, as the paper's loop does, even where the temporal fit decides the frame
    /// and its points go unused (the evaluation's `forest_point_mm`); off, the same poses without that forest pass.
    pub forest_every_frame: bool,
    /// Standard deviation of the feedback prior per axis, metres.
    pub prior_sigma_m: f32,
    /// Torso ICP.
    pub icp: TorsoIcpConfig,
    /// State transitions.
    pub limits: StateLimits,
    /// The calibration: where the camera sits in `robot_base`.
    pub robot_base_from_camera: Isometry3,
    /// A body-shape packet is sent on change and every this many frames (150 = 5 s at 30 Hz).
    pub shape_every_frames: u32,
    /// Seed of the forest's pixel sampling and the RANSAC (mixed with the frame count: replays are identical).
    pub seed: u64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        let mut torso_coeffs = [false; SHAPE_COMPONENTS];
        torso_coeffs[0] = true;
        torso_coeffs[3] = true;
        TrackerConfig {
            variant: Variant::ForestIcpFeedback,
            budget: BudgetConfig::default(),
            shape_frames: 10,
            bed_frames: 5,
            shape_combine: ShapeCombine::Mean,
            refine_shape: true,
            shape_point_features: false,
            known_shape: None,
            torso_coeffs,
            shape_free_weight: 1e-3,
            search_shape_start: false,
            acquire_from_init: true,
            lock_refits: 3,
            refit_min_visible: 0.5,
            refit_late_frames: 30,
            refit_rounds: 2,
            refit_settle_frames: 10,
            shape_mode: ShapeMode::Once,
            continuous_refit_frames: 90,
            refit_late_min_visible: 0.4,
            refit_bed_contact: None,
            refit_lambda: 0.01,
            refit_stride: 2,
            doubt_frames: 8,
            doubt_rms_m: 0.0075,
            screen_stride: 4,
            occluded_hold_rotation: 0.3,
            surface: SurfaceConfig::default(),
            planes: PlaneConfig::default(),
            up_camera: None,
            forest_samples: 0,
            forest_ceiling_m: FOREST_CEILING_M,
            forest_every_frame: false,
            prior_sigma_m: 0.05,
            icp: TorsoIcpConfig::default(),
            limits: StateLimits::default(),
            robot_base_from_camera: Isometry3::identity(),
            shape_every_frames: 150,
            seed: 0x7EAC_4E55,
        }
    }
}

/// The models the tracker reads: borrowed views validated once.
#[derive(Clone, Copy)]
pub struct Models<'m> {
    /// The statistical body model.
    pub body: BodyModelView<'m>,
    /// The joint forest.
    pub joints: ForestView<'m>,
    /// The shape model (subspace and regression forest).
    pub shape: ShapeModelView<'m>,
}

/// How long each scratch buffer must be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScratchSizes {
    /// `plane_points` and `plane_labels`.
    pub plane_points: usize,
    /// `canonical`.
    pub canonical: usize,
    /// `fit_points`, `fit_normals`, `surface_sums` and the three torso buffers (the body model's torso subset).
    pub torso: usize,
    /// `normal_memo` and `refit_depth` (the frame's pixels).
    pub pixels: usize,
}

impl ScratchSizes {
    /// The sizes for `models`, frames of `k`'s size and the plane search's stride.
    pub fn of(models: &Models<'_>, k: &Intrinsics, planes: &PlaneConfig) -> Self {
        ScratchSizes {
            plane_points: planes::scratch_points(
                k.width as usize,
                k.height as usize,
                planes.stride.max(1) as usize,
            ),
            canonical: models.shape.pixels(),
            torso: models.body.counts().subset,
            pixels: k.width as usize * k.height as usize,
        }
    }
}

/// The caller's working memory (allocated once, before the first frame).
pub struct Scratch<'s> {
    /// Bed search points.
    pub plane_points: &'s mut [Point3],
    /// Bed search labels.
    pub plane_labels: &'s mut [u8],
    /// Canonical depth image of the shape estimate.
    pub canonical: &'s mut [f32],
    /// Shaped torso subset during the refinement.
    pub fit_points: &'s mut [[f32; 3]],
    /// Its normals (and the surface adaptation's working memory).
    pub fit_normals: &'s mut [[f32; 3]],
    /// The surface adaptation's per-vertex sums.
    pub surface_sums: &'s mut [VertexSums],
    /// The shaped torso model's vertices (torso frame).
    pub torso_vertices: &'s mut [Point3],
    /// Its normals.
    pub torso_normals: &'s mut [Vector3],
    /// Its body regions.
    pub torso_regions: &'s mut [BodyRegion],
    /// The forest's working memory.
    pub forest: &'s mut Workspace,
    /// The memo of each frame's observed normals, one cell per pixel ([`crate::normal_memo`]).
    pub normal_memo: &'s mut [MemoCell],
    /// The depth of the frame a lock refit was chosen on, kept for the next frame, which runs that refit.
    pub refit_depth: &'s mut [u16],
}

/// Why a tracker could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum TrackerError {
    /// A scratch buffer has the wrong length.
    Scratch {
        /// Which buffer.
        buffer: &'static str,
        /// Entries needed.
        expected: usize,
        /// Entries given.
        found: usize,
    },
}

impl core::fmt::Display for TrackerError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TrackerError::Scratch {
                buffer,
                expected,
                found,
            } => write!(
                f,
                "tracker scratch `{buffer}` holds {found} entries, {expected} needed"
            ),
        }
    }
}

impl core::error::Error for TrackerError {}

/// At most this many packets per frame: torso pose, salient points, probe, body shape, health.
pub const MAX_PACKETS: usize = 5;

/// What one frame produced.
#[derive(Debug, Clone)]
pub struct FrameReport {
    /// The state after this frame (what its health packet says).
    pub state: TrackerState,
    /// Per-stage times, µs.
    pub times: StageTimes,
    /// The packets to send, in order, stamped with the frame's capture time.
    pub packets: heapless::Vec<Message, MAX_PACKETS>,
    /// The refined torso pose when one is reported.
    pub camera_from_torso: Option<Isometry3>,
    /// The six salient points (camera frame) when a pose is reported.
    pub salient_camera: Option<[Point3; P]>,
    /// The forest's raw points of this frame.
    pub forest_points: [Option<PointEstimate>; P],
    /// The torso fit of this frame (default when none ran).
    pub fit: TorsoFit,
    /// The pose the best fit of this frame reached, accepted or not (for diagnostics: why acquisition waits).
    pub fit_pose: Option<Isometry3>,
    /// The probe mapping when an arm state was given and a pose is reported.
    pub probe: Option<ProbeMapping>,
    /// Age of the arm state used (frame capture minus arm time), µs.
    pub arm_age_us: Option<i64>,
    /// Whether the frame was rejected unprocessed (its size differs from the intrinsics).
    pub rejected: bool,
}

#[derive(Debug, Clone, Copy)]
struct Init {
    bed: Option<BedScene>,
    /// The bed estimates so far while the bed is voted on (`None`: a frame without one), and the frames tried.
    beds: [Option<BedScene>; MAX_BED_FRAMES],
    bed_tries: u8,
    /// The init frames' shape estimates so far, and how many.
    shape_views: [[f32; SHAPE_COMPONENTS]; MAX_SHAPE_FRAMES],
    shape_n: u16,
    /// Lock refits still to run (set when the init phase estimated the shape).
    refits_left: u8,
    /// Sum of the lock refits' shapes so far, how many, and the last refit's `camera_from_body` (`None` until one
    /// succeeds).
    refit_sum: [f32; SHAPE_COMPONENTS],
    refit_n: u8,
    refit_pose: Option<Isometry3>,
    /// Frames with a pose while lock refits wait ([`TrackerConfig::refit_late_frames`]).
    waited: u16,
    /// Consecutive good tracked frames with the current torso model ([`TrackerConfig::refit_settle_frames`],
    /// [`SurfaceConfig::settle_frames`]).
    settled: u16,
    /// Lock refit rounds completed after the first ([`TrackerConfig::refit_rounds`]).
    round: u8,
    /// Whether a round of lock refits has run since the init phase (or the doubt) set the torso model: what the
    /// [`doubt`] waits for. A known shape plans no refits, so its locks are never doubted.
    refits_in: bool,
    /// Frames the surface adaptation's round has summed, and its rounds applied.
    surface_n: u16,
    surface_rounds: u8,
    /// The init phase's shape estimate (what a doubted lock's torso model goes back to) and the doubt's count.
    init_shape: Option<[f32; SHAPE_COMPONENTS]>,
    doubt: doubt::LockDoubt,
}

impl Init {
    /// A round of `refits` lock refits to run, from nothing summed.
    fn start_refit_round(&mut self, refits: u8) {
        self.refits_left = refits;
        self.refit_sum = [0.0; SHAPE_COMPONENTS];
        self.refit_n = 0;
        self.refit_pose = None;
    }

    const fn new() -> Self {
        Init {
            bed: None,
            beds: [None; MAX_BED_FRAMES],
            bed_tries: 0,
            shape_views: [[0.0; SHAPE_COMPONENTS]; MAX_SHAPE_FRAMES],
            shape_n: 0,
            refits_left: 0,
            refit_sum: [0.0; SHAPE_COMPONENTS],
            refit_n: 0,
            refit_pose: None,
            waited: 0,
            settled: 0,
            round: 0,
            refits_in: false,
            surface_n: 0,
            surface_rounds: 0,
            init_shape: None,
            doubt: doubt::LockDoubt::new(),
        }
    }
}

/// A lock refit chosen on a frame and run at the start of the next ([`TrackerConfig::lock_refits`]): the torso
/// model and pose it starts from, and the frame's stamp; its depth waits in [`Scratch::refit_depth`].
#[derive(Debug, Clone, Copy)]
struct PendingRefit {
    torso: TorsoModel,
    camera_from_torso: Isometry3,
    capture: Timestamp,
    index: u32,
}

#[derive(Debug, Clone, Copy)]
struct TorsoModel {
    bed: BedScene,
    body_from_torso: Isometry3,
    salient_torso: [Point3; P],
    shape: [f32; SHAPE_COMPONENTS],
}

/// The tracker: models, the caller's scratch, the state machine and the pose carried between frames.
pub struct Tracker<'m, 's> {
    models: Models<'m>,
    k: Intrinsics,
    cfg: TrackerConfig,
    scratch: Scratch<'s>,
    machine: StateMachine,
    counters: BudgetCounters,
    init: Init,
    torso: Option<TorsoModel>,
    pose: Option<Isometry3>,
    last_good_pose: Option<Isometry3>,
    /// The acquisition candidate awaiting confirmation and how many consistent frames found it.
    candidate: Option<(Isometry3, u8)>,
    /// The near-good acquisition candidate ([`TorsoIcpConfig::near_confirm`]) and how many consistent frames found it.
    near_candidate: Option<(Isometry3, u8)>,
    /// A far fit that sees more of the torso than the pose's own, awaiting its second frame
    /// ([`TorsoIcpConfig::switch_margin`]).
    switch_candidate: Option<Isometry3>,
    /// The support of a right fit of this patient with this shape: set at acquisition, followed while tracking.
    support_ref: Option<f32>,
    /// The lock refit the last frame chose, run when the next frame arrives.
    pending_refit: Option<PendingRefit>,
    /// The shape a re-initialise in [`ShapeMode::Frozen`] kept: the next init phases use it as a known shape.
    frozen_shape: Option<[f32; SHAPE_COMPONENTS]>,
    frames: u32,
    seq: u16,
    shape_revision: u8,
    last_shape_frame: Option<u32>,
    last_capture: Option<Timestamp>,
    interval_us: f32,
    memo_cells: &'s [Cell<MemoCell>],
    memo_stamp: MemoStamp,
    /// The last forest pass's time, µs: a fit's cost estimate on frames the forest has not run in yet.
    forest_us: u32,
}

fn check(buffer: &'static str, expected: usize, found: usize) -> Result<(), TrackerError> {
    if expected == found {
        Ok(())
    } else {
        Err(TrackerError::Scratch {
            buffer,
            expected,
            found,
        })
    }
}

fn mm(p: &Point3) -> [i32; 3] {
    [p.x, p.y, p.z].map(|c| libm::roundf(c * 1000.0) as i32)
}

fn quat_q14(q: &UnitQuaternion) -> UnitQuatQ14 {
    UnitQuatQ14::from_f32([q.w, q.i, q.j, q.k]).unwrap_or(UnitQuatQ14::IDENTITY)
}

/// Most frames whose bed estimates the init phase can vote on ([`TrackerConfig::bed_frames`]).
pub const MAX_BED_FRAMES: usize = 8;

/// Highest hip centre above the mattress a lying patient has, metres (the pelvis is 10-20 cm thick), for the fits
/// that may acquire a pose: higher ones have locked onto the arm or the bed frame.
const MAX_HIP_HEIGHT_M: f32 = 0.3;
/// The same for a fit from the tracked pose whose residual is low enough to acquire at once (`TorsoFit::sure`),
/// metres: the heaviest generated bodies lie with the hip centre 0.33 m up, a few centimetres more rolled onto one
/// side. With 0.3 m the tracker refused a heavy patient's right fits (70001-70200's s70037: hip centre 0.325 m up,
/// RMS 3 mm, lost three times). For every fit it let a re-acquisition take a pose
/// 0.22 m off (s70139), for every tracked one a wrong first lock rise and stay (validation s29019 under seed 2, RMS
/// 8.5-11.4 mm). Measured in `docs/tracking.md`, twenty-sixth round.
const TRACKED_MAX_HIP_HEIGHT_M: f32 = 0.4;
/// Least cosine between the chest's outward axis and the mattress normal (lying, rolled or on a raised head
/// section up to about 60°).
const MIN_CHEST_UP_COS: f32 = 0.5;

/// The consecutive frames that found `pose` (`found`): one more than `last`'s run when it found the same pose, none
/// when this frame did not find it.
fn consistent_run(last: Option<(Isometry3, u8)>, pose: &Isometry3, found: bool, cfg: &TorsoIcpConfig) -> u8 {
    match last {
        Some((c, n)) if found && cfg.same_pose(&c, pose) => n.saturating_add(1),
        _ => u8::from(found),
    }
}

/// Whether a torso pose is one of a patient lying on the bed.
fn lies_on_bed(camera_from_torso: &Isometry3, bed: &BedScene, max_hip_m: f32) -> bool {
    let hip = Point3::from(camera_from_torso.translation.vector);
    let h = bed.mattress.signed_distance(&hip);
    let chest = camera_from_torso.rotation * Vector3::z();
    (-0.05..=max_hip_m).contains(&h)
        && chest.dot(&bed.mattress.normal()) >= MIN_CHEST_UP_COS
        && bed_search::along_the_bed(camera_from_torso, bed)
        && bed_search::near_the_hinge(camera_from_torso, bed)
}

/// The share of the torso a lock refit's frame must show after `waited` frames with a pose and refits waiting:
/// [`TrackerConfig::refit_min_visible`], then [`TrackerConfig::refit_late_min_visible`] from
/// [`TrackerConfig::refit_late_frames`] on (never when that is 0).
fn refit_gate(cfg: &TrackerConfig, waited: u16) -> f32 {
    if cfg.refit_late_frames > 0 && waited >= cfg.refit_late_frames {
        cfg.refit_late_min_visible
    } else {
        cfg.refit_min_visible
    }
}

/// The consecutive good tracked frames (this one included) a lock refit of round `round` (0: the first) needs
/// beyond the first: none in the first round, [`TrackerConfig::refit_settle_frames`] in the later ones, and at least
/// [`TrackerConfig::continuous_refit_frames`] in the rounds past [`TrackerConfig::refit_rounds`]
/// ([`ShapeMode::Continuous`]).
fn refit_settle(cfg: &TrackerConfig, round: u8) -> u16 {
    match round {
        0 => 0,
        r if r <= cfg.refit_rounds => cfg.refit_settle_frames,
        _ => cfg.refit_settle_frames.max(cfg.continuous_refit_frames),
    }
}

/// Per good tracking frame, the share by which the reference support follows the fit's (a slow follow: a pose
/// sliding off the body over a few frames still shows as a drop).
const SUPPORT_FOLLOW: f32 = 0.02;

/// Roll offsets tried when acquiring without a pose, radians.
const ACQUIRE_ROLLS_RAD: [f32; 2] = [-0.35, 0.35];

/// `pose` turned about the body's long axis by each of [`ACQUIRE_ROLLS_RAD`] (its roll is the forest's least
/// certain part): the acquisition's and the second look's extra starts.
fn rolled(pose: &Isometry3) -> [Isometry3; 2] {
    ACQUIRE_ROLLS_RAD.map(|roll| pose * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), roll))
}

fn rank(q: FitQuality) -> u8 {
    match q {
        FitQuality::Good => 2,
        FitQuality::Occluded => 1,
        FitQuality::Failed => 0,
    }
}

/// `camera_from_torso` placing the model's salient points (torso frame) on the forest's (camera frame), weighted by
/// the forest's confidence (Kabsch); `None` with fewer than three points.
fn forest_pose(points: &[Option<PointEstimate>; P], model: &[Point3; P]) -> Option<Isometry3> {
    let mut pairs = [Pair {
        robot_base: Point3::origin(),
        camera: Point3::origin(),
    }; P];
    let mut w = [0.0f32; P];
    for i in 0..P {
        if let Some(e) = points[i] {
            pairs[i] = Pair {
                robot_base: e.position,
                camera: model[i],
            };
            w[i] = e.confidence.max(1e-3);
        }
    }
    kabsch(&pairs, |i| w[i])
}

fn all_points(points: &[Option<PointEstimate>; P]) -> Option<[Point3; P]> {
    let mut out = [Point3::origin(); P];
    for (o, p) in out.iter_mut().zip(points) {
        *o = p.as_ref()?.position;
    }
    Some(out)
}

impl<'m, 's> Tracker<'m, 's> {
    /// A tracker over `models` for frames of `k`, with the caller's `scratch` (lengths from [`ScratchSizes::of`]).
    pub fn new(
        models: Models<'m>,
        k: Intrinsics,
        cfg: TrackerConfig,
        mut scratch: Scratch<'s>,
    ) -> Result<Self, TrackerError> {
        let sizes = ScratchSizes::of(&models, &k, &cfg.planes);
        check("plane_points", sizes.plane_points, scratch.plane_points.len())?;
        check("plane_labels", sizes.plane_points, scratch.plane_labels.len())?;
        check("canonical", sizes.canonical, scratch.canonical.len())?;
        check("fit_points", sizes.torso, scratch.fit_points.len())?;
        check("fit_normals", sizes.torso, scratch.fit_normals.len())?;
        check("surface_sums", sizes.torso, scratch.surface_sums.len())?;
        check("torso_vertices", sizes.torso, scratch.torso_vertices.len())?;
        check("torso_normals", sizes.torso, scratch.torso_normals.len())?;
        check("torso_regions", sizes.torso, scratch.torso_regions.len())?;
        check("normal_memo", sizes.pixels, scratch.normal_memo.len())?;
        check("refit_depth", sizes.pixels, scratch.refit_depth.len())?;
        let memo_cells = Cell::from_mut(core::mem::take(&mut scratch.normal_memo)).as_slice_of_cells();
        // The init phase's shape regression, chosen once (`TrackerConfig::shape_point_features`).
        let models = Models {
            shape: if cfg.shape_point_features {
                models.shape
            } else {
                models.shape.coefficients_only()
            },
            ..models
        };
        Ok(Tracker {
            models,
            k,
            cfg,
            scratch,
            machine: StateMachine::new(cfg.limits),
            counters: BudgetCounters::default(),
            init: Init::new(),
            torso: None,
            pose: None,
            last_good_pose: None,
            candidate: None,
            near_candidate: None,
            switch_candidate: None,
            support_ref: None,
            pending_refit: None,
            frozen_shape: None,
            frames: 0,
            seq: 0,
            shape_revision: 0,
            last_shape_frame: None,
            last_capture: None,
            interval_us: 0.0,
            memo_cells,
            memo_stamp: MemoStamp::default(),
            forest_us: 0,
        })
    }

    /// The settings.
    pub fn config(&self) -> &TrackerConfig {
        &self.cfg
    }

    /// The current state.
    pub fn state(&self) -> TrackerState {
        self.machine.state()
    }

    /// Budget counters (overruns, drops, cuts).
    pub fn counters(&self) -> BudgetCounters {
        self.counters
    }

    /// The bed found by the init phase.
    pub fn bed(&self) -> Option<&BedScene> {
        self.torso.as_ref().map(|t| &t.bed).or(self.init.bed.as_ref())
    }

    /// The estimated shape (σ units) once the init phase is done.
    pub fn shape(&self) -> Option<&[f32; SHAPE_COMPONENTS]> {
        self.torso.as_ref().map(|t| &t.shape)
    }

    /// Surface adaptation rounds applied to the current patient's torso model ([`surface`]; 0 before the first).
    pub fn surface_rounds(&self) -> u8 {
        self.init.surface_rounds
    }

    /// The shaped torso surface (torso frame) once the init phase is done.
    pub fn surface(&self) -> Option<TorsoSurface<'_>> {
        let t = self.torso.as_ref()?;
        TorsoSurface::from_parts(
            &self.models.body,
            self.scratch.torso_vertices,
            self.scratch.torso_normals,
            self.scratch.torso_regions,
            t.body_from_torso,
        )
    }

    /// Switch the shape mode ([`TrackerConfig::shape_mode`]) from the next frame on. Frozen drops the lock refits
    /// still to run (a round half summed is not adopted); continuous starts a round when none is under way once the
    /// init phase is done (the first at once when none has run, a later one after
    /// [`TrackerConfig::continuous_refit_frames`]).
    pub fn set_shape_mode(&mut self, mode: ShapeMode) {
        self.cfg.shape_mode = mode;
        match mode {
            ShapeMode::Frozen => {
                self.init.refits_left = 0;
                self.pending_refit = None;
            }
            ShapeMode::Continuous if self.torso.is_some() && self.init.refits_left == 0 => {
                if self.init.refits_in {
                    self.init.round = self.init.round.max(self.cfg.refit_rounds).saturating_add(1);
                }
                self.init.start_refit_round(self.cfg.lock_refits);
            }
            _ => {}
        }
    }

    /// Drop the track and run the init phase again (the re-initialise command). In [`ShapeMode::Frozen`] the shape
    /// is kept (the init phase then only finds the bed, as with [`TrackerConfig::known_shape`]); in the other modes
    /// it is estimated again.
    pub fn reinitialise(&mut self) {
        // Re-initialised again before the init phase ended: the shape kept the last time is still the one.
        self.frozen_shape = match self.cfg.shape_mode {
            ShapeMode::Frozen => self.shape().copied().or(self.frozen_shape),
            _ => None,
        };
        self.machine.reinitialise();
        self.init = Init::new();
        self.torso = None;
        self.forget_lock();
    }

    /// Forget the pose and what the acquisition and tracking carry between frames (re-initialise, a doubted lock).
    fn forget_lock(&mut self) {
        self.pose = None;
        self.last_good_pose = None;
        self.candidate = None;
        self.near_candidate = None;
        self.switch_candidate = None;
        self.support_ref = None;
        self.pending_refit = None;
    }

    /// The source reported a fault; the next usable frame re-acquires.
    pub fn sensor_fault(&mut self) {
        self.machine.sensor_fault();
        self.pose = None;
        // Its adoption would restore a pose the fault dropped; a later tracked frame refits instead.
        self.pending_refit = None;
    }

    /// The caller dropped `n` frames unprocessed (it only ever hands over the newest).
    pub fn dropped(&mut self, n: u32) {
        self.counters.dropped = self.counters.dropped.wrapping_add(n);
    }

    /// A health packet for the current state (for the caller's own messages: a final one at shutdown, a sensor
    /// fault between frames).
    pub fn health(&mut self, time: Timestamp, latency_us: u32) -> Message {
        let body = wire::Body::Health(Health {
            state: self.machine.state(),
            frame_rate_chz: self.frame_rate_chz(),
            latency_us,
            budget_overruns: self.counters.overruns,
            dropped_frames: self.counters.dropped,
        });
        self.message(time, body)
    }

    fn frame_rate_chz(&self) -> u16 {
        if self.interval_us > 0.0 {
            (1e8 / self.interval_us).clamp(0.0, u16::MAX as f32) as u16
        } else {
            0
        }
    }

    fn message(&mut self, time: Timestamp, body: wire::Body) -> Message {
        let m = Message {
            seq: self.seq,
            timestamp: time,
            body,
        };
        self.seq = self.seq.wrapping_add(1);
        m
    }

    /// [`Self::forest`] timed as the frame's forest stage, its points in `report`.
    #[allow(clippy::too_many_arguments)] // the forest's inputs, the clock and the frame's record
    fn forest_stage(
        &mut self,
        frame: &DepthFrame<'_>,
        bed: &BedScene,
        priors: &[Option<Prior>; P],
        clock: &(impl Clock + ?Sized),
        watch: &mut Stopwatch,
        report: &mut FrameReport,
    ) -> [Option<PointEstimate>; P] {
        let points = self.forest(frame, bed, priors);
        watch.lap(clock, Stage::Forest);
        self.forest_us = watch.times.of(Stage::Forest);
        report.forest_points = points;
        points
    }

    fn forest(
        &mut self,
        frame: &DepthFrame<'_>,
        bed: &BedScene,
        priors: &[Option<Prior>; P],
    ) -> [Option<PointEstimate>; P] {
        let samples = match self.cfg.forest_samples {
            0 => self.models.joints.samples_per_frame(),
            n => n as usize,
        };
        let cfg = InferConfig {
            samples,
            seed: mix_seed(self.cfg.seed, self.frames as u64),
            method: Method::Refined,
        };
        infer::estimate_above(
            &self.models.joints,
            frame,
            &self.k,
            &bed.clip_planes(),
            self.cfg.forest_ceiling_m,
            &cfg,
            priors,
            self.scratch.forest,
        )
    }

    /// Process one frame: `arm` is the newest arm state, `clock` times the stages (core reads no clock itself).
    pub fn process(
        &mut self,
        frame: &DepthFrame<'_>,
        arm: Option<&ArmSample>,
        clock: &(impl Clock + ?Sized),
    ) -> FrameReport {
        let mut watch = Stopwatch::start(clock);
        let mut report = FrameReport {
            state: self.machine.state(),
            times: StageTimes::default(),
            packets: heapless::Vec::new(),
            camera_from_torso: None,
            salient_camera: None,
            forest_points: [None; P],
            fit: TorsoFit::default(),
            fit_pose: None,
            probe: None,
            arm_age_us: None,
            rejected: false,
        };
        if frame.width() != self.k.width || frame.height() != self.k.height {
            report.rejected = true;
            let h = self.health(frame.capture, watch.elapsed(clock));
            let _ = report.packets.push(h);
            return report;
        }
        if let Some(last) = self.last_capture {
            let dt = frame.capture.since(last);
            if dt > 0 && dt < 1_000_000 {
                self.interval_us = if self.interval_us > 0.0 {
                    0.9 * self.interval_us + 0.1 * dt as f32
                } else {
                    dt as f32
                };
            }
        }
        self.last_capture = Some(frame.capture);
        // The last frame's lock refit, before this frame's stamp retires that frame's normals.
        if let Some(pending) = self.pending_refit.take() {
            self.run_pending_refit(pending, clock, &watch);
            watch.lap(clock, Stage::Init);
        }
        // Every ICP fit of this frame reads its normals through one memo (the results are the same bits).
        let memo = self
            .memo_stamp
            .next(self.memo_cells, self.k.width, icp::NORMAL_STEP_PX);
        let frame = &frame.with_normal_memo(memo);
        self.machine.frame_arrived();
        if self.machine.initialised() {
            self.track(frame, arm, clock, &mut watch, &mut report);
        } else {
            self.initialise(frame, clock, &mut watch, &mut report);
        }
        self.frames = self.frames.wrapping_add(1);
        report.state = self.machine.state();
        self.packets(frame.capture, &mut report);
        watch.lap(clock, Stage::Output);
        report.times = watch.times;
        if watch.times.total() > self.cfg.budget.frame_us {
            self.counters.overruns = self.counters.overruns.wrapping_add(1);
        }
        // The health packet is last: it carries this frame's latency and counters.
        let h = self.health(frame.capture, watch.times.total());
        let _ = report.packets.push(h);
        report
    }

    fn initialise(
        &mut self,
        frame: &DepthFrame<'_>,
        clock: &(impl Clock + ?Sized),
        watch: &mut Stopwatch,
        report: &mut FrameReport,
    ) {
        let wanted = self.cfg.bed_frames.clamp(1, MAX_BED_FRAMES as u8);
        if self.init.bed.is_none() || self.init.bed_tries < wanted {
            self.vote_bed(frame, wanted);
        }
        let Some(bed) = self.init.bed else {
            watch.lap(clock, Stage::Init);
            return;
        };
        let voted = self.init.bed_tries >= wanted;
        if let Some(z) = self.cfg.known_shape.or(self.frozen_shape) {
            if voted {
                self.finish_init(frame, &bed, None, z, clock, watch);
            }
            watch.lap(clock, Stage::Init);
            return;
        }
        let points = self.forest(frame, &bed, &[None; P]);
        report.forest_points = points;
        watch.lap(clock, Stage::Forest);
        let Some(observed) = all_points(&points) else {
            return;
        };
        if let Ok(e) =
            self.models
                .shape
                .estimate(frame, &self.k, &observed, &bed.mattress, self.scratch.canonical)
            && let Some(v) = self.init.shape_views.get_mut(self.init.shape_n as usize)
        {
            *v = e.shape;
            self.init.shape_n += 1;
        }
        let frames = self.cfg.shape_frames.clamp(1, MAX_SHAPE_FRAMES as u16);
        if self.init.shape_n >= frames && voted {
            let z = self
                .cfg
                .shape_combine
                .of(&self.init.shape_views[..self.init.shape_n as usize]);
            self.finish_init(frame, &bed, Some(&observed), z, clock, watch);
        }
        watch.lap(clock, Stage::Init);
    }

    /// One frame's bed estimate for the init phase: the first bed found is the init phase's; when the
    /// `wanted`-th frame has been tried the estimates so far are voted on ([`bed_vote`]), and a bed that differs from
    /// the one in use replaces it and restarts the shape frames (their forest points were clipped by the other bed).
    fn vote_bed(&mut self, frame: &DepthFrame<'_>, wanted: u8) {
        let mut cfg = self.cfg.planes;
        cfg.seed = mix_seed(cfg.seed ^ self.cfg.seed, self.frames as u64);
        let found = planes::estimate_bed(
            frame,
            &self.k,
            &cfg,
            self.cfg.up_camera.as_ref(),
            self.scratch.plane_points,
            self.scratch.plane_labels,
        )
        .ok();
        // Past the last slot (only while no frame has found a bed) the newest frame's estimate takes it.
        let slot = (self.init.bed_tries as usize).min(MAX_BED_FRAMES - 1);
        self.init.beds[slot] = found;
        self.init.bed_tries = self.init.bed_tries.saturating_add(1);
        if self.init.bed.is_none() {
            self.init.bed = found;
        }
        if self.init.bed_tries != wanted {
            return;
        }
        let beds: heapless::Vec<BedScene, MAX_BED_FRAMES> =
            self.init.beds.iter().flatten().copied().collect();
        if let Some(b) = self.init.bed.and_then(|used| bed_vote::replacement(&beds, &used)) {
            self.init.bed = Some(b);
            self.init.shape_n = 0;
        }
    }

    fn finish_init(
        &mut self,
        frame: &DepthFrame<'_>,
        bed: &BedScene,
        observed: Option<&[Point3; P]>,
        mut z: [f32; SHAPE_COMPONENTS],
        clock: &(impl Clock + ?Sized),
        watch: &Stopwatch,
    ) {
        // A new patient (or the same one again), and whatever the caller's buffer held: no surface adaptation
        // yet. Every torso model is built from here on.
        self.scratch.surface_sums.fill(VertexSums::ZERO);
        let body = self.models.body;
        let up = bed.mattress.normal();
        let mut camera_from_body = None;
        if let Some(observed) = observed
            && self.cfg.refine_shape
        {
            if watch.elapsed(clock) > self.cfg.budget.frame_us / 2 {
                self.counters.refinements_skipped += 1;
            } else if let Ok(forest_start) = fit::initial_pose(&body, &z, observed, &up) {
                let searched = if self.cfg.search_shape_start {
                    self.shape_fit_start(frame, bed, &z, forest_start, clock, watch)
                } else {
                    None
                };
                let start = searched.unwrap_or(forest_start);
                let mut coeffs = [0usize; SHAPE_COMPONENTS];
                let mut m = 0;
                for (i, &t) in self.cfg.torso_coeffs.iter().enumerate() {
                    if t {
                        coeffs[m] = i;
                        m += 1;
                    }
                }
                let params = FitParams::combined_with(
                    torso_icp::icp_params(&self.cfg.icp, bed),
                    &coeffs[..m],
                    self.cfg.shape_free_weight,
                );
                if let Ok(r) = fit::fit_shape(
                    &body,
                    frame,
                    &self.k,
                    &z,
                    start,
                    &params,
                    self.scratch.fit_points,
                    self.scratch.fit_normals,
                ) {
                    z = r.shape;
                    camera_from_body = Some(r.camera_from_model);
                }
            }
        }
        self.init.init_shape = Some(z);
        let Some(torso) = self.shaped_torso(*bed, z) else {
            // The scratch lengths were checked when the tracker was built.
            return;
        };
        let pose = camera_from_body
            .map(|c| c * torso.body_from_torso)
            .or_else(|| observed.and_then(torso::a_from_torso));
        self.adopt_torso(torso, pose);
        if self.cfg.acquire_from_init && camera_from_body.is_some() {
            self.last_good_pose = pose;
            self.candidate = pose.map(|p| (p, 1));
        }
        // A known shape runs no refits unless the shape is to be refined continuously.
        self.init.refits_left = match self.cfg.shape_mode {
            ShapeMode::Once if observed.is_some() => self.cfg.lock_refits,
            ShapeMode::Continuous => self.cfg.lock_refits,
            _ => 0,
        };
        self.machine.init_done();
    }

    /// Keep `frame` for a lock refit from `camera_from_torso` with the torso model `t`, run when the next frame
    /// arrives ([`Tracker::run_pending_refit`]): the frame that locks pays for the acquisition's fits, and a refit
    /// beside them took it past 4 ms; the next frame pays for the refit beside a tracking frame's work. The same
    /// refit on the same pixels either way. Cost: a copy of the frame (0.6 MB at 640x480).
    fn defer_refit(&mut self, frame: &DepthFrame<'_>, t: TorsoModel, camera_from_torso: Isometry3) {
        // `process` checked the frame's size against the intrinsics, so the lengths agree.
        self.scratch.refit_depth.copy_from_slice(frame.depth_mm());
        self.pending_refit = Some(PendingRefit {
            torso: t,
            camera_from_torso,
            capture: frame.capture,
            index: frame.index,
        });
    }

    /// The lock refit the last frame chose, on that frame's kept depth and normals (its memo stays valid until this
    /// frame is stamped).
    fn run_pending_refit(&mut self, p: PendingRefit, clock: &(impl Clock + ?Sized), watch: &Stopwatch) {
        let depth = core::mem::take(&mut self.scratch.refit_depth);
        if let Ok(kept) = DepthFrame::new(depth, self.k.width, self.k.height, p.capture, p.index) {
            let memo = self
                .memo_stamp
                .current(self.memo_cells, self.k.width, icp::NORMAL_STEP_PX);
            let kept = memo.map_or(kept, |m| kept.with_normal_memo(m));
            self.refit_on_lock(&kept, &p.torso, p.camera_from_torso, clock, watch);
        }
        self.scratch.refit_depth = depth;
    }

    /// One lock refit: Eq. 7 (with the bed contact, when configured) from the tracked pose `camera_from_torso` and
    /// the tracked shape; after the last one of a round the refits' mean shape becomes the torso model (a new shape
    /// revision), the pose moves to the last refit's, and the next round, if any, waits for the tracker to settle.
    /// A refit that fails still counts; one that does not fit in the budget waits for the next frame.
    fn refit_on_lock(
        &mut self,
        frame: &DepthFrame<'_>,
        t: &TorsoModel,
        camera_from_torso: Isometry3,
        clock: &(impl Clock + ?Sized),
        watch: &Stopwatch,
    ) {
        if !self.refinement_fits(clock, watch) {
            return;
        }
        self.init.refits_left -= 1;
        self.init.refits_in |= self.init.refits_left == 0;
        let body = self.models.body;
        // From a confirmed pose: drop pairs the camera sees far behind the model, as the temporal fit does. Plain
        // fitting (no pull toward the init estimate, only λ's toward the mean body): on the validation sequences
        // the init estimate is close to the mean and carries little, and holding the non-torso coefficients at it
        // left torso errors 1.4x as large (docs/tracking.md, "Shape refit on lock").
        let params = FitParams {
            lambda: self.cfg.refit_lambda,
            stride: self.cfg.refit_stride,
            ..FitParams::plain(torso_icp::temporal_params(&self.cfg.icp, &t.bed))
        };
        let start = camera_from_torso * t.body_from_torso.inverse();
        let (points, normals) = (&mut *self.scratch.fit_points, &mut *self.scratch.fit_normals);
        let contact = self.cfg.refit_bed_contact.as_ref();
        if let Ok(r) = fit::fit_shape_with(
            &body, frame, &self.k, &t.shape, start, &params, contact, points, normals,
        ) {
            for (s, x) in self.init.refit_sum.iter_mut().zip(r.shape) {
                *s += x;
            }
            self.init.refit_n += 1;
            self.init.refit_pose = Some(r.camera_from_model);
        }
        // No refit succeeded: the init phase's shape stays.
        let (0, Some(camera_from_body)) = (self.init.refits_left, self.init.refit_pose) else {
            return;
        };
        let n = f32::from(self.init.refit_n);
        let Some(torso) = self.shaped_torso(t.bed, self.init.refit_sum.map(|s| s / n)) else {
            return;
        };
        self.adopt_torso(torso, Some(camera_from_body * torso.body_from_torso));
        self.last_good_pose = self.pose;
        // The support a right fit reaches depends on the shape: measure it afresh.
        self.support_ref = None;
        // The next round starts from this shape once the tracker has settled with it. `waited` runs on, so a round
        // that starts after `refit_late_frames` takes the late visibility gate at once (as measured).
        if self.init.round < self.cfg.refit_rounds || self.cfg.shape_mode == ShapeMode::Continuous {
            self.init.round = self.init.round.saturating_add(1);
            self.init.start_refit_round(self.cfg.lock_refits);
        }
    }

    /// Feed the [`doubt`] with this frame's fit; when it fires, drop the lock: the init phase's shape back in the
    /// torso model (the surface adaptation's displacements and the lock refits' rounds undone), the state lost so the
    /// next frame re-acquires from scratch. Returns whether it fired.
    fn doubts_lock(&mut self, quality: FitQuality, fit: &TorsoFit, bed: &BedScene) -> bool {
        // Counted once the first round of lock refits is in: before it the init phase's shape fits right locks
        // at 5-9 mm too. A known shape runs no refits: had its locks been doubted, the refits the doubt starts
        // would have replaced it.
        let refitted =
            self.init.refits_in && self.pending_refit.is_none() && self.cfg.shape_mode != ShapeMode::Frozen;
        let good = quality == FitQuality::Good && self.machine.state() == TrackerState::Tracking;
        let observed = (self.cfg.lock_refits > 0 && refitted).then_some((good, fit.association.rms_m()));
        let Some(z) = self.init.init_shape else {
            return false;
        };
        if !self
            .init
            .doubt
            .observe(observed, self.cfg.doubt_rms_m, self.cfg.doubt_frames)
        {
            return false;
        }
        self.scratch.surface_sums.fill(VertexSums::ZERO);
        if let Some(torso) = self.shaped_torso(*bed, z) {
            self.adopt_torso(torso, None);
        }
        self.init.start_refit_round(self.cfg.lock_refits);
        self.init.round = 0;
        self.init.refits_in = false;
        self.init.waited = 0;
        self.init.surface_rounds = 0;
        self.forget_lock();
        self.machine.lose();
        true
    }

    /// One frame of the surface adaptation ([`surface`]) from the tracked pose; after
    /// [`SurfaceConfig::frames`] of them the torso model's vertices move and its normals follow. Skipped (and
    /// counted) when the frame has used half its budget.
    fn adapt_surface(
        &mut self,
        frame: &DepthFrame<'_>,
        bed: &BedScene,
        camera_from_torso: Isometry3,
        arm: Option<&ArmSample>,
        clock: &(impl Clock + ?Sized),
        watch: &Stopwatch,
    ) {
        if !self.refinement_fits(clock, watch) {
            return;
        }
        let cfg = self.cfg.surface;
        let sums = &mut *self.scratch.surface_sums;
        if self.init.surface_n == 0 {
            sums.iter_mut().for_each(VertexSums::new_round);
        }
        let tip = arm.map(|a| {
            probe::tip_in_torso(
                &a.tip_robot_base,
                &self.cfg.robot_base_from_camera,
                &camera_from_torso,
            )
        });
        surface::accumulate(
            frame,
            &self.k,
            self.scratch.torso_vertices,
            self.scratch.torso_normals,
            &camera_from_torso,
            &torso_icp::temporal_params(&self.cfg.icp, bed),
            tip.as_ref(),
            &cfg,
            sums,
        );
        self.init.surface_n += 1;
        if self.init.surface_n < cfg.frames {
            return;
        }
        surface::apply(
            self.models.body.torso_subset_triangles(),
            self.scratch.torso_vertices,
            self.scratch.torso_normals,
            sums,
            self.scratch.fit_normals,
            cfg.frames,
            &cfg,
        );
        self.init.surface_n = 0;
        self.init.surface_rounds += 1;
        // The support a right fit reaches depends on the surface: measure it afresh.
        self.support_ref = None;
    }

    /// Whether a torso model revision (a lock refit, a surface adaptation frame) may run in this frame: only while
    /// the frame has used at most half its budget; otherwise it waits for a later frame, counted as skipped.
    fn refinement_fits(&mut self, clock: &(impl Clock + ?Sized), watch: &Stopwatch) -> bool {
        let fits = watch.elapsed(clock) <= self.cfg.budget.frame_us / 2;
        if !fits {
            self.counters.refinements_skipped += 1;
        }
        fits
    }

    /// Make `torso` the tracked model at `pose`: a new shape revision, announced on the next frame.
    fn adopt_torso(&mut self, torso: TorsoModel, pose: Option<Isometry3>) {
        // The tracker settles with the new model, and a surface round in progress measured against the previous
        // one starts again.
        self.init.settled = 0;
        self.init.surface_n = 0;
        self.pose = pose;
        self.torso = Some(torso);
        self.shape_revision = self.shape_revision.wrapping_add(1);
        self.last_shape_frame = None;
    }

    /// The torso model on `bed` shaped with `z` (σ units), built into the scratch buffers, with its salient points.
    fn shaped_torso(&mut self, bed: BedScene, z: [f32; SHAPE_COMPONENTS]) -> Option<TorsoModel> {
        let (body_from_torso, raw) = self.build_torso(&z)?;
        let torso_from_body = body_from_torso.inverse();
        let salient_torso = self
            .models
            .body
            .salient_points(&raw)
            .map(|p| torso_from_body * Point3::from(p));
        Some(TorsoModel {
            bed,
            body_from_torso,
            salient_torso,
            shape: z,
        })
    }

    /// Shape the torso model with `z` (σ units) into the scratch buffers; its `body_from_torso` and the raw
    /// (unscaled) coefficients.
    fn build_torso(&mut self, z: &[f32; SHAPE_COMPONENTS]) -> Option<(Isometry3, [f32; SHAPE_COMPONENTS])> {
        let body = self.models.body;
        let mut raw = [0.0f32; SHAPE_COMPONENTS];
        for (i, r) in raw.iter_mut().enumerate() {
            *r = z[i] * body.sigma(i);
        }
        let body_from_torso = TorsoSurface::build(
            &body,
            &raw,
            TorsoBuffers {
                vertices: self.scratch.torso_vertices,
                normals: self.scratch.torso_normals,
                regions: self.scratch.torso_regions,
            },
        )
        .ok()?
        .body_from_torso();
        surface::displace(
            body.torso_subset_triangles(),
            self.scratch.torso_vertices,
            self.scratch.torso_normals,
            self.scratch.surface_sums,
        );
        Some((body_from_torso, raw))
    }

    /// Where the shape refinement starts (`camera_from_body`): the forest's points place the model up to 20 cm and
    /// 50° off on some views, too far for Eq. 7's ICP. So the estimated torso is registered rigidly first, from the
    /// forest's pose and from the [`bed_search`] grid around it, and the start with the best support wins. `None`
    /// when no start has enough pairs.
    fn shape_fit_start(
        &mut self,
        frame: &DepthFrame<'_>,
        bed: &BedScene,
        z: &[f32; SHAPE_COMPONENTS],
        forest_start: Isometry3,
        clock: &(impl Clock + ?Sized),
        watch: &Stopwatch,
    ) -> Option<Isometry3> {
        let (body_from_torso, _) = self.build_torso(z)?;
        let forest = forest_start * body_from_torso;
        let params = torso_icp::icp_params(&self.cfg.icp, bed);
        let mut starts = self.screen_bed_starts(frame, &forest, bed, &params, clock, watch);
        let _ = starts.push(forest);
        let mut best: Option<(f32, Isometry3)> = None;
        for start in starts {
            let min_iterations = self.cfg.icp.acquire_min_iterations;
            let budget = self.cfg.budget;
            let Some((pose, support)) = self.fit_lying(
                frame,
                bed,
                start,
                &self.cfg.icp,
                &params,
                &budget,
                min_iterations,
                clock,
                watch,
            ) else {
                continue;
            };
            if best.is_none_or(|(s, _)| support > s) {
                best = Some((support, pose));
            }
        }
        best.map(|(_, pose)| pose * body_from_torso.inverse())
    }

    fn track(
        &mut self,
        frame: &DepthFrame<'_>,
        arm: Option<&ArmSample>,
        clock: &(impl Clock + ?Sized),
        watch: &mut Stopwatch,
        report: &mut FrameReport,
    ) {
        let Some(t) = self.torso else {
            return;
        };
        let variant = self.cfg.variant;
        let mut priors = [None; P];
        let prior_pose = self.pose.filter(|_| self.machine.has_pose());
        if variant == Variant::ForestIcpFeedback
            && let Some(pose) = prior_pose
        {
            let s = self.cfg.prior_sigma_m;
            for (prior, p) in priors.iter_mut().zip(&t.salient_torso) {
                *prior = Some(Prior {
                    mean: (pose * p).coords.into(),
                    sigma_m: [s; 3],
                });
            }
        }
        // With a pose to fit from, the temporal fit decides most frames and the forest's start is tried only after
        // it: the forest then runs when that start is needed (same poses, the forest's 1 ms saved on most frames).
        let lazy =
            variant == Variant::ForestIcpFeedback && prior_pose.is_some() && !self.cfg.forest_every_frame;
        let mut points = [None; P];
        if !lazy {
            points = self.forest_stage(frame, &t.bed, &priors, clock, watch, report);
        }
        let forest_start = forest_pose(&points, &t.salient_torso);
        let (quality, cut) = if variant == Variant::Forest {
            match forest_start {
                Some(p) => {
                    self.pose = Some(p);
                    (FitQuality::Good, false)
                }
                None => (FitQuality::Failed, false),
            }
        } else {
            // Starts, best first: the last refined pose (feedback), the forest's pose, and when acquiring without
            // a pose, the forest's pose turned about the body's long axis (its roll is the least certain part).
            let mut starts: heapless::Vec<Isometry3, { 5 + bed_search::KEEP }> = heapless::Vec::new();
            if variant == Variant::ForestIcpFeedback
                && let Some(p) = prior_pose
            {
                let _ = starts.push(p);
            }
            // Re-acquiring: the patient is most likely near where the track was lost.
            if prior_pose.is_none()
                && variant == Variant::ForestIcpFeedback
                && let Some(p) = self.last_good_pose
            {
                let _ = starts.push(p);
            }
            if let Some(f) = forest_start {
                let _ = starts.push(f);
                if prior_pose.is_none() && variant == Variant::ForestIcpFeedback {
                    for r in rolled(&f) {
                        let _ = starts.push(r);
                    }
                }
            }
            let acquire_params = torso_icp::icp_params(&self.cfg.icp, &t.bed);
            let temporal_params = torso_icp::temporal_params(&self.cfg.icp, &t.bed);
            let icp_cfg = self.cfg.icp;
            if prior_pose.is_none()
                && variant == Variant::ForestIcpFeedback
                && let Some(f) = forest_start
            {
                for pose in self.screen_bed_starts(frame, &f, &t.bed, &acquire_params, clock, watch) {
                    let _ = starts.push(pose);
                }
            }
            let from_prior =
                |i: usize| i == 0 && prior_pose.is_some() && variant == Variant::ForestIcpFeedback;
            // The back-on-the-bed prior steers fits from the forest and the bed, not the temporal one.
            // The rotation hold is the temporal fit's alone, and only while occluded: the other starts are there to
            // move far, and a well-seen torso needs no hold.
            let temporal_cfg = TorsoIcpConfig {
                bed_pitch_weight: 0.0,
                hold_rotation_weight: if self.machine.state() == TrackerState::Occluded {
                    self.cfg.occluded_hold_rotation
                } else {
                    0.0
                },
                ..icp_cfg
            };
            let min_support = match (prior_pose, self.support_ref) {
                (Some(_), Some(r)) => icp_cfg.min_support.max(r - icp_cfg.support_drop),
                _ => icp_cfg.min_support,
            };
            // The best fit, and whether it moves the coasting pose (`TorsoIcpConfig::follow_occluded`).
            let mut best: Option<(Isometry3, TorsoFit, FitQuality, bool)> = None;
            // The temporal fit, and a far fit that sees more than it (`TorsoIcpConfig::switch_margin`).
            let mut temporal: Option<TorsoFit> = None;
            let mut switch: Option<(Isometry3, TorsoFit)> = None;
            let mut forest_ran = !lazy;
            let mut i = 0;
            loop {
                if i == starts.len() {
                    // The temporal fit did not decide the frame: now the forest's start.
                    if forest_ran {
                        break;
                    }
                    forest_ran = true;
                    watch.lap(clock, Stage::Icp);
                    points = self.forest_stage(frame, &t.bed, &priors, clock, watch, report);
                    match forest_pose(&points, &t.salient_torso) {
                        Some(f) => {
                            let _ = starts.push(f);
                        }
                        None => break,
                    }
                }
                let start = &starts[i];
                let (cfg_i, params_i) = if from_prior(i) {
                    (&temporal_cfg, &temporal_params)
                } else {
                    (&icp_cfg, &acquire_params)
                };
                let (pose, fit) = self.fit_model(
                    frame,
                    *start,
                    cfg_i,
                    params_i,
                    &self.cfg.budget,
                    if prior_pose.is_none() {
                        icp_cfg.acquire_min_iterations
                    } else {
                        0
                    },
                    clock,
                    watch,
                );
                let mut q = fit.quality(&icp_cfg, min_support, prior_pose.is_none());
                let max_hip = if from_prior(i) && fit.sure(&icp_cfg) {
                    TRACKED_MAX_HIP_HEIGHT_M
                } else {
                    MAX_HIP_HEIGHT_M
                };
                let on_bed = lies_on_bed(&pose, &t.bed, max_hip);
                if q == FitQuality::Good && !on_bed {
                    // A fit that floats above the bed or stands on edge has locked onto the arm or the bed frame.
                    q = FitQuality::Failed;
                }
                if from_prior(i) {
                    temporal = Some(fit);
                } else if let (Some(p), Some(own)) = (prior_pose, &temporal)
                    && on_bed
                    && fit.replaces(&icp_cfg, own, &p, &pose)
                {
                    // With a pose the only other start is the forest's: one candidate at most.
                    switch = Some((pose, fit));
                }
                if q == FitQuality::Good
                    && !from_prior(i)
                    && let Some(p) = prior_pose
                    && !icp_cfg.same_pose(&p, &pose)
                {
                    // While tracking, the patient cannot jump: a good fit far from the prior is another local
                    // minimum (the forest's start on a turned torso); coast instead, and re-acquire if it persists.
                    q = FitQuality::Failed;
                }
                let follows = on_bed && prior_pose.is_some_and(|p| fit.follows(&icp_cfg, q, &p, &pose));
                let better = match &best {
                    None => true,
                    Some((_, bf, bq, _)) => {
                        rank(q) > rank(*bq) || (rank(q) == rank(*bq) && fit.support() > bf.support())
                    }
                };
                if better {
                    best = Some((pose, fit, q, follows));
                }
                // A good fit from the temporal start is the common case: no second opinion needed. Nor for an
                // occluded one the pose follows: the other starts' fits would only be judged against it.
                if prior_pose.is_some() && (q == FitQuality::Good || (from_prior(i) && follows)) {
                    break;
                }
                if !self.another_fit_fits(clock, watch) {
                    break;
                }
                i += 1;
            }
            // The pose's own fit sees the torso clearly and does not match it: look again from the forest without
            // the prior (which the pose pulls to itself) and its rolls, as an acquisition would.
            if variant == Variant::ForestIcpFeedback
                && icp_cfg.clear_view_min_support > 0.0
                && switch.is_none()
                && best.is_some_and(|(_, _, q, _)| q != FitQuality::Good)
                && let (Some(p), Some(own)) = (prior_pose, temporal)
                && own.clear_view_mismatch(&icp_cfg)
            {
                // The second look reads this frame's forest votes.
                if !forest_ran {
                    watch.lap(clock, Stage::Icp);
                    points = self.forest_stage(frame, &t.bed, &priors, clock, watch, report);
                }
                switch = self.second_look(frame, &t, &p, &own, &acquire_params, clock, watch);
            }
            // A far fit that sees more of the torso than the pose's own (or, from the second look, has more
            // support), found at the same place on two frames in a row while the pose's fit is not good: the pose is
            // a wrong lock whose fit calls the patient an occluder.
            let mut switched = false;
            match switch {
                Some((pose, fit)) if best.is_some_and(|(_, _, q, _)| q != FitQuality::Good) => {
                    if self
                        .switch_candidate
                        .is_some_and(|c| icp_cfg.same_pose(&c, &pose))
                    {
                        best = Some((pose, fit, FitQuality::Good, false));
                        self.switch_candidate = None;
                        switched = true;
                    } else {
                        self.switch_candidate = Some(pose);
                    }
                }
                _ => self.switch_candidate = None,
            }
            match best {
                None => {
                    self.candidate = None;
                    self.near_candidate = None;
                    (FitQuality::Failed, false)
                }
                Some((pose, fit, mut q, follows)) => {
                    report.fit = fit;
                    report.fit_pose = Some(pose);
                    if prior_pose.is_none() && variant == Variant::ForestIcpFeedback {
                        let relaxed = TorsoIcpConfig {
                            max_rms_m: icp_cfg.near_max_rms_m,
                            ..icp_cfg
                        };
                        let near = icp_cfg.near_confirm > 0
                            && fit.quality(&relaxed, min_support, true) == FitQuality::Good
                            && lies_on_bed(&pose, &t.bed, MAX_HIP_HEIGHT_M);
                        q = self.confirm(pose, &fit, q, near);
                    }
                    match q {
                        FitQuality::Good => {
                            self.pose = Some(pose);
                            self.last_good_pose = Some(pose);
                            let sup = fit.support();
                            self.support_ref = Some(match (prior_pose, self.support_ref) {
                                (Some(_), Some(r)) if !switched => r + SUPPORT_FOLLOW * (sup - r),
                                _ => sup,
                            });
                        }
                        FitQuality::Occluded if follows => {
                            self.pose = Some(pose);
                        }
                        // Coasting: the pose stays where the last good fit left it.
                        FitQuality::Occluded | FitQuality::Failed => {
                            if prior_pose.is_none() {
                                self.pose = None;
                            }
                        }
                    }
                    if fit.cut {
                        self.counters.icp_cuts += 1;
                    }
                    (q, fit.cut)
                }
            }
        };
        watch.lap(clock, Stage::Icp);
        self.machine.fitted(quality, cut);
        if !self.machine.has_pose() {
            if self.machine.state() == TrackerState::Lost {
                self.pose = None;
            }
            return;
        }
        if variant == Variant::ForestIcpFeedback && self.doubts_lock(quality, &report.fit, &t.bed) {
            return;
        }
        if self.init.refits_left > 0 {
            self.init.waited = self.init.waited.saturating_add(1);
        }
        if quality == FitQuality::Good && self.machine.state() == TrackerState::Tracking {
            self.init.settled = self.init.settled.saturating_add(1);
        } else {
            self.init.settled = 0;
        }
        if quality == FitQuality::Good
            && variant != Variant::Forest
            && self.init.refits_left > 0
            && self.machine.state() == TrackerState::Tracking
            && self.init.settled > refit_settle(&self.cfg, self.init.round)
            && report.fit.visible >= refit_gate(&self.cfg, self.init.waited)
            && let Some(pose) = self.pose
        {
            self.defer_refit(frame, t, pose);
            watch.lap(clock, Stage::Init);
        }
        // A round's last refit adopts its shape when it runs, and the surface waits for the tracker to settle with
        // that shape, as it would had the refit run in this frame.
        let adopting = self.pending_refit.is_some() && self.init.refits_left == 1;
        if variant != Variant::Forest
            && !adopting
            && self.cfg.surface.frames > 0
            && self.init.surface_rounds < self.cfg.surface.rounds
            && self.init.settled > self.cfg.surface.settle_frames
            && report.fit.visible >= self.cfg.surface.min_visible
            && let Some(pose) = self.pose
        {
            self.adapt_surface(frame, &t.bed, pose, arm, clock, watch);
            watch.lap(clock, Stage::Init);
        }
        let (Some(pose), Some(t)) = (self.pose, self.torso) else {
            return;
        };
        report.camera_from_torso = Some(pose);
        report.salient_camera = Some(if variant == Variant::Forest {
            all_points(&points).unwrap_or(t.salient_torso.map(|p| pose * p))
        } else {
            t.salient_torso.map(|p| pose * p)
        });
        if let (Some(a), Some(surface)) = (arm, self.surface()) {
            let tip = probe::tip_in_torso(&a.tip_robot_base, &self.cfg.robot_base_from_camera, &pose);
            report.probe = probe::map_tip(&surface, &tip);
            report.arm_age_us = Some(frame.capture.since(a.time));
        }
    }

    /// The second look of a pose `prior` whose own fit `own` is a clear-view mismatch
    /// ([`TorsoIcpConfig::clear_view_min_support`]): the frame's forest votes without the prior, their pose and its two
    /// rolls, each fitted as an acquisition (while the budget allows); the fit that [`TorsoFit::outsupports`] `own`
    /// and lies on the bed with the most support. The bed search's starts are left out: with them the choice sets
    /// gave the same figures at twice the cost. Cost: a second mean-shift and three fits, on a wrong lock's frames
    /// only.
    #[allow(clippy::too_many_arguments)] // the frame, the torso, the pose and its fit, the fit's settings, clock
    fn second_look(
        &mut self,
        frame: &DepthFrame<'_>,
        t: &TorsoModel,
        prior: &Isometry3,
        own: &TorsoFit,
        params: &icp::IcpParams,
        clock: &(impl Clock + ?Sized),
        watch: &Stopwatch,
    ) -> Option<(Isometry3, TorsoFit)> {
        // The frame's forest pass left its samples and leaves in the workspace: only the mean-shift differs.
        let points = infer::reestimate(
            &self.models.joints,
            Method::Refined,
            &[None; P],
            self.scratch.forest,
        );
        let f = forest_pose(&points, &t.salient_torso)?;
        let [left, right] = rolled(&f);
        let cfg = self.cfg.icp;
        let mut found: Option<(Isometry3, TorsoFit)> = None;
        for start in [f, left, right] {
            if !self.another_fit_fits(clock, watch) {
                break;
            }
            let (pose, fit) = self.fit_model(
                frame,
                start,
                &cfg,
                params,
                &self.cfg.budget,
                cfg.acquire_min_iterations,
                clock,
                watch,
            );
            if lies_on_bed(&pose, &t.bed, MAX_HIP_HEIGHT_M)
                && fit.outsupports(&cfg, own, prior, &pose)
                && found.is_none_or(|(_, b)| fit.support() > b.support())
            {
                found = Some((pose, fit));
            }
        }
        found
    }

    /// The [`bed_search`] grid around the forest's pose `forest`, each start screened by a few ICP iterations
    /// (while the budget allows); the best [`bed_search::KEEP`] screened poses by support, best first.
    fn screen_bed_starts(
        &self,
        frame: &DepthFrame<'_>,
        forest: &Isometry3,
        bed: &BedScene,
        params: &icp::IcpParams,
        clock: &(impl Clock + ?Sized),
        watch: &Stopwatch,
    ) -> heapless::Vec<Isometry3, { bed_search::KEEP + 1 }> {
        let screen = BudgetConfig {
            icp_iterations: bed_search::SCREEN_ITERATIONS,
            ..self.cfg.budget
        };
        let cfg = TorsoIcpConfig {
            stride: self.cfg.screen_stride.max(1),
            ..self.cfg.icp
        };
        let back = bed_search::back_depth_m(self.scratch.torso_vertices);
        let mut kept: [(f32, Isometry3); bed_search::KEEP] = [(0.0, Isometry3::identity()); bed_search::KEEP];
        for start in bed_search::grid_starts(forest, bed, back) {
            if !self.another_fit_fits(clock, watch) {
                break;
            }
            let iterations = bed_search::SCREEN_ITERATIONS;
            let Some((pose, score)) =
                self.fit_lying(frame, bed, start, &cfg, params, &screen, iterations, clock, watch)
            else {
                continue;
            };
            if let Some(i) = kept.iter().position(|(s, _)| score > *s) {
                kept[i..].rotate_right(1);
                kept[i] = (score, pose);
            }
        }
        kept.iter().filter(|(s, _)| *s > 0.0).map(|(_, p)| *p).collect()
    }

    /// Whether the frame's budget leaves room for one more start's fit (the time left against a quarter of the
    /// forest stage's): the frame's starts, the bed search's screening and the second look all ask it.
    fn another_fit_fits(&self, clock: &(impl Clock + ?Sized), watch: &Stopwatch) -> bool {
        budget::iteration_fits(
            &self.cfg.budget,
            watch.elapsed(clock),
            // A frame that has not run the forest yet estimates a fit from the last pass's time.
            match watch.times.of(Stage::Forest) {
                0 => self.forest_us,
                us => us,
            } / 4,
        )
    }

    /// [`torso_icp::fit_torso`] of the tracker's torso model from `start`.
    #[allow(clippy::too_many_arguments)] // fit_torso's inputs that differ between the callers
    fn fit_model(
        &self,
        frame: &DepthFrame<'_>,
        start: Isometry3,
        cfg: &TorsoIcpConfig,
        params: &icp::IcpParams,
        budget: &BudgetConfig,
        min_iterations: u8,
        clock: &(impl Clock + ?Sized),
        watch: &Stopwatch,
    ) -> (Isometry3, TorsoFit) {
        torso_icp::fit_torso(
            frame,
            &self.k,
            self.scratch.torso_vertices,
            self.scratch.torso_normals,
            start,
            cfg,
            params,
            budget,
            min_iterations,
            clock,
            watch,
        )
    }

    /// The torso fit from `start` and its support, when it has enough pairs and lies on the bed.
    #[allow(clippy::too_many_arguments)] // fit_torso's inputs that differ between the callers
    fn fit_lying(
        &self,
        frame: &DepthFrame<'_>,
        bed: &BedScene,
        start: Isometry3,
        cfg: &TorsoIcpConfig,
        params: &icp::IcpParams,
        budget: &BudgetConfig,
        min_iterations: u8,
        clock: &(impl Clock + ?Sized),
        watch: &Stopwatch,
    ) -> Option<(Isometry3, f32)> {
        let (pose, fit) = self.fit_model(frame, start, cfg, params, budget, min_iterations, clock, watch);
        let pairs = cfg.model_points(fit.association.pairs);
        (pairs >= cfg.min_pairs as usize && lies_on_bed(&pose, bed, MAX_HIP_HEIGHT_M))
            .then(|| (pose, fit.support()))
    }

    /// Acquisition without a pose: a good fit is taken at once when its residual is low, otherwise only once
    /// `acquire_confirm` consecutive frames found the same pose (a wrong local minimum moves with the forest's
    /// start from frame to frame; the right pose stays); a near-good fit (`near`) only once
    /// [`TorsoIcpConfig::near_confirm`] consecutive frames found it.
    fn confirm(&mut self, pose: Isometry3, fit: &TorsoFit, q: FitQuality, near: bool) -> FitQuality {
        let cfg = self.cfg.icp;
        let near_run = consistent_run(self.near_candidate, &pose, near, &cfg);
        self.near_candidate = (near_run > 0).then_some((pose, near_run));
        if q != FitQuality::Good {
            self.candidate = None;
            if cfg.near_confirm > 0 && near_run >= cfg.near_confirm {
                self.near_candidate = None;
                return FitQuality::Good;
            }
            return q;
        }
        let run = consistent_run(self.candidate, &pose, true, &cfg);
        if fit.sure(&cfg) || run >= cfg.acquire_confirm {
            // The acquisition ends: neither run may carry over to the next one.
            self.candidate = None;
            self.near_candidate = None;
            FitQuality::Good
        } else {
            self.candidate = Some((pose, run));
            FitQuality::Failed
        }
    }

    fn packets(&mut self, time: Timestamp, report: &mut FrameReport) {
        let rb = self.cfg.robot_base_from_camera;
        if let (Some(pose), Some(points)) = (report.camera_from_torso, report.salient_camera) {
            let conf = match report.state {
                TrackerState::Occluded => Confidence::from_fraction(0.3),
                _ if self.cfg.variant == Variant::Forest => Confidence::from_fraction(
                    report
                        .forest_points
                        .iter()
                        .flatten()
                        .map(|p| p.confidence)
                        .sum::<f32>()
                        / P as f32,
                ),
                _ => Confidence::from_fraction(report.fit.visible),
            };
            let rb_torso = rb * pose;
            let body = wire::Body::TorsoPose(TorsoPose {
                position_mm: mm(&Point3::from(rb_torso.translation.vector)),
                orientation: quat_q14(&rb_torso.rotation),
                confidence: conf,
            });
            let m = self.message(time, body);
            let _ = report.packets.push(m);
            let mut sp = [SalientPointReport {
                position_mm: [0; 3],
                confidence: conf,
            }; P];
            for (r, p) in sp.iter_mut().zip(&points) {
                r.position_mm = mm(&(rb * p));
            }
            let m = self.message(time, wire::Body::SalientPoints(SalientPoints { points: sp }));
            let _ = report.packets.push(m);
        }
        if let Some(p) = report.probe {
            let m = self.message(time, wire::Body::Probe(p.report()));
            let _ = report.packets.push(m);
        }
        if let Some(t) = self.torso {
            let due = match self.last_shape_frame {
                None => true,
                Some(f) => self.frames.wrapping_sub(f) >= self.cfg.shape_every_frames.max(1),
            };
            if due {
                let coefficients_milli = t
                    .shape
                    .map(|c| libm::roundf(c * 1000.0).clamp(-32767.0, 32767.0) as i16);
                let body = wire::Body::BodyShape(BodyShape {
                    revision: self.shape_revision,
                    coefficients_milli,
                });
                let m = self.message(time, body);
                let _ = report.packets.push(m);
                self.last_shape_frame = Some(self.frames);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_of_frames_counts_up_at_the_same_pose_and_restarts_on_a_jump_or_a_miss() {
        let cfg = TorsoIcpConfig::default();
        let at = |x: f32| Isometry3::translation(x, 0.0, 1.5);
        let mut last = None;
        let mut runs = [0u8; 6];
        // Found at 0, 1 cm, 2 cm (each within confirm_m of the last), then 10 cm away, then not found, then found.
        for (r, (x, found)) in runs.iter_mut().zip([
            (0.0, true),
            (0.01, true),
            (0.02, true),
            (0.12, true),
            (0.12, false),
            (0.12, true),
        ]) {
            *r = consistent_run(last, &at(x), found, &cfg);
            last = (*r > 0).then_some((at(x), *r));
        }
        assert_eq!(runs, [1, 2, 3, 1, 0, 1]);
    }

    #[test]
    fn a_tracked_hip_may_lie_higher_above_the_mattress_than_an_acquired_one() {
        use crate::geometry::Translation3;
        let bed = bed_search::tests::bed();
        // Lying on the back, the chest toward the camera, the hip centre `h` above the mattress 1.5 m away.
        let at = |h: f32, roll: f32| {
            Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 1.5 - h),
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), core::f32::consts::PI)
                    * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), roll),
            )
        };
        for (h, acquired, tracked) in [
            (0.15, true, true),
            (0.29, true, true),
            (0.33, false, true),
            (0.39, false, true),
            (0.42, false, false),
            (-0.08, false, false),
        ] {
            assert_eq!(
                lies_on_bed(&at(h, 0.0), &bed, MAX_HIP_HEIGHT_M),
                acquired,
                "{h} m"
            );
            assert_eq!(
                lies_on_bed(&at(h, 0.0), &bed, TRACKED_MAX_HIP_HEIGHT_M),
                tracked,
                "{h} m"
            );
        }
        // Rolled 30° it lies; on its side it does not, however low.
        assert!(lies_on_bed(&at(0.2, 0.5), &bed, MAX_HIP_HEIGHT_M));
        assert!(!lies_on_bed(&at(0.2, 1.3), &bed, TRACKED_MAX_HIP_HEIGHT_M));
    }

    #[test]
    fn only_later_lock_refit_rounds_wait_for_the_tracker_to_settle() {
        let cfg = TrackerConfig::default();
        assert!(cfg.refit_rounds > 0 && cfg.refit_settle_frames > 0);
        assert_eq!(refit_settle(&cfg, 0), 0);
        assert_eq!(refit_settle(&cfg, 1), cfg.refit_settle_frames);
        assert_eq!(refit_settle(&cfg, cfg.refit_rounds), cfg.refit_settle_frames);
    }

    #[test]
    fn waiting_lock_refits_lower_their_visibility_gate_only_after_the_late_frames() {
        let cfg = TrackerConfig::default();
        assert_eq!(refit_gate(&cfg, 0), cfg.refit_min_visible);
        assert_eq!(refit_gate(&cfg, cfg.refit_late_frames - 1), cfg.refit_min_visible);
        assert_eq!(
            refit_gate(&cfg, cfg.refit_late_frames),
            cfg.refit_late_min_visible
        );
        assert!(cfg.refit_late_min_visible < cfg.refit_min_visible);
        let never = TrackerConfig {
            refit_late_frames: 0,
            ..cfg
        };
        assert_eq!(refit_gate(&never, u16::MAX), never.refit_min_visible);
    }
}
