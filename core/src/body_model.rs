//! The statistical body model (paper §3.2, §3.4): a borrowed, validated view of a `BODY` model file.
//!
//! The model is linear in its shape coefficients `s` (Eq. 7: `M + V s`). It stores, for every *row* — the skin
//! vertices, then the rig joints, then the six salient points — a mean position `M` (f32, metres) and `K` basis
//! vectors `V` (i16 with one dequantisation scale per component). Joints and salient points are linear in the
//! vertices, so they are rows of the same model: their regressors are folded into `M` and `V`. Coefficients are raw
//! PCA coordinates in metres along orthonormal basis directions; [`BodyModelView::sigma`] gives each component's
//! standard deviation over the training population (divide by it to get the normalised values of paper §4.2).
//!
//! The file also carries what posing needs on the host (bones, rolls, skin weights, triangles, body-part labels) and
//! the torso ICP subset (front of chest, belly, pelvis and shoulders, fixed on the mean body).
//!
//! Body frame: metres, z up, the body faces -y, x is the body's left (the MakeHuman/Blender frame).
//!
//! Sections of kind `BODY`, format version [`FORMAT_VERSION`] (element type, count):
//! ```text
//! HEAD u32  8      n_vertices, n_joints, n_components, n_bones, n_subset, n_triangles, n_subset_triangles, max_infl
//! MEAN f32  3·R    mean position of every row, R = n_vertices + n_joints + 6
//! BSCL f32  K      dequantisation scale of each component
//! BASI i16  3·R·K  basis, row-major: element (row r, coordinate c, component k) at (3r + c)·K + k
//! SIGM f32  K      standard deviation of each component's coefficient over the training population
//! TSUB u16  n_subset                torso ICP subset (vertex indices, ascending)
//! TSTR u16  3·n_subset_triangles    triangles of the skin lying wholly in the subset (indices into TSUB)
//! TRIS u16  3·n_triangles           skin triangles (counter-clockwise seen from outside)
//! BPAR u16  n_bones                 parent bone, 0xFFFF for the root; parents precede children
//! BJNT u16  2·n_bones               head joint and tail joint of each bone
//! BROL f32  n_bones                 Blender bone roll (radians)
//! SKNB u8   n_vertices·max_infl     skinning bone of each influence (0 with weight 0 for unused slots)
//! SKNW u16  n_vertices·max_infl     skinning weight · 65535 (each vertex sums to 65535 ± max_infl)
//! VPRT u8   n_vertices              BodyPart of each vertex
//! NAME u8   text                    bone names then joint names, one per line ('\n'), UTF-8
//! ```
//!
//! Per-frame cost: shaping the torso subset is `3·n_subset·K` multiply-adds (about 75 k for 1250 vertices and
//! K = 20, some 30-60 µs on a Cortex-A72 class core); salient points cost `18·K`. Nothing allocates.

use crate::error::BufferLenError;
use crate::model_file::{LeSlice, ModelFile, ModelFileError, Tag};
use crate::salient::SalientPoint;
use crate::wire::BodyRegion;

/// Kind tag of body model files.
pub const KIND: Tag = *b"BODY";
/// Format version of the `BODY` kind that this build reads.
pub const FORMAT_VERSION: u16 = 1;
/// Shape components of the body model (the paper's 20): the wire's body-shape message carries exactly this many,
/// and a body model file may have at most this many (a smaller model leaves the rest at zero).
pub const SHAPE_COMPONENTS: usize = 20;
/// Bone-parent value of the root bone.
pub const NO_PARENT: u16 = 0xFFFF;

/// Coarse body part of a skin vertex (from its dominant skinning bone); used for ground-truth part labels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[repr(u8)]
pub enum BodyPart {
    /// Head (skull, face).
    Head = 0,
    /// Neck.
    Neck = 1,
    /// Chest and upper back (upper spine, clavicles, shoulder girdle).
    Chest = 2,
    /// Abdomen and lower back (lower spine).
    Abdomen = 3,
    /// Pelvis (root and pelvis bones).
    Pelvis = 4,
    /// Left upper arm.
    LeftUpperArm = 5,
    /// Right upper arm.
    RightUpperArm = 6,
    /// Left forearm.
    LeftForearm = 7,
    /// Right forearm.
    RightForearm = 8,
    /// Left hand.
    LeftHand = 9,
    /// Right hand.
    RightHand = 10,
    /// Left thigh.
    LeftThigh = 11,
    /// Right thigh.
    RightThigh = 12,
    /// Left shank.
    LeftShank = 13,
    /// Right shank.
    RightShank = 14,
    /// Left foot.
    LeftFoot = 15,
    /// Right foot.
    RightFoot = 16,
}

impl BodyPart {
    /// Number of parts.
    pub const COUNT: usize = 17;

    /// Decode a stored id.
    pub const fn from_u8(id: u8) -> Option<Self> {
        use BodyPart::*;
        Some(match id {
            0 => Head,
            1 => Neck,
            2 => Chest,
            3 => Abdomen,
            4 => Pelvis,
            5 => LeftUpperArm,
            6 => RightUpperArm,
            7 => LeftForearm,
            8 => RightForearm,
            9 => LeftHand,
            10 => RightHand,
            11 => LeftThigh,
            12 => RightThigh,
            13 => LeftShank,
            14 => RightShank,
            15 => LeftFoot,
            16 => RightFoot,
            _ => return None,
        })
    }

    /// Whether the part is an upper arm, a forearm or a hand.
    pub const fn is_arm(self) -> bool {
        use BodyPart::*;
        matches!(
            self,
            LeftUpperArm | RightUpperArm | LeftForearm | RightForearm | LeftHand | RightHand
        )
    }

    /// The snake_case name (`left_upper_arm`, ...).
    pub const fn name(self) -> &'static str {
        use BodyPart::*;
        match self {
            Head => "head",
            Neck => "neck",
            Chest => "chest",
            Abdomen => "abdomen",
            Pelvis => "pelvis",
            LeftUpperArm => "left_upper_arm",
            RightUpperArm => "right_upper_arm",
            LeftForearm => "left_forearm",
            RightForearm => "right_forearm",
            LeftHand => "left_hand",
            RightHand => "right_hand",
            LeftThigh => "left_thigh",
            RightThigh => "right_thigh",
            LeftShank => "left_shank",
            RightShank => "right_shank",
            LeftFoot => "left_foot",
            RightFoot => "right_foot",
        }
    }
}

impl BodyPart {
    /// The wire's [`BodyRegion`] of a point on this part. The probe report names upper-body regions only: the upper
    /// arms count as their shoulder, and forearms, hands and legs as [`BodyRegion::OffBody`]. The flanks are a
    /// lateral band of the chest and abdomen: see [`BodyPart::region_at`].
    pub const fn region(self) -> BodyRegion {
        use BodyPart::*;
        match self {
            Head => BodyRegion::Head,
            Neck => BodyRegion::Neck,
            Chest => BodyRegion::Chest,
            Abdomen => BodyRegion::Abdomen,
            Pelvis => BodyRegion::Pelvis,
            LeftUpperArm => BodyRegion::LeftShoulder,
            RightUpperArm => BodyRegion::RightShoulder,
            LeftForearm | RightForearm | LeftHand | RightHand | LeftThigh | RightThigh | LeftShank
            | RightShank | LeftFoot | RightFoot => BodyRegion::OffBody,
        }
    }

    /// The region of a point on this part at `lateral`, its signed distance from the torso midline as a fraction of
    /// the torso half-width (+1 at the patient's left side): chest and abdomen points beyond [`FLANK_FRACTION`]
    /// are the left or right flank; every other part keeps [`BodyPart::region`].
    pub fn region_at(self, lateral: f32) -> BodyRegion {
        match self {
            BodyPart::Chest | BodyPart::Abdomen if lateral >= FLANK_FRACTION => BodyRegion::LeftFlank,
            BodyPart::Chest | BodyPart::Abdomen if lateral <= -FLANK_FRACTION => BodyRegion::RightFlank,
            _ => self.region(),
        }
    }
}

/// Where the flanks begin, as a fraction of the torso half-width from the midline (the side of the torso a frontal
/// probe cannot reach squarely).
pub const FLANK_FRACTION: f32 = 0.7;

/// Header counts of a body model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BodyModelCounts {
    /// Skin vertices.
    pub vertices: usize,
    /// Rig joints (bone heads and tails).
    pub joints: usize,
    /// Shape components K.
    pub components: usize,
    /// Bones of the posing rig.
    pub bones: usize,
    /// Vertices in the torso ICP subset.
    pub subset: usize,
    /// Skin triangles.
    pub triangles: usize,
    /// Triangles wholly inside the torso subset.
    pub subset_triangles: usize,
    /// Skinning influences stored per vertex.
    pub max_influences: usize,
}

impl BodyModelCounts {
    /// Rows of the linear model: vertices, then joints, then the salient points.
    pub const fn rows(&self) -> usize {
        self.vertices + self.joints + SalientPoint::COUNT
    }
}

/// A validated, borrowed body model. Cheap to copy; every accessor is allocation-free.
#[derive(Clone, Copy, Debug)]
pub struct BodyModelView<'a> {
    counts: BodyModelCounts,
    file: ModelFile<'a>,
    mean: LeSlice<'a, f32>,
    scale: LeSlice<'a, f32>,
    basis: LeSlice<'a, i16>,
    sigma: LeSlice<'a, f32>,
    subset: LeSlice<'a, u16>,
    subset_tris: LeSlice<'a, u16>,
    tris: LeSlice<'a, u16>,
    parents: LeSlice<'a, u16>,
    bone_joints: LeSlice<'a, u16>,
    rolls: LeSlice<'a, f32>,
    skin_bones: LeSlice<'a, u8>,
    skin_weights: LeSlice<'a, u16>,
    parts: LeSlice<'a, u8>,
    names: &'a str,
}

fn invalid(tag: &[u8; 4], what: &'static str) -> ModelFileError {
    ModelFileError::InvalidData { tag: *tag, what }
}

fn all_finite(s: &LeSlice<'_, f32>) -> bool {
    s.iter().all(f32::is_finite)
}

impl<'a> BodyModelView<'a> {
    /// Validate `bytes` as a body model: the container checks, then every count, index, parent order, weight sum,
    /// part id, name and float (finite). After this, no accessor can index out of range.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, ModelFileError> {
        let file = ModelFile::parse(bytes, KIND, FORMAT_VERSION)?;
        let head = file.typed::<u32>(*b"HEAD", Some(8))?;
        let c = BodyModelCounts {
            vertices: head.at(0) as usize,
            joints: head.at(1) as usize,
            components: head.at(2) as usize,
            bones: head.at(3) as usize,
            subset: head.at(4) as usize,
            triangles: head.at(5) as usize,
            subset_triangles: head.at(6) as usize,
            max_influences: head.at(7) as usize,
        };
        // Bounds that keep every later product far from overflow and indices within u16/u8.
        if c.vertices == 0 || c.vertices > 65535 || c.joints > 4096 || c.bones > 255 || c.bones == 0 {
            return Err(invalid(b"HEAD", "vertex, joint or bone count out of range"));
        }
        if c.components == 0
            || c.components > SHAPE_COMPONENTS
            || c.max_influences == 0
            || c.max_influences > 16
        {
            return Err(invalid(b"HEAD", "component or influence count out of range"));
        }
        if c.subset > c.vertices || c.triangles > 4 * c.vertices || c.subset_triangles > c.triangles {
            return Err(invalid(b"HEAD", "subset or triangle count out of range"));
        }
        let rows = c.rows();
        let k = c.components;
        let mean = file.typed::<f32>(*b"MEAN", Some(3 * rows))?;
        let scale = file.typed::<f32>(*b"BSCL", Some(k))?;
        let basis = file.typed::<i16>(*b"BASI", Some(3 * rows * k))?;
        let sigma = file.typed::<f32>(*b"SIGM", Some(k))?;
        let subset = file.typed::<u16>(*b"TSUB", Some(c.subset))?;
        let subset_tris = file.typed::<u16>(*b"TSTR", Some(3 * c.subset_triangles))?;
        let tris = file.typed::<u16>(*b"TRIS", Some(3 * c.triangles))?;
        let parents = file.typed::<u16>(*b"BPAR", Some(c.bones))?;
        let bone_joints = file.typed::<u16>(*b"BJNT", Some(2 * c.bones))?;
        let rolls = file.typed::<f32>(*b"BROL", Some(c.bones))?;
        let skin_bones = file.typed::<u8>(*b"SKNB", Some(c.vertices * c.max_influences))?;
        let skin_weights = file.typed::<u16>(*b"SKNW", Some(c.vertices * c.max_influences))?;
        let parts = file.typed::<u8>(*b"VPRT", Some(c.vertices))?;
        let name_bytes = file.typed::<u8>(*b"NAME", None)?.as_bytes();

        if !all_finite(&mean) || !all_finite(&rolls) {
            return Err(invalid(b"MEAN", "non-finite value"));
        }
        if !scale.iter().all(|x| x.is_finite() && x >= 0.0)
            || !sigma.iter().all(|x| x.is_finite() && x >= 0.0)
        {
            return Err(invalid(
                b"BSCL",
                "scales and sigmas must be finite and non-negative",
            ));
        }
        let mut prev: Option<u16> = None;
        for v in subset.iter() {
            if v as usize >= c.vertices || prev.is_some_and(|p| p >= v) {
                return Err(invalid(
                    b"TSUB",
                    "subset indices must be ascending vertex indices",
                ));
            }
            prev = Some(v);
        }
        if subset_tris.iter().any(|i| i as usize >= c.subset) {
            return Err(invalid(b"TSTR", "triangle index outside the subset"));
        }
        if tris.iter().any(|i| i as usize >= c.vertices) {
            return Err(invalid(b"TRIS", "triangle index outside the vertices"));
        }
        for (b, p) in parents.iter().enumerate() {
            let root_ok = b == 0 && p == NO_PARENT;
            if !root_ok && (b == 0 || p as usize >= b) {
                return Err(invalid(
                    b"BPAR",
                    "bone 0 must be the only root and parents must precede children",
                ));
            }
        }
        if bone_joints.iter().any(|j| j as usize >= c.joints) {
            return Err(invalid(b"BJNT", "bone joint index out of range"));
        }
        if skin_bones.iter().any(|b| b as usize >= c.bones) {
            return Err(invalid(b"SKNB", "skinning bone index out of range"));
        }
        for v in 0..c.vertices {
            let sum: u32 = (0..c.max_influences)
                .map(|i| skin_weights.at(v * c.max_influences + i) as u32)
                .sum();
            if sum.abs_diff(65535) > c.max_influences as u32 {
                return Err(invalid(b"SKNW", "skinning weights of a vertex do not sum to one"));
            }
        }
        if parts.iter().any(|p| BodyPart::from_u8(p).is_none()) {
            return Err(invalid(b"VPRT", "unknown body part id"));
        }
        let names = core::str::from_utf8(name_bytes).map_err(|_| invalid(b"NAME", "names are not UTF-8"))?;
        if names.split('\n').count() != c.bones + c.joints {
            return Err(invalid(b"NAME", "expected one line per bone and per joint"));
        }
        Ok(Self {
            counts: c,
            file,
            mean,
            scale,
            basis,
            sigma,
            subset,
            subset_tris,
            tris,
            parents,
            bone_joints,
            rolls,
            skin_bones,
            skin_weights,
            parts,
            names,
        })
    }

    /// The header counts.
    pub fn counts(&self) -> BodyModelCounts {
        self.counts
    }

    /// Number of skin vertices.
    pub fn vertex_count(&self) -> usize {
        self.counts.vertices
    }

    /// Number of shape components K.
    pub fn component_count(&self) -> usize {
        self.counts.components
    }

    /// The validated container (size, CRC, sections).
    pub fn file(&self) -> &ModelFile<'a> {
        &self.file
    }

    /// Standard deviation of coefficient `k` over the training population (metres along a unit direction).
    pub fn sigma(&self, k: usize) -> f32 {
        self.sigma.get(k).unwrap_or(0.0)
    }

    /// Torso ICP subset: ascending skin-vertex indices.
    pub fn torso_subset(&self) -> LeSlice<'a, u16> {
        self.subset
    }

    /// Triangles of the torso subset, 3 indices each into [`Self::torso_subset`] (for sampling points on faces).
    pub fn torso_subset_triangles(&self) -> LeSlice<'a, u16> {
        self.subset_tris
    }

    /// Skin triangles, 3 vertex indices each, counter-clockwise seen from outside.
    pub fn triangles(&self) -> LeSlice<'a, u16> {
        self.tris
    }

    /// Mean position of model row `row` (vertex, joint or salient point).
    #[inline]
    pub fn mean_row(&self, row: usize) -> [f32; 3] {
        [
            self.mean.at(3 * row),
            self.mean.at(3 * row + 1),
            self.mean.at(3 * row + 2),
        ]
    }

    /// Dequantised basis element: coordinate `c` of row `row` in component `k`.
    #[inline]
    pub fn basis(&self, row: usize, c: usize, k: usize) -> f32 {
        self.basis.at((3 * row + c) * self.counts.components + k) as f32 * self.scale.at(k)
    }

    /// Position of row `row` for coefficients `s` (`M + V s`; coefficients past `s.len()` are zero, extra ones are
    /// ignored).
    #[inline]
    pub fn shape_row(&self, row: usize, s: &[f32]) -> [f32; 3] {
        let mut scale = [0.0f32; SHAPE_COMPONENTS];
        let n = self.scales(s, &mut scale);
        self.shape_row_scaled(row, &s[..n], &scale[..n])
    }

    /// The dequantisation scales of the first `min(s.len(), K)` components into `out`; returns that count.
    #[inline]
    fn scales(&self, s: &[f32], out: &mut [f32; SHAPE_COMPONENTS]) -> usize {
        let n = s.len().min(self.counts.components);
        for (j, o) in out.iter_mut().enumerate().take(n) {
            *o = self.scale.at(j);
        }
        n
    }

    /// [`Self::shape_row`] with the components' scales read once (`s` and `scale` of equal length, at most K): the
    /// same products in the same order, so the same bits; the row's basis is read as one slice, without a bounds
    /// check per element.
    #[inline(always)]
    fn shape_row_scaled(&self, row: usize, s: &[f32], scale: &[f32]) -> [f32; 3] {
        self.shape_rows_scaled([row], s, scale)[0]
    }

    /// [`Self::shape_row_scaled`] for `R` rows at once. Each coordinate's sum is a chain of dependent adds; the
    /// `3 R` chains of the rows run side by side, which is where the shaping loops spent their time (each chain's
    /// order, and so its bits, is unchanged).
    #[inline(always)]
    fn shape_rows_scaled<const R: usize>(&self, rows: [usize; R], s: &[f32], scale: &[f32]) -> [[f32; 3]; R] {
        let k = self.counts.components;
        let n = s.len().min(scale.len());
        let bytes = self.basis.as_bytes();
        let basis = rows.map(|row| {
            [0, 1, 2].map(|c| {
                let base = 2 * (3 * row + c) * k;
                &bytes[base..base + 2 * n]
            })
        });
        let mut acc = [[0.0f32; 3]; R];
        for (j, (sc, sj)) in scale.iter().zip(s).enumerate() {
            for (a, b) in acc.iter_mut().zip(&basis) {
                for (ac, bc) in a.iter_mut().zip(b) {
                    *ac += i16::from_le_bytes([bc[2 * j], bc[2 * j + 1]]) as f32 * sc * sj;
                }
            }
        }
        let mut out = rows.map(|row| self.mean_row(row));
        for (p, a) in out.iter_mut().zip(&acc) {
            for (pc, ac) in p.iter_mut().zip(a) {
                *pc += ac;
            }
        }
        out
    }

    /// `out[i]` = row `row(i)` shaped for `s`, four rows at a time.
    fn shape_rows_into(&self, row: impl Fn(usize) -> usize, s: &[f32], out: &mut [[f32; 3]]) {
        let mut scale = [0.0f32; SHAPE_COMPONENTS];
        let n = self.scales(s, &mut scale);
        let (s, scale) = (&s[..n], &scale[..n]);
        let done = out.len() - out.len() % 4;
        let mut chunks = out.chunks_exact_mut(4);
        for (c, o) in (&mut chunks).enumerate() {
            o.copy_from_slice(&self.shape_rows_scaled([0, 1, 2, 3].map(|d| row(4 * c + d)), s, scale));
        }
        for (i, o) in chunks.into_remainder().iter_mut().enumerate() {
            *o = self.shape_row_scaled(row(done + i), s, scale);
        }
    }

    /// Skin vertex `v` for coefficients `s`.
    pub fn shape_vertex(&self, v: usize, s: &[f32]) -> [f32; 3] {
        self.shape_row(v, s)
    }

    /// The K basis vectors of row `row` (`out[k]` = dequantised `V` rows for component k); returns how many were
    /// written (`min(out.len(), K)`). This is the Jacobian of the row's position w.r.t. `s`, as Eq. 7 needs.
    pub fn row_basis(&self, row: usize, out: &mut [[f32; 3]]) -> usize {
        let k = self.counts.components;
        let n = out.len().min(k);
        let bytes = self.basis.as_bytes();
        let base = 2 * 3 * row * k;
        // The row's three coordinates, each K components long: one slice each, no bounds check per element.
        let [x, y, z] = [0, 1, 2].map(|c| &bytes[base + 2 * c * k..base + 2 * (c * k + n)]);
        for (q, o) in out.iter_mut().enumerate().take(n) {
            let sc = self.scale.at(q);
            let at = |b: &[u8]| i16::from_le_bytes([b[2 * q], b[2 * q + 1]]) as f32 * sc;
            *o = [at(x), at(y), at(z)];
        }
        n
    }

    /// Shape the torso subset for coefficients `s` into `out` (one point per subset vertex, in subset order).
    pub fn shape_torso_subset(&self, s: &[f32], out: &mut [[f32; 3]]) -> Result<(), BufferLenError> {
        if out.len() != self.counts.subset {
            return Err(BufferLenError {
                expected: self.counts.subset,
                found: out.len(),
            });
        }
        self.shape_rows_into(|i| usize::from(self.subset.at(i)), s, out);
        Ok(())
    }

    /// Shape every skin vertex for coefficients `s` into `out`.
    pub fn shape_vertices(&self, s: &[f32], out: &mut [[f32; 3]]) -> Result<(), BufferLenError> {
        if out.len() != self.counts.vertices {
            return Err(BufferLenError {
                expected: self.counts.vertices,
                found: out.len(),
            });
        }
        self.shape_rows_into(|v| v, s, out);
        Ok(())
    }

    /// Number of rig joints.
    pub fn joint_count(&self) -> usize {
        self.counts.joints
    }

    /// Rig joint `j` for coefficients `s`.
    pub fn joint(&self, j: usize, s: &[f32]) -> [f32; 3] {
        self.shape_row(self.counts.vertices + j, s)
    }

    /// All rig joints for coefficients `s` into `out`.
    pub fn joint_positions(&self, s: &[f32], out: &mut [[f32; 3]]) -> Result<(), BufferLenError> {
        if out.len() != self.counts.joints {
            return Err(BufferLenError {
                expected: self.counts.joints,
                found: out.len(),
            });
        }
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.joint(j, s);
        }
        Ok(())
    }

    /// Salient point `p` for coefficients `s` (rest pose, body frame).
    pub fn salient_point(&self, p: SalientPoint, s: &[f32]) -> [f32; 3] {
        self.shape_row(self.counts.vertices + self.counts.joints + p as usize, s)
    }

    /// The six salient points for coefficients `s` (rest pose, body frame), in [`SalientPoint::ALL`] order.
    pub fn salient_points(&self, s: &[f32]) -> [[f32; 3]; SalientPoint::COUNT] {
        SalientPoint::ALL.map(|p| self.salient_point(p, s))
    }

    /// Number of bones of the posing rig.
    pub fn bone_count(&self) -> usize {
        self.counts.bones
    }

    /// Parent of bone `b` (`None` for the root, bone 0).
    pub fn bone_parent(&self, b: usize) -> Option<usize> {
        let p = self.parents.at(b);
        if p == NO_PARENT { None } else { Some(p as usize) }
    }

    /// Head and tail joint indices of bone `b`.
    pub fn bone_joints(&self, b: usize) -> (usize, usize) {
        (
            self.bone_joints.at(2 * b) as usize,
            self.bone_joints.at(2 * b + 1) as usize,
        )
    }

    /// Blender roll of bone `b` (radians).
    pub fn bone_roll(&self, b: usize) -> f32 {
        self.rolls.at(b)
    }

    /// Skinning influences stored per vertex.
    pub fn max_influences(&self) -> usize {
        self.counts.max_influences
    }

    /// Influence `i` of vertex `v` as (bone, weight in 0..=1); unused slots have weight 0.
    pub fn skin_influence(&self, v: usize, i: usize) -> (usize, f32) {
        let at = v * self.counts.max_influences + i;
        (
            self.skin_bones.at(at) as usize,
            self.skin_weights.at(at) as f32 / 65535.0,
        )
    }

    /// Body part of vertex `v`.
    pub fn part_of_vertex(&self, v: usize) -> BodyPart {
        // Validated at parse time, so the fallback is unreachable; it avoids a panic path.
        BodyPart::from_u8(self.parts.at(v)).unwrap_or(BodyPart::Chest)
    }

    /// Name of bone `b` (Blender name of the MakeHuman default rig, e.g. `upperarm01.L`).
    pub fn bone_name(&self, b: usize) -> &'a str {
        self.names.split('\n').nth(b).unwrap_or("")
    }

    /// Name of joint `j` (a joint cube such as `joint-l-shoulder`, or `v<idx>[+<idx>...]` for vertex means).
    pub fn joint_name(&self, j: usize) -> &'a str {
        self.names.split('\n').nth(self.counts.bones + j).unwrap_or("")
    }

    /// Index of the bone called `name`.
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.names
            .split('\n')
            .take(self.counts.bones)
            .position(|n| n == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixture::{self, COMPONENTS, ROWS, TINY_BODY_LEN};

    fn tiny() -> ([u8; TINY_BODY_LEN], usize) {
        let mut buf = [0u8; TINY_BODY_LEN];
        let n = fixture::tiny_body_model(&mut buf).unwrap();
        (buf, n)
    }

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        (0..3).all(|c| (a[c] - b[c]).abs() < 1e-6)
    }

    #[test]
    fn the_view_reads_what_the_fixture_wrote() {
        let (buf, n) = tiny();
        let v = BodyModelView::parse(&buf[..n]).unwrap();
        let c = v.counts();
        assert_eq!(
            (c.vertices, c.joints, c.components, c.bones),
            (4, 2, COMPONENTS, 2)
        );
        assert_eq!(c.rows(), ROWS);
        let s = [0.7f32, -1.3];
        for vtx in 0..c.vertices {
            assert!(
                close(v.shape_vertex(vtx, &s), fixture::shaped(vtx, &s)),
                "vertex {vtx}"
            );
            assert_eq!(v.part_of_vertex(vtx), fixture::PARTS[vtx]);
        }
        for j in 0..c.joints {
            assert!(
                close(v.joint(j, &s), fixture::shaped(c.vertices + j, &s)),
                "joint {j}"
            );
        }
        for p in SalientPoint::ALL {
            let row = c.vertices + c.joints + p.index();
            assert!(
                close(v.salient_point(p, &s), fixture::shaped(row, &s)),
                "{}",
                p.name()
            );
        }
        let mut subset = [[0.0; 3]; 3];
        v.shape_torso_subset(&s, &mut subset).unwrap();
        for (i, &vtx) in fixture::SUBSET.iter().enumerate() {
            assert!(close(subset[i], fixture::shaped(vtx as usize, &s)));
        }
        assert_eq!(
            v.shape_torso_subset(&s, &mut subset[..2]),
            Err(BufferLenError {
                expected: 3,
                found: 2
            })
        );
        assert_eq!(v.bone_parent(0), None);
        assert_eq!(v.bone_parent(1), Some(0));
        assert_eq!(v.bone_name(1), "spine");
        assert_eq!(v.joint_name(1), "j-neck");
        assert_eq!(v.bone_index("spine"), Some(1));
        assert_eq!(v.skin_influence(1, 0).0, 0);
        assert!((v.skin_influence(1, 0).1 - 0.5).abs() < 1e-4);
        assert_eq!(v.sigma(1), fixture::SIGMA[1]);
    }

    #[test]
    fn the_shaping_loops_give_the_bits_of_the_element_formula() {
        // shape_row, the subset and row_basis read each row as a slice with the scales read once: the same
        // products, summed in the same order, as M + sum_j basis(row, c, j) s_j (the fits' answers rest on it).
        let (buf, n) = tiny();
        let v = BodyModelView::parse(&buf[..n]).unwrap();
        let c = v.counts();
        let bits = |p: [f32; 3]| p.map(f32::to_bits);
        for s in [&[0.7f32, -1.3][..], &[0.7], &[0.7, -1.3, 5.0], &[]] {
            for row in 0..c.rows() {
                let mut want = v.mean_row(row);
                for (axis, w) in want.iter_mut().enumerate() {
                    let mut acc = 0.0f32;
                    for (j, sj) in s.iter().enumerate().take(c.components) {
                        acc += v.basis(row, axis, j) * sj;
                    }
                    *w += acc;
                }
                assert_eq!(
                    bits(v.shape_row(row, s)),
                    bits(want),
                    "row {row}, {} coefficients",
                    s.len()
                );
            }
            let mut subset = [[0.0; 3]; 3];
            v.shape_torso_subset(s, &mut subset).unwrap();
            for (i, &vtx) in fixture::SUBSET.iter().enumerate() {
                assert_eq!(bits(subset[i]), bits(v.shape_row(vtx as usize, s)));
            }
            // Four vertices: the four-row path (the subset's three take the one-row path).
            let mut all = [[0.0; 3]; 4];
            v.shape_vertices(s, &mut all).unwrap();
            for (vtx, p) in all.iter().enumerate() {
                assert_eq!(bits(*p), bits(v.shape_row(vtx, s)));
            }
        }
        let mut basis = [[f32::NAN; 3]; COMPONENTS + 1];
        for row in 0..c.rows() {
            assert_eq!(v.row_basis(row, &mut basis), COMPONENTS);
            for (k, b) in basis.iter().take(COMPONENTS).enumerate() {
                assert_eq!(
                    bits(*b),
                    bits([0, 1, 2].map(|axis| v.basis(row, axis, k))),
                    "row {row}"
                );
            }
            assert!(basis[COMPONENTS][0].is_nan(), "past K nothing is written");
            assert_eq!(v.row_basis(row, &mut basis[..1]), 1);
        }
    }

    #[test]
    fn every_damaged_byte_is_an_error_not_a_panic() {
        let (buf, n) = tiny();
        // Flipping any byte breaks the CRC (or, in the CRC field itself, disagrees with it): always an error.
        for at in 0..n {
            let mut bad = buf;
            bad[at] ^= 0x5A;
            assert!(
                BodyModelView::parse(&bad[..n]).is_err(),
                "flip at byte {at} accepted"
            );
        }
        for len in 0..n {
            assert!(
                BodyModelView::parse(&buf[..len]).is_err(),
                "truncated to {len} accepted"
            );
        }
        let mut other_kind = [0u8; TINY_BODY_LEN];
        let m = crate::model_file::write(*b"FRST", 1, &[], &mut other_kind).unwrap();
        assert!(matches!(
            BodyModelView::parse(&other_kind[..m]),
            Err(ModelFileError::WrongKind { .. })
        ));
    }

    #[test]
    fn every_part_has_a_region_and_the_flanks_are_lateral() {
        for id in 0..BodyPart::COUNT as u8 {
            let part = BodyPart::from_u8(id).unwrap();
            assert_eq!(part as u8, id);
            assert_eq!(part.region_at(0.0), part.region());
        }
        assert_eq!(BodyPart::from_u8(BodyPart::COUNT as u8), None);
        assert_eq!(BodyPart::LeftUpperArm.region(), BodyRegion::LeftShoulder);
        assert_eq!(BodyPart::LeftThigh.region(), BodyRegion::OffBody);
        assert_eq!(BodyPart::Abdomen.region_at(0.9), BodyRegion::LeftFlank);
        assert_eq!(BodyPart::Chest.region_at(-0.8), BodyRegion::RightFlank);
        assert_eq!(BodyPart::Pelvis.region_at(0.9), BodyRegion::Pelvis);
    }
}
