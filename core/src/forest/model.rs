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
//! RCON u8  [L*P]      refined leaf confidences v_l = exp(-E_l^2) (Eq. 6) as code c: v_l = exp(-c/8), 255 = 0
//!                     (log scale: 12 % steps over 14 decades; small confidences must not round to 0)
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
    confidence: [f32; 256],
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
            weight: self.confidence[self.rcon.at(i) as usize],
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model_file::{ElemType, SectionData, encoded_len, write};

    /// A two-tree forest: tree 0 is one split and two leaves, tree 1 a single leaf; 3 leaves.
    struct Parts {
        head: [u32; 4],
        tree: [u32; 2],
        split: [i8; 16],
        thrs: [i16; 4],
        chld: [u32; 4],
        rvot: [i16; 3 * P * 3],
        rcon: [u8; 3 * P],
        bvot: [i16; 3 * P * MODES * 3],
        bwgt: [u8; 3 * P * MODES],
        parm: [f32; P * 3],
    }

    fn parts() -> Parts {
        let mut p = Parts {
            head: [2, 4, 3, 512],
            tree: [0, 3],
            split: [0; 16],
            thrs: [0; 4],
            chld: [1, LEAF_BIT, LEAF_BIT | 1, LEAF_BIT | 2],
            rvot: [0; 3 * P * 3],
            rcon: [0; 3 * P],
            bvot: [0; 3 * P * MODES * 3],
            bwgt: [0; 3 * P * MODES],
            parm: [0.05; P * 3],
        };
        p.split[..4].copy_from_slice(&[10, -3, 0, 7]);
        p.thrs[0] = -25;
        for (i, v) in p.rvot.iter_mut().enumerate() {
            *v = i as i16 * 7 - 100;
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
        let mut b = [[0u8; 512]; 10];
        let n = [
            le(&p.head, u32::to_le_bytes, &mut b[0]),
            le(&p.tree, u32::to_le_bytes, &mut b[1]),
            le(&p.split, i8::to_le_bytes, &mut b[2]),
            le(&p.thrs, i16::to_le_bytes, &mut b[3]),
            le(&p.chld, u32::to_le_bytes, &mut b[4]),
            le(&p.rvot, i16::to_le_bytes, &mut b[5]),
            le(&p.rcon, u8::to_le_bytes, &mut b[6]),
            le(&p.bvot, i16::to_le_bytes, &mut b[7]),
            le(&p.bwgt, u8::to_le_bytes, &mut b[8]),
            le(&p.parm, f32::to_le_bytes, &mut b[9]),
        ];
        let s = |tag, elem, i: usize| SectionData {
            tag,
            elem,
            bytes: &b[i][..n[i]],
        };
        let secs = [
            s(tags::HEAD, ElemType::U32, 0),
            s(tags::TREE, ElemType::U32, 1),
            s(tags::SPLT, ElemType::I8, 2),
            s(tags::THRS, ElemType::I16, 3),
            s(tags::CHLD, ElemType::U32, 4),
            s(tags::RVOT, ElemType::I16, 5),
            s(tags::RCON, ElemType::U8, 6),
            s(tags::BVOT, ElemType::I16, 7),
            s(tags::BWGT, ElemType::U8, 8),
            s(tags::PARM, ElemType::F32, 9),
        ];
        assert!(encoded_len(&secs) <= out.len());
        write(kind, VERSION, &secs, out).unwrap()
    }

    /// Read every field back through the view (the inverse of `encode`).
    fn decode(v: &ForestView<'_>) -> Parts {
        let mut p = parts();
        p.head = [
            v.tree_count() as u32,
            v.node_count() as u32,
            v.leaf_count() as u32,
            v.samples_per_frame() as u32,
        ];
        p.split = [0; 16];
        p.thrs = [0; 4];
        for t in 0..v.tree_count() {
            p.tree[t] = v.tree_start[t];
            for i in 0..(v.tree_start[t + 1] - v.tree_start[t]) {
                let g = (v.tree_start[t] + i) as usize;
                p.chld[g] = match v.node(t, i) {
                    Node::Leaf(l) => LEAF_BIT | l,
                    Node::Split { test, left } => {
                        p.split[g * 4..g * 4 + 4]
                            .copy_from_slice(&[test.u[0], test.u[1], test.v[0], test.v[1]]);
                        p.thrs[g] = test.threshold_mm;
                        left
                    }
                };
            }
        }
        for l in 0..v.leaf_count() {
            for pt in 0..P {
                let r = v.refined(l as u32, pt);
                let i = l * P + pt;
                for a in 0..3 {
                    p.rvot[i * 3 + a] = libm::roundf(r.offset[a] * 1000.0) as i16;
                }
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
            let _ = l;
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
    fn exact_byte_round_trip() {
        let mut a = [0u8; 2048];
        let n = encode(&parts(), KIND, &mut a);
        let v = ForestView::parse(&a[..n]).unwrap();
        assert_eq!((v.tree_count(), v.node_count(), v.leaf_count()), (2, 4, 3));
        let mut b = [0u8; 2048];
        let m = encode(&decode(&v), KIND, &mut b);
        assert_eq!(&a[..n], &b[..m], "decode then encode gives the same bytes");
        assert_eq!(
            v.node(0, 0),
            Node::Split {
                test: SplitTest {
                    u: [10, -3],
                    v: [0, 7],
                    threshold_mm: -25
                },
                left: 1
            }
        );
        assert_eq!(v.node(1, 0), Node::Leaf(2));
    }

    #[test]
    fn bad_files_are_distinct_errors() {
        let mut buf = [0u8; 2048];
        let n = encode(&parts(), KIND, &mut buf);
        let good = &buf[..n];
        assert!(matches!(
            ForestView::parse(&good[..n - 16]),
            Err(ModelFileError::Truncated { .. })
        ));
        let mut bad = [0u8; 2048];
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
        // Structurally valid containers with bad forest data.
        type Edit = fn(&mut Parts);
        let cases: [(Edit, Tag); 6] = [
            (|p| p.chld[0] = 0, tags::CHLD),            // a cycle: child not after its node
            (|p| p.chld[0] = 2, tags::CHLD),            // right child past the tree's end
            (|p| p.chld[3] = LEAF_BIT | 3, tags::CHLD), // leaf id out of range
            (|p| p.tree[1] = 0, tags::TREE),
            (|p| p.head[0] = 9, tags::HEAD),
            (|p| p.parm[4] = f32::NAN, tags::PARM),
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
        let mut buf = [0u8; 2048];
        let n = encode(&parts(), KIND, &mut buf);
        let mut x: u32 = 0x9E37_79B9;
        let mut bad = [0u8; 2048];
        for _ in 0..3000 {
            bad[..n].copy_from_slice(&buf[..n]);
            for _ in 0..3 {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                bad[x as usize % n] ^= (x >> 8) as u8 | 1;
            }
            let _ = ForestView::parse(&bad[..(x as usize >> 4) % (n + 1)]);
            let _ = ForestView::parse(&bad[..n]);
        }
    }
}
