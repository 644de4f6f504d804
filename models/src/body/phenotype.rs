//! MakeHuman phenotypes: macro values plus torso-relevant local modifiers, turned into target weights with
//! MakeHuman's interpolation rules (apps/human.py, humanmodifier.py; re-verified in
//! `shared/reference/makehuman-assets.md` §2), and applied to all 19158 base-mesh vertices.
//!
//! Rules, for MakeHuman values in [0, 1] (gender 0 = female, 1 = male):
//! - a macro target's weight is the product of the per-variable weights named in its file name;
//! - age a: below 0.5, baby = max(0, 1 − a/0.1875), young = max(0, (a − 0.1875)/0.3125),
//!   child = max(0, min(1, a/0.1875) − young), old = 0; from 0.5, old = 2a − 1, young = 1 − old;
//! - muscle, weight, cup, firmness: min = max(0, 1 − 2x), max = max(0, 2x − 1), average = 1 − min − max;
//! - height: minheight = max(0, 1 − 2h), maxheight = max(0, 2h − 1); proportions: uncommon = max(0, 1 − 2p),
//!   ideal = max(0, 2p − 1);
//! - race values are normalised to sum to one;
//! - a local modifier v ∈ [−1, 1] gives its negative target −min(v, 0) and its positive target max(v, 0).

use std::collections::HashMap;

use anyhow::Result;

use crate::assets::{Assets, BaseMesh, Target};

/// Torso-relevant local modifiers: (name, negative target, positive target), paths under `targets/`.
pub const LOCAL_MODIFIERS: [(&str, &str, &str); 15] = [
    (
        "stomach-pregnant",
        "stomach/stomach-pregnant-decr",
        "stomach/stomach-pregnant-incr",
    ),
    (
        "waist-circ",
        "torso/measure-waist-circ-decr",
        "torso/measure-waist-circ-incr",
    ),
    (
        "hips-circ",
        "torso/measure-hips-circ-decr",
        "torso/measure-hips-circ-incr",
    ),
    (
        "bust-circ",
        "torso/measure-bust-circ-decr",
        "torso/measure-bust-circ-incr",
    ),
    (
        "underbust-circ",
        "torso/measure-underbust-circ-decr",
        "torso/measure-underbust-circ-incr",
    ),
    (
        "torso-scale-depth",
        "torso/torso-scale-depth-decr",
        "torso/torso-scale-depth-incr",
    ),
    (
        "torso-scale-horiz",
        "torso/torso-scale-horiz-decr",
        "torso/torso-scale-horiz-incr",
    ),
    (
        "torso-scale-vert",
        "torso/torso-scale-vert-decr",
        "torso/torso-scale-vert-incr",
    ),
    (
        "torso-vshape",
        "torso/torso-vshape-decr",
        "torso/torso-vshape-incr",
    ),
    (
        "pectoral",
        "torso/torso-muscle-pectoral-decr",
        "torso/torso-muscle-pectoral-incr",
    ),
    (
        "hip-scale-horiz",
        "hip/hip-scale-horiz-decr",
        "hip/hip-scale-horiz-incr",
    ),
    (
        "hip-scale-depth",
        "hip/hip-scale-depth-decr",
        "hip/hip-scale-depth-incr",
    ),
    (
        "buttocks-volume",
        "buttocks/buttocks-volume-decr",
        "buttocks/buttocks-volume-incr",
    ),
    (
        "breast-volume-vert",
        "breast/breast-volume-vert-down",
        "breast/breast-volume-vert-up",
    ),
    (
        "breast-dist",
        "breast/breast-dist-decr",
        "breast/breast-dist-incr",
    ),
];

/// Index of a local modifier in [`LOCAL_MODIFIERS`].
pub fn local_index(name: &str) -> Option<usize> {
    LOCAL_MODIFIERS.iter().position(|m| m.0 == name)
}

/// MakeHuman values of one body.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Phenotype {
    /// 0 = female, 1 = male.
    pub gender: f64,
    /// MakeHuman age value (0 = 1 y, 0.1875 = 11 y, 0.5 = 25 y, 1 = 90 y); see [`age_value_from_years`].
    pub age: f64,
    /// Muscularity.
    pub muscle: f64,
    /// Weight (not BMI).
    pub weight: f64,
    /// Height.
    pub height: f64,
    /// Body proportions (0 uncommon … 1 ideal).
    pub proportions: f64,
    /// Breast size (cup).
    pub cup: f64,
    /// Breast firmness.
    pub firmness: f64,
    /// African, Asian, Caucasian shares (normalised when applied).
    pub race: [f64; 3],
    /// Local modifier values in [−1, 1], in [`LOCAL_MODIFIERS`] order.
    pub locals: [f64; LOCAL_MODIFIERS.len()],
}

impl Default for Phenotype {
    /// MakeHuman's default body: every macro 0.5, races 1/3 each, no local modifier.
    fn default() -> Self {
        Phenotype {
            gender: 0.5,
            age: 0.5,
            muscle: 0.5,
            weight: 0.5,
            height: 0.5,
            proportions: 0.5,
            cup: 0.5,
            firmness: 0.5,
            race: [1.0 / 3.0; 3],
            locals: [0.0; LOCAL_MODIFIERS.len()],
        }
    }
}

/// MakeHuman age value for an age in years (piecewise linear through 1 y → 0, 11 y → 0.1875, 25 y → 0.5,
/// 90 y → 1).
pub fn age_value_from_years(years: f64) -> f64 {
    if years <= 1.0 {
        0.0
    } else if years <= 11.0 {
        0.1875 * (years - 1.0) / 10.0
    } else if years <= 25.0 {
        0.1875 + 0.3125 * (years - 11.0) / 14.0
    } else {
        (0.5 + 0.5 * (years - 25.0) / 65.0).min(1.0)
    }
}

/// Age in years for a MakeHuman age value (inverse of [`age_value_from_years`]).
pub fn years_from_age_value(a: f64) -> f64 {
    if a <= 0.1875 {
        1.0 + 10.0 * a / 0.1875
    } else if a <= 0.5 {
        11.0 + 14.0 * (a - 0.1875) / 0.3125
    } else {
        25.0 + 65.0 * (a - 0.5) / 0.5
    }
}

/// min/average/max weights of a muscle, weight, cup or firmness value.
fn three_way(x: f64) -> [(&'static str, f64); 3] {
    let min = (1.0 - 2.0 * x).max(0.0);
    let max = (2.0 * x - 1.0).max(0.0);
    [("min", min), ("average", 1.0 - min - max), ("max", max)]
}

fn age_weights(a: f64) -> [(&'static str, f64); 4] {
    let (baby, child, young, old);
    if a < 0.5 {
        baby = (1.0 - a / 0.1875).max(0.0);
        young = ((a - 0.1875) / 0.3125).max(0.0);
        child = ((a / 0.1875).min(1.0) - young).max(0.0);
        old = 0.0;
    } else {
        old = 2.0 * a - 1.0;
        young = 1.0 - old;
        baby = 0.0;
        child = 0.0;
    }
    [("baby", baby), ("child", child), ("young", young), ("old", old)]
}

/// Every (target path under `targets/`, weight) with a non-zero weight for `p`.
pub fn target_weights(p: &Phenotype) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    let genders = [("female", 1.0 - p.gender), ("male", p.gender)];
    let ages = age_weights(p.age);
    let muscles = three_way(p.muscle);
    let weights = three_way(p.weight);
    let heights = [
        ("min", (1.0 - 2.0 * p.height).max(0.0)),
        ("max", (2.0 * p.height - 1.0).max(0.0)),
    ];
    let props = [
        ("uncommon", (1.0 - 2.0 * p.proportions).max(0.0)),
        ("ideal", (2.0 * p.proportions - 1.0).max(0.0)),
    ];
    let race_sum: f64 = p.race.iter().sum();
    let races = ["african", "asian", "caucasian"];
    let cups = three_way(p.cup);
    let firms = three_way(p.firmness);
    for &(g, gw) in &genders {
        if gw == 0.0 {
            continue;
        }
        for &(a, aw) in &ages {
            if aw == 0.0 {
                continue;
            }
            if race_sum > 0.0 {
                for (r, rv) in races.iter().zip(p.race) {
                    let w = rv / race_sum * gw * aw;
                    if w != 0.0 {
                        out.push((format!("macrodetails/{r}-{g}-{a}"), w));
                    }
                }
            }
            for &(m, mw) in &muscles {
                for &(wt, ww) in &weights {
                    let u = gw * aw * mw * ww;
                    if u == 0.0 {
                        continue;
                    }
                    out.push((format!("macrodetails/universal-{g}-{a}-{m}muscle-{wt}weight"), u));
                    for &(h, hw) in &heights {
                        if hw != 0.0 {
                            out.push((
                                format!("macrodetails/height/{g}-{a}-{m}muscle-{wt}weight-{h}height"),
                                u * hw,
                            ));
                        }
                    }
                    if a != "baby" {
                        for &(pr, pw) in &props {
                            if pw != 0.0 {
                                out.push((
                                    format!("macrodetails/proportions/{g}-{a}-{m}muscle-{wt}weight-{pr}proportions"),
                                    u * pw,
                                ));
                            }
                        }
                    }
                    if g == "female" && a != "baby" {
                        for &(c, cw) in &cups {
                            for &(f, fw) in &firms {
                                // The average/average combination is the base shape: MakeHuman has no file for it.
                                if (c, f) == ("average", "average") || cw * fw == 0.0 {
                                    continue;
                                }
                                out.push((
                                    format!("breast/{g}-{a}-{m}muscle-{wt}weight-{c}cup-{f}firmness"),
                                    u * cw * fw,
                                ));
                            }
                        }
                    }
                }
            }
        }
    }
    for (i, &(_, neg, pos)) in LOCAL_MODIFIERS.iter().enumerate() {
        let v = p.locals[i].clamp(-1.0, 1.0);
        if v < 0.0 {
            out.push((neg.to_string(), -v));
        } else if v > 0.0 {
            out.push((pos.to_string(), v));
        }
    }
    out
}

/// Every target an adult phenotype (age ≥ 11 y) can use: loaded once, then meshes are built from memory.
pub struct TargetLibrary {
    base: BaseMesh,
    targets: HashMap<String, Target>,
}

impl TargetLibrary {
    /// Load the base mesh and every child/young/old macro, breast and local target from the wheel.
    pub fn load(assets: &mut Assets) -> Result<TargetLibrary> {
        let base = assets.base_mesh()?;
        let mut names: Vec<String> = Vec::new();
        // Enumerate through target_weights over a grid that touches every adult file: each variable at 0 and 1
        // for the min/max sides (and 0.5 for average), child to old ages.
        for g in [0.0, 1.0] {
            for a in [0.1875, 0.5, 1.0] {
                for m in [0.0, 0.5, 1.0] {
                    for w in [0.0, 0.5, 1.0] {
                        for h in [0.0, 1.0] {
                            for pr in [0.0, 1.0] {
                                for (c, f) in [0.0, 0.5, 1.0]
                                    .into_iter()
                                    .flat_map(|c| [(c, 0.0), (c, 0.5), (c, 1.0)])
                                {
                                    let p = Phenotype {
                                        gender: g,
                                        age: a,
                                        muscle: m,
                                        weight: w,
                                        height: h,
                                        proportions: pr,
                                        cup: c,
                                        firmness: f,
                                        ..Phenotype::default()
                                    };
                                    names.extend(target_weights(&p).into_iter().map(|x| x.0));
                                }
                            }
                        }
                    }
                }
            }
        }
        for (_, neg, pos) in LOCAL_MODIFIERS {
            names.push(neg.to_string());
            names.push(pos.to_string());
        }
        names.sort();
        names.dedup();
        let mut targets = HashMap::with_capacity(names.len());
        for n in names {
            let t = assets.target(&n)?;
            targets.insert(n, t);
        }
        Ok(TargetLibrary { base, targets })
    }

    /// The unmodified base mesh.
    pub fn base(&self) -> &BaseMesh {
        &self.base
    }

    /// Number of loaded targets.
    pub fn len(&self) -> usize {
        self.targets.len()
    }

    /// True when no target is loaded.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }

    /// All 19158 vertices (body frame, metres) of phenotype `p`. Fails when `p` needs a target that is not loaded
    /// (a baby age).
    pub fn build(&self, p: &Phenotype) -> Result<Vec<[f64; 3]>> {
        let mut v = self.base.vertices.clone();
        for (name, w) in target_weights(p) {
            let t = self.targets.get(&name).ok_or_else(|| {
                anyhow::anyhow!("target {name} is not loaded (ages below 11 y are not supported)")
            })?;
            t.apply(w, &mut v);
        }
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_weights_follow_makehuman_rules() {
        let w = target_weights(&Phenotype::default());
        let get = |n: &str| w.iter().find(|x| x.0 == n).map(|x| x.1);
        // Default: both genders at 1/2, young only, average muscle and weight, no height/proportion targets.
        assert_eq!(
            get("macrodetails/universal-female-young-averagemuscle-averageweight"),
            Some(0.5)
        );
        assert!((get("macrodetails/caucasian-male-young").unwrap() - 0.5 / 3.0).abs() < 1e-12);
        assert!(
            w.iter()
                .all(|x| !x.0.contains("height/") && !x.0.contains("proportions/"))
        );
        assert!(w.iter().all(|x| !x.0.contains("-old") && !x.0.contains("-child")));
        // Breast average/average has no file and must not appear.
        assert!(w.iter().all(|x| !x.0.contains("averagecup-averagefirmness")));
    }

    #[test]
    fn macro_interpolation_is_piecewise_linear() {
        let p = Phenotype {
            gender: 1.0,
            weight: 0.75,
            muscle: 1.0,
            height: 0.2,
            age: 0.75,
            ..Phenotype::default()
        };
        let w = target_weights(&p);
        let get = |n: &str| w.iter().find(|x| x.0 == n).map(|x| x.1).unwrap_or(0.0);
        // weight 0.75 → average 0.5, max 0.5; age 0.75 → young 0.5, old 0.5; muscle 1 → max.
        assert!((get("macrodetails/universal-male-old-maxmuscle-maxweight") - 0.25).abs() < 1e-12);
        assert!((get("macrodetails/universal-male-young-maxmuscle-averageweight") - 0.25).abs() < 1e-12);
        // height 0.2 → minheight 0.6.
        assert!((get("macrodetails/height/male-old-maxmuscle-maxweight-minheight") - 0.15).abs() < 1e-12);
        assert_eq!(get("macrodetails/universal-female-old-maxmuscle-maxweight"), 0.0);
        let sum: f64 = w
            .iter()
            .filter(|x| x.0.starts_with("macrodetails/universal"))
            .map(|x| x.1)
            .sum();
        assert!(
            (sum - 1.0).abs() < 1e-12,
            "universal weights sum to one, got {sum}"
        );
    }

    #[test]
    fn age_mapping_round_trips() {
        for y in [11.0, 18.0, 25.0, 40.0, 90.0] {
            assert!((years_from_age_value(age_value_from_years(y)) - y).abs() < 1e-9);
        }
        assert_eq!(age_value_from_years(25.0), 0.5);
        // 18 years is between child and young.
        let a = age_weights(age_value_from_years(18.0));
        assert!((a[1].1 - 0.5).abs() < 1e-12 && (a[2].1 - 0.5).abs() < 1e-12);
    }

    #[test]
    fn local_modifiers_pick_one_side() {
        let mut p = Phenotype::default();
        p.locals[local_index("stomach-pregnant").unwrap()] = -0.4;
        p.locals[local_index("waist-circ").unwrap()] = 0.7;
        let w = target_weights(&p);
        assert!(w.contains(&("stomach/stomach-pregnant-decr".to_string(), 0.4)));
        assert!(w.contains(&("torso/measure-waist-circ-incr".to_string(), 0.7)));
        assert!(!w.iter().any(|x| x.0 == "stomach/stomach-pregnant-incr"));
    }
}
