//! A realistic adult patient population: MakeHuman phenotypes whose measured height, BMI and waist follow
//! published adult statistics per sex.
//!
//! MakeHuman's macros are not anthropometric quantities ("weight" is not BMI, height depends on gender, age,
//! muscle and weight targets), so the population is calibrated by *matching*, not by choosing macro values:
//! 1. a broad proposal pool of phenotypes ([`propose`]) is built and measured (height, BMI from mesh volume, waist);
//! 2. N target triples (height, BMI, waist) are drawn from a per-sex trivariate normal with the published means,
//!    SDs and correlations ([`AdultStats`]), truncated to plausible adult ranges;
//! 3. each target (in random order) takes the nearest unused pool member in SD-normalised units.
//!
//! The selected phenotypes are the population; their measured statistics are reported next to the targets.
//!
//! Reference figures ([`NHANES_MALE`], [`NHANES_FEMALE`]): US adults aged 20 and over, NHANES 2015–2018 (CDC
//! FastStats "Body measurements"; Fryar et al., Anthropometric reference data for children and adults: United
//! States, 2015–2018, Vital Health Stat 3(46), 2021): means men 175.3 cm, 90.6 kg (BMI ≈ 29.4), waist 102.9 cm;
//! women 161.3 cm, 77.5 kg (BMI ≈ 29.8), waist 98.3 cm. The SDs (height 7.5/7.0 cm, BMI 6.0/7.4, waist 15.5/16.0 cm)
//! are read from the published 5th–95th percentile spreads (≈ 3.3 SD), rounded; the correlations (BMI–waist ≈ 0.9,
//! height–waist ≈ 0.2, height–BMI ≈ 0) are typical adult values. They are approximations for synthetic data, not
//! a clinical reference.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::measure::Measurements;
use super::phenotype::{LOCAL_MODIFIERS, Phenotype, age_value_from_years, local_index};

/// Target statistics of one sex.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct AdultStats {
    /// Height mean and SD, metres.
    pub height_m: (f64, f64),
    /// BMI mean and SD, kg/m².
    pub bmi: (f64, f64),
    /// Waist circumference mean and SD, metres.
    pub waist_m: (f64, f64),
    /// Correlation of height and BMI.
    pub r_height_bmi: f64,
    /// Correlation of height and waist.
    pub r_height_waist: f64,
    /// Correlation of BMI and waist.
    pub r_bmi_waist: f64,
}

/// US men aged 20+, NHANES 2015–2018 (see the module docs).
pub const NHANES_MALE: AdultStats = AdultStats {
    height_m: (1.753, 0.075),
    bmi: (29.4, 6.0),
    waist_m: (1.029, 0.155),
    r_height_bmi: 0.0,
    r_height_waist: 0.2,
    r_bmi_waist: 0.9,
};

/// US women aged 20+, NHANES 2015–2018 (see the module docs).
pub const NHANES_FEMALE: AdultStats = AdultStats {
    height_m: (1.613, 0.070),
    bmi: (29.8, 7.4),
    waist_m: (0.983, 0.160),
    r_height_bmi: -0.05,
    r_height_waist: 0.15,
    r_bmi_waist: 0.9,
};

/// Plausible adult range for targets (values outside are redrawn): BMI 16–50, waist 0.60–1.55 m, height ±3 SD.
const BMI_RANGE: (f64, f64) = (16.0, 50.0);
const WAIST_RANGE: (f64, f64) = (0.60, 1.55);

/// Age range of the population, years (uniform: bed patients of every adult age).
pub const AGE_RANGE: (f64, f64) = (18.0, 90.0);

/// One proposal: a phenotype and its age in years.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Candidate {
    /// Male (else female).
    pub male: bool,
    /// Age in years.
    pub age_years: f64,
    /// MakeHuman values.
    pub phenotype: Phenotype,
}

fn clipped_normal<R: Rng>(rng: &mut R, mean: f64, sd: f64, lo: f64, hi: f64) -> f64 {
    let z: f64 = StandardNormal.sample(rng);
    (mean + sd * z).clamp(lo, hi)
}

/// A broad proposal: wide enough that the matched population can reach thin, tall, obese and big-bellied bodies.
/// Gender stays near its end (0–0.15 or 0.85–1) so bodies read as female or male; races stay at 1/3 each (the
/// MakeHuman default; ethnicity is not part of the calibration targets); local torso modifiers vary around zero,
/// the belly more towards protrusion (common in patients).
pub fn propose<R: Rng>(rng: &mut R, male: bool) -> Candidate {
    let age_years = rng.gen_range(AGE_RANGE.0..AGE_RANGE.1);
    let mut p = Phenotype {
        gender: if male {
            rng.gen_range(0.85..1.0)
        } else {
            rng.gen_range(0.0..0.15)
        },
        age: age_value_from_years(age_years),
        // High BMI needs low muscle and high weight (notes §2 table): skew the proposal that way.
        muscle: rng.gen_range(0.0..0.7),
        weight: 0.1 + 0.9 * rng.gen_range(0.0f64..1.0).sqrt(),
        // MakeHuman height 0..1 spans about 1.15..2.45 m: ±0.3 around the middle covers ±4 SD of adult heights.
        height: rng.gen_range(0.2..0.8),
        proportions: rng.gen_range(0.2..1.0),
        cup: if male { 0.5 } else { rng.gen_range(0.15..1.0) },
        firmness: if male { 0.5 } else { rng.gen_range(0.1..0.8) },
        ..Phenotype::default()
    };
    // Girth-related locals follow the weight macro (fat is stored around the waist, hips and chest), so the pool
    // reaches the high-BMI, high-waist bodies that the macros alone cannot (female BMI tops out near 33 otherwise).
    let fat = 1.2 * (p.weight - 0.4) * (1.0 - 0.5 * p.muscle);
    for (i, (name, _, _)) in LOCAL_MODIFIERS.iter().enumerate() {
        p.locals[i] = match *name {
            "stomach-pregnant" => clipped_normal(rng, fat - 0.05, 0.35, -0.5, 1.0),
            "waist-circ" | "hips-circ" | "bust-circ" | "underbust-circ" | "torso-scale-depth"
            | "torso-scale-horiz" | "hip-scale-horiz" | "hip-scale-depth" | "buttocks-volume" => {
                clipped_normal(rng, fat, 0.3, -1.0, 1.0)
            }
            // Scaling the torso length moves the joints; keep it modest.
            "torso-scale-vert" => clipped_normal(rng, 0.0, 0.2, -0.5, 0.5),
            "breast-volume-vert" | "breast-dist" if male => 0.0,
            _ => clipped_normal(rng, 0.0, 0.3, -1.0, 1.0),
        };
    }
    debug_assert!(local_index("stomach-pregnant").is_some());
    Candidate {
        male,
        age_years,
        phenotype: p,
    }
}

/// Draw `n` (height m, BMI, waist m) triples from the truncated trivariate normal of `s`.
pub fn draw_targets<R: Rng>(rng: &mut R, s: &AdultStats, n: usize) -> Vec<[f64; 3]> {
    // Cholesky factor of the correlation matrix [[1, a, b], [a, 1, c], [b, c, 1]] (h, bmi, waist).
    let (a, b, c) = (s.r_height_bmi, s.r_height_waist, s.r_bmi_waist);
    let l11 = 1.0;
    let l21 = a;
    let l22 = (1.0 - a * a).sqrt();
    let l31 = b;
    let l32 = (c - a * b) / l22;
    let l33 = (1.0 - l31 * l31 - l32 * l32).sqrt();
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let z: [f64; 3] = [
            StandardNormal.sample(rng),
            StandardNormal.sample(rng),
            StandardNormal.sample(rng),
        ];
        let e = [
            l11 * z[0],
            l21 * z[0] + l22 * z[1],
            l31 * z[0] + l32 * z[1] + l33 * z[2],
        ];
        let t = [
            s.height_m.0 + s.height_m.1 * e[0],
            s.bmi.0 + s.bmi.1 * e[1],
            s.waist_m.0 + s.waist_m.1 * e[2],
        ];
        let ok = e[0].abs() <= 3.0
            && (BMI_RANGE.0..=BMI_RANGE.1).contains(&t[1])
            && (WAIST_RANGE.0..=WAIST_RANGE.1).contains(&t[2]);
        if ok {
            out.push(t);
        }
    }
    out
}

/// For each target (in the given order), the nearest unused pool member in units of the target SDs. Returns the
/// chosen pool indices (parallel to `targets`) and the mean matching distance.
pub fn match_targets(targets: &[[f64; 3]], pool: &[Measurements], s: &AdultStats) -> (Vec<usize>, f64) {
    assert!(pool.len() >= targets.len(), "pool smaller than the population");
    let sd = [s.height_m.1, s.bmi.1, s.waist_m.1];
    let scaled: Vec<[f64; 3]> = pool
        .iter()
        .map(|m| [m.height_m / sd[0], m.bmi / sd[1], m.waist_m / sd[2]])
        .collect();
    let mut used = vec![false; pool.len()];
    let mut chosen = Vec::with_capacity(targets.len());
    let mut total = 0.0;
    for t in targets {
        let ts = [t[0] / sd[0], t[1] / sd[1], t[2] / sd[2]];
        let mut best = (f64::INFINITY, usize::MAX);
        for (i, p) in scaled.iter().enumerate() {
            if used[i] {
                continue;
            }
            let d = (p[0] - ts[0]).powi(2) + (p[1] - ts[1]).powi(2) + (p[2] - ts[2]).powi(2);
            if d < best.0 {
                best = (d, i);
            }
        }
        used[best.1] = true;
        chosen.push(best.1);
        total += best.0.sqrt();
    }
    (chosen, total / targets.len().max(1) as f64)
}

/// Mean, SD and correlations of measured (height, BMI, waist), for reports.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Summary {
    /// Members summarised.
    pub n: usize,
    /// Height mean and SD, metres.
    pub height_m: (f64, f64),
    /// BMI mean and SD.
    pub bmi: (f64, f64),
    /// Waist mean and SD, metres.
    pub waist_m: (f64, f64),
    /// Correlation of BMI and waist.
    pub r_bmi_waist: f64,
    /// 5th and 95th percentile of BMI.
    pub bmi_p5_p95: (f64, f64),
}

/// Summarise measurements.
pub fn summarise(ms: &[Measurements]) -> Summary {
    let n = ms.len().max(1) as f64;
    let mean_sd = |f: &dyn Fn(&Measurements) -> f64| {
        let m = ms.iter().map(f).sum::<f64>() / n;
        let v = ms.iter().map(|x| (f(x) - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        (m, v.sqrt())
    };
    let h = mean_sd(&|m| m.height_m);
    let b = mean_sd(&|m| m.bmi);
    let w = mean_sd(&|m| m.waist_m);
    let cov = ms.iter().map(|x| (x.bmi - b.0) * (x.waist_m - w.0)).sum::<f64>() / (n - 1.0).max(1.0);
    let mut bmis: Vec<f64> = ms.iter().map(|m| m.bmi).collect();
    bmis.sort_by(f64::total_cmp);
    let pct = |p: f64| {
        bmis.get(((bmis.len() as f64 - 1.0) * p).round() as usize)
            .copied()
            .unwrap_or(0.0)
    };
    Summary {
        n: ms.len(),
        height_m: h,
        bmi: b,
        waist_m: w,
        r_bmi_waist: cov / (b.1 * w.1).max(1e-12),
        bmi_p5_p95: (pct(0.05), pct(0.95)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_chacha::ChaCha8Rng;
    use rand_chacha::rand_core::SeedableRng;

    fn m(h: f64, bmi: f64, w: f64) -> Measurements {
        Measurements {
            height_m: h,
            volume_m3: 0.0,
            mass_kg: 0.0,
            bmi,
            waist_m: w,
        }
    }

    #[test]
    fn targets_follow_the_requested_statistics() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let t = draw_targets(&mut rng, &NHANES_MALE, 20000);
        let ms: Vec<Measurements> = t.iter().map(|x| m(x[0], x[1], x[2])).collect();
        let s = summarise(&ms);
        assert!((s.height_m.0 - 1.753).abs() < 0.003 && (s.height_m.1 - 0.075).abs() < 0.003);
        // Truncation at BMI 16 trims the low tail a little.
        assert!(
            (s.bmi.0 - 29.4).abs() < 0.4 && (s.bmi.1 - 6.0).abs() < 0.5,
            "{s:?}"
        );
        assert!((s.r_bmi_waist - 0.9).abs() < 0.03, "{s:?}");
    }

    #[test]
    fn matching_picks_nearest_unused() {
        let pool = [m(1.70, 25.0, 0.9), m(1.80, 30.0, 1.0), m(1.71, 25.0, 0.9)];
        let (idx, _) = match_targets(&[[1.70, 25.0, 0.9], [1.70, 25.0, 0.9]], &pool, &NHANES_MALE);
        assert_eq!(idx, vec![0, 2]);
    }
}
