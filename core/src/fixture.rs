//! Fixture model files for tests: a tiny but complete body model written with [`model_file::write`] into a caller
//! buffer, with its expected values, so core tests its own views and the cross-crate tests (`supine-tests`, feature
//! `fixtures`) load the same bytes. Not compiled into the product (only under `cfg(test)` or the `fixtures`
//! feature); nothing allocates.

use crate::body_model::{self, BodyPart};
use crate::model_file::{self, ElemType, SectionData, WriteError};
use crate::salient::SalientPoint;

/// Skin vertices of the tiny body.
pub const VERTICES: usize = 4;
/// Rig joints of the tiny body.
pub const JOINTS: usize = 2;
/// Shape components of the tiny body.
pub const COMPONENTS: usize = 2;
/// Bones of the tiny body.
pub const BONES: usize = 2;
/// Rows of its linear model (vertices, joints, salient points).
pub const ROWS: usize = VERTICES + JOINTS + SalientPoint::COUNT;
/// Bytes the tiny body model file occupies (a buffer of this size always suffices).
pub const TINY_BODY_LEN: usize = 1024;

/// Dequantisation scale of each component.
pub const SCALE: [f32; COMPONENTS] = [0.001, 0.002];
/// Population standard deviation of each component.
pub const SIGMA: [f32; COMPONENTS] = [0.05, 0.02];
/// Part of each vertex.
pub const PARTS: [BodyPart; VERTICES] = [
    BodyPart::Chest,
    BodyPart::Abdomen,
    BodyPart::Pelvis,
    BodyPart::Head,
];
/// Torso subset (vertex indices).
pub const SUBSET: [u16; 3] = [0, 1, 2];

/// Mean position of `row`, coordinate `c` (metres).
pub const fn mean(row: usize, c: usize) -> f32 {
    match c {
        0 => row as f32 * 0.125,
        1 => row as f32 * -0.0625,
        _ => 1.0 + row as f32 * 0.25,
    }
}

/// Quantised basis element (row, coordinate, component): small distinct integers, some negative.
pub const fn basis_q(row: usize, c: usize, k: usize) -> i16 {
    ((row * 7 + c * 3 + k * 5) % 23) as i16 - 11
}

/// Shaped position of `row` for coefficients `s`, as the view must compute it: `M + V s`.
pub fn shaped(row: usize, s: &[f32; COMPONENTS]) -> [f32; 3] {
    let mut p = [0.0; 3];
    for (c, pc) in p.iter_mut().enumerate() {
        *pc = mean(row, c);
        for (k, sk) in s.iter().enumerate() {
            *pc += basis_q(row, c, k) as f32 * SCALE[k] * sk;
        }
    }
    p
}

fn put<const N: usize, const B: usize, T: Copy>(vals: [T; N], to_le: impl Fn(T, &mut [u8])) -> [u8; B] {
    let mut out = [0u8; B];
    let w = B / N;
    for (i, v) in vals.into_iter().enumerate() {
        to_le(v, &mut out[i * w..(i + 1) * w]);
    }
    out
}

fn f32s<const N: usize, const B: usize>(v: [f32; N]) -> [u8; B] {
    put(v, |x, o| o.copy_from_slice(&x.to_le_bytes()))
}

fn u16s<const N: usize, const B: usize>(v: [u16; N]) -> [u8; B] {
    put(v, |x, o| o.copy_from_slice(&x.to_le_bytes()))
}

/// Write the tiny body model into `out`; returns its length (at most [`TINY_BODY_LEN`]).
pub fn tiny_body_model(out: &mut [u8]) -> Result<usize, WriteError> {
    let head: [u8; 32] = put(
        [
            VERTICES as u32,
            JOINTS as u32,
            COMPONENTS as u32,
            BONES as u32,
            3,
            2,
            1,
            2,
        ],
        |x: u32, o| o.copy_from_slice(&x.to_le_bytes()),
    );
    let mut mean_v = [0.0f32; 3 * ROWS];
    let mut basis_v = [0i16; 3 * ROWS * COMPONENTS];
    for r in 0..ROWS {
        for c in 0..3 {
            mean_v[3 * r + c] = mean(r, c);
            for k in 0..COMPONENTS {
                basis_v[(3 * r + c) * COMPONENTS + k] = basis_q(r, c, k);
            }
        }
    }
    let mean_b: [u8; 4 * 3 * ROWS] = f32s(mean_v);
    let basis_b: [u8; 2 * 3 * ROWS * COMPONENTS] =
        put(basis_v, |x: i16, o| o.copy_from_slice(&x.to_le_bytes()));
    let scale_b: [u8; 8] = f32s(SCALE);
    let sigma_b: [u8; 8] = f32s(SIGMA);
    let subset_b: [u8; 6] = u16s(SUBSET);
    let subset_tris_b: [u8; 6] = u16s([0, 1, 2]);
    let tris_b: [u8; 12] = u16s([0, 1, 2, 0, 2, 3]);
    let parents_b: [u8; 4] = u16s([body_model::NO_PARENT, 0]);
    let bone_joints_b: [u8; 8] = u16s([0, 1, 1, 0]);
    let rolls_b: [u8; 8] = f32s([0.0, 0.25]);
    let skin_bones = [0u8, 1, 0, 1, 1, 0, 1, 0];
    let skin_weights_b: [u8; 16] = u16s([65535, 0, 32768, 32767, 65535, 0, 40000, 25535]);
    let parts = PARTS.map(|p| p as u8);
    let sections = [
        SectionData {
            tag: *b"HEAD",
            elem: ElemType::U32,
            bytes: &head,
        },
        SectionData {
            tag: *b"MEAN",
            elem: ElemType::F32,
            bytes: &mean_b,
        },
        SectionData {
            tag: *b"BSCL",
            elem: ElemType::F32,
            bytes: &scale_b,
        },
        SectionData {
            tag: *b"BASI",
            elem: ElemType::I16,
            bytes: &basis_b,
        },
        SectionData {
            tag: *b"SIGM",
            elem: ElemType::F32,
            bytes: &sigma_b,
        },
        SectionData {
            tag: *b"TSUB",
            elem: ElemType::U16,
            bytes: &subset_b,
        },
        SectionData {
            tag: *b"TSTR",
            elem: ElemType::U16,
            bytes: &subset_tris_b,
        },
        SectionData {
            tag: *b"TRIS",
            elem: ElemType::U16,
            bytes: &tris_b,
        },
        SectionData {
            tag: *b"BPAR",
            elem: ElemType::U16,
            bytes: &parents_b,
        },
        SectionData {
            tag: *b"BJNT",
            elem: ElemType::U16,
            bytes: &bone_joints_b,
        },
        SectionData {
            tag: *b"BROL",
            elem: ElemType::F32,
            bytes: &rolls_b,
        },
        SectionData {
            tag: *b"SKNB",
            elem: ElemType::U8,
            bytes: &skin_bones,
        },
        SectionData {
            tag: *b"SKNW",
            elem: ElemType::U16,
            bytes: &skin_weights_b,
        },
        SectionData {
            tag: *b"VPRT",
            elem: ElemType::U8,
            bytes: &parts,
        },
        SectionData {
            tag: *b"NAME",
            elem: ElemType::U8,
            bytes: b"root\nspine\nj-hip\nj-neck",
        },
    ];
    model_file::write(body_model::KIND, body_model::FORMAT_VERSION, &sections, out)
}

/// Canonical width of the tiny shape model.
pub const SHAPE_W: usize = 8;
/// Canonical height of the tiny shape model.
pub const SHAPE_H: usize = 6;
/// Bytes the tiny shape model file occupies (a buffer of this size always suffices).
pub const TINY_SHAPE_LEN: usize = 4096;
/// Leaf vectors of the tiny forest: tree 0 splits on `c[0] < 0` into leaves 0 and 1, tree 1 is leaf 2.
pub const SHAPE_LEAVES: [[i16; 20]; 3] = {
    let mut l = [[0i16; 20]; 3];
    let mut k = 0;
    while k < 20 {
        l[0][k] = -(k as i16) * 10;
        l[1][k] = k as i16 * 10;
        l[2][k] = 100;
        k += 1;
    }
    l
};
/// Dequantisation scale of the tiny forest's outputs.
pub const SHAPE_LEAF_SCALE: f32 = 0.01;

/// Quantised eigen-image element (pixel, component) of the tiny shape model: a fixed pseudo-random integer.
pub const fn eigen_q(pixel: usize, k: usize) -> i16 {
    let h = (pixel as u32).wrapping_mul(2_654_435_761) ^ (k as u32).wrapping_mul(40_503).wrapping_add(12_345);
    let h = h ^ (h >> 13);
    (h.wrapping_mul(1_274_126_177) >> 20) as i16 % 1000
}

/// Dequantisation scale of the tiny eigen-images.
pub const EIGEN_SCALE: f32 = 1e-3;

/// Mean canonical value of `pixel` of the tiny shape model.
pub fn shape_mean(pixel: usize) -> f32 {
    0.01 * (pixel % 7) as f32
}

/// Write the tiny shape model (8x6 canonical view, 20 eigen-images, two trees) into `out`; returns its length.
pub fn tiny_shape_model(out: &mut [u8]) -> Result<usize, WriteError> {
    tiny_shape_model_with_reference(out, None)
}

/// [`tiny_shape_model`] with a `CREF` section holding `cref` (none for `None`).
pub fn tiny_shape_model_with_reference(out: &mut [u8], cref: Option<u32>) -> Result<usize, WriteError> {
    use crate::shape::{FORMAT_VERSION, KIND};
    const P: usize = SHAPE_W * SHAPE_H;
    let head = [SHAPE_W as u32, SHAPE_H as u32, 1, 2];
    let camr = [20.0f32, 3.5, 2.5, 2.0, 0.5, 0.5, 0.9, 0.45, 0.03];
    let mut mean = [0u8; 4 * P];
    let mut eigs = [0u8; 2 * P * 20];
    for i in 0..P {
        mean[4 * i..4 * i + 4].copy_from_slice(&shape_mean(i).to_le_bytes());
        for k in 0..20 {
            let at = 2 * (i * 20 + k);
            eigs[at..at + 2].copy_from_slice(&eigen_q(i, k).to_le_bytes());
        }
    }
    let mut escl = [0u8; 80];
    let mut lscl = [0u8; 80];
    for k in 0..20 {
        escl[4 * k..4 * k + 4].copy_from_slice(&EIGEN_SCALE.to_le_bytes());
        lscl[4 * k..4 * k + 4].copy_from_slice(&SHAPE_LEAF_SCALE.to_le_bytes());
    }
    let epri = [0u8; 80];
    let tree = le_u32(&[0, 3]);
    // Nodes: 0 split c[0] < 0 → 1, 2; 1 leaf 0; 2 leaf 1; 3 leaf 2.
    let nfea = le_u16(&[0, 0xFFFF, 0xFFFF, 0xFFFF]);
    let mut nthr = [0u8; 16];
    nthr[..4].copy_from_slice(&0.0f32.to_le_bytes());
    let nchl = le_u32(&[1, 0, 1, 2]);
    let mut leaf = [0u8; 2 * 60];
    for (l, row) in SHAPE_LEAVES.iter().enumerate() {
        for (k, x) in row.iter().enumerate() {
            leaf[2 * (l * 20 + k)..2 * (l * 20 + k) + 2].copy_from_slice(&x.to_le_bytes());
        }
    }
    let h = le_u32(&head);
    let mut c = [0u8; 36];
    for (i, x) in camr.iter().enumerate() {
        c[4 * i..4 * i + 4].copy_from_slice(&x.to_le_bytes());
    }
    let s = |tag: &[u8; 4], elem, bytes| SectionData {
        tag: *tag,
        elem,
        bytes,
    };
    let cref_bytes = cref.unwrap_or(0).to_le_bytes();
    let sections = [
        s(b"HEAD", ElemType::U32, &h[..16]),
        s(b"CAMR", ElemType::F32, &c),
        s(b"MEAN", ElemType::F32, &mean),
        s(b"EIGS", ElemType::I16, &eigs),
        s(b"ESCL", ElemType::F32, &escl),
        s(b"EPRI", ElemType::F32, &epri),
        s(b"TREE", ElemType::U32, &tree[..8]),
        s(b"NFEA", ElemType::U16, &nfea[..8]),
        s(b"NTHR", ElemType::F32, &nthr),
        s(b"NCHL", ElemType::U32, &nchl[..16]),
        s(b"LEAF", ElemType::I16, &leaf),
        s(b"LSCL", ElemType::F32, &lscl),
        s(b"CREF", ElemType::U32, &cref_bytes),
    ];
    let n = if cref.is_some() {
        sections.len()
    } else {
        sections.len() - 1
    };
    model_file::write(KIND, FORMAT_VERSION, &sections[..n], out)
}

fn le_u32(xs: &[u32]) -> [u8; 16] {
    let mut out = [0u8; 16];
    for (i, x) in xs.iter().enumerate().take(4) {
        out[4 * i..4 * i + 4].copy_from_slice(&x.to_le_bytes());
    }
    out
}

fn le_u16(xs: &[u16]) -> [u8; 16] {
    let mut out = [0u8; 16];
    for (i, x) in xs.iter().enumerate().take(8) {
        out[2 * i..2 * i + 2].copy_from_slice(&x.to_le_bytes());
    }
    out
}
