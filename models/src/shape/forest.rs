//! Trainer of the shape regression forest (paper §3.2, "TreeBagger" in the paper): 16 bagged multi-output
//! regression trees from the 20 subspace coefficients to the 20 shape coefficients (σ units).
//!
//! Each tree draws a bootstrap sample; each node tries `mtry` random features (a third of them, as TreeBagger does
//! for regression) and every threshold between consecutive sorted values, and keeps the split with the largest drop
//! of the summed squared error over all 20 outputs; nodes stop at `min_leaf` samples per side or `max_depth`.
//! Deterministic for a seed (each tree has its own stream; trees train in parallel). Cost: O(trees · depth · mtry ·
//! n log n), about a second for 2 k samples.

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::dataset::mix_seed;

/// Inputs and outputs per sample.
pub const DIM: usize = 20;

/// Training parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ForestConfig {
    /// Trees.
    pub trees: usize,
    /// Minimum samples per leaf.
    pub min_leaf: usize,
    /// Maximum depth.
    pub max_depth: usize,
    /// Features tried per node.
    pub mtry: usize,
    /// Seed.
    pub seed: u64,
}

impl Default for ForestConfig {
    fn default() -> Self {
        ForestConfig {
            trees: 16,
            min_leaf: 5,
            max_depth: 20,
            mtry: 7,
            seed: 0,
        }
    }
}

/// One node of a trained tree (children of node `i` are `left` and `left + 1`, both after `i`).
#[derive(Debug, Clone, PartialEq)]
pub enum Node {
    /// `c[feature] < threshold` goes to `left`.
    Split {
        /// Feature index.
        feature: u16,
        /// Threshold.
        threshold: f32,
        /// Index of the left child in the tree.
        left: usize,
    },
    /// Mean output of the node's samples.
    Leaf([f32; DIM]),
}

/// A trained forest.
#[derive(Debug, Clone, PartialEq)]
pub struct Forest {
    /// Trees, each a node list with the root first.
    pub trees: Vec<Vec<Node>>,
}

fn mean_of(y: &[[f32; DIM]], idx: &[usize]) -> [f32; DIM] {
    let mut m = [0.0f64; DIM];
    for &i in idx {
        for k in 0..DIM {
            m[k] += y[i][k] as f64;
        }
    }
    m.map(|v| (v / idx.len().max(1) as f64) as f32)
}

fn best_split(
    x: &[[f32; DIM]],
    y: &[[f32; DIM]],
    idx: &mut [usize],
    features: &[usize],
    min_leaf: usize,
) -> Option<(usize, f32)> {
    let n = idx.len();
    let mut total = [0.0f64; DIM];
    for &i in idx.iter() {
        for k in 0..DIM {
            total[k] += y[i][k] as f64;
        }
    }
    let base: f64 = total.iter().map(|s| s * s).sum::<f64>() / n as f64;
    let mut best: Option<(f64, usize, f32)> = None;
    for &f in features {
        idx.sort_by(|&a, &b| x[a][f].total_cmp(&x[b][f]));
        let mut left = [0.0f64; DIM];
        for j in 0..n - 1 {
            for k in 0..DIM {
                left[k] += y[idx[j]][k] as f64;
            }
            let nl = j + 1;
            let (a, b) = (x[idx[j]][f], x[idx[j + 1]][f]);
            if nl < min_leaf || n - nl < min_leaf || a == b {
                continue;
            }
            let mut score = 0.0;
            for k in 0..DIM {
                let r = total[k] - left[k];
                score += left[k] * left[k] / nl as f64 + r * r / (n - nl) as f64;
            }
            let gain = score - base;
            if gain > 1e-9 && best.is_none_or(|(g, _, _)| gain > g) {
                best = Some((gain, f, 0.5 * (a + b)));
            }
        }
    }
    best.map(|(_, f, t)| (f, t))
}

fn train_tree(x: &[[f32; DIM]], y: &[[f32; DIM]], cfg: &ForestConfig, seed: u64) -> Vec<Node> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = x.len();
    let sample: Vec<usize> = (0..n).map(|_| rng.gen_range(0..n)).collect();
    let mut nodes = vec![Node::Leaf([0.0; DIM])];
    // Breadth-first: children are appended in pairs, so they always come after their parent.
    let mut queue = std::collections::VecDeque::from([(0usize, sample, 0usize)]);
    let mut all: Vec<usize> = (0..DIM).collect();
    while let Some((slot, mut idx, depth)) = queue.pop_front() {
        let split = if depth < cfg.max_depth && idx.len() >= 2 * cfg.min_leaf {
            all.shuffle(&mut rng);
            best_split(x, y, &mut idx, &all[..cfg.mtry.clamp(1, DIM)], cfg.min_leaf)
        } else {
            None
        };
        match split {
            Some((f, t)) => {
                let left = nodes.len();
                nodes.push(Node::Leaf([0.0; DIM]));
                nodes.push(Node::Leaf([0.0; DIM]));
                nodes[slot] = Node::Split {
                    feature: f as u16,
                    threshold: t,
                    left,
                };
                let (l, r): (Vec<usize>, Vec<usize>) = idx.iter().partition(|&&i| x[i][f] < t);
                queue.push_back((left, l, depth + 1));
                queue.push_back((left + 1, r, depth + 1));
            }
            None => nodes[slot] = Node::Leaf(mean_of(y, &idx)),
        }
    }
    nodes
}

impl Forest {
    /// Train on inputs `x` and outputs `y` (same length, at least one sample).
    pub fn train(x: &[[f32; DIM]], y: &[[f32; DIM]], cfg: &ForestConfig) -> Forest {
        assert_eq!(x.len(), y.len(), "inputs and outputs differ in count");
        let trees = (0..cfg.trees)
            .into_par_iter()
            .map(|t| train_tree(x, y, cfg, mix_seed(cfg.seed, t as u64)))
            .collect();
        Forest { trees }
    }

    /// Unquantised prediction (validation and tests).
    pub fn predict(&self, c: &[f32; DIM]) -> [f32; DIM] {
        let mut acc = [0.0f32; DIM];
        for t in &self.trees {
            let mut i = 0;
            loop {
                match &t[i] {
                    Node::Split {
                        feature,
                        threshold,
                        left,
                    } => {
                        i = if c[*feature as usize] < *threshold {
                            *left
                        } else {
                            left + 1
                        }
                    }
                    Node::Leaf(v) => {
                        for k in 0..DIM {
                            acc[k] += v[k];
                        }
                        break;
                    }
                }
            }
        }
        acc.map(|a| a / self.trees.len() as f32)
    }

    /// Total nodes.
    pub fn node_count(&self) -> usize {
        self.trees.iter().map(Vec::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn learns_a_step_and_a_ramp() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let x: Vec<[f32; DIM]> = (0..400)
            .map(|_| std::array::from_fn(|_| rng.gen_range(-1.0..1.0f32)))
            .collect();
        let y: Vec<[f32; DIM]> = x
            .iter()
            .map(|c| {
                std::array::from_fn(|k| {
                    if k == 0 {
                        if c[3] > 0.0 { 1.0 } else { -1.0 }
                    } else {
                        c[5]
                    }
                })
            })
            .collect();
        let f = Forest::train(
            &x,
            &y,
            &ForestConfig {
                mtry: 20,
                ..Default::default()
            },
        );
        let mut c = [0.0f32; DIM];
        c[3] = 0.5;
        c[5] = 0.6;
        let p = f.predict(&c);
        assert!((p[0] - 1.0).abs() < 0.15, "step {}", p[0]);
        assert!((p[1] - 0.6).abs() < 0.15, "ramp {}", p[1]);
        c[3] = -0.5;
        assert!((f.predict(&c)[0] + 1.0).abs() < 0.15);
        assert_eq!(
            f,
            Forest::train(
                &x,
                &y,
                &ForestConfig {
                    mtry: 20,
                    ..Default::default()
                }
            )
        );
    }
}
