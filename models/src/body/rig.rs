//! The reduced posing rig (36 bones of MakeHuman's default rig), its joints, skin weights, body-part labels, the six
//! salient points and the torso ICP subset (`shared/reference/makehuman-assets.md` §3, §5).
//!
//! Why the default rig reduced to 36 bones: 5 spine and 3 neck bones bend the trunk smoothly for bed poses, while
//! fingers, toes, face, eyes and breasts carry no information at Kinect resolution; their weights are merged into
//! the nearest kept ancestor (as anny's `_filter_rig`) and renormalised, and each vertex keeps its
//! [`MAX_INFLUENCES`] strongest influences.

use std::collections::HashMap;

use anyhow::{Context, Result, anyhow, bail};
use serde_json::Value;
use supine_core::body_model::BodyPart;
use supine_core::salient::SalientPoint;

use crate::assets::{Assets, BODY_VERTICES, BaseMesh};

/// Bones kept for posing, parents before children.
pub const KEPT_BONES: [&str; 36] = [
    "root",
    "spine05",
    "spine04",
    "spine03",
    "spine02",
    "spine01",
    "neck01",
    "neck02",
    "neck03",
    "head",
    "clavicle.L",
    "shoulder01.L",
    "upperarm01.L",
    "upperarm02.L",
    "lowerarm01.L",
    "lowerarm02.L",
    "wrist.L",
    "clavicle.R",
    "shoulder01.R",
    "upperarm01.R",
    "upperarm02.R",
    "lowerarm01.R",
    "lowerarm02.R",
    "wrist.R",
    "pelvis.L",
    "upperleg01.L",
    "upperleg02.L",
    "lowerleg01.L",
    "lowerleg02.L",
    "foot.L",
    "pelvis.R",
    "upperleg01.R",
    "upperleg02.R",
    "lowerleg01.R",
    "lowerleg02.R",
    "foot.R",
];

/// Skinning influences kept per vertex.
pub const MAX_INFLUENCES: usize = 8;
/// The navel vertex (front midline; the belly salient point follows the stomach targets).
pub const NAVEL_VERTEX: u32 = 4116;
/// A front-midline chest vertex at the level of joint-spine-1 (the sternum).
pub const STERNUM_VERTEX: u32 = 1891;

/// Body part of a kept bone.
pub fn part_of_bone(name: &str) -> BodyPart {
    let left = name.ends_with(".L");
    let side = |l: BodyPart, r: BodyPart| if left { l } else { r };
    match name.trim_end_matches(".L").trim_end_matches(".R") {
        "head" => BodyPart::Head,
        "neck01" | "neck02" | "neck03" => BodyPart::Neck,
        "spine01" | "spine02" | "clavicle" | "shoulder01" => BodyPart::Chest,
        "spine03" | "spine04" | "spine05" => BodyPart::Abdomen,
        "root" | "pelvis" => BodyPart::Pelvis,
        "upperarm01" | "upperarm02" => side(BodyPart::LeftUpperArm, BodyPart::RightUpperArm),
        "lowerarm01" | "lowerarm02" => side(BodyPart::LeftForearm, BodyPart::RightForearm),
        "wrist" => side(BodyPart::LeftHand, BodyPart::RightHand),
        "upperleg01" | "upperleg02" => side(BodyPart::LeftThigh, BodyPart::RightThigh),
        "lowerleg01" | "lowerleg02" => side(BodyPart::LeftShank, BodyPart::RightShank),
        _ => side(BodyPart::LeftFoot, BodyPart::RightFoot),
    }
}

/// A joint: the mean of some base-mesh vertices (a joint cube, one vertex, or a vertex list).
#[derive(Clone, Debug, PartialEq)]
pub struct JointDef {
    /// Cube name (`joint-l-shoulder`) or `v<idx>[+<idx>…]`.
    pub name: String,
    /// Vertices averaged (indices into all 19158).
    pub vertices: Vec<u32>,
}

impl JointDef {
    /// Position in a full base-mesh vertex array.
    pub fn position(&self, v: &[[f64; 3]]) -> [f64; 3] {
        let mut p = [0.0; 3];
        for &i in &self.vertices {
            for c in 0..3 {
                p[c] += v[i as usize][c];
            }
        }
        p.map(|x| x / self.vertices.len() as f64)
    }
}

/// A kept bone.
#[derive(Clone, Debug, PartialEq)]
pub struct BoneDef {
    /// Blender name.
    pub name: String,
    /// Parent index in [`RigDef::bones`].
    pub parent: Option<usize>,
    /// Head joint index.
    pub head: usize,
    /// Tail joint index.
    pub tail: usize,
    /// Blender roll, radians.
    pub roll: f64,
    /// `default_position` of the head in the rig file (MakeHuman default body), for checks.
    pub default_head: [f64; 3],
}

/// The reduced rig with skinning and labels.
#[derive(Clone, Debug)]
pub struct RigDef {
    /// Kept bones, parents first.
    pub bones: Vec<BoneDef>,
    /// Distinct joints used by the bones.
    pub joints: Vec<JointDef>,
    /// Per skin vertex: up to [`MAX_INFLUENCES`] (bone, weight), weights summing to 1, strongest first.
    pub skin: Vec<Vec<(u16, f32)>>,
    /// Per skin vertex: the dominant bone of the full 163-bone default weights (for the torso subset).
    pub dominant_full_bone: Vec<String>,
    /// Per skin vertex: [`BodyPart`] of its dominant kept bone.
    pub part_of_vertex: Vec<u8>,
}

fn joint_of(end: &Value, groups: &HashMap<String, Vec<u32>>) -> Result<JointDef> {
    let strategy = end["strategy"]
        .as_str()
        .ok_or_else(|| anyhow!("bone end without strategy"))?;
    Ok(match strategy {
        "CUBE" => {
            let name = end["cube_name"]
                .as_str()
                .ok_or_else(|| anyhow!("CUBE without cube_name"))?;
            let vertices = groups
                .get(name)
                .cloned()
                .ok_or_else(|| anyhow!("joint cube {name} not in base.obj"))?;
            JointDef {
                name: name.to_string(),
                vertices,
            }
        }
        "VERTEX" => {
            let i = end["vertex_index"]
                .as_u64()
                .ok_or_else(|| anyhow!("VERTEX without vertex_index"))? as u32;
            JointDef {
                name: format!("v{i}"),
                vertices: vec![i],
            }
        }
        "MEAN" => {
            let vs: Vec<u32> = end["vertex_indices"]
                .as_array()
                .ok_or_else(|| anyhow!("MEAN without vertex_indices"))?
                .iter()
                .map(|x| {
                    x.as_u64()
                        .map(|x| x as u32)
                        .ok_or_else(|| anyhow!("bad vertex index"))
                })
                .collect::<Result<_>>()?;
            let name = format!(
                "v{}",
                vs.iter().map(|x| x.to_string()).collect::<Vec<_>>().join("+")
            );
            JointDef { name, vertices: vs }
        }
        other => bail!("unknown joint strategy {other}"),
    })
}

fn vec3(v: &Value) -> [f64; 3] {
    let a = |i: usize| v.get(i).and_then(Value::as_f64).unwrap_or(0.0);
    [a(0), a(1), a(2)]
}

/// Load `rig.default.json` and `weights.default.json` and reduce them to [`KEPT_BONES`].
pub fn load_rig(assets: &mut Assets, base: &BaseMesh) -> Result<RigDef> {
    let rig = assets.json("rigs/standard/rig.default.json")?;
    let rig = rig
        .as_object()
        .ok_or_else(|| anyhow!("rig.default.json is not an object"))?;
    let mut joints: Vec<JointDef> = Vec::new();
    let joint_index = |j: JointDef, joints: &mut Vec<JointDef>| -> usize {
        if let Some(i) = joints.iter().position(|x| x.vertices == j.vertices) {
            i
        } else {
            joints.push(j);
            joints.len() - 1
        }
    };
    let mut bones: Vec<BoneDef> = Vec::new();
    for name in KEPT_BONES {
        let b = rig
            .get(name)
            .with_context(|| format!("bone {name} not in rig.default.json"))?;
        // Parent: nearest kept ancestor (all kept bones' parents are kept in this selection, but walk anyway).
        let mut parent = b["parent"].as_str().unwrap_or("").to_string();
        let parent_idx = loop {
            if parent.is_empty() {
                break None;
            }
            if let Some(i) = bones.iter().position(|x| x.name == parent) {
                break Some(i);
            }
            parent = rig
                .get(&parent)
                .and_then(|p| p["parent"].as_str())
                .unwrap_or("")
                .to_string();
        };
        if parent_idx.is_none() && name != "root" {
            bail!("bone {name} has no kept ancestor");
        }
        let head = joint_index(joint_of(&b["head"], &base.groups)?, &mut joints);
        let tail = joint_index(joint_of(&b["tail"], &base.groups)?, &mut joints);
        bones.push(BoneDef {
            name: name.to_string(),
            parent: parent_idx,
            head,
            tail,
            roll: b["roll"].as_f64().unwrap_or(0.0),
            default_head: vec3(&b["head"]["default_position"]),
        });
    }

    // Map each of the 163 bones to its nearest kept ancestor.
    let kept_of = |mut n: String| -> Option<usize> {
        loop {
            if let Some(i) = KEPT_BONES.iter().position(|k| *k == n) {
                return Some(i);
            }
            n = rig.get(&n)?["parent"].as_str()?.to_string();
            if n.is_empty() {
                return None;
            }
        }
    };
    let w = assets.json("rigs/standard/weights.default.json")?;
    let w = w["weights"]
        .as_object()
        .ok_or_else(|| anyhow!("weights.default.json has no weights object"))?;
    let mut merged: Vec<Vec<f64>> = vec![vec![0.0; KEPT_BONES.len()]; BODY_VERTICES];
    let mut best_full: Vec<(f64, String)> = vec![(0.0, String::new()); BODY_VERTICES];
    for (bone, list) in w {
        let k = kept_of(bone.clone()).with_context(|| format!("weights bone {bone} has no kept ancestor"))?;
        for pair in list
            .as_array()
            .ok_or_else(|| anyhow!("weights of {bone} not a list"))?
        {
            let v = pair[0]
                .as_u64()
                .ok_or_else(|| anyhow!("bad vertex in weights of {bone}"))? as usize;
            let x = pair[1].as_f64().unwrap_or(0.0);
            if v < BODY_VERTICES {
                merged[v][k] += x;
                // Ties broken by name so the result does not depend on JSON map order.
                if x > best_full[v].0 || (x == best_full[v].0 && *bone < best_full[v].1) {
                    best_full[v] = (x, bone.clone());
                }
            }
        }
    }
    let mut skin = Vec::with_capacity(BODY_VERTICES);
    let mut part_of_vertex = Vec::with_capacity(BODY_VERTICES);
    for (v, m) in merged.iter().enumerate() {
        let mut inf: Vec<(u16, f64)> = m
            .iter()
            .enumerate()
            .filter(|x| *x.1 > 0.0)
            .map(|(b, &x)| (b as u16, x))
            .collect();
        inf.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        inf.truncate(MAX_INFLUENCES);
        let sum: f64 = inf.iter().map(|x| x.1).sum();
        if inf.is_empty() || sum <= 0.0 {
            bail!("skin vertex {v} has no skinning weight");
        }
        part_of_vertex.push(part_of_bone(KEPT_BONES[inf[0].0 as usize]) as u8);
        skin.push(inf.into_iter().map(|(b, x)| (b, (x / sum) as f32)).collect());
    }
    Ok(RigDef {
        bones,
        joints,
        skin,
        dominant_full_bone: best_full.into_iter().map(|x| x.1).collect(),
        part_of_vertex,
    })
}

/// The six salient points as weighted vertex sums (indices into all 19158), in
/// [`supine_core::salient::SalientPoint::ALL`] order: head = midpoint of the joint-neck and joint-head cubes,
/// shoulders = joint-l/r-shoulder, belly = navel vertex 4116, hips = joint-l/r-upper-leg.
pub fn salient_defs(base: &BaseMesh) -> Result<[Vec<(u32, f64)>; SalientPoint::COUNT]> {
    let cube = |n: &str| -> Result<Vec<u32>> {
        base.groups
            .get(n)
            .cloned()
            .with_context(|| format!("no cube {n}"))
    };
    let mean = |vs: Vec<u32>| -> Vec<(u32, f64)> {
        let w = 1.0 / vs.len() as f64;
        vs.into_iter().map(|v| (v, w)).collect()
    };
    let neck = cube("joint-neck")?;
    let head = cube("joint-head")?;
    let mut head_pt: Vec<(u32, f64)> = mean(neck).into_iter().map(|(v, w)| (v, 0.5 * w)).collect();
    head_pt.extend(mean(head).into_iter().map(|(v, w)| (v, 0.5 * w)));
    Ok([
        head_pt,
        mean(cube("joint-l-shoulder")?),
        mean(cube("joint-r-shoulder")?),
        vec![(NAVEL_VERTEX, 1.0)],
        mean(cube("joint-l-upper-leg")?),
        mean(cube("joint-r-upper-leg")?),
    ])
}

/// Area-weighted vertex normals of the skin (unit length; zero for unused vertices).
pub fn vertex_normals(v: &[[f64; 3]], triangles: &[[u32; 3]]) -> Vec<[f64; 3]> {
    let mut n = vec![[0.0f64; 3]; BODY_VERTICES];
    for t in triangles {
        let [a, b, c] = t.map(|i| v[i as usize]);
        let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let cr = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        for &i in t {
            for k in 0..3 {
                n[i as usize][k] += cr[k];
            }
        }
    }
    for x in &mut n {
        let l = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
        if l > 0.0 {
            *x = x.map(|c| c / l);
        }
    }
    n
}

/// Bones of the full default rig whose dominant vertices form the torso ICP subset: the trunk (root, spine, pelvis,
/// breasts) plus the shoulder girdle and the neck base.
pub const TORSO_SUBSET_BONES: [&str; 16] = [
    "root",
    "spine01",
    "spine02",
    "spine03",
    "spine04",
    "spine05",
    "pelvis.L",
    "pelvis.R",
    "breast.L",
    "breast.R",
    "clavicle.L",
    "clavicle.R",
    "shoulder01.L",
    "shoulder01.R",
    "neck01",
    "neck02",
];

/// The torso ICP subset on the mean body `v` (skin + joints available through `shoulder_x`, `hip_z`): vertices
/// whose dominant full-rig bone is in [`TORSO_SUBSET_BONES`], facing the camera of a supine patient (normal
/// y < 0), inside the shoulder joints (|x| < shoulder x: arms move independently of the rigid torso) and outside
/// the crotch box (|x| < 0.08 m, z < hip + 0.02 m, y < −0.02 m). Notes §5 recommend also the upper arms and thighs;
/// they are left out here because rigid torso ICP cannot follow limbs that the pose moves.
pub fn torso_subset(
    v: &[[f64; 3]],
    triangles: &[[u32; 3]],
    dominant_full_bone: &[String],
    shoulder_x: f64,
    hip_z: f64,
) -> Vec<u32> {
    let normals = vertex_normals(v, triangles);
    (0..BODY_VERTICES as u32)
        .filter(|&i| {
            let p = v[i as usize];
            let n = normals[i as usize];
            let crotch = p[0].abs() < 0.08 && p[2] < hip_z + 0.02 && p[1] < -0.02;
            TORSO_SUBSET_BONES.contains(&dominant_full_bone[i as usize].as_str())
                && n[1] < 0.0
                && p[0].abs() < shoulder_x
                && !crotch
        })
        .collect()
}
