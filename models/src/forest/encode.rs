//! The `JFOR` writer's integer form of a forest ([`Quantised`]: node tests, child indices and leaf votes already
//! in the file's units) and its encoding as a version 2 file, plus the reader of version 1 files that
//! `supine-models convert joints` re-encodes. Both the trainer (`FloatForest::to_file_bytes`) and the converter
//! go through [`Quantised::to_bytes`], so a trained and a converted forest are laid out by the same code.
//! Host only; the cost is one pass over nodes and leaves.

use anyhow::{Context, Result, bail, ensure};
use supine_core::forest::feature::SplitTest;
use supine_core::forest::model::{
    FLAG_BASELINE, ForestModel, ForestView, KIND, LEAF_BIT, MAX_VOTE_SHIFT, Node, VERSION, VOTE_FIELD_MAX,
    node_words, pack_votes, tags, vote_bytes,
};
use supine_core::forest::{MAX_TREES, MODES};
use supine_core::model_file::{ElemType, ModelFile, SectionData, encoded_len, write};
use supine_core::salient::SalientPoint;

const P: usize = SalientPoint::COUNT;

/// A forest in the file's integer units, ready to encode.
#[derive(Debug, Clone, PartialEq)]
pub struct Quantised {
    /// Samples per frame the forest was trained with.
    pub samples: u32,
    /// First node of each tree.
    pub tree_start: Vec<u32>,
    /// Every node in file order: a split's test and its left child's index within the tree, or (`None`, the
    /// leaf's forest-wide id).
    pub nodes: Vec<(Option<SplitTest>, u32)>,
    /// Refined weights per leaf, point and axis, mm.
    pub refined_mm: Vec<i32>,
    /// `RCON` codes per leaf and point.
    pub rcon: Vec<u8>,
    /// Baseline mode offsets (mm, per leaf, point, mode and axis) and weights (x255), when kept.
    pub baseline: Option<(Vec<i16>, Vec<u8>)>,
    /// Per point: refined bandwidth, baseline bandwidth, vote length (m).
    pub parm: Vec<f32>,
    /// Provenance JSON.
    pub meta: String,
}

/// The smallest vote shift s at which every weight (mm) fits a 12-bit field once divided by 2^s and rounded.
fn vote_shift(mm: &[i32]) -> Result<u32> {
    let max = mm.iter().map(|v| v.unsigned_abs()).max().unwrap_or(0) as i64;
    for s in 0..=MAX_VOTE_SHIFT {
        if (max + ((1i64 << s) >> 1)) >> s <= VOTE_FIELD_MAX as i64 {
            return Ok(s);
        }
    }
    bail!("a refined leaf weight of {max} mm does not fit the file's 12-bit votes even in 16 mm units")
}

/// `v` / 2^s rounded half away from zero.
fn scaled(v: i32, s: u32) -> i32 {
    if s == 0 {
        return v;
    }
    let h = 1i32 << (s - 1);
    if v >= 0 { (v + h) >> s } else { -((-v + h) >> s) }
}

impl Quantised {
    /// Leaves in all.
    pub fn leaf_count(&self) -> usize {
        self.rcon.len() / P
    }

    /// Encode as a version 2 `JFOR` file.
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let trees = self.tree_start.len();
        ensure!(
            (1..=MAX_TREES).contains(&trees),
            "forest must have 1..={MAX_TREES} trees"
        );
        let leaves = self.leaf_count();
        ensure!(
            self.refined_mm.len() == leaves * P * 3 && self.rcon.len() == leaves * P,
            "leaf sections disagree on the leaf count"
        );
        let shift = vote_shift(&self.refined_mm)?;
        let flags = if self.baseline.is_some() { FLAG_BASELINE } else { 0 };
        let head = [
            trees as u32,
            self.nodes.len() as u32,
            leaves as u32,
            self.samples,
            shift,
            flags,
        ];
        let mut node_bytes = Vec::with_capacity(self.nodes.len() * 8);
        for (i, &(test, index)) in self.nodes.iter().enumerate() {
            let w = node_words(test, index).with_context(|| {
                format!(
                    "node {i}: threshold {:?} mm or index {index} does not fit a version 2 node record (i8 mm, 23 bits)",
                    test.map(|t| t.threshold_mm)
                )
            })?;
            node_bytes.extend(w[0].to_le_bytes());
            node_bytes.extend(w[1].to_le_bytes());
        }
        let q: Vec<i32> = self.refined_mm.iter().map(|&v| scaled(v, shift)).collect();
        let mut rvot = vec![0u8; vote_bytes(leaves)];
        ensure!(pack_votes(&q, &mut rvot), "refined votes do not pack");
        let le32 = |v: &[u32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let b_head = le32(&head);
        let b_tree = le32(&self.tree_start);
        let b_parm: Vec<u8> = self.parm.iter().flat_map(|x| x.to_le_bytes()).collect();
        let b_bvot: Vec<u8> = match &self.baseline {
            Some((v, w)) => {
                ensure!(
                    v.len() == leaves * P * MODES * 3 && w.len() == leaves * P * MODES,
                    "baseline sections disagree on the leaf count"
                );
                v.iter().flat_map(|x| x.to_le_bytes()).collect()
            }
            None => Vec::new(),
        };
        let sec = |tag, elem, bytes| SectionData { tag, elem, bytes };
        let mut sections = vec![
            sec(tags::HEAD, ElemType::U32, &b_head[..]),
            sec(tags::TREE, ElemType::U32, &b_tree[..]),
            sec(tags::NODE, ElemType::U32, &node_bytes[..]),
            sec(tags::RVOT, ElemType::U8, &rvot[..]),
            sec(tags::RCON, ElemType::U8, &self.rcon[..]),
        ];
        if let Some((_, w)) = &self.baseline {
            sections.push(sec(tags::BVOT, ElemType::I16, &b_bvot[..]));
            sections.push(sec(tags::BWGT, ElemType::U8, &w[..]));
        }
        sections.push(sec(tags::PARM, ElemType::F32, &b_parm[..]));
        sections.push(sec(tags::META, ElemType::U8, self.meta.as_bytes()));
        let mut out = vec![0u8; encoded_len(&sections)];
        let n = write(KIND, VERSION, &sections, &mut out).map_err(|e| anyhow::anyhow!("{e}"))?;
        out.truncate(n);
        ForestView::parse(&out).context("the encoded forest does not validate")?;
        Ok(out)
    }

    /// Read a version 1 `JFOR` file (SPLT/THRS/CHLD nodes, i16 votes, baseline always stored).
    pub fn from_v1(bytes: &[u8]) -> Result<Self> {
        let f = ModelFile::parse(bytes, KIND, 1).context("not a version 1 joint forest")?;
        let head = f.typed::<u32>(tags::HEAD, Some(4))?;
        let (trees, nodes, leaves, samples) = (
            head.at(0) as usize,
            head.at(1) as usize,
            head.at(2) as usize,
            head.at(3),
        );
        ensure!(
            (1..=MAX_TREES).contains(&trees),
            "tree count {trees} out of range"
        );
        let tree = f.typed::<u32>(tags::TREE, Some(trees))?;
        let split = f.typed::<i8>(tags::SPLT, Some(nodes * 4))?;
        let thrs = f.typed::<i16>(tags::THRS, Some(nodes))?;
        let chld = f.typed::<u32>(tags::CHLD, Some(nodes))?;
        let rvot = f.typed::<i16>(tags::RVOT, Some(leaves * P * 3))?;
        let rcon = f.typed::<u8>(tags::RCON, Some(leaves * P))?;
        let bvot = f.typed::<i16>(tags::BVOT, Some(leaves * P * MODES * 3))?;
        let bwgt = f.typed::<u8>(tags::BWGT, Some(leaves * P * MODES))?;
        let parm = f.typed::<f32>(tags::PARM, Some(P * 3))?;
        let meta = match f.section(tags::META) {
            Ok(s) => String::from_utf8(s.bytes.to_vec()).context("META is not UTF-8")?,
            Err(_) => String::new(),
        };
        let nodes = (0..nodes)
            .map(|g| {
                let c = chld.at(g);
                if c & LEAF_BIT != 0 {
                    (None, c & !LEAF_BIT)
                } else {
                    let test = SplitTest {
                        u: [split.at(g * 4), split.at(g * 4 + 1)],
                        v: [split.at(g * 4 + 2), split.at(g * 4 + 3)],
                        threshold_mm: thrs.at(g),
                    };
                    (Some(test), c)
                }
            })
            .collect();
        let q = Quantised {
            samples,
            tree_start: tree.iter().collect(),
            nodes,
            refined_mm: rvot.iter().map(i32::from).collect(),
            rcon: rcon.iter().collect(),
            baseline: Some((bvot.iter().collect(), bwgt.iter().collect())),
            parm: parm.iter().collect(),
            meta,
        };
        Ok(q)
    }
}

/// Check that `new` answers every node, refined and (with `baseline`) baseline query of `old` with the same bits;
/// returns the number of leaf votes compared.
pub fn check_same_inference(
    old: &dyn ForestModel,
    new: &ForestView<'_>,
    nodes_per_tree: &[u32],
    baseline: bool,
) -> Result<usize> {
    ensure!(old.tree_count() == new.tree_count(), "tree counts differ");
    for (t, &n) in nodes_per_tree.iter().enumerate() {
        for i in 0..n {
            let (a, b) = (old.node(t, i), new.node(t, i));
            ensure!(a == b, "tree {t} node {i}: {a:?} became {b:?}");
        }
    }
    let mut votes = 0;
    for l in 0..new.leaf_count() as u32 {
        for p in 0..P {
            let (a, b) = (old.refined(l, p), new.refined(l, p));
            ensure!(
                a.offset.map(f32::to_bits) == b.offset.map(f32::to_bits)
                    && a.weight.to_bits() == b.weight.to_bits(),
                "leaf {l} point {p}: refined vote {a:?} became {b:?}"
            );
            votes += 1;
            if baseline {
                for m in 0..MODES {
                    let (a, b) = (old.baseline(l, p, m), new.baseline(l, p, m));
                    ensure!(a == b, "leaf {l} point {p} mode {m}: baseline {a:?} became {b:?}");
                }
            }
        }
    }
    Ok(votes)
}

/// A version 1 file seen through [`ForestModel`] (for [`check_same_inference`]).
pub struct V1Forest<'a> {
    q: &'a Quantised,
}

impl<'a> V1Forest<'a> {
    /// View `q` (as read by [`Quantised::from_v1`]) the way the version 1 reader did.
    pub fn new(q: &'a Quantised) -> Self {
        V1Forest { q }
    }
}

impl ForestModel for V1Forest<'_> {
    fn tree_count(&self) -> usize {
        self.q.tree_start.len()
    }

    fn node(&self, tree: usize, index: u32) -> Node {
        match self.q.nodes[(self.q.tree_start[tree] + index) as usize] {
            (None, l) => Node::Leaf(l),
            (Some(test), left) => Node::Split { test, left },
        }
    }

    fn refined(&self, leaf: u32, point: usize) -> supine_core::forest::model::LeafVote {
        let i = leaf as usize * P + point;
        supine_core::forest::model::LeafVote {
            offset: [0, 1, 2].map(|a| self.q.refined_mm[i * 3 + a] as i16 as f32 * 1e-3),
            weight: supine_core::forest::model::confidence_of(self.q.rcon[i]),
        }
    }

    fn baseline(&self, leaf: u32, point: usize, mode: usize) -> supine_core::forest::model::LeafVote {
        let i = (leaf as usize * P + point) * MODES + mode;
        match &self.q.baseline {
            Some((v, w)) => supine_core::forest::model::LeafVote {
                offset: [0, 1, 2].map(|a| v[i * 3 + a] as f32 * 1e-3),
                weight: w[i] as f32 * (1.0 / 255.0),
            },
            None => Default::default(),
        }
    }

    fn params(&self, point: usize) -> supine_core::forest::model::PointParams {
        supine_core::forest::model::PointParams {
            refined_bandwidth_m: self.q.parm[point * 3],
            baseline_bandwidth_m: self.q.parm[point * 3 + 1],
            vote_length_m: self.q.parm[point * 3 + 2],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shift_is_the_smallest_that_fits() {
        assert_eq!(vote_shift(&[0, 2047, -2047]).unwrap(), 0);
        assert_eq!(vote_shift(&[2048]).unwrap(), 1);
        assert_eq!(vote_shift(&[-4094]).unwrap(), 1);
        assert_eq!(vote_shift(&[4095]).unwrap(), 2);
        assert!(vote_shift(&[40_000]).is_err());
        assert_eq!(
            (scaled(3, 1), scaled(-3, 1), scaled(2, 1), scaled(-1, 1)),
            (2, -2, 1, -1)
        );
    }
}
