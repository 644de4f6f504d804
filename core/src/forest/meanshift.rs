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

/// Lanes of the kernel sums: votes are summed in this many interleaved partial sums (vote `i` into lane `i % LANES`),
/// so the SIMD path and the scalar slice path add in the same order and give the same bits.
pub const LANES: usize = 8;

/// Votes readable `LANES` at a time (positions and weights; lanes past the end read weight 0).
trait VoteLanes {
    /// Number of votes.
    fn count(&self) -> usize;
    /// Vote `i` (`i < count()`).
    fn vote(&self, i: usize) -> Vote;
    /// Votes `[j * LANES, (j + 1) * LANES)` as x, y, z, w lanes.
    fn chunk(&self, j: usize) -> [[f32; LANES]; 4];
}

impl VoteLanes for [Vote] {
    #[inline]
    fn count(&self) -> usize {
        self.len()
    }
    #[inline]
    fn vote(&self, i: usize) -> Vote {
        self[i]
    }
    #[inline]
    fn chunk(&self, j: usize) -> [[f32; LANES]; 4] {
        let mut c = [[0.0f32; LANES]; 4];
        let base = j * LANES;
        for l in 0..LANES.min(self.len().saturating_sub(base)) {
            let v = &self[base + l];
            c[0][l] = v.p[0];
            c[1][l] = v.p[1];
            c[2][l] = v.p[2];
            c[3][l] = v.w;
        }
        c
    }
}

/// Votes of one point in structure-of-arrays form with capacity `N` (a multiple of [`LANES`]), the layout the
/// vectorised mean-shift reads; entries past `len` up to the next lane boundary hold weight 0.
pub struct VoteBuffer<const N: usize> {
    x: [f32; N],
    y: [f32; N],
    z: [f32; N],
    w: [f32; N],
    len: usize,
}

impl<const N: usize> Default for VoteBuffer<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> VoteBuffer<N> {
    /// An empty buffer.
    pub const fn new() -> Self {
        assert!(N.is_multiple_of(LANES), "capacity must be a multiple of LANES");
        VoteBuffer {
            x: [0.0; N],
            y: [0.0; N],
            z: [0.0; N],
            w: [0.0; N],
            len: 0,
        }
    }

    /// Forget all votes.
    #[inline]
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Number of votes.
    #[inline]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there is no vote.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether the buffer is full.
    #[inline]
    pub fn is_full(&self) -> bool {
        self.len == N
    }

    /// Append a vote; returns false (and drops it) when full.
    #[inline]
    pub fn push(&mut self, v: Vote) -> bool {
        if self.len >= N {
            return false;
        }
        let i = self.len;
        self.x[i] = v.p[0];
        self.y[i] = v.p[1];
        self.z[i] = v.p[2];
        self.w[i] = v.w;
        self.len += 1;
        true
    }

    /// Vote `i`, if present.
    pub fn get(&self, i: usize) -> Option<Vote> {
        (i < self.len).then(|| Vote {
            p: [self.x[i], self.y[i], self.z[i]],
            w: self.w[i],
        })
    }

    /// Zero the weights up to the next lane boundary (the kernel sums read whole chunks).
    #[inline]
    fn pad(&mut self) {
        let end = self.len.div_ceil(LANES) * LANES;
        for i in self.len..end.min(N) {
            self.w[i] = 0.0;
            self.x[i] = 0.0;
            self.y[i] = 0.0;
            self.z[i] = 0.0;
        }
    }

    /// The highest-density mode of the votes, as [`mean_shift`] (same arithmetic, same result bit for bit).
    pub fn mean_shift(&mut self, h: f32, extra_start: Option<[f32; 3]>) -> Option<Mode> {
        self.pad();
        mean_shift_lanes(&*self, h, extra_start)
    }
}

impl<const N: usize> VoteLanes for VoteBuffer<N> {
    #[inline]
    fn count(&self) -> usize {
        self.len
    }
    #[inline]
    fn vote(&self, i: usize) -> Vote {
        Vote {
            p: [self.x[i], self.y[i], self.z[i]],
            w: self.w[i],
        }
    }
    #[inline]
    fn chunk(&self, j: usize) -> [[f32; LANES]; 4] {
        let b = j * LANES;
        let lane = |a: &[f32; N]| -> [f32; LANES] { a[b..b + LANES].try_into().unwrap_or([0.0; LANES]) };
        [lane(&self.x), lane(&self.y), lane(&self.z), lane(&self.w)]
    }
}

/// Kernel-weighted mean and density around `c`; `inv` is 1 / (32 h^2), `cut2` the squared cut radius.
#[inline]
fn step<V: VoteLanes + ?Sized>(votes: &V, c: &[f32; 3], inv: f32, cut2: f32) -> ([f32; 3], f32) {
    let mut sx = [0.0f32; LANES];
    let mut sy = [0.0f32; LANES];
    let mut sz = [0.0f32; LANES];
    let mut sw = [0.0f32; LANES];
    for j in 0..votes.count().div_ceil(LANES) {
        let [x, y, z, w] = votes.chunk(j);
        // Branch-free, so the lanes vectorise: (1 - q/(32 h^2))^16 ~ exp(-q / (2 h^2)), 0 beyond the cut.
        for l in 0..LANES {
            let (dx, dy, dz) = (x[l] - c[0], y[l] - c[1], z[l] - c[2]);
            let q = dx * dx + dy * dy + dz * dz;
            let mut k = 1.0 - q * inv;
            k *= k;
            k *= k;
            k *= k;
            k *= k;
            let k = if q < cut2 { w[l] * k } else { 0.0 };
            sx[l] += k * x[l];
            sy[l] += k * y[l];
            sz[l] += k * z[l];
            sw[l] += k;
        }
    }
    let sum = |a: [f32; LANES]| ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]));
    let (s, wsum) = ([sum(sx), sum(sy), sum(sz)], sum(sw));
    if wsum > 0.0 {
        ([s[0] / wsum, s[1] / wsum, s[2] / wsum], wsum)
    } else {
        (*c, 0.0)
    }
}

/// The highest-density mode of `votes` (weights already include any prior) for bandwidth `h` metres; `extra_start`
/// (the prior's mean) is tried besides the heaviest vote and the weighted mean. `None` without positive weight.
pub fn mean_shift(votes: &[Vote], h: f32, extra_start: Option<[f32; 3]>) -> Option<Mode> {
    mean_shift_lanes(votes, h, extra_start)
}

fn mean_shift_lanes<V: VoteLanes + ?Sized>(votes: &V, h: f32, extra_start: Option<[f32; 3]>) -> Option<Mode> {
    let mut total = 0.0f32;
    let mut mean = [0.0f32; 3];
    let mut heaviest: Option<Vote> = None;
    for i in 0..votes.count() {
        let v = votes.vote(i);
        total += v.w;
        for a in 0..3 {
            mean[a] += v.w * v.p[a];
        }
        if heaviest.is_none_or(|b| v.w > b.w) {
            heaviest = Some(v);
        }
    }
    if total <= 0.0 || !total.is_finite() {
        return None;
    }
    for m in mean.iter_mut() {
        *m /= total;
    }
    let heaviest = heaviest?.p;
    let inv = 1.0 / (32.0 * h * h);
    let cut2 = 9.0 * h * h;
    let starts = [Some(heaviest), Some(mean), extra_start];
    // Modes found by earlier starts: a later start that comes within a converged step of one (1 mm) would end
    // there, so it stops and takes that mode (most frames: the heaviest vote and the mean reach the same mode).
    let mut found = [([0.0f32; 3], 0.0f32); 3];
    let mut nfound = 0;
    let mut best: Option<([f32; 3], f32)> = None;
    for s in starts.into_iter().flatten() {
        let mut c = s;
        let mut dens = 0.0;
        let mut joined = None;
        for _ in 0..MAX_ITERATIONS {
            if let Some(f) = found[..nfound].iter().find(|(m, _)| d2(m, &c) < CONVERGED_M2) {
                joined = Some(*f);
                break;
            }
            let (n, w) = step(votes, &c, inv, cut2);
            let moved = d2(&n, &c);
            c = n;
            dens = w;
            if moved < CONVERGED_M2 {
                break;
            }
        }
        if let Some((m, d)) = joined {
            (c, dens) = (m, d);
        } else {
            found[nfound] = (c, dens);
            nfound += 1;
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

/// A mean-shift step shorter than this (squared, m^2: 1 mm) has converged.
const CONVERGED_M2: f32 = 1e-6;

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

    #[test]
    fn the_vote_buffer_gives_the_slice_result_bit_for_bit() {
        let mut x: u32 = 12345;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x >> 8) as f32 / (1u32 << 24) as f32
        };
        let mut votes = [Vote::default(); 203];
        for v in votes.iter_mut() {
            *v = Vote {
                p: [next() * 0.4, next() * 0.3, 1.0 + next() * 0.2],
                w: next() + 0.01,
            };
        }
        let mut buf = VoteBuffer::<256>::new();
        for n in [0, 1, 7, 8, 9, 100, 203] {
            buf.clear();
            for v in &votes[..n] {
                assert!(buf.push(*v));
            }
            for extra in [None, Some([0.1, 0.1, 1.1])] {
                let a = mean_shift(&votes[..n], 0.05, extra);
                let b = buf.mean_shift(0.05, extra);
                assert_eq!(a, b, "{n} votes");
                assert_eq!(a.is_some(), n > 0);
            }
        }
        let mut small = VoteBuffer::<8>::new();
        for v in &votes[..8] {
            assert!(small.push(*v));
        }
        assert!(small.is_full() && !small.push(votes[8]));
        assert_eq!(small.get(3), Some(votes[3]));
        assert_eq!(small.get(8), None);
    }
}
