//! Growing one tree of the joint forest for body-part classification (Shotton et al. 2011: entropy gain over the
//! 17 parts, the robot arm and "other"), the structure Girshick et al. reuse for their votes; optionally, on a share
//! of the nodes drawn per node as in Hough forests, by the reduction of the body samples' offset variance toward the
//! six points (`TreeParams::offset_objective_share`), and nodes of one body part split further by those offsets
//! (`TreeParams::pure_by_offsets`). Depth-first with a stack; each node draws its candidate
//! (offset pair, threshold) tests from a generator seeded by the tree seed and the node's index, and candidates are
//! scored in parallel, each over the node's samples in order, so the tree is the same whatever the thread count.
//! Cost: samples x candidates x depth feature evaluations.

use super::data::{CLASSES, TrainImage, TrainSample};
use indicatif::ProgressBar;
use rayon::prelude::*;
use supine_core::body_model::BodyPart;
use supine_core::forest::feature::{ProbeScale, SplitTest};
use supine_core::forest::model::LEAF_BIT;
use supine_core::rng::{SplitMix64, mix_seed};
use supine_core::salient::SalientPoint;

const P: usize = SalientPoint::COUNT;

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
    /// Share of the nodes of mixed classes scored by the reduction of the body samples' offset variance toward the
    /// six points instead of the class entropy (Gall and Lempitsky's Hough forests draw the objective per node).
    /// 0: Shotton's classification structure throughout.
    #[serde(default)]
    pub offset_objective_share: f32,
    /// A node of one body part is split further by its offsets (instead of becoming a leaf).
    #[serde(default)]
    pub pure_by_offsets: bool,
}

impl Default for TreeParams {
    fn default() -> Self {
        TreeParams {
            max_depth: 24,
            candidates: 128,
            min_split: 50,
            offset_px_m: 50,
            threshold_mm: 50,
            offset_objective_share: 0.0,
            pure_by_offsets: false,
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

/// Offsets farther than this from their point do not count in the offset objective (the baseline leaves' default
/// vote length: beyond it a pixel says little about the point).
const OFFSET_OBJECTIVE_RADIUS_M: f32 = 0.5;

/// Per point: count, sum of offsets, sum of squared norms (metres).
type OffsetStats = [(u32, [f64; 3], f64); P];

/// No offsets counted.
const NO_OFFSETS: OffsetStats = [(0, [0.0; 3], 0.0); P];

/// The statistics of `offsets`.
fn offset_stats<'a>(offsets: impl IntoIterator<Item = &'a SampleOffsets>) -> OffsetStats {
    let mut st = NO_OFFSETS;
    for o in offsets {
        add_offsets(&mut st, o);
    }
    st
}

/// Sum over points of the squared deviations from the points' mean offsets.
fn offset_sse(st: &OffsetStats) -> f64 {
    st.iter()
        .filter(|(n, _, _)| *n > 0)
        .map(|(n, s, q)| q - (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) / *n as f64)
        .sum()
}

/// A body sample's offsets to the six points, `None` for those beyond [`OFFSET_OBJECTIVE_RADIUS_M`].
type SampleOffsets = [Option<[f32; 3]>; P];

fn add_offsets(st: &mut OffsetStats, o: &SampleOffsets) {
    for (acc, o) in st.iter_mut().zip(o) {
        if let Some(o) = o {
            acc.0 += 1;
            for a in 0..3 {
                acc.1[a] += o[a] as f64;
            }
            acc.2 += (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]) as f64;
        }
    }
}

fn offsets_of(s: &TrainSample, targets: &[[[f32; 3]; P]]) -> Option<SampleOffsets> {
    if s.class as usize >= BodyPart::COUNT {
        return None;
    }
    let t = &targets[s.image as usize];
    let r2 = OFFSET_OBJECTIVE_RADIUS_M * OFFSET_OBJECTIVE_RADIUS_M;
    Some(core::array::from_fn(|p| {
        let o = [t[p][0] - s.px.p[0], t[p][1] - s.px.p[1], t[p][2] - s.px.p[2]];
        (o[0] * o[0] + o[1] * o[1] + o[2] * o[2] <= r2).then_some(o)
    }))
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

/// Grow a tree on `samples` (reordered in place), reading depth from `images` and, for the offset objective, the six
/// points from `targets` (camera frame, one row per image); `bar` advances by the samples that reach a leaf.
pub fn grow(
    images: &[TrainImage],
    targets: &[[[f32; 3]; P]],
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
        // The objective of this node: its own generator, so the classification trees stay as they were.
        let share = params.offset_objective_share;
        let by_offsets = if pure {
            params.pure_by_offsets
        } else {
            share > 0.0 && SplitMix64::new(mix_seed(seed ^ 0x0FF5E7, node as u64)).unit_f32() < share
        };
        let offsets: Vec<Option<SampleOffsets>> = if by_offsets {
            ss.iter().map(|s| offsets_of(s, targets)).collect()
        } else {
            Vec::new()
        };
        let parent = offset_stats(offsets.iter().flatten());
        let counted: u32 = parent.iter().map(|p| p.0).sum();
        let splittable = if by_offsets { counted >= 2 } else { !pure };
        let mut best: Option<(SplitTest, f64)> = None;
        if n >= params.min_split && depth < params.max_depth && splittable {
            let h_parent = entropy(&hist, n as u32);
            let sse_parent = offset_sse(&parent);
            let mut rng = SplitMix64::new(mix_seed(seed, node as u64));
            let tests: Vec<SplitTest> = (0..params.candidates)
                .map(|_| draw_test(&mut rng, params))
                .collect();
            let entropy_gain = |t: &SplitTest| {
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
            // Offset variance reduction per counted offset (m^2).
            let offset_gain = |t: &SplitTest| {
                let mut l = NO_OFFSETS;
                let mut nl = 0usize;
                for (s, o) in ss.iter().zip(&offsets) {
                    if left(t, images, s) {
                        nl += 1;
                        if let Some(o) = o {
                            add_offsets(&mut l, o);
                        }
                    }
                }
                if nl == 0 || nl == n {
                    return f64::NEG_INFINITY;
                }
                let r: OffsetStats = core::array::from_fn(|p| {
                    let (a, b) = (&parent[p], &l[p]);
                    (a.0 - b.0, core::array::from_fn(|k| a.1[k] - b.1[k]), a.2 - b.2)
                });
                (sse_parent - offset_sse(&l) - offset_sse(&r)) / counted as f64
            };
            let score = |t: &SplitTest| {
                if by_offsets {
                    offset_gain(t)
                } else {
                    entropy_gain(t)
                }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::forest::data::CLASS_ARM;
    use crate::render::noise::Rect;
    use supine_core::forest::sample::SamplePixel;

    /// One 64 x 8 image of a single class: the left half at 1.0 m, the right half at 1.2 m; every pixel a sample,
    /// its point 1 cm per column along x at its depth; the six points all at (0.3, 0, 1.1).
    fn scene(class: u8) -> (Vec<TrainImage>, Vec<[[f32; 3]; P]>, Vec<TrainSample>) {
        let (w, h) = (64u16, 8u16);
        let depth_of = |x: u16| if x < w / 2 { 1000u16 } else { 1200 };
        let img = TrainImage {
            crop: Rect { x0: 0, y0: 0, w, h },
            depth: (0..w as usize * h as usize)
                .map(|i| depth_of((i % w as usize) as u16))
                .collect(),
            class: vec![class; w as usize * h as usize],
        };
        let samples = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| TrainSample {
                image: 0,
                px: SamplePixel {
                    x,
                    y,
                    d_mm: depth_of(x),
                    p: [x as f32 * 0.01, 0.0, depth_of(x) as f32 * 1e-3],
                },
                class,
            })
            .collect();
        (vec![img], vec![[[0.3, 0.0, 1.1]; P]], samples)
    }

    fn grow_with(class: u8, pure_by_offsets: bool) -> (Tree, Vec<TrainSample>) {
        let (images, targets, mut samples) = scene(class);
        let params = TreeParams {
            max_depth: 1,
            candidates: 64,
            min_split: 2,
            pure_by_offsets,
            ..TreeParams::default()
        };
        let tree = grow(
            &images,
            &targets,
            &mut samples,
            &params,
            5,
            &ProgressBar::hidden(),
        );
        (tree, samples)
    }

    #[test]
    fn a_node_of_one_body_part_is_split_by_its_offsets_only_under_the_offset_objective() {
        let (classification, _) = grow_with(0, false);
        assert_eq!(classification.nodes.len(), 1, "entropy cannot split a pure node");
        let (offsets, samples) = grow_with(0, true);
        assert_eq!(offsets.nodes.len(), 3, "the offsets split the pure root");
        assert_eq!(offsets.leaves, 2);
        // The split lowers the offsets' spread: the two sides' squared deviations sum to less than the root's.
        let (images, targets, _) = scene(0);
        let sse = |s: &[TrainSample]| {
            let offsets: Vec<SampleOffsets> = s.iter().filter_map(|s| offsets_of(s, &targets)).collect();
            offset_sse(&offset_stats(&offsets))
        };
        // The split partitions the samples in place, left ones first.
        let test = offsets.nodes[0].test;
        let nl = samples.iter().take_while(|q| left(&test, &images, q)).count();
        assert!(nl > 0 && nl < samples.len(), "both sides get samples");
        assert!(
            sse(&samples[..nl]) + sse(&samples[nl..]) < 0.9 * sse(&samples),
            "the split explains part of the offsets' spread"
        );
    }

    #[test]
    fn occluder_samples_carry_no_offsets() {
        let (arm, _) = grow_with(CLASS_ARM, true);
        assert_eq!(
            arm.nodes.len(),
            1,
            "a node of arm samples has no offsets to split by"
        );
    }
}
