//! Growing one tree of the joint forest for body-part classification (Shotton et al. 2011: entropy gain over the
//! 17 parts, the robot arm and "other"), the structure Girshick et al. reuse for their votes. Depth-first with a
//! stack; each node draws its candidate (offset pair, threshold) tests from a generator seeded by the tree seed and
//! the node's index, and candidates are scored in parallel with integer class counts, so the tree is the same
//! whatever the thread count. Cost: samples x candidates x depth feature evaluations.

use super::data::{CLASSES, TrainImage, TrainSample};
use indicatif::ProgressBar;
use rayon::prelude::*;
use supine_core::forest::feature::{ProbeScale, SplitTest};
use supine_core::forest::model::LEAF_BIT;
use supine_core::rng::{SplitMix64, mix_seed};

/// Tree-growing parameters (paper Table 1 as defaults).
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct TreeParams {
    /// Maximum depth (root at depth 0).
    pub max_depth: usize,
    /// Candidate (offset pair, threshold) tests per split.
    pub candidates: usize,
    /// Nodes with fewer samples become leaves.
    pub min_split: usize,
    /// Offsets are drawn within ±this many pixel·metres (px at 1 m).
    pub offset_px_m: i32,
    /// Thresholds are drawn within ±this many mm.
    pub threshold_mm: i32,
}

impl Default for TreeParams {
    fn default() -> Self {
        TreeParams {
            max_depth: 24,
            candidates: 128,
            min_split: 50,
            offset_px_m: 50,
            threshold_mm: 50,
        }
    }
}

/// One node: its test and `LEAF_BIT | local leaf id` or the left child's index (the right child is next to it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TreeNode {
    /// Split test (zero for leaves).
    pub test: SplitTest,
    /// Child or leaf word as in the model file's `CHLD`.
    pub child: u32,
}

/// A grown tree: nodes (root first) and its leaf count (leaf ids local to the tree).
#[derive(Debug, Clone, PartialEq)]
pub struct Tree {
    /// Nodes.
    pub nodes: Vec<TreeNode>,
    /// Number of leaves.
    pub leaves: u32,
}

fn entropy(h: &[u32; CLASSES], n: u32) -> f64 {
    if n == 0 {
        return 0.0;
    }
    let inv = 1.0 / n as f64;
    h.iter()
        .filter(|&&c| c > 0)
        .map(|&c| {
            let p = c as f64 * inv;
            -p * p.log2()
        })
        .sum()
}

fn draw_test(rng: &mut SplitMix64, p: &TreeParams) -> SplitTest {
    let o = p.offset_px_m;
    SplitTest {
        u: [rng.range_i32(-o, o) as i8, rng.range_i32(-o, o) as i8],
        v: [rng.range_i32(-o, o) as i8, rng.range_i32(-o, o) as i8],
        threshold_mm: rng.range_i32(-p.threshold_mm, p.threshold_mm) as i16,
    }
}

#[inline]
fn left(t: &SplitTest, images: &[TrainImage], s: &TrainSample) -> bool {
    t.goes_left(
        &images[s.image as usize],
        s.px.x as i32,
        s.px.y as i32,
        ProbeScale::new(s.px.d_mm),
    )
}

/// Grow a tree on `samples` (reordered in place), reading depth from `images`; `bar` advances by the samples that
/// reach a leaf.
pub fn grow(
    images: &[TrainImage],
    samples: &mut [TrainSample],
    params: &TreeParams,
    seed: u64,
    bar: &ProgressBar,
) -> Tree {
    let mut nodes = vec![TreeNode {
        test: SplitTest::default(),
        child: 0,
    }];
    let mut leaves = 0u32;
    // (node index, sample range, depth)
    let mut stack = vec![(0usize, 0usize, samples.len(), 0usize)];
    while let Some((node, lo, hi, depth)) = stack.pop() {
        let ss = &mut samples[lo..hi];
        let n = ss.len();
        let mut hist = [0u32; CLASSES];
        for s in ss.iter() {
            hist[s.class as usize] += 1;
        }
        let pure = hist.iter().filter(|&&c| c > 0).count() <= 1;
        let mut best: Option<(SplitTest, f64)> = None;
        if n >= params.min_split && depth < params.max_depth && !pure {
            let h_parent = entropy(&hist, n as u32);
            let mut rng = SplitMix64::new(mix_seed(seed, node as u64));
            let tests: Vec<SplitTest> = (0..params.candidates)
                .map(|_| draw_test(&mut rng, params))
                .collect();
            let score = |t: &SplitTest| {
                let mut l = [0u32; CLASSES];
                let mut nl = 0u32;
                for s in ss.iter() {
                    if left(t, images, s) {
                        l[s.class as usize] += 1;
                        nl += 1;
                    }
                }
                let nr = n as u32 - nl;
                if nl == 0 || nr == 0 {
                    return f64::NEG_INFINITY;
                }
                let mut r = [0u32; CLASSES];
                for c in 0..CLASSES {
                    r[c] = hist[c] - l[c];
                }
                h_parent - (nl as f64 / n as f64) * entropy(&l, nl) - (nr as f64 / n as f64) * entropy(&r, nr)
            };
            let gains: Vec<f64> = if n * params.candidates > 20_000 {
                tests.par_iter().map(score).collect()
            } else {
                tests.iter().map(score).collect()
            };
            for (t, g) in tests.iter().zip(gains) {
                if g > 1e-9 && best.is_none_or(|(_, b)| g > b) {
                    best = Some((*t, g));
                }
            }
        }
        match best {
            None => {
                nodes[node].child = LEAF_BIT | leaves;
                leaves += 1;
                bar.inc(n as u64);
            }
            Some((test, _)) => {
                // Stable partition: left samples first, in their order.
                let flags: Vec<bool> = ss.iter().map(|s| left(&test, images, s)).collect();
                let mut l: Vec<TrainSample> = Vec::with_capacity(n);
                let mut r: Vec<TrainSample> = Vec::new();
                for (s, f) in ss.iter().zip(&flags) {
                    if *f {
                        l.push(*s);
                    } else {
                        r.push(*s);
                    }
                }
                let nl = l.len();
                ss[..nl].copy_from_slice(&l);
                ss[nl..].copy_from_slice(&r);
                let li = nodes.len();
                nodes[node] = TreeNode {
                    test,
                    child: li as u32,
                };
                nodes.push(TreeNode {
                    test: SplitTest::default(),
                    child: 0,
                });
                nodes.push(TreeNode {
                    test: SplitTest::default(),
                    child: 0,
                });
                // Right first on the stack so the left subtree is finished first (any fixed order would do).
                stack.push((li + 1, lo + nl, hi, depth + 1));
                stack.push((li, lo, lo + nl, depth + 1));
            }
        }
    }
    // Child indices are stored relative to the tree: root is 0, children always after their parent.
    Tree { nodes, leaves }
}

impl Tree {
    /// The local leaf id a sample reaches.
    pub fn descend(&self, img: &TrainImage, x: i32, y: i32, d_mm: u16) -> u32 {
        let s = ProbeScale::new(d_mm);
        let mut i = 0usize;
        loop {
            let n = &self.nodes[i];
            if n.child & LEAF_BIT != 0 {
                return n.child & !LEAF_BIT;
            }
            i = n.child as usize + usize::from(!n.test.goes_left(img, x, y, s));
        }
    }
}

/// The trees of a quantised forest, with leaf ids made local to each tree again (the trainer numbers each tree's
/// leaves consecutively, after the previous tree's).
pub fn trees_from_view(view: &supine_core::forest::model::ForestView<'_>) -> anyhow::Result<Vec<Tree>> {
    use supine_core::forest::model::{ForestModel, Node};
    let mut out = Vec::new();
    let mut base = 0u32;
    for t in 0..view.tree_count() {
        let mut nodes = Vec::new();
        let mut leaves = 0u32;
        let mut stack = vec![0u32];
        let mut count = 1usize;
        // Walk the reachable nodes to find the tree's size (children always follow their parent).
        while let Some(i) = stack.pop() {
            if let Node::Split { left, .. } = view.node(t, i) {
                count = count.max(left as usize + 2);
                stack.push(left);
                stack.push(left + 1);
            }
        }
        for i in 0..count as u32 {
            nodes.push(match view.node(t, i) {
                Node::Leaf(l) => {
                    anyhow::ensure!(l >= base, "tree {t}: leaf ids are not numbered per tree");
                    leaves = leaves.max(l - base + 1);
                    TreeNode {
                        test: SplitTest::default(),
                        child: LEAF_BIT | (l - base),
                    }
                }
                Node::Split { test, left } => TreeNode { test, child: left },
            });
        }
        base += leaves;
        out.push(Tree { nodes, leaves });
    }
    Ok(out)
}
