//! The float leaves beside a quantised forest (`FILE.float`, kind `JFLT`): the trainer's f32 refined weights,
//! confidences and baseline modes, tied to one `JFOR` file by its CRC. `eval joints` uses it to report the
//! `baseline` and `refined` rows in float, against which `quantised` (the `JFOR` file alone, as the head
//! computer runs it) is compared. Host only; never read by core.

use super::float::FloatForest;
use anyhow::{Context, Result, ensure};
use supine_core::forest::MODES;
use supine_core::forest::model::{ForestModel, ForestView, LeafVote, Node, PointParams};
use supine_core::model_file::{ElemType, ModelFile, SectionData, encoded_len, write};
use supine_core::salient::SalientPoint;

/// Kind tag of the float sidecar.
pub const KIND: [u8; 4] = *b"JFLT";
/// Its format version.
pub const VERSION: u16 = 1;
const P: usize = SalientPoint::COUNT;
/// f32 per leaf: refined offsets (P*3), confidences (P), baseline offsets and weights (P*MODES*4).
const PER_LEAF: usize = P * 3 + P + P * MODES * 4;

/// Encode the float leaves of `forest`, tied to the `JFOR` file whose CRC is `jfor_crc`.
pub fn to_bytes(forest: &FloatForest, jfor_crc: u32) -> Result<Vec<u8>> {
    let mut v: Vec<f32> = Vec::with_capacity(forest.leaf_count() * PER_LEAF);
    for l in 0..forest.leaf_count() {
        for p in 0..P {
            v.extend(forest.refined[l][p]);
        }
        for p in 0..P {
            v.push(forest.confidence(l, p));
        }
        for p in 0..P {
            for m in 0..MODES {
                let b = forest.baseline(l as u32, p, m);
                v.extend(b.offset);
                v.push(b.weight);
            }
        }
    }
    let leaves: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    let link = jfor_crc.to_le_bytes();
    let sections = [
        SectionData {
            tag: *b"LINK",
            elem: ElemType::U32,
            bytes: &link,
        },
        SectionData {
            tag: *b"LEAF",
            elem: ElemType::F32,
            bytes: &leaves,
        },
    ];
    let mut out = vec![0u8; encoded_len(&sections)];
    let n = write(KIND, VERSION, &sections, &mut out).map_err(|e| anyhow::anyhow!("{e}"))?;
    out.truncate(n);
    Ok(out)
}

/// A quantised forest's trees with the trainer's float leaves.
pub struct FloatLeaves<'a> {
    view: ForestView<'a>,
    leaves: Vec<f32>,
}

impl<'a> FloatLeaves<'a> {
    /// Parse the sidecar `bytes` for `view`; fails when it belongs to another `JFOR` file.
    pub fn parse(view: ForestView<'a>, bytes: &[u8]) -> Result<Self> {
        let f = ModelFile::parse(bytes, KIND, VERSION).context("float sidecar")?;
        let link = f.typed::<u32>(*b"LINK", Some(1))?.at(0);
        ensure!(
            link == view.file().crc(),
            "float sidecar belongs to another forest file (CRC {link:#010x}, forest {:#010x})",
            view.file().crc()
        );
        let leaves: Vec<f32> = f
            .typed::<f32>(*b"LEAF", Some(view.leaf_count() * PER_LEAF))?
            .iter()
            .collect();
        ensure!(
            leaves.iter().all(|x| x.is_finite()),
            "float sidecar holds non-finite values"
        );
        Ok(FloatLeaves { view, leaves })
    }
}

impl ForestModel for FloatLeaves<'_> {
    fn tree_count(&self) -> usize {
        self.view.tree_count()
    }
    fn node(&self, tree: usize, index: u32) -> Node {
        self.view.node(tree, index)
    }
    fn record(&self, tree: usize, index: u32) -> u64 {
        self.view.record(tree, index)
    }
    fn child_records(&self, tree: usize, left: u32) -> [u64; 2] {
        self.view.child_records(tree, left)
    }
    fn refined(&self, leaf: u32, point: usize) -> LeafVote {
        let b = leaf as usize * PER_LEAF;
        let o = &self.leaves[b + point * 3..b + point * 3 + 3];
        LeafVote {
            offset: [o[0], o[1], o[2]],
            weight: self.leaves[b + P * 3 + point],
        }
    }
    fn baseline(&self, leaf: u32, point: usize, mode: usize) -> LeafVote {
        let b = leaf as usize * PER_LEAF + P * 4 + (point * MODES + mode) * 4;
        let o = &self.leaves[b..b + 4];
        LeafVote {
            offset: [o[0], o[1], o[2]],
            weight: o[3],
        }
    }
    fn params(&self, point: usize) -> PointParams {
        self.view.params(point)
    }
}
