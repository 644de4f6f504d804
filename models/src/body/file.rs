//! Writer of `BODY` model files (layout: [`supine_core::body_model`]) and reader of the host-only sections.
//!
//! Host-only sections that core ignores: `POPS` (f32, 20 per member: shape coefficients of the training and
//! held-out population), `POPM` (f32, 5 per member: male 0/1, age years, height m, BMI, waist m) and `INFO` (u8,
//! the build report as JSON, for provenance).
//!
//! Quantisation: each basis component k is stored as i16 with scale `max_i |V_ik| / 32767`, so the rounding error
//! of an element is at most half a step; the build reports what that costs in millimetres.

use anyhow::{Result, bail};
use supine_core::body_model::{FORMAT_VERSION, KIND, NO_PARENT};
use supine_core::model_file::{ElemType, ModelFile, SectionData, encoded_len, write};

use super::{COMPONENTS, PopulationMember, Shape};

/// Everything a body model file holds, unquantised.
#[derive(Clone, Debug)]
pub struct BodyFileData {
    /// Skin vertices.
    pub n_vertices: usize,
    /// Rig joints.
    pub n_joints: usize,
    /// Mean of every row (vertices, joints, 6 salient points), flattened xyz.
    pub mean: Vec<f32>,
    /// Basis, `(3·row + c)·K + k`.
    pub basis: Vec<f64>,
    /// Coefficient SDs.
    pub sigma: Vec<f32>,
    /// Torso ICP subset, ascending.
    pub subset: Vec<u32>,
    /// Subset triangles, indices into `subset`.
    pub subset_triangles: Vec<[u32; 3]>,
    /// Skin triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Bones: name, parent, head joint, tail joint, roll.
    pub bones: Vec<(String, Option<usize>, usize, usize, f32)>,
    /// Joint names.
    pub joint_names: Vec<String>,
    /// Skin influences per vertex (bone, weight), weights summing to 1.
    pub skin: Vec<Vec<(u16, f32)>>,
    /// Influences stored per vertex.
    pub max_influences: usize,
    /// Body part per vertex.
    pub parts: Vec<u8>,
    /// Population (training then held-out).
    pub population: Vec<PopulationMember>,
    /// Build report, JSON.
    pub info_json: String,
}

/// Quantise a `(3·rows)·K` basis to i16 with one scale per component.
pub fn quantise_basis(basis: &[f64], k: usize) -> (Vec<i16>, Vec<f32>) {
    let mut scale = vec![0.0f32; k];
    for (i, &x) in basis.iter().enumerate() {
        let s = &mut scale[i % k];
        *s = s.max((x.abs() / 32767.0) as f32);
    }
    // A zero component would divide by zero; give it a unit scale (all its elements quantise to 0 anyway).
    scale.iter_mut().filter(|s| **s == 0.0).for_each(|s| *s = 1.0);
    let q = basis
        .iter()
        .enumerate()
        .map(|(i, &x)| (x / scale[i % k] as f64).round().clamp(-32767.0, 32767.0) as i16)
        .collect();
    (q, scale)
}

fn le<T: Copy, const N: usize>(xs: &[T], f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
    xs.iter().flat_map(|&x| f(x)).collect()
}

/// Encode a body model file.
pub fn write_body_model(d: &BodyFileData) -> Result<Vec<u8>> {
    let k = d.sigma.len();
    let rows = d.n_vertices + d.n_joints + supine_core::salient::SalientPoint::COUNT;
    if d.mean.len() != 3 * rows || d.basis.len() != 3 * rows * k {
        bail!("mean/basis sizes do not match {rows} rows and {k} components");
    }
    if d.n_vertices > 65535 {
        bail!("{} vertices do not fit u16 indices", d.n_vertices);
    }
    let head: Vec<u32> = [
        d.n_vertices,
        d.n_joints,
        k,
        d.bones.len(),
        d.subset.len(),
        d.triangles.len(),
        d.subset_triangles.len(),
        d.max_influences,
    ]
    .iter()
    .map(|&x| x as u32)
    .collect();
    let (q, scale) = quantise_basis(&d.basis, k);
    let mut skin_b = Vec::with_capacity(d.n_vertices * d.max_influences);
    let mut skin_w: Vec<u16> = Vec::with_capacity(d.n_vertices * d.max_influences);
    for inf in &d.skin {
        let mut w: Vec<u16> = inf.iter().map(|x| (x.1 * 65535.0).round() as u16).collect();
        // Make each vertex sum to exactly 65535 by correcting its strongest influence.
        let sum: i64 = w.iter().map(|&x| x as i64).sum();
        if let Some(strongest) = (0..w.len()).max_by_key(|&i| w[i]) {
            w[strongest] = (w[strongest] as i64 + 65535 - sum).clamp(0, 65535) as u16;
        }
        for i in 0..d.max_influences {
            skin_b.push(inf.get(i).map(|x| x.0 as u8).unwrap_or(0));
            skin_w.push(w.get(i).copied().unwrap_or(0));
        }
    }
    let names: Vec<u8> = d
        .bones
        .iter()
        .map(|b| b.0.as_str())
        .chain(d.joint_names.iter().map(String::as_str))
        .collect::<Vec<_>>()
        .join("\n")
        .into_bytes();
    let parents: Vec<u16> = d
        .bones
        .iter()
        .map(|b| b.1.map(|p| p as u16).unwrap_or(NO_PARENT))
        .collect();
    let bj: Vec<u16> = d.bones.iter().flat_map(|b| [b.2 as u16, b.3 as u16]).collect();
    let rolls: Vec<f32> = d.bones.iter().map(|b| b.4).collect();
    let tris: Vec<u16> = d.triangles.iter().flatten().map(|&i| i as u16).collect();
    let stris: Vec<u16> = d.subset_triangles.iter().flatten().map(|&i| i as u16).collect();
    let subset: Vec<u16> = d.subset.iter().map(|&i| i as u16).collect();
    let pops: Vec<f32> = d.population.iter().flat_map(|m| m.shape.coeffs).collect();
    let popm: Vec<f32> = d
        .population
        .iter()
        .flat_map(|m| [m.male as u8 as f32, m.age_years, m.height_m, m.bmi, m.waist_m])
        .collect();

    let b_head = le(&head, u32::to_le_bytes);
    let b_mean = le(&d.mean, f32::to_le_bytes);
    let b_scale = le(&scale, f32::to_le_bytes);
    let b_basis = le(&q, i16::to_le_bytes);
    let b_sigma = le(&d.sigma, f32::to_le_bytes);
    let b_subset = le(&subset, u16::to_le_bytes);
    let b_stris = le(&stris, u16::to_le_bytes);
    let b_tris = le(&tris, u16::to_le_bytes);
    let b_par = le(&parents, u16::to_le_bytes);
    let b_bj = le(&bj, u16::to_le_bytes);
    let b_rol = le(&rolls, f32::to_le_bytes);
    let b_sw = le(&skin_w, u16::to_le_bytes);
    let b_pops = le(&pops, f32::to_le_bytes);
    let b_popm = le(&popm, f32::to_le_bytes);
    let s = sec;
    let sections = [
        s(b"HEAD", ElemType::U32, &b_head),
        s(b"MEAN", ElemType::F32, &b_mean),
        s(b"BSCL", ElemType::F32, &b_scale),
        s(b"BASI", ElemType::I16, &b_basis),
        s(b"SIGM", ElemType::F32, &b_sigma),
        s(b"TSUB", ElemType::U16, &b_subset),
        s(b"TSTR", ElemType::U16, &b_stris),
        s(b"TRIS", ElemType::U16, &b_tris),
        s(b"BPAR", ElemType::U16, &b_par),
        s(b"BJNT", ElemType::U16, &b_bj),
        s(b"BROL", ElemType::F32, &b_rol),
        s(b"SKNB", ElemType::U8, &skin_b),
        s(b"SKNW", ElemType::U16, &b_sw),
        s(b"VPRT", ElemType::U8, &d.parts),
        s(b"NAME", ElemType::U8, &names),
        s(b"POPS", ElemType::F32, &b_pops),
        s(b"POPM", ElemType::F32, &b_popm),
        s(b"INFO", ElemType::U8, d.info_json.as_bytes()),
    ];
    let mut out = vec![0u8; encoded_len(&sections)];
    let n = write(KIND, FORMAT_VERSION, &sections, &mut out).map_err(|e| anyhow::anyhow!("{e}"))?;
    out.truncate(n);
    // Validate what we wrote with the reader the head computer uses.
    supine_core::body_model::BodyModelView::parse(&out)
        .map_err(|e| anyhow::anyhow!("written model invalid: {e}"))?;
    Ok(out)
}

fn sec<'a>(tag: &[u8; 4], elem: ElemType, bytes: &'a [u8]) -> SectionData<'a> {
    SectionData {
        tag: *tag,
        elem,
        bytes,
    }
}

/// The population stored in `POPS`/`POPM` (empty when the file has none).
pub fn read_population(file: &ModelFile<'_>) -> Result<Vec<PopulationMember>> {
    let (Ok(pops), Ok(popm)) = (
        file.typed::<f32>(*b"POPS", None),
        file.typed::<f32>(*b"POPM", None),
    ) else {
        return Ok(Vec::new());
    };
    if pops.len() % COMPONENTS != 0 || popm.len() != pops.len() / COMPONENTS * 5 {
        bail!("population sections have inconsistent lengths");
    }
    Ok((0..pops.len() / COMPONENTS)
        .map(|i| {
            let mut coeffs = [0.0; COMPONENTS];
            for (k, c) in coeffs.iter_mut().enumerate() {
                *c = pops.at(i * COMPONENTS + k);
            }
            PopulationMember {
                shape: Shape { coeffs },
                male: popm.at(5 * i) > 0.5,
                age_years: popm.at(5 * i + 1),
                height_m: popm.at(5 * i + 2),
                bmi: popm.at(5 * i + 3),
                waist_m: popm.at(5 * i + 4),
            }
        })
        .collect())
}

/// The build report stored in `INFO`, if any.
pub fn read_info(file: &ModelFile<'_>) -> Option<String> {
    let s = file.typed::<u8>(*b"INFO", None).ok()?;
    std::str::from_utf8(s.as_bytes()).ok().map(str::to_string)
}
