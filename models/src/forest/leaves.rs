//! Leaf statistics of the grown trees from the training samples that reach them: the body/arm/other share (leaves
//! whose samples were mostly not body carry no vote), the mean offset per point (the refinement's start), and the
//! baseline's Girshick leaves: the offsets within the vote length threshold, uniformly subsampled to at most
//! `reservoir` per leaf and point, compressed by mean-shift to at most [`MODES`] weighted modes.
//! Cost: one pass over samples x trees, then per leaf and point a mean-shift over at most `reservoir` offsets.

use super::data::{CLASS_ARM, ImageInfo, TrainSample};
use super::float::BaselineLeaf;
use rayon::prelude::*;
use supine_core::forest::{MAX_TREES, MODES};
use supine_core::rng::{SplitMix64, mix_seed};
use supine_core::salient::SalientPoint;

const P: usize = SalientPoint::COUNT;
/// Starts of the per-leaf mode search (evenly spread over the subsample).
const MODE_STARTS: usize = 6;

/// One leaf's body majority, mean offsets, baseline modes and class counts.
type LeafRow = (bool, [[f32; 3]; P], BaselineLeaf, [u32; 3]);

/// Per-leaf results of [`leaf_statistics`].
#[derive(Debug, Clone)]
pub struct LeafStats {
    /// Most of the leaf's samples were on the body.
    pub body_leaf: Vec<bool>,
    /// Mean offset of the leaf's body samples per point (0 without any), metres.
    pub mean_offset: Vec<[[f32; 3]; P]>,
    /// Baseline leaves.
    pub baseline: Vec<BaselineLeaf>,
    /// Body, arm and other samples per leaf.
    pub counts: Vec<[u32; 3]>,
}

/// Whether a sample's class is a body part.
pub fn is_body(class: u8) -> bool {
    class < CLASS_ARM
}

/// Offset from a sample to point `p` of its image.
#[inline]
pub fn offset(s: &TrainSample, info: &ImageInfo, p: usize) -> [f32; 3] {
    let t = info.targets[p];
    [t[0] - s.px.p[0], t[1] - s.px.p[1], t[2] - s.px.p[2]]
}

fn modes(offs: &[[f32; 3]], h: f32) -> [([f32; 3], f32); MODES] {
    let mut out = [([0.0f32; 3], 0.0f32); MODES];
    if offs.is_empty() {
        return out;
    }
    let inv2h2 = 0.5 / (h * h);
    let dens_at = |c: &[f32; 3]| -> ([f32; 3], f32) {
        let mut s = [0.0f32; 3];
        let mut w = 0.0f32;
        for o in offs {
            let d2 = (o[0] - c[0]).powi(2) + (o[1] - c[1]).powi(2) + (o[2] - c[2]).powi(2);
            let k = (-d2 * inv2h2).exp();
            for a in 0..3 {
                s[a] += k * o[a];
            }
            w += k;
        }
        ([s[0] / w, s[1] / w, s[2] / w], w)
    };
    let mut found: Vec<([f32; 3], f32)> = Vec::new();
    let starts = MODE_STARTS.min(offs.len());
    for k in 0..starts {
        let mut c = offs[k * offs.len() / starts];
        let mut w = 0.0;
        for _ in 0..20 {
            let (n, nw) = dens_at(&c);
            let moved = (n[0] - c[0]).powi(2) + (n[1] - c[1]).powi(2) + (n[2] - c[2]).powi(2);
            c = n;
            w = nw;
            if moved < 1e-8 {
                break;
            }
        }
        let dup = found.iter().any(|(f, _)| {
            (f[0] - c[0]).powi(2) + (f[1] - c[1]).powi(2) + (f[2] - c[2]).powi(2) < 0.25 * h * h
        });
        if !dup {
            found.push((c, w));
        }
    }
    found.sort_by(|a, b| b.1.total_cmp(&a.1));
    for (slot, (c, w)) in out.iter_mut().zip(found) {
        *slot = (c, w / offs.len() as f32);
    }
    out
}

/// Statistics of `n_leaves` leaves from the samples whose `use_sample` is true; `leaves[i]` holds sample `i`'s
/// global leaf per tree.
#[allow(clippy::too_many_arguments)]
pub fn leaf_statistics(
    samples: &[TrainSample],
    leaves: &[[u32; MAX_TREES]],
    infos: &[ImageInfo],
    use_sample: &[bool],
    trees: usize,
    n_leaves: usize,
    vote_length_m: f32,
    reservoir: usize,
    bandwidth_m: f32,
    seed: u64,
) -> LeafStats {
    // Samples per leaf, as compressed rows (counting sort keeps sample order within a leaf).
    let mut start = vec![0u32; n_leaves + 1];
    for (i, row) in leaves.iter().enumerate() {
        if use_sample[i] {
            for &l in &row[..trees] {
                start[l as usize + 1] += 1;
            }
        }
    }
    for l in 0..n_leaves {
        start[l + 1] += start[l];
    }
    let mut fill = start.clone();
    let mut members = vec![0u32; start[n_leaves] as usize];
    for (i, row) in leaves.iter().enumerate() {
        if use_sample[i] {
            for &l in &row[..trees] {
                members[fill[l as usize] as usize] = i as u32;
                fill[l as usize] += 1;
            }
        }
    }
    let max_len2 = vote_length_m * vote_length_m;
    let per_leaf: Vec<LeafRow> = (0..n_leaves)
        .into_par_iter()
        .map(|l| {
            let m = &members[start[l] as usize..start[l + 1] as usize];
            let mut counts = [0u32; 3];
            let mut sum = [[0.0f64; 3]; P];
            for &i in m {
                let s = &samples[i as usize];
                if is_body(s.class) {
                    counts[0] += 1;
                    let info = &infos[s.image as usize];
                    for (p, acc) in sum.iter_mut().enumerate() {
                        let o = offset(s, info, p);
                        for a in 0..3 {
                            acc[a] += o[a] as f64;
                        }
                    }
                } else if s.class == CLASS_ARM {
                    counts[1] += 1;
                } else {
                    counts[2] += 1;
                }
            }
            let body_leaf = counts[0] > 0 && 2 * counts[0] >= counts[0] + counts[1] + counts[2];
            let mut mean = [[0.0f32; 3]; P];
            if counts[0] > 0 {
                for p in 0..P {
                    for a in 0..3 {
                        mean[p][a] = (sum[p][a] / counts[0] as f64) as f32;
                    }
                }
            }
            let mut base: BaselineLeaf = [[([0.0; 3], 0.0); MODES]; P];
            for (p, slot) in base.iter_mut().enumerate() {
                let mut offs: Vec<[f32; 3]> = m
                    .iter()
                    .map(|&i| &samples[i as usize])
                    .filter(|s| is_body(s.class))
                    .map(|s| offset(s, &infos[s.image as usize], p))
                    .filter(|o| o[0] * o[0] + o[1] * o[1] + o[2] * o[2] <= max_len2)
                    .collect();
                if offs.len() > reservoir {
                    // A uniform subsample (partial Fisher-Yates), seeded per leaf and point.
                    let mut rng = SplitMix64::new(mix_seed(seed, (l * P + p) as u64));
                    for k in 0..reservoir {
                        let j = k + rng.below(offs.len() - k);
                        offs.swap(k, j);
                    }
                    offs.truncate(reservoir);
                }
                *slot = modes(&offs, bandwidth_m);
            }
            (body_leaf, mean, base, counts)
        })
        .collect();
    let mut st = LeafStats {
        body_leaf: Vec::with_capacity(n_leaves),
        mean_offset: Vec::with_capacity(n_leaves),
        baseline: Vec::with_capacity(n_leaves),
        counts: Vec::with_capacity(n_leaves),
    };
    for (b, m, base, c) in per_leaf {
        st.body_leaf.push(b);
        st.mean_offset.push(m);
        st.baseline.push(base);
        st.counts.push(c);
    }
    st
}
