//! The trainer's float forest ([`FloatForest`]: the grown trees with f32 leaves, both baseline and refined) and its
//! quantisation into a `JFOR` model file (offsets and thresholds are already small integers; leaf votes become
//! mm, packed by [`super::encode`] into 12 bits, confidences u8 on a log scale, mode weights u8). The float forest runs through core's inference too (it implements
//! [`ForestModel`]), so "refined" and "quantised" differ only by the quantisation.

use super::encode::Quantised;
use super::tree::Tree;
use anyhow::{Result, ensure};
use supine_core::forest::model::confidence_code;
use supine_core::forest::model::{ForestModel, LEAF_BIT, LeafVote, Node, PointParams};
use supine_core::forest::{MAX_TREES, MODES};
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

    /// Encode as a `JFOR` model file with `meta` (UTF-8 JSON) as provenance, baseline leaves included (the file
    /// evaluates both methods).
    pub fn to_file_bytes(&self, meta: &str) -> Result<Vec<u8>> {
        self.quantised(meta, true)?.to_bytes()
    }

    /// Encode as the file the head computer ships: refined leaves only (its inference never reads the baseline;
    /// `eval joints` takes the baseline from the float sidecar).
    pub fn to_shipped_bytes(&self, meta: &str) -> Result<Vec<u8>> {
        self.quantised(meta, false)?.to_bytes()
    }

    /// The forest in the file's integer units (votes mm, confidences as codes, mode weights x255).
    pub fn quantised(&self, meta: &str, baseline: bool) -> Result<Quantised> {
        ensure!(
            !self.trees.is_empty() && self.trees.len() <= MAX_TREES,
            "forest must have 1..={MAX_TREES} trees"
        );
        let leaves = self.leaf_count();
        let mut tree_start = Vec::new();
        let mut nodes = Vec::with_capacity(self.node_count());
        let mut at = 0u32;
        for (t, tree) in self.trees.iter().enumerate() {
            tree_start.push(at);
            at += tree.nodes.len() as u32;
            for n in &tree.nodes {
                if n.child & LEAF_BIT != 0 {
                    nodes.push((None, (n.child & !LEAF_BIT) + self.leaf_base[t]));
                } else {
                    nodes.push((Some(n.test), n.child));
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
                rvot.extend(self.refined[l][p].map(|x| i32::from(mm(x))));
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
        Ok(Quantised {
            samples: self.samples,
            tree_start,
            nodes,
            refined_mm: rvot,
            rcon,
            baseline: baseline.then_some((bvot, bwgt)),
            parm,
            meta: meta.to_owned(),
        })
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
