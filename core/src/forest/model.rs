//! What inference needs of a forest ([`ForestModel`]) and the quantised model file that the head computer loads
//! ([`ForestView`], kind `JFOR`).
//!
//! File layout (sections of a [`crate::model_file`] container, kind [`KIND`], version [`VERSION`]); `T` trees,
//! `N` nodes in all, `L` leaves in all, `P` = 6 points, `M` = [`MODES`]:
//! ```text
//! HEAD u32 [4]        T, N, L, samples per frame the forest was trained with
//! TREE u32 [T]        first node of each tree (tree t owns nodes [TREE[t], TREE[t+1]), the last up to N)
//! SPLT i8  [N*4]      u.x u.y v.x v.y per node, pixel·metres (unused for leaves, 0)
//! THRS i16 [N]        threshold per node, mm
//! CHLD u32 [N]        LEAF_BIT | leaf id, or the left child's index within the tree (right = left + 1, left > node)
//! RVOT i16 [L*P*3]    refined leaf weights (Eq. 2), mm
//! RCON u8  [L*P]      refined leaf confidences v_l = exp(-E_l^2) (Eq. 6), x255
//! BVOT i16 [L*P*M*3]  baseline (Girshick) mode offsets, mm
//! BWGT u8  [L*P*M]    baseline mode weights, x255
//! PARM f32 [P*3]      per point: refined mean-shift bandwidth, baseline bandwidth, baseline vote length (m)
//! META u8  [..]       UTF-8 JSON provenance (training command, seed, data), not read by core
//! ```
//! Validation (once, in [`ForestView::parse`]) checks every count, every child and leaf index (children always
//! point forward, so a descent ends within the tree's node count) and every parameter; after that, evaluation
//! cannot index out of bounds. A wrong, truncated or corrupted file is a [`ModelFileError`], never a panic.

use crate::forest::feature::SplitTest;
use crate::forest::{MAX_TREES, MODES};
use crate::model_file::{LeSlice, ModelFile, ModelFileError, Tag};
use crate::salient::SalientPoint;

/// Kind tag of a joint forest file.
pub const KIND: Tag = *b"JFOR";
/// Format version of the `JFOR` kind this build reads and writes.
pub const VERSION: u16 = 1;
/// Marks a leaf in `CHLD`.
pub const LEAF_BIT: u32 = 1 << 31;
/// Points per leaf.
const P: usize = SalientPoint::COUNT;

/// Section tags.
pub mod tags {
    use crate::model_file::Tag;
    /// Counts.
    pub const HEAD: Tag = *b"HEAD";
    /// Tree starts.
    pub const TREE: Tag = *b"TREE";
    /// Split offsets.
    pub const SPLT: Tag = *b"SPLT";
    /// Split thresholds.
    pub const THRS: Tag = *b"THRS";
    /// Children / leaf ids.
    pub const CHLD: Tag = *b"CHLD";
    /// Refined votes.
    pub const RVOT: Tag = *b"RVOT";
    /// Refined confidences.
    pub const RCON: Tag = *b"RCON";
    /// Baseline votes.
    pub const BVOT: Tag = *b"BVOT";
    /// Baseline weights.
    pub const BWGT: Tag = *b"BWGT";
    /// Inference parameters.
    pub const PARM: Tag = *b"PARM";
    /// Provenance JSON.
    pub const META: Tag = *b"META";
}

/// One node as the descent sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Node {
    /// An internal node: test, and the left child's index within the tree (the right child is `left + 1`).
    Split {
        /// The test.
        test: SplitTest,
        /// Left child index within the tree.
        left: u32,
    },
    /// A leaf with its forest-wide id.
    Leaf(u32),
}

/// One leaf vote for one point: an offset from the sample (metres, camera frame) and its weight.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct LeafVote {
    /// Offset from the sample's 3D position, metres.
    pub offset: [f32; 3],
    /// Weight (refined: leaf confidence v_l; baseline: mode weight); 0 = no vote.
    pub weight: f32,
}

/// Per-point inference parameters stored with a forest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointParams {
    /// Mean-shift bandwidth for the refined votes, metres.
    pub refined_bandwidth_m: f32,
    /// Mean-shift bandwidth for the baseline votes, metres.
    pub baseline_bandwidth_m: f32,
    /// Baseline votes longer than this are dropped (Girshick's vote length threshold), metres.
    pub vote_length_m: f32,
}

/// What inference needs of a forest: the float forest of the trainer and the quantised file both provide it.
pub trait ForestModel {
    /// Number of trees (at most [`MAX_TREES`]).
    fn tree_count(&self) -> usize;
    /// Node `index` of tree `tree` (index 0 is the root). Callers only pass indices reached by descent.
    fn node(&self, tree: usize, index: u32) -> Node;
    /// Refined vote of `leaf` for point `point` (Eq. 2 weight and Eq. 6 confidence).
    fn refined(&self, leaf: u32, point: usize) -> LeafVote;
    /// Baseline mode `mode` of `leaf` for point `point`.
    fn baseline(&self, leaf: u32, point: usize, mode: usize) -> LeafVote;
    /// Inference parameters of point `point`.
    fn params(&self, point: usize) -> PointParams;
}

/// A validated, borrowed view of a `JFOR` file (zero-copy; every access is a bounds-safe little-endian load).
#[derive(Clone, Copy, Debug)]
pub struct ForestView<'a> {
    file: ModelFile<'a>,
    trees: usize,
    tree_start: [u32; MAX_TREES + 1],
    leaves: usize,
    samples: u32,
    split: LeSlice<'a, i8>,
    thrs: LeSlice<'a, i16>,
    chld: LeSlice<'a, u32>,
    rvot: LeSlice<'a, i16>,
    rcon: LeSlice<'a, u8>,
    bvot: LeSlice<'a, i16>,
    bwgt: LeSlice<'a, u8>,
    params: [PointParams; P],
}

fn invalid(tag: Tag, what: &'static str) -> ModelFileError {
    ModelFileError::InvalidData { tag, what }
}

impl<'a> ForestView<'a> {
    /// Validate `bytes` as a joint forest file.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, ModelFileError> {
        let file = ModelFile::parse(bytes, KIND, VERSION)?;
        let head = file.typed::<u32>(tags::HEAD, Some(4))?;
        let (trees, nodes, leaves, samples) = (
            head.at(0) as usize,
            head.at(1) as usize,
            head.at(2) as usize,
            head.at(3),
        );
        if trees == 0 || trees > MAX_TREES {
            return Err(invalid(tags::HEAD, "tree count must be 1..=4"));
        }
        if nodes < trees || nodes >= LEAF_BIT as usize || leaves == 0 || leaves >= LEAF_BIT as usize {
            return Err(invalid(tags::HEAD, "node or leaf count out of range"));
        }
        if samples == 0 || samples as usize > crate::forest::MAX_SAMPLES {
            return Err(invalid(tags::HEAD, "samples per frame out of range"));
        }
        let tree = file.typed::<u32>(tags::TREE, Some(trees))?;
        let mut tree_start = [0u32; MAX_TREES + 1];
        for t in 0..trees {
            tree_start[t] = tree.at(t);
        }
        tree_start[trees] = nodes as u32;
        if tree_start[0] != 0 {
            return Err(invalid(tags::TREE, "first tree must start at node 0"));
        }
        for t in 0..trees {
            if tree_start[t + 1] <= tree_start[t] {
                return Err(invalid(tags::TREE, "tree starts must increase"));
            }
        }
        let split = file.typed::<i8>(tags::SPLT, Some(nodes * 4))?;
        let thrs = file.typed::<i16>(tags::THRS, Some(nodes))?;
        let chld = file.typed::<u32>(tags::CHLD, Some(nodes))?;
        for t in 0..trees {
            let (s, e) = (tree_start[t], tree_start[t + 1]);
            let n = e - s;
            for i in 0..n {
                let c = chld.at((s + i) as usize);
                if c & LEAF_BIT != 0 {
                    if (c & !LEAF_BIT) as usize >= leaves {
                        return Err(invalid(tags::CHLD, "leaf id out of range"));
                    }
                } else if c <= i || c.checked_add(1).is_none_or(|r| r >= n) {
                    return Err(invalid(tags::CHLD, "child index not forward within its tree"));
                }
            }
        }
        let rvot = file.typed::<i16>(tags::RVOT, Some(leaves * P * 3))?;
        let rcon = file.typed::<u8>(tags::RCON, Some(leaves * P))?;
        let bvot = file.typed::<i16>(tags::BVOT, Some(leaves * P * MODES * 3))?;
        let bwgt = file.typed::<u8>(tags::BWGT, Some(leaves * P * MODES))?;
        let parm = file.typed::<f32>(tags::PARM, Some(P * 3))?;
        let mut params = [PointParams {
            refined_bandwidth_m: 0.0,
            baseline_bandwidth_m: 0.0,
            vote_length_m: 0.0,
        }; P];
        for (p, out) in params.iter_mut().enumerate() {
            let v = [parm.at(p * 3), parm.at(p * 3 + 1), parm.at(p * 3 + 2)];
            if v.iter().any(|x| !x.is_finite() || *x <= 0.0 || *x > 10.0) {
                return Err(invalid(tags::PARM, "parameters must be finite, in (0, 10] m"));
            }
            *out = PointParams {
                refined_bandwidth_m: v[0],
                baseline_bandwidth_m: v[1],
                vote_length_m: v[2],
            };
        }
        Ok(ForestView {
            file,
            trees,
            tree_start,
            leaves,
            samples,
            split,
            thrs,
            chld,
            rvot,
            rcon,
            bvot,
            bwgt,
            params,
        })
    }

    /// Number of leaves.
    pub fn leaf_count(&self) -> usize {
        self.leaves
    }

    /// Number of nodes (internal and leaves).
    pub fn node_count(&self) -> usize {
        self.tree_start[self.trees] as usize
    }

    /// Samples per frame the forest was trained with (the default for inference).
    pub fn samples_per_frame(&self) -> usize {
        self.samples as usize
    }

    /// The provenance JSON, if present and UTF-8.
    pub fn meta(&self) -> Option<&'a str> {
        let s = self.file.section(tags::META).ok()?;
        core::str::from_utf8(s.bytes).ok()
    }

    /// The underlying container (size, CRC).
    pub fn file(&self) -> &ModelFile<'a> {
        &self.file
    }
}

impl ForestModel for ForestView<'_> {
    fn tree_count(&self) -> usize {
        self.trees
    }

    #[inline]
    fn node(&self, tree: usize, index: u32) -> Node {
        let g = (self.tree_start[tree] + index) as usize;
        let c = self.chld.at(g);
        if c & LEAF_BIT != 0 {
            return Node::Leaf(c & !LEAF_BIT);
        }
        let test = SplitTest {
            u: [self.split.at(g * 4), self.split.at(g * 4 + 1)],
            v: [self.split.at(g * 4 + 2), self.split.at(g * 4 + 3)],
            threshold_mm: self.thrs.at(g),
        };
        Node::Split { test, left: c }
    }

    #[inline]
    fn refined(&self, leaf: u32, point: usize) -> LeafVote {
        let i = leaf as usize * P + point;
        LeafVote {
            offset: [
                self.rvot.at(i * 3) as f32 * 1e-3,
                self.rvot.at(i * 3 + 1) as f32 * 1e-3,
                self.rvot.at(i * 3 + 2) as f32 * 1e-3,
            ],
            weight: self.rcon.at(i) as f32 * (1.0 / 255.0),
        }
    }

    #[inline]
    fn baseline(&self, leaf: u32, point: usize, mode: usize) -> LeafVote {
        let i = (leaf as usize * P + point) * MODES + mode;
        LeafVote {
            offset: [
                self.bvot.at(i * 3) as f32 * 1e-3,
                self.bvot.at(i * 3 + 1) as f32 * 1e-3,
                self.bvot.at(i * 3 + 2) as f32 * 1e-3,
            ],
            weight: self.bwgt.at(i) as f32 * (1.0 / 255.0),
        }
    }

    fn params(&self, point: usize) -> PointParams {
        self.params[point]
    }
}
