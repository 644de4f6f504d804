//! Arm states beside a tracking sequence, `DIR/arm.cobs`: what the arm controller would have sent while the
//! sequence was captured, in the serial framing `sequence --calibration` writes (readable by the `file:` link and by
//! [`crate::eval::calibration::read_arm_capture`]).
//!
//! Samples at `rate_hz` on the capture clock, each timestamp jittered by ±0.5 ms; each carries the true probe pose
//! `latency` earlier (one latency per sequence), interpolated between the two frames around that time (linear tip,
//! spherical rotation: the arm moves smoothly, well under a millimetre off its path within a frame), plus a constant
//! kinematic error per sequence and encoder noise per sample. Where the arm is absent on either side of that time
//! (before it appears or after it leaves, with no sweep), no sample is sent.
//!
//! Cost: a few µs per sample, after the frames are generated.

use crate::dataset::mix_seed;
use anyhow::{Context, Result};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::io::Write;
use std::path::Path;
use supine_core::time::Timestamp;
use supine_core::wire::{ArmState as WireArmState, Body, Message, UnitQuatQ14};

/// File name of the arm states beside `sequence.oni`.
pub const FILE_NAME: &str = "arm.cobs";

/// How the arm reports its state (`sequence.json`'s `arm`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ArmStream {
    /// File name, relative to the sequence directory.
    pub file: String,
    /// Arm-state rate, Hz.
    pub rate_hz: f32,
    /// Encoder noise on the reported tip, mm (sd per axis, every sample).
    pub encoder_noise_mm: f32,
    /// Encoder noise on the reported orientation, degrees (sd per axis).
    pub orientation_noise_deg: f32,
    /// Sd per axis of the arm model's kinematic error, mm (one offset for the whole sequence).
    pub kinematic_error_mm: f32,
    /// The arm's latency in this sequence (sample time to reported pose), µs.
    pub latency_us: u32,
    /// The kinematic error drawn for this sequence, `robot_base`, mm.
    pub kinematic_offset_mm: [f32; 3],
    /// Arm states written.
    pub samples: u32,
}

/// Write the arm states for the per-frame true probe poses `world_from_probe` (world = `robot_base`; `None` where
/// the arm is absent) of a sequence at `fps`, into `dir`. Noise, latency and jitter are drawn from `seed`.
pub fn write_arm_states(
    dir: &Path,
    world_from_probe: &[Option<Isometry3<f32>>],
    fps: f32,
    seed: u64,
) -> Result<ArmStream> {
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, 0xA5E));
    let mut s = ArmStream {
        file: FILE_NAME.to_string(),
        rate_hz: 100.0,
        encoder_noise_mm: 0.3,
        orientation_noise_deg: 0.02,
        kinematic_error_mm: 0.5,
        latency_us: rng.gen_range(5_000..=25_000),
        kinematic_offset_mm: [0.0; 3],
        samples: 0,
    };
    let kin = Normal::new(0.0f32, s.kinematic_error_mm)?;
    s.kinematic_offset_mm = [kin.sample(&mut rng), kin.sample(&mut rng), kin.sample(&mut rng)];
    let enc = Normal::new(0.0f32, s.encoder_noise_mm * 0.001)?;
    let ori = Normal::new(0.0f32, s.orientation_noise_deg.to_radians())?;
    let path = dir.join(FILE_NAME);
    let mut out = std::io::BufWriter::new(
        std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?,
    );
    let n = world_from_probe.len();
    if n == 0 {
        out.flush()?;
        return Ok(s);
    }
    let duration_s = n as f32 / fps;
    let count = (duration_s * s.rate_hz) as u32;
    let mut buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
    let offset = Vector3::from(s.kinematic_offset_mm) * 0.001;
    for j in 0..count {
        let t_us = (j as f64 * 1e6 / s.rate_hz as f64).round() as i64 + rng.gen_range(-500..=500);
        let t_us = t_us.max(0) as u64;
        // Draw the noise for every sample slot, sent or not, so one absent stretch does not shift the rest.
        let noise = Vector3::new(enc.sample(&mut rng), enc.sample(&mut rng), enc.sample(&mut rng));
        let turn = UnitQuaternion::new(Vector3::new(
            ori.sample(&mut rng),
            ori.sample(&mut rng),
            ori.sample(&mut rng),
        ));
        let frame = ((t_us as f64 - s.latency_us as f64) * 1e-6 * fps as f64).max(0.0);
        let i0 = (frame.floor() as usize).min(n - 1);
        let i1 = (i0 + 1).min(n - 1);
        let (Some(a), Some(b)) = (world_from_probe[i0], world_from_probe[i1]) else {
            continue;
        };
        let w = (frame - i0 as f64).clamp(0.0, 1.0) as f32;
        let tip = a.translation.vector.lerp(&b.translation.vector, w) + offset + noise;
        let rot = turn * a.rotation.slerp(&b.rotation, w);
        let q = rot.quaternion();
        let msg = Message {
            seq: s.samples as u16,
            timestamp: Timestamp::from_us(t_us).context("arm time out of range")?,
            body: Body::ArmState(WireArmState {
                position_mm: [tip.x, tip.y, tip.z].map(|v| (v * 1000.0).round() as i32),
                orientation: UnitQuatQ14::from_f32([q.w, q.i, q.j, q.k]).context("arm orientation")?,
            }),
        };
        let len = msg
            .encode_serial(&mut buf)
            .map_err(|e| anyhow::anyhow!("encoding arm state {j}: {e:?}"))?;
        out.write_all(&buf[..len])?;
        s.samples += 1;
    }
    out.flush()?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::calibration::read_arm_capture;
    use nalgebra::Translation3;

    #[test]
    fn samples_follow_the_path_late_and_skip_where_the_arm_is_absent() {
        let dir = std::env::temp_dir().join(format!("supine-arm-stream-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // The tip moves 3 mm per frame along x; the arm is absent for the last 10 of 30 frames.
        let poses: Vec<Option<Isometry3<f32>>> = (0..30)
            .map(|f| {
                (f < 20).then(|| {
                    Isometry3::from_parts(
                        Translation3::new(0.003 * f as f32, 0.5, 0.8),
                        UnitQuaternion::identity(),
                    )
                })
            })
            .collect();
        let s = write_arm_states(&dir, &poses, 30.0, 9).unwrap();
        let (arm, errors) = read_arm_capture(&dir.join(FILE_NAME)).unwrap();
        assert_eq!(errors, 0);
        assert_eq!(arm.len() as u32, s.samples);
        // 1 s at 100 Hz, of which about the last third has no arm.
        assert!((60..=70).contains(&arm.len()), "{} samples", arm.len());
        for a in &arm {
            let t = a.time.as_us() as f32 * 1e-6 - s.latency_us as f32 * 1e-6;
            let x = 0.003 * (t * 30.0).max(0.0) + s.kinematic_offset_mm[0] * 0.001;
            assert!(
                (a.tip_robot_base.x - x).abs() < 0.0025,
                "{} vs {x}",
                a.tip_robot_base.x
            );
            assert!((a.tip_robot_base.y - 0.5 - s.kinematic_offset_mm[1] * 0.001).abs() < 0.0025);
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
