//! Turning a stream of arm states and depth frames into calibration pairs: the arm history (each depth frame is
//! matched to the arm state nearest its capture time, and told whether the arm stood still around it), and the
//! dwell collector (consecutive still frames at one arm pose become one averaged pair).
//!
//! Only frames where the arm stood still for `settle_us` on both sides are used: the arm's latency and the depth
//! camera's exposure then do not matter. Cost per frame: a scan of the arm history (at most `N` samples) and a
//! few additions. Nothing allocates: capacities are const generics.

use crate::geometry::{Point3, UnitQuaternion, Vector3};
use crate::time::Timestamp;
use crate::wire::{ArmState, Message};

/// One arm state: where the arm says its probe tip is, and when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmSample {
    /// The arm's sample time on the capture clock.
    pub time: Timestamp,
    /// Probe tip, `robot_base`, metres.
    pub tip_robot_base: Point3,
    /// Probe orientation `robot_base_from_probe` (z along the probe, into the body).
    pub robot_base_from_probe: UnitQuaternion,
}

impl ArmSample {
    /// The sample an arm-state message carries.
    pub fn from_wire(time: Timestamp, state: &ArmState) -> ArmSample {
        let [w, x, y, z] = state.orientation.to_f32();
        let q = nalgebra::Quaternion::new(w, x, y, z);
        ArmSample {
            time,
            tip_robot_base: Point3::from(state.position_mm.map(|v| v as f32 * 0.001)),
            robot_base_from_probe: UnitQuaternion::from_quaternion(q),
        }
    }

    /// The sample of an arm-state message; `None` for other kinds.
    pub fn from_message(m: &Message) -> Option<ArmSample> {
        match &m.body {
            crate::wire::Body::ArmState(s) => Some(ArmSample::from_wire(m.timestamp, s)),
            _ => None,
        }
    }

    /// The probe axis (from the wrist toward the tip) in `robot_base`.
    pub fn axis_robot_base(&self) -> Vector3 {
        self.robot_base_from_probe * Vector3::z()
    }
}

/// The arm states of the last moments, in time order (a ring of `N`).
#[derive(Debug, Clone)]
pub struct ArmHistory<const N: usize> {
    samples: [Option<ArmSample>; N],
    next: usize,
    len: usize,
    rejected: u32,
}

impl<const N: usize> Default for ArmHistory<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// How a depth frame's capture time relates to the arm history.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Match {
    /// The arm state nearest the frame, and the frame's distance from it.
    Found {
        /// The arm state.
        sample: ArmSample,
        /// Frame time minus arm time, µs.
        offset_us: i64,
        /// Whether the arm moved less than the stillness tolerance over ±settle around the frame.
        still: bool,
    },
    /// The nearest arm state is further away than the allowed offset (clocks disagree, or the arm is silent).
    OutOfTime {
        /// Frame time minus nearest arm time, µs (0 when the history is empty).
        offset_us: i64,
    },
}

impl<const N: usize> ArmHistory<N> {
    /// An empty history.
    pub const fn new() -> Self {
        ArmHistory {
            samples: [None; N],
            next: 0,
            len: 0,
            rejected: 0,
        }
    }

    /// Add a sample; samples not later than the newest held one are rejected (replays, reordering) and counted.
    pub fn push(&mut self, s: ArmSample) -> bool {
        if let Some(newest) = self.newest()
            && s.time <= newest.time
        {
            self.rejected = self.rejected.saturating_add(1);
            return false;
        }
        self.samples[self.next] = Some(s);
        self.next = (self.next + 1) % N;
        self.len = (self.len + 1).min(N);
        true
    }

    /// The newest sample.
    pub fn newest(&self) -> Option<ArmSample> {
        if self.len == 0 {
            return None;
        }
        self.samples[(self.next + N - 1) % N]
    }

    /// Samples rejected as not newer.
    pub fn rejected(&self) -> u32 {
        self.rejected
    }

    fn iter(&self) -> impl Iterator<Item = &ArmSample> {
        self.samples.iter().filter_map(|s| s.as_ref())
    }

    /// Match a frame captured at `t`: the nearest sample within `max_offset_us`, and whether every sample within
    /// `settle_us` of `t` lies within `still_m` of it (and the history covers that whole window).
    pub fn match_frame(&self, t: Timestamp, max_offset_us: u64, settle_us: u64, still_m: f32) -> Match {
        let Some(nearest) = self.iter().min_by_key(|s| t.since(s.time).unsigned_abs()) else {
            return Match::OutOfTime { offset_us: 0 };
        };
        let offset_us = t.since(nearest.time);
        if offset_us.unsigned_abs() > max_offset_us {
            return Match::OutOfTime { offset_us };
        }
        let (mut before, mut after) = (false, false);
        let mut still = true;
        for s in self.iter() {
            let dt = s.time.since(t);
            if dt.unsigned_abs() <= settle_us {
                still &= (s.tip_robot_base - nearest.tip_robot_base).norm() <= still_m;
            }
            before |= dt <= -(settle_us as i64);
            after |= dt >= settle_us as i64;
        }
        Match::Found {
            sample: *nearest,
            offset_us,
            still: still && before && after,
        }
    }
}

/// One calibration pose: the averaged arm tip and camera tip over the still frames of one dwell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseObservation {
    /// Mean arm tip, `robot_base`, metres.
    pub robot_base: Point3,
    /// Mean detected tip, `camera`, metres.
    pub camera: Point3,
    /// Still frames averaged.
    pub frames: u32,
    /// Arm time of the first frame of the dwell.
    pub first_time: Timestamp,
    /// Root mean square distance of the frames' detections from their mean, metres.
    pub spread_m: f32,
    /// Mean detection confidence.
    pub confidence: f32,
    /// Mean probe axis (from the wrist toward the tip) the arm reported, `robot_base`, unit; zero when unknown
    /// (pairs read without it). The solver weights a pair's error along it less: the detector places the tip
    /// across the axis to a fraction of a millimetre, along it only to 1-3 mm.
    pub axis_robot_base: Vector3,
}

/// Groups still, matched frames into poses: a new pose starts when the arm tip is more than `same_pose_m` from the
/// current pose's, or a frame of motion came in between. Poses of fewer than `min_frames` frames are dropped.
#[derive(Debug, Clone)]
pub struct DwellCollector<const P: usize> {
    poses: [Option<PoseObservation>; P],
    done: usize,
    current: Option<Accumulator>,
    /// A pose continues only within this distance of its mean arm tip, metres.
    pub same_pose_m: f32,
    /// Fewest frames of a pose.
    pub min_frames: u32,
    /// A frame's detection farther than this from the dwell's median detection is left out of the pose, metres.
    pub outlier_m: f32,
}

/// Detections of one dwell kept for the robust mean; later frames of a longer dwell add to the arm's mean only.
pub const DWELL_FRAMES: usize = 32;

#[derive(Debug, Clone, Copy)]
struct Accumulator {
    rb: Vector3,
    axis: Vector3,
    /// Detections (camera, metres) and confidences of the first [`DWELL_FRAMES`] frames.
    cam: [Point3; DWELL_FRAMES],
    conf: [f32; DWELL_FRAMES],
    kept: usize,
    frames: u32,
    first_time: Timestamp,
}

impl Accumulator {
    /// The pose: the arm's mean over all frames; the camera's mean over the detections within `outlier_m` of their
    /// per-axis median (a frame now and then takes the wrist or the other face of the head for the tip, 2-10 cm
    /// off with full confidence, and one such frame among 8 moves a plain mean by centimetres). `None` when fewer
    /// than `min_frames` or no more than half of the detections agree.
    fn observation(&self, outlier_m: f32, min_frames: u32) -> Option<PoseObservation> {
        let k = self.kept;
        let cam = &self.cam[..k];
        let mut axis = [0.0f32; DWELL_FRAMES];
        let mut median = [0.0f32; 3];
        for (j, m) in median.iter_mut().enumerate() {
            for (a, p) in axis.iter_mut().zip(cam) {
                *a = p.coords[j];
            }
            let (_, mid, _) = axis[..k].select_nth_unstable_by(k / 2, |x, y| x.total_cmp(y));
            *m = *mid;
        }
        let median = Point3::new(median[0], median[1], median[2]);
        let (mut sum, mut sq, mut conf, mut used) = (Vector3::zeros(), 0.0f32, 0.0f32, 0usize);
        for (p, c) in cam.iter().zip(&self.conf[..k]) {
            let d = p - median;
            if d.norm() <= outlier_m {
                sum += d;
                sq += d.norm_squared();
                conf += c;
                used += 1;
            }
        }
        if (used as u32) < min_frames || 2 * used <= k {
            return None;
        }
        let n = used as f32;
        // Offsets from the median, so the variance keeps its precision in f32.
        let mean = sum / n;
        let var = (sq / n - mean.norm_squared()).max(0.0);
        Some(PoseObservation {
            robot_base: Point3::from(self.rb / self.frames as f32),
            camera: median + mean,
            frames: used as u32,
            first_time: self.first_time,
            spread_m: libm::sqrtf(var),
            confidence: conf / n,
            axis_robot_base: self.axis.try_normalize(1e-6).unwrap_or_else(Vector3::zeros),
        })
    }
}

impl<const P: usize> Default for DwellCollector<P> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const P: usize> DwellCollector<P> {
    /// An empty collector: 5 mm pose tolerance, at least 3 frames a pose, detections 8 mm from the dwell's median
    /// left out (a good frame's detection is within 1-5 mm of the truth on the validation sequences).
    pub const fn new() -> Self {
        DwellCollector {
            poses: [None; P],
            done: 0,
            current: None,
            same_pose_m: 0.005,
            min_frames: 3,
            outlier_m: 0.008,
        }
    }

    /// A still frame: the arm's tip and the detected tip (with its confidence).
    pub fn still(&mut self, arm: &ArmSample, tip_camera: Point3, confidence: f32) {
        if let Some(c) = &self.current
            && (arm.tip_robot_base.coords - c.rb / c.frames as f32).norm() > self.same_pose_m
        {
            self.close();
        }
        let c = self.current.get_or_insert(Accumulator {
            rb: Vector3::zeros(),
            axis: Vector3::zeros(),
            cam: [Point3::origin(); DWELL_FRAMES],
            conf: [0.0; DWELL_FRAMES],
            kept: 0,
            frames: 0,
            first_time: arm.time,
        });
        c.rb += arm.tip_robot_base.coords;
        c.axis += arm.axis_robot_base();
        if c.kept < DWELL_FRAMES {
            c.cam[c.kept] = tip_camera;
            c.conf[c.kept] = confidence;
            c.kept += 1;
        }
        c.frames += 1;
    }

    /// A frame where the arm moved (or the tip was not found): the current pose ends.
    pub fn moving(&mut self) {
        self.close();
    }

    /// Close the current pose (also at the end of the input).
    pub fn close(&mut self) {
        if let Some(c) = self.current.take()
            && c.frames >= self.min_frames
            && self.done < P
            && let Some(o) = c.observation(self.outlier_m, self.min_frames)
        {
            self.poses[self.done] = Some(o);
            self.done += 1;
        }
    }

    /// Poses completed so far.
    pub fn len(&self) -> usize {
        self.done
    }

    /// No pose completed yet.
    pub fn is_empty(&self) -> bool {
        self.done == 0
    }

    /// Whether the capacity is used up.
    pub fn is_full(&self) -> bool {
        self.done == P
    }

    /// The completed poses, in order.
    pub fn poses(&self) -> impl Iterator<Item = PoseObservation> + '_ {
        self.poses[..self.done].iter().filter_map(|p| *p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(us: u64) -> Timestamp {
        Timestamp::from_us(us).unwrap()
    }

    fn sample(us: u64, x: f32) -> ArmSample {
        ArmSample {
            time: at(us),
            tip_robot_base: Point3::new(x, 0.5, 0.9),
            robot_base_from_probe: UnitQuaternion::identity(),
        }
    }

    #[test]
    fn frames_match_the_nearest_state_and_see_motion() {
        let mut h: ArmHistory<64> = ArmHistory::new();
        // 100 Hz: still at x = 0 until 200 ms, then moving 1 mm per sample.
        for i in 0..40u64 {
            let x = if i < 20 { 0.0 } else { 0.001 * (i - 19) as f32 };
            assert!(h.push(sample(i * 10_000, x)));
        }
        assert!(!h.push(sample(100_000, 0.0)), "older states are rejected");
        assert_eq!(h.rejected(), 1);
        match h.match_frame(at(103_000), 20_000, 50_000, 0.002) {
            Match::Found {
                sample,
                offset_us,
                still,
            } => {
                assert_eq!((sample.time.as_us(), offset_us), (100_000, 3_000));
                assert!(still);
            }
            m => panic!("{m:?}"),
        }
        let Match::Found { still, .. } = h.match_frame(at(190_000), 20_000, 50_000, 0.002) else {
            panic!()
        };
        assert!(!still, "the arm starts moving within the settle window");
        assert!(matches!(
            h.match_frame(at(900_000), 20_000, 50_000, 0.002),
            Match::OutOfTime { offset_us: 510_000 }
        ));
        let Match::Found { still, .. } = h.match_frame(at(10_000), 20_000, 50_000, 0.002) else {
            panic!()
        };
        assert!(!still, "no history before the frame: not known to be still");
    }

    #[test]
    fn dwells_become_averaged_poses() {
        let mut c: DwellCollector<4> = DwellCollector::new();
        for i in 0..5 {
            c.still(
                &sample(i * 33_000, 0.0),
                Point3::new(0.1, 0.2, 1.0 + 0.001 * i as f32),
                0.9,
            );
        }
        c.moving();
        c.still(&sample(400_000, 0.3), Point3::new(0.4, 0.2, 1.0), 0.8);
        c.moving(); // one frame only: dropped
        for i in 0..3 {
            c.still(
                &sample(500_000 + i * 33_000, 0.2),
                Point3::new(0.3, 0.2, 1.0),
                0.8,
            );
        }
        // A jump of the arm without a moving frame in between still starts a new pose.
        for i in 0..3 {
            c.still(
                &sample(700_000 + i * 33_000, 0.25),
                Point3::new(0.35, 0.2, 1.0),
                0.8,
            );
        }
        c.close();
        let poses: heapless::Vec<PoseObservation, 4> = c.poses().collect();
        assert_eq!(poses.len(), 3);
        assert_eq!(poses[0].frames, 5);
        assert!((poses[0].camera.z - 1.002).abs() < 1e-5);
        assert!(
            (poses[0].spread_m - 0.001414).abs() < 1e-4,
            "{}",
            poses[0].spread_m
        );
        assert!((poses[1].robot_base.x - 0.2).abs() < 1e-6);
        // The arm's probe axis comes along (identity orientation: probe z).
        assert!((poses[0].axis_robot_base - Vector3::z()).norm() < 1e-6);
        assert!((poses[2].robot_base.x - 0.25).abs() < 1e-6);
    }

    #[test]
    fn a_dwell_leaves_out_frames_that_took_something_else_for_the_tip() {
        let mut c: DwellCollector<4> = DwellCollector::new();
        // Seven frames agree within 2 mm; one took the wrist for the tip, 7 cm up the probe.
        for i in 0..8u64 {
            let z = if i == 5 {
                0.93
            } else {
                1.0 + 0.0005 * (i % 3) as f32
            };
            c.still(&sample(i * 33_000, 0.0), Point3::new(0.1, 0.2, z), 0.9);
        }
        c.moving();
        // Detections that agree on nothing (half here, half 3 cm away): no pose.
        for i in 0..6u64 {
            let x = if i % 2 == 0 { 0.1 } else { 0.13 };
            c.still(&sample(400_000 + i * 33_000, 0.2), Point3::new(x, 0.2, 1.0), 0.9);
        }
        c.close();
        let poses: heapless::Vec<PoseObservation, 4> = c.poses().collect();
        assert_eq!(poses.len(), 1, "{poses:?}");
        assert_eq!(poses[0].frames, 7);
        let mean_z = (3.0 * 1.0 + 3.0 * 1.0005 + 1.001) / 7.0;
        assert!((poses[0].camera.z - mean_z).abs() < 1e-5, "{}", poses[0].camera.z);
        assert!(poses[0].spread_m < 0.001, "{}", poses[0].spread_m);
    }
}
