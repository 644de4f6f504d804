//! Arm states for a replay (`supine replay --arm FILE`): a capture of the arm controller's messages in the serial
//! framing (a sequence's `arm.cobs`, or what `--link file:PATH` recorded; see docs/dataset-format.md), decoded once
//! and kept sorted by the arm's sample time. Per frame the tracker gets the newest state sampled at or before the
//! frame's capture time, as a live link would have delivered it by then.
//!
//! Without `--arm` but with `--truth`, [`synthesise`] makes a state per frame from the truth's probe pose, with the
//! arm's own sample time (up to ±0.5 ms off the capture) and encoder noise (0.3 mm per axis, 0.02° per sample), from
//! a fixed seed so that a replay reproduces its figures.
//!
//! Cost: the file is read and decoded once (O(n log n) to sort); per frame a binary search.

use std::path::Path;

use supine_core::calib::ArmSample;
use supine_core::depth::DepthFrame;
use supine_core::geometry::{Point3, UnitQuaternion, Vector3};
use supine_core::rng::SplitMix64;
use supine_core::time::Timestamp;
use supine_core::wire::stream::SerialDecoder;

use crate::truth::Truth;

/// Arm states of a capture file, sorted by sample time.
#[derive(Debug)]
pub struct ArmTrack {
    samples: Vec<ArmSample>,
    /// Frames of the file that did not decode (counted, skipped).
    pub bad_frames: u64,
}

impl ArmTrack {
    /// Read and decode `path`; a file that holds no arm state is an error naming it.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Self::decode(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    }

    /// Decode a capture in the serial framing.
    pub fn decode(bytes: &[u8]) -> anyhow::Result<Self> {
        let mut decoder: SerialDecoder = SerialDecoder::new();
        let mut samples = Vec::new();
        decoder.feed_all(bytes, |m| samples.extend(ArmSample::from_message(&m)));
        decoder.finish();
        let bad_frames = u64::from(decoder.stats().errors());
        if samples.is_empty() {
            anyhow::bail!(
                "holds no arm state in the serial framing ({} bytes, {bad_frames} undecodable frames); an arm \
                 capture such as a sequence's arm.cobs is expected",
                bytes.len()
            );
        }
        samples.sort_by_key(|s| s.time);
        Ok(ArmTrack { samples, bad_frames })
    }

    /// Arm states in the file.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// The newest state sampled at or before `t`.
    pub fn at(&self, t: Timestamp) -> Option<&ArmSample> {
        let n = self.samples.partition_point(|s| s.time <= t);
        n.checked_sub(1).map(|i| &self.samples[i])
    }
}

/// The true probe pose of truth frame `i` as an arm state stamped with the frame's capture time (the reference the
/// probe errors are measured against).
pub fn from_truth(truth: &Truth, i: usize, frame: &DepthFrame<'_>) -> Option<ArmSample> {
    let m = truth.frame(i)?.world_from_probe.as_ref()?;
    let p = supine_core::geometry::isometry_from_rows(m);
    Some(ArmSample {
        time: frame.capture,
        tip_robot_base: Point3::from(p.translation.vector),
        robot_base_from_probe: p.rotation,
    })
}

/// Seed of the synthesised arm's noise.
pub const SYNTH_SEED: u64 = 0x5eed_a12e;

/// An arm state as the controller would report the true one: its own sample time and encoder noise.
pub fn synthesise(truth: &ArmSample, rng: &mut SplitMix64) -> ArmSample {
    let mut gauss = || {
        // Box-Muller from two uniforms in (0, 1].
        let u1 = ((rng.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64;
        let u2 = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
    };
    let jitter_us = (gauss() * 250.0).clamp(-500.0, 500.0) as i64;
    let offset = Vector3::new(gauss(), gauss(), gauss()) * 0.0003;
    let axis = Vector3::new(gauss(), gauss(), gauss());
    let turn = UnitQuaternion::from_scaled_axis(axis * 0.02f32.to_radians());
    ArmSample {
        time: truth.time.offset_by(jitter_us),
        tip_robot_base: truth.tip_robot_base + offset,
        robot_base_from_probe: turn * truth.robot_base_from_probe,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use supine_core::wire::{ArmState, Body, Message, UnitQuatQ14};

    fn state(t_us: u64, x_mm: i32) -> Vec<u8> {
        let m = Message {
            seq: 0,
            timestamp: Timestamp::from_us(t_us).unwrap(),
            body: Body::ArmState(ArmState {
                position_mm: [x_mm, 0, 500],
                orientation: UnitQuatQ14::new_checked([16384, 0, 0, 0]).unwrap(),
            }),
        };
        let mut buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
        let n = m.encode_serial(&mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn the_newest_state_at_or_before_a_frame() {
        let mut bytes = state(20_000, 2);
        bytes.extend([0, 7, 7, 7, 0]);
        bytes.extend(state(10_000, 1));
        let track = ArmTrack::decode(&bytes).unwrap();
        assert_eq!(track.len(), 2);
        assert_eq!(track.bad_frames, 1);
        let at = |us| {
            track
                .at(Timestamp::from_us(us).unwrap())
                .map(|s| s.tip_robot_base.x)
        };
        assert_eq!(at(5_000), None);
        assert_eq!(at(10_000), Some(0.001));
        assert_eq!(at(19_999), Some(0.001));
        assert_eq!(at(40_000), Some(0.002));
    }

    #[test]
    fn a_file_without_arm_states_is_an_error() {
        let e = ArmTrack::decode(b"not a capture").unwrap_err().to_string();
        assert!(e.contains("no arm state"), "{e}");
    }

    #[test]
    fn synthesised_states_are_noisy_near_the_truth_and_seeded() {
        let truth = ArmSample {
            time: Timestamp::from_us(1_000_000).unwrap(),
            tip_robot_base: Point3::new(0.5, 0.1, 0.9),
            robot_base_from_probe: UnitQuaternion::identity(),
        };
        let (mut a, mut b) = (SplitMix64(SYNTH_SEED), SplitMix64(SYNTH_SEED));
        let mut moved = 0;
        for _ in 0..100 {
            let s = synthesise(&truth, &mut a);
            assert_eq!(s, synthesise(&truth, &mut b));
            let d = (s.tip_robot_base - truth.tip_robot_base).norm();
            assert!(d < 0.003, "{d}");
            assert!(s.time.since(truth.time).abs() <= 500);
            assert!(s.robot_base_from_probe.angle() < 0.2f32.to_radians());
            moved += usize::from(d > 0.0);
        }
        assert!(moved > 90);
    }
}
