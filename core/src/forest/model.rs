//! What inference needs of a forest ([`ForestModel`]) and the quantised model file that the head computer loads
//! ([`ForestView`], kind `JFOR`).
//!
//! File layout (sections of a [`crate::model_file`] container, kind [`KIND`], version [`VERSION`]); `T` trees,
//! `N` nodes in all, `L` leaves in all, `P` = 6 points, `M` = [`MODES`]:
//! ```text
//! HEAD u32 [6]        T, N, L, samples per frame the forest was trained with, vote shift s (0..=4), flags
//!                     (bit 0 = FLAG_BASELINE: the baseline leaves BVOT/BWGT are stored)
//! TREE u32 [T]        first node of each tree (tree t owns nodes [TREE[t], TREE[t+1]), the last up to N)
//! NODE u32 [N*2]      one 8-byte record per node: word 0 = u.x u.y v.x v.y (i8, pixel·metres, low byte first),
//!                     word 1 = threshold (i8 mm, bits 0..8) | child << 8, child (24 bits) = NODE_LEAF | leaf id, or
//!                     the left child's index within the tree (right = left + 1, left > node); leaves: words 0, child
//! RVOT u8  [V + 8]    refined leaf weights (Eq. 2): per leaf and point x, y, z as 12-bit two's complement in units
//!                     of 2^s mm, bit-packed low bit first (36 bits per leaf and point, V = ceil(L*P*36/8)), then 8
//!                     zero bytes so that every 64-bit load of a vote stays inside the section
//! RCON u8  [L*P]      refined leaf confidences v_l = exp(-E_l^2) (Eq. 6) as code c: v_l = exp(-c/8), 255 = 0
//!                     (log scale: 12 % steps over 14 decades; small confidences must not round to 0)
//! BVOT i16 [L*P*M*3]  baseline (Girshick) mode offsets, mm              (only with FLAG_BASELINE)
//! BWGT u8  [L*P*M]    baseline mode weights, x255                       (only with FLAG_BASELINE)
//! PARM f32 [P*3]      per point: refined mean-shift bandwidth, baseline bandwidth, baseline vote length (m)
//! META u8  [..]       UTF-8 JSON provenance (training command, seed, data), not read by core
//! ```
//! Version 2 (this one) packs what version 1 spread over three sections (SPLT i8x4, THRS i16, CHLD u32: 10 bytes,
//! three cache lines per node) into one 8-byte record, the refined weights into 12 bits instead of 16, and makes the
//! baseline leaves optional: the head computer runs only the refined leaves (42 B per leaf in v1's refined part
//! became 33 B), and the baseline (72 + 12 B per leaf) is kept for evaluation beside the shipped file. Every
//! trained forest so far fits s = 0 (weights within ±2047 mm, thresholds within ±50 mm), so a v1 file re-encoded as
//! v2 gives bit-identical inference. A v1 file is refused as `UnsupportedKindVersion` (found 1, supported 2);
//! `supine-models convert joints` re-encodes it.
//!
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
pub const VERSION: u16 = 2;
/// Marks a leaf in the trainer's child fields (the 32-bit convention of [`Node`] users; the file uses [`NODE_LEAF`]).
pub const LEAF_BIT: u32 = 1 << 31;
/// Marks a leaf in a `NODE` record's 24-bit child field.
pub const NODE_LEAF: u32 = 1 << 23;
/// Most nodes per tree and most leaves per forest a `NODE` record can address.
pub const MAX_NODE_INDEX: u32 = NODE_LEAF - 1;
/// `HEAD` flag: the baseline leaves (`BVOT`, `BWGT`) are stored.
pub const FLAG_BASELINE: u32 = 1;
/// Largest vote shift s (weights in units of 2^s mm; 4 covers ±32 m).
pub const MAX_VOTE_SHIFT: u32 = 4;
/// Largest magnitude of a 12-bit vote field.
pub const VOTE_FIELD_MAX: i32 = 2047;
/// Points per leaf.
const P: usize = SalientPoint::COUNT;
/// `RCON` code meaning "no vote" (leaves whose samples were mostly not body).
pub const NO_VOTE: u8 = 255;
/// `RCON` codes per unit of -ln(v_l).
pub const CONFIDENCE_STEPS: f32 = 8.0;

/// The `RCON` code of confidence `v` (0..1).
pub fn confidence_code(v: f32) -> u8 {
    if v.is_nan() || v <= 0.0 {
        return NO_VOTE;
    }
    let c = libm::roundf(-libm::logf(v.min(1.0)) * CONFIDENCE_STEPS);
    if c >= NO_VOTE as f32 { NO_VOTE - 1 } else { c as u8 }
}

/// The confidence an `RCON` code stands for.
pub fn confidence_of(code: u8) -> f32 {
    if code == NO_VOTE {
        0.0
    } else {
        libm::expf(-(code as f32) / CONFIDENCE_STEPS)
    }
}

/// Bytes of the `RVOT` section for `leaves` leaves (packed votes and the 8 padding bytes).
pub const fn vote_bytes(leaves: usize) -> usize {
    (leaves * P * 36).div_ceil(8) + 8
}

/// Pack the refined weights `q` (per leaf, point and axis, in units of 2^s mm, each within ±[`VOTE_FIELD_MAX`])
/// into `out` (length [`vote_bytes`] of `q.len() / (P * 3)` leaves, zeroed by the caller). Returns false when a
/// value does not fit 12 bits or the lengths disagree.
pub fn pack_votes(q: &[i32], out: &mut [u8]) -> bool {
    if !q.len().is_multiple_of(P * 3) || out.len() != vote_bytes(q.len() / (P * 3)) {
        return false;
    }
    for (k, &v) in q.iter().enumerate() {
        if !(-VOTE_FIELD_MAX..=VOTE_FIELD_MAX).contains(&v) {
            return false;
        }
        let bits = (v as u32) & 0xFFF;
        let bit = k * 12;
        let (byte, shift) = (bit / 8, bit % 8);
        let w = bits << shift;
        out[byte] |= w as u8;
        out[byte + 1] |= (w >> 8) as u8;
    }
    true
}

/// The two `NODE` words of a split node (`test`, left child `left` within its tree) or of a leaf (`test` `None`,
/// `left` its forest-wide leaf id); `None` when the threshold does not fit i8 or the index does not fit 23 bits.
pub fn node_words(test: Option<SplitTest>, index: u32) -> Option<[u32; 2]> {
    if index > MAX_NODE_INDEX {
        return None;
    }
    match test {
        None => Some([0, (NODE_LEAF | index) << 8]),
        Some(t) => {
            let thr = i8::try_from(t.threshold_mm).ok()?;
            let w0 = u32::from_le_bytes([t.u[0] as u8, t.u[1] as u8, t.v[0] as u8, t.v[1] as u8]);
            Some([w0, (thr as u8 as u32) | (index << 8)])
        }
    }
}

/// `node` as a `NODE` record: its two [`node_words`] as one little-endian u64 ([`decode_node`] gives it back).
/// Every forest here fits the record: the trainer draws thresholds within i8 and refuses trees beyond 2^23 nodes or
/// leaves, and [`ForestView::parse`] checks the file's.
#[inline]
pub fn node_record(node: Node) -> u64 {
    let (test, index) = match node {
        Node::Split { test, left } => (Some(test), left),
        Node::Leaf(l) => (None, l),
    };
    let words = node_words(test, index);
    debug_assert!(words.is_some(), "{node:?} does not fit a NODE record");
    let [w0, w1] = words.unwrap_or([0, (NODE_LEAF | MAX_NODE_INDEX) << 8]);
    u64::from(w0) | (u64::from(w1) << 32)
}

/// The node a `NODE` record (its two words as one little-endian u64) holds; [`node_record`]'s inverse.
#[inline]
pub fn decode_node(r: u64) -> Node {
    let w1 = (r >> 32) as u32;
    let c = w1 >> 8;
    if c & NODE_LEAF != 0 {
        return Node::Leaf(c & !NODE_LEAF);
    }
    let [ux, uy, vx, vy] = (r as u32).to_le_bytes();
    let test = SplitTest {
        u: [ux as i8, uy as i8],
        v: [vx as i8, vy as i8],
        threshold_mm: w1 as u8 as i8 as i16,
    };
    Node::Split { test, left: c }
}

/// Section tags.
pub mod tags {
    use crate::model_file::Tag;
    /// Counts.
    pub const HEAD: Tag = *b"HEAD";
    /// Tree starts.
    pub const TREE: Tag = *b"TREE";
    /// Node records (version 2).
    pub const NODE: Tag = *b"NODE";
    /// Split offsets (version 1).
    pub const SPLT: Tag = *b"SPLT";
    /// Split thresholds (version 1).
    pub const THRS: Tag = *b"THRS";
    /// Children / leaf ids (version 1).
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
    /// Node `index` of tree `tree` as a `NODE` record ([`node_record`]), the form the lockstep descent carries from
    /// level to level. The default packs [`Self::node`]; a model that stores records reads them.
    #[inline]
    fn record(&self, tree: usize, index: u32) -> u64 {
        node_record(self.node(tree, index))
    }
    /// The records of nodes `left` and `left + 1` of tree `tree`: a split's two children, which the descent loads
    /// before its test is decided.
    #[inline]
    fn child_records(&self, tree: usize, left: u32) -> [u64; 2] {
        [self.record(tree, left), self.record(tree, left + 1)]
    }
    /// Refined vote of `leaf` for point `point` (Eq. 2 weight and Eq. 6 confidence).
    fn refined(&self, leaf: u32, point: usize) -> LeafVote;
    /// Baseline mode `mode` of `leaf` for point `point` (weight 0 where the model stores no baseline).
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
    /// The `NODE` section's bytes (8 per record, read as one little-endian u64).
    nodes: &'a [u8],
    rvot: &'a [u8],
    vote_shift: u32,
    rcon: LeSlice<'a, u8>,
    baseline: Option<(LeSlice<'a, i16>, LeSlice<'a, u8>)>,
    params: [PointParams; P],
    confidence: [f32; 256],
}

fn invalid(tag: Tag, what: &'static str) -> ModelFileError {
    ModelFileError::InvalidData { tag, what }
}

impl<'a> ForestView<'a> {
    /// Validate `bytes` as a joint forest file.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, ModelFileError> {
        let file = ModelFile::parse(bytes, KIND, VERSION)?;
        let head = file.typed::<u32>(tags::HEAD, Some(6))?;
        let (trees, nodes, leaves, samples, shift, flags) = (
            head.at(0) as usize,
            head.at(1) as usize,
            head.at(2) as usize,
            head.at(3),
            head.at(4),
            head.at(5),
        );
        if trees == 0 || trees > MAX_TREES {
            return Err(invalid(tags::HEAD, "tree count must be 1..=4"));
        }
        if nodes < trees || nodes >= LEAF_BIT as usize || leaves == 0 || leaves > MAX_NODE_INDEX as usize + 1
        {
            return Err(invalid(tags::HEAD, "node or leaf count out of range"));
        }
        if samples == 0 || samples as usize > crate::forest::MAX_SAMPLES {
            return Err(invalid(tags::HEAD, "samples per frame out of range"));
        }
        if shift > MAX_VOTE_SHIFT {
            return Err(invalid(tags::HEAD, "vote shift must be 0..=4"));
        }
        if flags & !FLAG_BASELINE != 0 {
            return Err(invalid(tags::HEAD, "unknown flags"));
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
            if tree_start[t + 1] - tree_start[t] > MAX_NODE_INDEX {
                return Err(invalid(
                    tags::TREE,
                    "a tree has more nodes than a record can address",
                ));
            }
        }
        let node_words = file.typed::<u32>(tags::NODE, Some(nodes * 2))?;
        for t in 0..trees {
            let (s, e) = (tree_start[t], tree_start[t + 1]);
            let n = e - s;
            for i in 0..n {
                let g = (s + i) as usize * 2;
                let record = u64::from(node_words.at(g)) | (u64::from(node_words.at(g + 1)) << 32);
                match decode_node(record) {
                    Node::Leaf(l) if l as usize >= leaves => {
                        return Err(invalid(tags::NODE, "leaf id out of range"));
                    }
                    Node::Split { left, .. } if left <= i || left + 1 >= n => {
                        return Err(invalid(tags::NODE, "child index not forward within its tree"));
                    }
                    _ => {}
                }
            }
        }
        let rvot = file.typed::<u8>(tags::RVOT, Some(vote_bytes(leaves)))?.as_bytes();
        let rcon = file.typed::<u8>(tags::RCON, Some(leaves * P))?;
        let baseline = if flags & FLAG_BASELINE != 0 {
            Some((
                file.typed::<i16>(tags::BVOT, Some(leaves * P * MODES * 3))?,
                file.typed::<u8>(tags::BWGT, Some(leaves * P * MODES))?,
            ))
        } else {
            if file.section(tags::BVOT).is_ok() || file.section(tags::BWGT).is_ok() {
                return Err(invalid(
                    tags::HEAD,
                    "baseline sections present without the baseline flag",
                ));
            }
            None
        };
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
            nodes: node_words.as_bytes(),
            rvot,
            vote_shift: shift,
            rcon,
            baseline,
            params,
            confidence: core::array::from_fn(|c| confidence_of(c as u8)),
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

    /// First node of each tree, then the node count (`tree_count() + 1` entries).
    pub fn tree_starts(&self) -> &[u32] {
        &self.tree_start[..=self.trees]
    }

    /// Samples per frame the forest was trained with (the default for inference).
    pub fn samples_per_frame(&self) -> usize {
        self.samples as usize
    }

    /// Whether the file stores the baseline leaves (without them, [`ForestModel::baseline`] casts no vote).
    pub fn has_baseline(&self) -> bool {
        self.baseline.is_some()
    }

    /// The refined weights of `leaf` for `point` as stored: per axis in units of 2^[`Self::vote_shift`] mm.
    #[inline]
    pub fn refined_raw(&self, leaf: u32, point: usize) -> [i32; 3] {
        let bit = (leaf as usize * P + point) * 36;
        let mut b = [0u8; 8];
        b.copy_from_slice(&self.rvot[bit / 8..bit / 8 + 8]);
        let w = u64::from_le_bytes(b) >> (bit % 8);
        // Sign-extend each 12-bit field.
        let f = |k: u32| (((w >> (12 * k)) as i32) << 20) >> 20;
        [f(0), f(1), f(2)]
    }

    /// Vote shift s of the refined weights (units of 2^s mm).
    pub fn vote_shift(&self) -> u32 {
        self.vote_shift
    }

    /// The stored `RCON` code of `leaf` for `point`.
    pub fn confidence_code(&self, leaf: u32, point: usize) -> u8 {
        self.rcon.at(leaf as usize * P + point)
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
        decode_node(self.record(tree, index))
    }

    #[inline]
    fn record(&self, tree: usize, index: u32) -> u64 {
        let g = (self.tree_start[tree] + index) as usize;
        // One 8-byte load per record (one bounds check), the word order of the file.
        let mut b = [0u8; 8];
        b.copy_from_slice(&self.nodes[g * 8..g * 8 + 8]);
        u64::from_le_bytes(b)
    }

    #[inline]
    fn child_records(&self, tree: usize, left: u32) -> [u64; 2] {
        let g = (self.tree_start[tree] + left) as usize;
        // The sibling pair is adjacent: one 16-byte load (one bounds check).
        let mut b = [0u8; 16];
        b.copy_from_slice(&self.nodes[g * 8..g * 8 + 16]);
        let r = u128::from_le_bytes(b);
        [r as u64, (r >> 64) as u64]
    }

    #[inline]
    fn refined(&self, leaf: u32, point: usize) -> LeafVote {
        let q = self.refined_raw(leaf, point);
        // (q << s) is an exact integer in mm, so s = 0 gives the same f32 as v1's i16 mm.
        let s = self.vote_shift;
        LeafVote {
            offset: [
                (q[0] << s) as f32 * 1e-3,
                (q[1] << s) as f32 * 1e-3,
                (q[2] << s) as f32 * 1e-3,
            ],
            weight: self.confidence[self.rcon.at(leaf as usize * P + point) as usize],
        }
    }

    #[inline]
    fn baseline(&self, leaf: u32, point: usize, mode: usize) -> LeafVote {
        let Some((bvot, bwgt)) = &self.baseline else {
            return LeafVote::default();
        };
        let i = (leaf as usize * P + point) * MODES + mode;
        LeafVote {
            offset: [
                bvot.at(i * 3) as f32 * 1e-3,
                bvot.at(i * 3 + 1) as f32 * 1e-3,
                bvot.at(i * 3 + 2) as f32 * 1e-3,
            ],
            weight: bwgt.at(i) as f32 * (1.0 / 255.0),
        }
    }

    fn params(&self, point: usize) -> PointParams {
        self.params[point]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model_file::{ElemType, SectionData, encoded_len, write};

    const L: usize = 3;

    /// A two-tree forest: tree 0 is one split and two leaves, tree 1 a single leaf; 3 leaves.
    struct Parts {
        head: [u32; 6],
        tree: [u32; 2],
        nodes: [u32; 8],
        votes: [i32; L * P * 3],
        rcon: [u8; L * P],
        bvot: [i16; L * P * MODES * 3],
        bwgt: [u8; L * P * MODES],
        parm: [f32; P * 3],
    }

    fn split() -> SplitTest {
        SplitTest {
            u: [10, -3],
            v: [0, 7],
            threshold_mm: -25,
        }
    }

    fn parts() -> Parts {
        let w = |t, i| node_words(t, i).unwrap();
        let nodes = [w(Some(split()), 1), w(None, 0), w(None, 1), w(None, 2)];
        let mut p = Parts {
            head: [2, 4, L as u32, 512, 0, FLAG_BASELINE],
            tree: [0, 3],
            nodes: [0; 8],
            votes: [0; L * P * 3],
            rcon: [0; L * P],
            bvot: [0; L * P * MODES * 3],
            bwgt: [0; L * P * MODES],
            parm: [0.05; P * 3],
        };
        for (i, n) in nodes.iter().enumerate() {
            p.nodes[i * 2..i * 2 + 2].copy_from_slice(n);
        }
        for (i, v) in p.votes.iter_mut().enumerate() {
            // Both signs and both ends of the 12-bit range.
            *v = match i {
                0 => VOTE_FIELD_MAX,
                1 => -VOTE_FIELD_MAX,
                _ => i as i32 * 37 - 900,
            };
        }
        for (i, v) in p.rcon.iter_mut().enumerate() {
            *v = (i * 13) as u8;
        }
        for (i, v) in p.bvot.iter_mut().enumerate() {
            *v = 300 - i as i16;
        }
        for (i, v) in p.bwgt.iter_mut().enumerate() {
            *v = (i * 5) as u8;
        }
        p
    }

    fn le<T: Copy, const N: usize>(v: &[T], f: impl Fn(T) -> [u8; N], out: &mut [u8]) -> usize {
        for (i, &x) in v.iter().enumerate() {
            out[i * N..i * N + N].copy_from_slice(&f(x));
        }
        v.len() * N
    }

    fn encode(p: &Parts, kind: Tag, out: &mut [u8]) -> usize {
        let mut b = [[0u8; 512]; 9];
        let mut rvot = [0u8; vote_bytes(L)];
        assert!(pack_votes(&p.votes, &mut rvot));
        let n = [
            le(&p.head, u32::to_le_bytes, &mut b[0]),
            le(&p.tree, u32::to_le_bytes, &mut b[1]),
            le(&p.nodes, u32::to_le_bytes, &mut b[2]),
            le(&rvot, u8::to_le_bytes, &mut b[3]),
            le(&p.rcon, u8::to_le_bytes, &mut b[4]),
            le(&p.bvot, i16::to_le_bytes, &mut b[5]),
            le(&p.bwgt, u8::to_le_bytes, &mut b[6]),
            le(&p.parm, f32::to_le_bytes, &mut b[7]),
        ];
        let s = |tag, elem, i: usize| SectionData {
            tag,
            elem,
            bytes: &b[i][..n[i]],
        };
        let all = [
            s(tags::HEAD, ElemType::U32, 0),
            s(tags::TREE, ElemType::U32, 1),
            s(tags::NODE, ElemType::U32, 2),
            s(tags::RVOT, ElemType::U8, 3),
            s(tags::RCON, ElemType::U8, 4),
            s(tags::BVOT, ElemType::I16, 5),
            s(tags::BWGT, ElemType::U8, 6),
            s(tags::PARM, ElemType::F32, 7),
        ];
        let mut secs = [all[0]; 8];
        let mut k = 0;
        for sec in all {
            if p.head[5] & FLAG_BASELINE == 0 && (sec.tag == tags::BVOT || sec.tag == tags::BWGT) {
                continue;
            }
            secs[k] = sec;
            k += 1;
        }
        assert!(encoded_len(&secs[..k]) <= out.len());
        write(kind, VERSION, &secs[..k], out).unwrap()
    }

    /// Read every field back through the view (the inverse of `encode`).
    fn decode(v: &ForestView<'_>) -> Parts {
        let mut p = parts();
        p.head = [
            v.tree_count() as u32,
            v.node_count() as u32,
            v.leaf_count() as u32,
            v.samples_per_frame() as u32,
            v.vote_shift(),
            if v.has_baseline() { FLAG_BASELINE } else { 0 },
        ];
        p.nodes = [0; 8];
        for t in 0..v.tree_count() {
            p.tree[t] = v.tree_start[t];
            for i in 0..(v.tree_start[t + 1] - v.tree_start[t]) {
                let g = (v.tree_start[t] + i) as usize;
                let r = node_record(v.node(t, i));
                p.nodes[g * 2..g * 2 + 2].copy_from_slice(&[r as u32, (r >> 32) as u32]);
            }
        }
        for l in 0..v.leaf_count() {
            for pt in 0..P {
                let r = v.refined(l as u32, pt);
                let i = l * P + pt;
                for a in 0..3 {
                    p.votes[i * 3 + a] = libm::roundf(r.offset[a] * 1000.0) as i32;
                }
                assert_eq!(v.refined_raw(l as u32, pt), [0, 1, 2].map(|a| p.votes[i * 3 + a]));
                p.rcon[i] = confidence_code(r.weight);
                for m in 0..MODES {
                    let b = v.baseline(l as u32, pt, m);
                    let j = i * MODES + m;
                    for a in 0..3 {
                        p.bvot[j * 3 + a] = libm::roundf(b.offset[a] * 1000.0) as i16;
                    }
                    p.bwgt[j] = libm::roundf(b.weight * 255.0) as u8;
                }
            }
        }
        for pt in 0..P {
            let q = v.params(pt);
            p.parm[pt * 3..pt * 3 + 3].copy_from_slice(&[
                q.refined_bandwidth_m,
                q.baseline_bandwidth_m,
                q.vote_length_m,
            ]);
        }
        p
    }

    #[test]
    fn confidence_codes_round_trip() {
        for c in 0..=255u8 {
            assert_eq!(confidence_code(confidence_of(c)), c);
        }
        assert_eq!(confidence_code(0.0), NO_VOTE);
        assert_eq!(confidence_code(1.0), 0);
        assert_eq!(confidence_code(1e-30), NO_VOTE - 1);
    }

    #[test]
    fn node_records_are_the_files_words_and_decode_to_the_nodes() {
        let mut a = [0u8; 4096];
        let n = encode(&parts(), KIND, &mut a);
        let v = ForestView::parse(&a[..n]).unwrap();
        let p = parts();
        for t in 0..v.tree_count() {
            for i in 0..(v.tree_start[t + 1] - v.tree_start[t]) {
                let g = (v.tree_start[t] + i) as usize;
                let words = u64::from(p.nodes[g * 2]) | (u64::from(p.nodes[g * 2 + 1]) << 32);
                let node = v.node(t, i);
                assert_eq!((v.record(t, i), node_record(node)), (words, words));
                assert_eq!(decode_node(words), node);
            }
        }
        // A model that stores nodes, not records, gives the same records through the trait's defaults.
        struct Nodes<'a>(ForestView<'a>);
        impl ForestModel for Nodes<'_> {
            fn tree_count(&self) -> usize {
                self.0.tree_count()
            }
            fn node(&self, tree: usize, index: u32) -> Node {
                self.0.node(tree, index)
            }
            fn refined(&self, leaf: u32, point: usize) -> LeafVote {
                self.0.refined(leaf, point)
            }
            fn baseline(&self, leaf: u32, point: usize, mode: usize) -> LeafVote {
                self.0.baseline(leaf, point, mode)
            }
            fn params(&self, point: usize) -> PointParams {
                self.0.params(point)
            }
        }
        let pair = [v.record(0, 1), v.record(0, 2)];
        assert_eq!(v.child_records(0, 1), pair);
        assert_eq!(Nodes(v).child_records(0, 1), pair);
    }

    #[test]
    fn exact_byte_round_trip() {
        let mut a = [0u8; 4096];
        let n = encode(&parts(), KIND, &mut a);
        let v = ForestView::parse(&a[..n]).unwrap();
        assert_eq!((v.tree_count(), v.node_count(), v.leaf_count()), (2, 4, 3));
        assert!(v.has_baseline());
        let mut b = [0u8; 4096];
        let m = encode(&decode(&v), KIND, &mut b);
        assert_eq!(&a[..n], &b[..m], "decode then encode gives the same bytes");
        assert_eq!(
            v.node(0, 0),
            Node::Split {
                test: split(),
                left: 1
            }
        );
        assert_eq!(v.node(1, 0), Node::Leaf(2));
        assert_eq!(v.refined(0, 0).offset[0], 2047.0 * 1e-3);
        assert_eq!(v.refined(0, 0).offset[1], -2047.0 * 1e-3);
    }

    #[test]
    fn refined_only_files_round_trip_and_cast_no_baseline_vote() {
        let mut p = parts();
        p.head[5] = 0;
        let mut a = [0u8; 4096];
        let n = encode(&p, KIND, &mut a);
        let v = ForestView::parse(&a[..n]).unwrap();
        assert!(!v.has_baseline());
        assert_eq!(v.baseline(1, 2, 1), LeafVote::default());
        let mut b = [0u8; 4096];
        let m = encode(&decode(&v), KIND, &mut b);
        assert_eq!(&a[..n], &b[..m]);
        let mut full = [0u8; 4096];
        let k = encode(&parts(), KIND, &mut full);
        assert!(n + 120 < k, "the baseline sections take room: {n} vs {k} bytes");
    }

    #[test]
    fn vote_shift_scales_the_weights() {
        let mut p = parts();
        p.head[4] = 2;
        let mut a = [0u8; 4096];
        let n = encode(&p, KIND, &mut a);
        let v = ForestView::parse(&a[..n]).unwrap();
        assert_eq!(v.refined(0, 0).offset[0], 8188.0 * 1e-3);
        assert_eq!(v.refined_raw(0, 0)[0], VOTE_FIELD_MAX);
    }

    #[test]
    fn packing_refuses_what_does_not_fit() {
        let mut out = [0u8; vote_bytes(1)];
        let mut q = [0i32; P * 3];
        q[5] = VOTE_FIELD_MAX + 1;
        assert!(!pack_votes(&q, &mut out));
        q[5] = 0;
        assert!(!pack_votes(&q[..P * 3 - 1], &mut out));
        assert!(pack_votes(&q, &mut out));
        let mut t = split();
        t.threshold_mm = 200;
        assert_eq!(node_words(Some(t), 1), None);
        assert_eq!(node_words(None, NODE_LEAF), None);
    }

    #[test]
    fn bad_files_are_distinct_errors() {
        let mut buf = [0u8; 4096];
        let n = encode(&parts(), KIND, &mut buf);
        let good = &buf[..n];
        assert!(matches!(
            ForestView::parse(&good[..n - 16]),
            Err(ModelFileError::Truncated { .. })
        ));
        let mut bad = [0u8; 4096];
        bad[..n].copy_from_slice(good);
        bad[n - 20] ^= 0x40;
        assert!(matches!(
            ForestView::parse(&bad[..n]),
            Err(ModelFileError::ChecksumMismatch { .. })
        ));
        let m = encode(&parts(), *b"BODY", &mut bad);
        assert!(matches!(
            ForestView::parse(&bad[..m]),
            Err(ModelFileError::WrongKind { .. })
        ));
        // A version 1 file names its version.
        bad[..n].copy_from_slice(good);
        bad[16..18].copy_from_slice(&1u16.to_le_bytes());
        assert!(matches!(
            ForestView::parse(&bad[..n]),
            Err(ModelFileError::UnsupportedKindVersion {
                found: 1,
                supported: VERSION,
                ..
            })
        ));
        // Structurally valid containers with bad forest data.
        type Edit = fn(&mut Parts);
        let cases: [(Edit, Tag); 8] = [
            (
                |p| p.nodes[1] = node_words(Some(split()), 0).unwrap()[1],
                tags::NODE,
            ), // a cycle
            (
                |p| p.nodes[1] = node_words(Some(split()), 2).unwrap()[1],
                tags::NODE,
            ), // right child past the end
            (|p| p.nodes[7] = node_words(None, 3).unwrap()[1], tags::NODE), // leaf id out of range
            (|p| p.tree[1] = 0, tags::TREE),
            (|p| p.head[0] = 9, tags::HEAD),
            (|p| p.parm[4] = f32::NAN, tags::PARM),
            (|p| p.head[4] = 5, tags::HEAD),
            (|p| p.head[5] = 6, tags::HEAD),
        ];
        for (i, (edit, tag)) in cases.iter().enumerate() {
            let mut p = parts();
            edit(&mut p);
            let m = encode(&p, KIND, &mut bad);
            match ForestView::parse(&bad[..m]) {
                Err(ModelFileError::InvalidData { tag: t, .. }) => assert_eq!(t, *tag, "case {i}"),
                // A tree count of 9 also changes the expected TREE length.
                Err(ModelFileError::WrongSectionLength { .. }) if i == 4 => {}
                other => panic!("case {i}: {other:?}"),
            }
        }
        let mut p = parts();
        p.head[2] = 4; // more leaves than the leaf sections hold
        let m = encode(&p, KIND, &mut bad);
        assert!(matches!(
            ForestView::parse(&bad[..m]),
            Err(ModelFileError::WrongSectionLength { .. })
        ));
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        let mut buf = [0u8; 4096];
        let n = encode(&parts(), KIND, &mut buf);
        let mut x: u32 = 0x9E37_79B9;
        let mut bad = [0u8; 4096];
        for _ in 0..3000 {
            bad[..n].copy_from_slice(&buf[..n]);
            for _ in 0..3 {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                bad[x as usize % n] ^= (x >> 8) as u8 | 1;
            }
            let _ = ForestView::parse(&bad[..(x as usize >> 4) % (n + 1)]);
            if let Ok(v) = ForestView::parse(&bad[..n]) {
                // An accepted view never indexes out of bounds.
                for l in 0..v.leaf_count() as u32 {
                    let _ = (v.refined(l, 5), v.baseline(l, 5, 1));
                }
            }
        }
    }
}
