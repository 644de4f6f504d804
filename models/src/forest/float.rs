//! The trainer's float forest ([`FloatForest`]: the grown trees with f32 leaves, both baseline and refined) and its
//! quantisation into a `JFOR` model file (offsets and thresholds are already small integers; leaf votes become
//! i16 mm, confidences u8 on a log scale, mode weights u8). The float forest runs through core's inference too (it implements
//! [`ForestModel`]), so "refined" and "quantised" differ only by the quantisation.

use super::tree::Tree;
use anyhow::{Result, ensure};
use supine_core::forest::model::confidence_code;
use supine_core::forest::model::{ForestModel, KIND, LEAF_BIT, LeafVote, Node, PointParams, VERSION, tags};
use supine_core::forest::{MAX_TREES, MODES};
use supine_core::model_file::{ElemType, SectionData, encoded_len, write};
use supine_core::salient::SalientPoint;

const P: usize = SalientPoint::COUNT;

/// Per leaf and point: the baseline's modes (offset m, weight 0..1).
pub type BaselineLeaf = [[([f32; 3], f32); MODES]; P];

/// A trained forest with float leaves.
#[derive(Debug, Clone, PartialEq)]
pub struct FloatForest {
    /// The trees (leaf ids local to each tree).
    pub trees: Vec<Tree>,
    /// First global leaf id of each tree.
    pub leaf_base: Vec<u32>,
    /// Refined leaf weights (Eq. 2), per global leaf, point and axis, metres.
    pub refined: Vec<[[f32; 3]; P]>,
    /// Mean training error E_l per global leaf and point, metres.
    pub leaf_error: Vec<[f32; P]>,
    /// Whether most of a leaf's training samples were on the body (the others carry no vote).
    pub body_leaf: Vec<bool>,
    /// Baseline leaves.
    pub baseline: Vec<BaselineLeaf>,
    /// E_l scale s per point of v_l = exp(-(E_l / s)^2), metres (chosen on the validation bodies).
    pub error_scale_m: [f32; P],
    /// Per-point inference parameters.
    pub params: [PointParams; P],
    /// Samples per frame the forest was trained with.
    pub samples: u32,
}

impl FloatForest {
    /// Total leaves.
    pub fn leaf_count(&self) -> usize {
        self.refined.len()
    }

    /// Total nodes.
    pub fn node_count(&self) -> usize {
        self.trees.iter().map(|t| t.nodes.len()).sum()
    }

    /// Refined confidence v_l of `leaf` for `point` (Eq. 6).
    pub fn confidence(&self, leaf: usize, point: usize) -> f32 {
        if !self.body_leaf[leaf] {
            return 0.0;
        }
        let e = self.leaf_error[leaf][point] / self.error_scale_m[point];
        (-e * e).exp()
    }

    /// Encode as a `JFOR` model file with `meta` (UTF-8 JSON) as provenance.
    pub fn to_file_bytes(&self, meta: &str) -> Result<Vec<u8>> {
        ensure!(
            !self.trees.is_empty() && self.trees.len() <= MAX_TREES,
            "forest must have 1..={MAX_TREES} trees"
        );
        let nodes = self.node_count();
        let leaves = self.leaf_count();
        let head: Vec<u32> = vec![self.trees.len() as u32, nodes as u32, leaves as u32, self.samples];
        let mut tree_start = Vec::new();
        let mut split = Vec::with_capacity(nodes * 4);
        let mut thrs = Vec::with_capacity(nodes);
        let mut chld = Vec::with_capacity(nodes);
        let mut at = 0u32;
        for (t, tree) in self.trees.iter().enumerate() {
            tree_start.push(at);
            at += tree.nodes.len() as u32;
            for n in &tree.nodes {
                if n.child & LEAF_BIT != 0 {
                    split.extend([0i8; 4]);
                    thrs.push(0i16);
                    chld.push(LEAF_BIT | ((n.child & !LEAF_BIT) + self.leaf_base[t]));
                } else {
                    split.extend([n.test.u[0], n.test.u[1], n.test.v[0], n.test.v[1]]);
                    thrs.push(n.test.threshold_mm);
                    chld.push(n.child);
                }
            }
        }
        let mm = |x: f32| (x * 1000.0).round().clamp(-32767.0, 32767.0) as i16;
        let u8w = |x: f32| (x * 255.0).round().clamp(0.0, 255.0) as u8;
        let mut rvot = Vec::with_capacity(leaves * P * 3);
        let mut rcon = Vec::with_capacity(leaves * P);
        let mut bvot = Vec::with_capacity(leaves * P * MODES * 3);
        let mut bwgt = Vec::with_capacity(leaves * P * MODES);
        for l in 0..leaves {
            for p in 0..P {
                rvot.extend(self.refined[l][p].map(mm));
                rcon.push(confidence_code(self.confidence(l, p)));
                for m in 0..MODES {
                    let (o, w) = self.baseline[l][p][m];
                    bvot.extend(o.map(mm));
                    bwgt.push(u8w(if self.body_leaf[l] { w } else { 0.0 }));
                }
            }
        }
        let mut parm = Vec::with_capacity(P * 3);
        for p in &self.params {
            parm.extend([p.refined_bandwidth_m, p.baseline_bandwidth_m, p.vote_length_m]);
        }
        fn le<T: Copy, const N: usize>(v: &[T], f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
            v.iter().flat_map(|&x| f(x)).collect()
        }
        let b_head = le(&head, u32::to_le_bytes);
        let b_tree = le(&tree_start, u32::to_le_bytes);
        let b_split = le(&split, i8::to_le_bytes);
        let b_thrs = le(&thrs, i16::to_le_bytes);
        let b_chld = le(&chld, u32::to_le_bytes);
        let b_rvot = le(&rvot, i16::to_le_bytes);
        let b_bvot = le(&bvot, i16::to_le_bytes);
        let b_parm = le(&parm, f32::to_le_bytes);
        let sec = |tag, elem, bytes| SectionData { tag, elem, bytes };
        let sections = [
            sec(tags::HEAD, ElemType::U32, &b_head[..]),
            sec(tags::TREE, ElemType::U32, &b_tree[..]),
            sec(tags::SPLT, ElemType::I8, &b_split[..]),
            sec(tags::THRS, ElemType::I16, &b_thrs[..]),
            sec(tags::CHLD, ElemType::U32, &b_chld[..]),
            sec(tags::RVOT, ElemType::I16, &b_rvot[..]),
            sec(tags::RCON, ElemType::U8, &rcon[..]),
            sec(tags::BVOT, ElemType::I16, &b_bvot[..]),
            sec(tags::BWGT, ElemType::U8, &bwgt[..]),
            sec(tags::PARM, ElemType::F32, &b_parm[..]),
            sec(tags::META, ElemType::U8, meta.as_bytes()),
        ];
        let mut out = vec![0u8; encoded_len(&sections)];
        let n = write(KIND, VERSION, &sections, &mut out).map_err(|e| anyhow::anyhow!("{e}"))?;
        out.truncate(n);
        Ok(out)
    }
}

impl ForestModel for FloatForest {
    fn tree_count(&self) -> usize {
        self.trees.len()
    }

    #[inline]
    fn node(&self, tree: usize, index: u32) -> Node {
        let n = &self.trees[tree].nodes[index as usize];
        if n.child & LEAF_BIT != 0 {
            Node::Leaf((n.child & !LEAF_BIT) + self.leaf_base[tree])
        } else {
            Node::Split {
                test: n.test,
                left: n.child,
            }
        }
    }

    fn refined(&self, leaf: u32, point: usize) -> LeafVote {
        LeafVote {
            offset: self.refined[leaf as usize][point],
            weight: self.confidence(leaf as usize, point),
        }
    }

    fn baseline(&self, leaf: u32, point: usize, mode: usize) -> LeafVote {
        let (offset, w) = self.baseline[leaf as usize][point][mode];
        LeafVote {
            offset,
            weight: if self.body_leaf[leaf as usize] { w } else { 0.0 },
        }
    }

    fn params(&self, point: usize) -> PointParams {
        self.params[point]
    }
}
