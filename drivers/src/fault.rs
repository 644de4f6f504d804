//! [`FaultySource`]: a seeded [`DepthSource`] wrapper that misbehaves on purpose, for tests of everything
//! downstream (the tracker's gap handling, the service's reconnect logic).
//!
//! Faults, each drawn per call from a deterministic PRNG (SplitMix64) so a seed reproduces a run exactly:
//! - **drop**: the inner frame is discarded and the next one fetched (the caller sees a gap in the index);
//! - **stall**: the call returns [`SourceErrorKind::Timeout`] without touching the inner source;
//! - **corrupt frame**: the call returns [`SourceErrorKind::CorruptData`] (the frame is consumed);
//! - **corrupt pixels**: a fraction of the pixels get random values (0 or 1..=10000 mm);
//! - **disconnect after N frames**: every call after N delivered frames returns [`SourceErrorKind::Disconnected`].
//!
//! Per-frame cost: one copy of the frame into a buffer allocated at construction, plus the corrupted pixels.

use std::time::Duration;

use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;

use crate::source::{DepthSource, SourceError, SourceErrorKind};
use supine_core::rng::SplitMix64;

/// Which faults to inject and how often (probabilities per call, 0..=1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SourceFaultConfig {
    /// PRNG seed.
    pub seed: u64,
    /// Probability that a frame is dropped.
    pub drop: f64,
    /// Probability that a call stalls (returns Timeout).
    pub stall: f64,
    /// Probability that a frame is reported as corrupt.
    pub corrupt_frame: f64,
    /// Probability that a delivered frame has corrupted pixels.
    pub corrupt_pixels: f64,
    /// Fraction of the pixels corrupted in such a frame.
    pub corrupt_pixel_fraction: f64,
    /// Disconnect after this many delivered frames.
    pub disconnect_after: Option<u32>,
}

impl SourceFaultConfig {
    /// No faults at all (a transparent wrapper), with this seed.
    pub fn none(seed: u64) -> Self {
        SourceFaultConfig {
            seed,
            drop: 0.0,
            stall: 0.0,
            corrupt_frame: 0.0,
            corrupt_pixels: 0.0,
            corrupt_pixel_fraction: 0.0,
            disconnect_after: None,
        }
    }
}

/// What the wrapper has done so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultStats {
    /// Frames delivered to the caller.
    pub delivered: u32,
    /// Frames dropped.
    pub dropped: u32,
    /// Calls that stalled.
    pub stalls: u32,
    /// Frames reported as corrupt.
    pub corrupt_frames: u32,
    /// Delivered frames with corrupted pixels.
    pub corrupted_pixel_frames: u32,
}

/// Wraps a source and injects faults (see the [module docs](self)).
#[derive(Debug)]
pub struct FaultySource<S> {
    inner: S,
    config: SourceFaultConfig,
    rng: SplitMix64,
    buf: Vec<u16>,
    stats: FaultStats,
}

impl<S: DepthSource> FaultySource<S> {
    /// Wrap `inner`.
    pub fn new(inner: S, config: SourceFaultConfig) -> Self {
        let k = inner.intrinsics();
        FaultySource {
            buf: Vec::with_capacity(k.width as usize * k.height as usize),
            inner,
            rng: SplitMix64(config.seed),
            config,
            stats: FaultStats::default(),
        }
    }

    /// Counters of what was injected.
    pub fn stats(&self) -> FaultStats {
        self.stats
    }

    /// The wrapped source.
    pub fn into_inner(self) -> S {
        self.inner
    }
}

impl<S: DepthSource> DepthSource for FaultySource<S> {
    fn next_frame(&mut self, timeout: Duration) -> Result<DepthFrame<'_>, SourceError> {
        if self
            .config
            .disconnect_after
            .is_some_and(|n| self.stats.delivered >= n)
        {
            return Err(SourceError::new(
                SourceErrorKind::Disconnected,
                "injected fault: device disconnected",
            ));
        }
        if self.rng.chance(self.config.stall) {
            self.stats.stalls += 1;
            return Err(SourceError::timeout());
        }
        let (w, h, ts, index) = loop {
            let frame = self.inner.next_frame(timeout)?;
            if self.rng.chance(self.config.drop) {
                self.stats.dropped += 1;
                continue;
            }
            self.buf.clear();
            self.buf.extend_from_slice(frame.depth_mm());
            break (frame.width(), frame.height(), frame.capture, frame.index);
        };
        if self.rng.chance(self.config.corrupt_frame) {
            self.stats.corrupt_frames += 1;
            return Err(SourceError::new(
                SourceErrorKind::CorruptData,
                "injected fault: corrupt frame",
            ));
        }
        if self.rng.chance(self.config.corrupt_pixels) {
            self.stats.corrupted_pixel_frames += 1;
            let n = (self.buf.len() as f64 * self.config.corrupt_pixel_fraction.clamp(0.0, 1.0)) as usize;
            for _ in 0..n {
                let at = self.rng.below(self.buf.len());
                let v = if self.rng.chance(0.5) {
                    0
                } else {
                    1 + self.rng.below(10_000) as u16
                };
                self.buf[at] = v;
            }
        }
        self.stats.delivered += 1;
        DepthFrame::new(&self.buf, w, h, ts, index)
            .map_err(|e| SourceError::new(SourceErrorKind::Other, e.to_string()))
    }

    fn intrinsics(&self) -> Intrinsics {
        self.inner.intrinsics()
    }

    fn describe(&self) -> String {
        format!(
            "{} (fault injection, seed {})",
            self.inner.describe(),
            self.config.seed
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An endless synthetic source: frame i has every pixel = 1000 + i.
    struct Ramp {
        buf: Vec<u16>,
        i: u32,
    }

    impl DepthSource for Ramp {
        fn next_frame(&mut self, _: Duration) -> Result<DepthFrame<'_>, SourceError> {
            self.i += 1;
            self.buf.fill(1000 + self.i as u16);
            Ok(DepthFrame::new(
                &self.buf,
                8,
                6,
                supine_core::time::Timestamp::from_us(self.i as u64 * 10).unwrap(),
                self.i,
            )
            .unwrap())
        }
        fn intrinsics(&self) -> Intrinsics {
            Intrinsics::from_fov(8, 6, 1.0, 0.8)
        }
        fn describe(&self) -> String {
            "ramp".into()
        }
    }

    fn ramp() -> Ramp {
        Ramp {
            buf: vec![0; 48],
            i: 0,
        }
    }

    type Outcome = Result<(u32, Vec<u16>), SourceErrorKind>;

    fn run(config: SourceFaultConfig, calls: usize) -> (Vec<Outcome>, FaultStats) {
        let mut s = FaultySource::new(ramp(), config);
        let out = (0..calls)
            .map(|_| {
                s.next_frame(Duration::ZERO)
                    .map(|f| (f.index, f.depth_mm().to_vec()))
                    .map_err(|e| e.kind())
            })
            .collect();
        (out, s.stats())
    }

    #[test]
    fn no_faults_is_transparent() {
        let (out, stats) = run(SourceFaultConfig::none(1), 5);
        let idx: Vec<u32> = out.iter().map(|r| r.as_ref().unwrap().0).collect();
        assert_eq!(idx, [1, 2, 3, 4, 5]);
        assert_eq!(out[2].as_ref().unwrap().1, vec![1003; 48]);
        assert_eq!(stats.delivered, 5);
    }

    #[test]
    fn same_seed_same_faults_and_rates_are_plausible() {
        let cfg = SourceFaultConfig {
            drop: 0.2,
            stall: 0.1,
            corrupt_frame: 0.1,
            corrupt_pixels: 0.3,
            corrupt_pixel_fraction: 0.25,
            ..SourceFaultConfig::none(42)
        };
        let (a, sa) = run(cfg, 400);
        let (b, sb) = run(cfg, 400);
        assert_eq!(a, b);
        assert_eq!(sa, sb);
        let (c, _) = run(SourceFaultConfig { seed: 43, ..cfg }, 400);
        assert_ne!(a, c);
        assert!((20..=60).contains(&sa.stalls), "{sa:?}");
        assert!(
            sa.dropped > 40 && sa.corrupt_frames > 15 && sa.corrupted_pixel_frames > 50,
            "{sa:?}"
        );
        assert_eq!(
            a.iter().filter(|r| **r == Err(SourceErrorKind::Timeout)).count() as u32,
            sa.stalls
        );
        // Dropped frames show as index gaps; corrupted frames differ from the ramp value.
        let frames: Vec<&(u32, Vec<u16>)> = a.iter().filter_map(|r| r.as_ref().ok()).collect();
        assert!(frames.windows(2).any(|w| w[1].0 > w[0].0 + 1));
        assert!(
            frames
                .iter()
                .any(|(i, px)| px.iter().any(|&p| p != 1000 + *i as u16))
        );
    }

    #[test]
    fn disconnects_after_n_frames() {
        let (out, stats) = run(
            SourceFaultConfig {
                disconnect_after: Some(3),
                ..SourceFaultConfig::none(7)
            },
            6,
        );
        assert!(out[..3].iter().all(|r| r.is_ok()));
        assert!(out[3..].iter().all(|r| *r == Err(SourceErrorKind::Disconnected)));
        assert_eq!(stats.delivered, 3);
    }
}
