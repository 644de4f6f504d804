//! Weighted mean-shift over 3D votes with a near-Gaussian kernel (1 - q/32)^16 of q = d^2/h^2, within 3
//! bandwidths (0.5 % at the cut; no `exp`, so a kernel costs five multiplies), optionally weighted by a
//! 3D Gaussian prior per point (the tracker's temporal prior, paper Sect. 3.3). Started from a few seeds (the
//! heaviest vote, the weighted mean, the prior's mean); the mode of highest density wins.
//! Cost: starts x iterations (at most [`MAX_ITERATIONS`]) x votes kernel evaluations.

/// Iterations per start at most (stops earlier when a step is under 1 mm).
pub const MAX_ITERATIONS: usize = 12;

/// One weighted vote.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Vote {
    /// Voted position, camera frame, metres.
    pub p: [f32; 3],
    /// Weight (> 0).
    pub w: f32,
}

/// A Gaussian prior on a point: mean and standard deviation per camera axis (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    /// Mean, camera frame, metres.
    pub mean: [f32; 3],
    /// Standard deviation per axis, metres (> 0).
    pub sigma_m: [f32; 3],
}

impl Prior {
    /// The prior's unnormalised density at `p` (1 at the mean).
    #[inline]
    pub fn weight(&self, p: &[f32; 3]) -> f32 {
        let mut e = 0.0;
        for a in 0..3 {
            let z = (p[a] - self.mean[a]) / self.sigma_m[a];
            e += z * z;
        }
        libm::expf(-0.5 * e)
    }
}

/// A found mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mode {
    /// Position, metres.
    pub p: [f32; 3],
    /// Share of the total vote weight within the kernel at the mode (0..1).
    pub confidence: f32,
}

#[inline]
fn d2(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    x * x + y * y + z * z
}

/// Kernel-weighted mean and density around `c`.
#[inline]
fn step(votes: &[Vote], c: &[f32; 3], inv2h2: f32, cut2: f32) -> ([f32; 3], f32) {
    let mut s = [0.0f32; 3];
    let mut wsum = 0.0f32;
    for v in votes {
        let q = d2(&v.p, c);
        if q < cut2 {
            // (1 - q/(32 h^2))^16 ~ exp(-q / (2 h^2)).
            let mut k = 1.0 - q * inv2h2 * (1.0 / 16.0);
            k *= k;
            k *= k;
            k *= k;
            k *= k;
            let k = v.w * k;
            s[0] += k * v.p[0];
            s[1] += k * v.p[1];
            s[2] += k * v.p[2];
            wsum += k;
        }
    }
    if wsum > 0.0 {
        ([s[0] / wsum, s[1] / wsum, s[2] / wsum], wsum)
    } else {
        (*c, 0.0)
    }
}

/// The highest-density mode of `votes` (weights already include any prior) for bandwidth `h` metres; `extra_start`
/// (the prior's mean) is tried besides the heaviest vote and the weighted mean. `None` without positive weight.
pub fn mean_shift(votes: &[Vote], h: f32, extra_start: Option<[f32; 3]>) -> Option<Mode> {
    let mut total = 0.0f32;
    let mut mean = [0.0f32; 3];
    let mut heaviest: Option<Vote> = None;
    for v in votes {
        total += v.w;
        for a in 0..3 {
            mean[a] += v.w * v.p[a];
        }
        if heaviest.is_none_or(|b| v.w > b.w) {
            heaviest = Some(*v);
        }
    }
    if total <= 0.0 || !total.is_finite() {
        return None;
    }
    for m in mean.iter_mut() {
        *m /= total;
    }
    let heaviest = heaviest?.p;
    let inv2h2 = 0.5 / (h * h);
    let cut2 = 9.0 * h * h;
    let starts = [Some(heaviest), Some(mean), extra_start];
    let mut best: Option<([f32; 3], f32)> = None;
    for s in starts.into_iter().flatten() {
        let mut c = s;
        let mut dens = 0.0;
        for _ in 0..MAX_ITERATIONS {
            let (n, w) = step(votes, &c, inv2h2, cut2);
            let moved = d2(&n, &c);
            c = n;
            dens = w;
            if moved < 1e-6 {
                break;
            }
        }
        if best.is_none_or(|(_, b)| dens > b) {
            best = Some((c, dens));
        }
    }
    let (p, dens) = best?;
    Some(Mode {
        p,
        confidence: (dens / total).clamp(0.0, 1.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_heavier_cluster() {
        let mut votes = [Vote::default(); 30];
        for (i, v) in votes.iter_mut().enumerate() {
            let j = i as f32 * 0.001;
            *v = if i < 20 {
                Vote {
                    p: [0.5 + j, 0.0, 1.0],
                    w: 1.0,
                }
            } else {
                Vote {
                    p: [-0.5, j, 1.0],
                    w: 1.0,
                }
            };
        }
        let m = mean_shift(&votes, 0.05, None).unwrap();
        assert!((m.p[0] - 0.5095).abs() < 0.005, "{:?}", m.p);
        assert!(m.confidence > 0.5 && m.confidence < 0.7);
        assert!(mean_shift(&votes[..0], 0.05, None).is_none());
        let prior = Prior {
            mean: [-0.5, 0.0, 1.0],
            sigma_m: [0.1; 3],
        };
        let mut weighted = votes;
        for v in weighted.iter_mut() {
            v.w *= prior.weight(&v.p);
        }
        let m = mean_shift(&weighted, 0.05, Some(prior.mean)).unwrap();
        assert!(
            (m.p[0] + 0.5).abs() < 0.01,
            "prior should pull to the other cluster: {:?}",
            m.p
        );
    }
}
