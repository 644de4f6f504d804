//! `supine-models train joints` and `supine-models eval joints`: argument parsing, progress, the training summary
//! (wall time, peak memory, choices) and the evaluation report (stdout table, `--json`, `--png`).

use super::chart::{Panel, bar_chart};
use super::eval::{Candidate, apart_json, apart_text, evaluate, methods_json, text_table};
use super::refine::RefineParams;
use super::sidecar::FloatLeaves;
use super::train::{TrainConfig, train_on};
use super::tree::TreeParams;
use crate::dataset::Dataset;
use crate::provenance::commit;
use anyhow::{Context, Result, ensure};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use supine_core::forest::infer::Method;
use supine_core::forest::model::ForestView;
use supine_core::salient::SalientPoint;

/// Committed default forest, relative to the workspace root.
pub const DEFAULT_ARTIFACT: &str = "models/artifacts/joints.jfor";

/// Absolute path of the committed default forest.
pub fn default_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("artifacts")
        .join("joints.jfor")
}

/// The float sidecar's path beside a forest file.
pub fn sidecar_path(model: &Path) -> PathBuf {
    let mut s = model.as_os_str().to_owned();
    s.push(".float");
    PathBuf::from(s)
}

/// The quantised baseline's path beside a refined-only forest file (`FILE.baseline`, git-ignored).
pub fn baseline_path(model: &Path) -> PathBuf {
    let mut s = model.as_os_str().to_owned();
    s.push(".baseline");
    PathBuf::from(s)
}

/// Arguments of `convert joints`.
#[derive(Debug, clap::Args)]
pub struct ConvertJointsArgs {
    /// The forest to re-encode (`JFOR` version 1, or version 2).
    #[arg(long = "in")]
    pub input: PathBuf,
    /// The version 2 file to write, refined leaves only (what the head computer ships).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write a version 2 file with the baseline leaves kept (for `eval joints`: name it OUT.baseline).
    #[arg(long)]
    pub baseline_out: Option<PathBuf>,
}

/// Run `convert joints`: re-encode a forest as `JFOR` version 2 and check that inference reads the same bits.
pub fn run_convert(a: &ConvertJointsArgs) -> Result<()> {
    use super::encode::{Quantised, V1Forest, check_same_inference};
    let bytes = std::fs::read(&a.input).with_context(|| format!("reading {}", a.input.display()))?;
    let q = match ForestView::parse(&bytes) {
        Ok(v) => {
            ensure!(
                v.has_baseline() || a.baseline_out.is_none(),
                "{} stores no baseline leaves",
                a.input.display()
            );
            from_view(&v)
        }
        Err(supine_core::model_file::ModelFileError::UnsupportedKindVersion { found: 1, .. }) => {
            Quantised::from_v1(&bytes).with_context(|| format!("reading {}", a.input.display()))?
        }
        Err(e) => return Err(anyhow::anyhow!("loading {}: {e}", a.input.display())),
    };
    let per_tree: Vec<u32> = q
        .tree_start
        .iter()
        .enumerate()
        .map(|(t, &s)| q.tree_start.get(t + 1).copied().unwrap_or(q.nodes.len() as u32) - s)
        .collect();
    let old = V1Forest::new(&q);
    let mut outputs = vec![(a.out.clone(), false)];
    if let Some(b) = &a.baseline_out {
        outputs.push((b.clone(), true));
    }
    for (path, baseline) in outputs {
        let mut part = q.clone();
        if !baseline {
            part.baseline = None;
        }
        let out = part.to_bytes()?;
        let view = ForestView::parse(&out).context("the converted forest does not validate")?;
        let exact = view.vote_shift() == 0;
        if exact {
            let n = check_same_inference(&old, &view, &per_tree, baseline)?;
            eprintln!(
                "checked: {} nodes and {n} leaf votes read back bit for bit",
                q.nodes.len()
            );
        } else {
            eprintln!(
                "note: refined weights exceed ±2047 mm, stored in {} mm units (not bit-identical)",
                1 << view.vote_shift()
            );
        }
        std::fs::write(&path, &out).with_context(|| format!("writing {}", path.display()))?;
        println!(
            "wrote {} ({} bytes, JFOR v{}, {}) from {} ({} bytes)",
            path.display(),
            out.len(),
            supine_core::forest::model::VERSION,
            if baseline {
                "refined and baseline leaves"
            } else {
                "refined leaves only"
            },
            a.input.display(),
            bytes.len()
        );
    }
    Ok(())
}

/// A version 2 file back in the writer's integer form.
fn from_view(v: &ForestView<'_>) -> super::encode::Quantised {
    use supine_core::forest::MODES;
    use supine_core::forest::model::{ForestModel, Node};
    const P: usize = SalientPoint::COUNT;
    let starts = v.tree_starts();
    let mut nodes = Vec::with_capacity(v.node_count());
    for t in 0..v.tree_count() {
        for i in 0..starts[t + 1] - starts[t] {
            nodes.push(match v.node(t, i) {
                Node::Leaf(l) => (None, l),
                Node::Split { test, left } => (Some(test), left),
            });
        }
    }
    let mut refined_mm = Vec::new();
    let mut rcon = Vec::new();
    let mut bvot = Vec::new();
    let mut bwgt = Vec::new();
    for l in 0..v.leaf_count() as u32 {
        for p in 0..P {
            refined_mm.extend(v.refined_raw(l, p).map(|q| q << v.vote_shift()));
            rcon.push(v.confidence_code(l, p));
            for m in 0..MODES {
                let b = v.baseline(l, p, m);
                bvot.extend(b.offset.map(|x| (x * 1000.0).round() as i16));
                bwgt.push((b.weight * 255.0).round() as u8);
            }
        }
    }
    let parm = (0..P)
        .flat_map(|p| {
            let q = v.params(p);
            [q.refined_bandwidth_m, q.baseline_bandwidth_m, q.vote_length_m]
        })
        .collect();
    super::encode::Quantised {
        samples: v.samples_per_frame() as u32,
        tree_start: starts[..v.tree_count()].to_vec(),
        nodes,
        refined_mm,
        rcon,
        baseline: v.has_baseline().then_some((bvot, bwgt)),
        parm,
        meta: v.meta().unwrap_or("").to_owned(),
    }
}

/// Arguments of `train joints`.
#[derive(Debug, clap::Args)]
pub struct TrainJointsArgs {
    /// Dataset directory (`supine-models dataset`); only its training split is read.
    #[arg(long)]
    pub data: PathBuf,
    /// Output forest [default: models/artifacts/joints.jfor]; the float leaves go to FILE.float.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seed (the same seed and data give the same bytes whatever --threads).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Trees.
    #[arg(long, default_value_t = 3)]
    pub trees: usize,
    /// Maximum tree depth.
    #[arg(long, default_value_t = 24)]
    pub depth: usize,
    /// Candidate tests per split.
    #[arg(long, default_value_t = 128)]
    pub candidates: usize,
    /// Fewest samples a node needs to split.
    #[arg(long, default_value_t = 50)]
    pub min_split: usize,
    /// Training samples per image.
    #[arg(long, default_value_t = 512)]
    pub samples: usize,
    /// Samples per frame the trained forest asks for at inference (stored in the file) [default: --samples].
    #[arg(long)]
    pub infer_samples: Option<usize>,
    /// Probe offsets are drawn within ±this many pixel·metres (px at 1 m; at most 127, the file's i8).
    #[arg(long, default_value_t = 50)]
    pub offset_px_m: i32,
    /// Split thresholds are drawn within ±this many millimetres (at most 127, the file's i8).
    #[arg(long, default_value_t = 50)]
    pub threshold_mm: i32,
    /// Most fitting images each tree is grown on (bounds memory for large datasets).
    #[arg(long, default_value_t = 800)]
    pub tree_images: usize,
    /// Share of the nodes of mixed classes split by the body samples' offset variance toward the six points
    /// instead of the class entropy, drawn per node as Hough forests do; 0: the classification structure of
    /// Shotton et al. throughout.
    #[arg(long, default_value_t = 0.0)]
    pub offset_objective_share: f32,
    /// Split a node of one body part further by its samples' offsets instead of making it a leaf.
    #[arg(long)]
    pub pure_by_offsets: bool,
    /// Read the training views through the tracker's height ceiling: depth more than this many metres above the
    /// bed planes is no depth, as the tracker's forest reads it (0: the views as rendered).
    #[arg(long, default_value_t = supine_core::tracker::FOREST_CEILING_M)]
    pub ceiling_m: f32,
    /// Refinement epochs.
    #[arg(long, default_value_t = 48)]
    pub epochs: usize,
    /// Refinement: initial learning rate.
    #[arg(long, default_value_t = 1.0)]
    pub lr: f32,
    /// Refinement: momentum.
    #[arg(long, default_value_t = 0.8)]
    pub momentum: f32,
    /// Refinement: λ1, weight of the image term (Eq. 4).
    #[arg(long, default_value_t = 1e-3)]
    pub lambda1: f32,
    /// Refinement: λ2, weight of the per-sample term (Eq. 4); Table 1 says 1e-4, 1e-2 won on the validation bodies.
    /// One value, or six comma-separated ones, one per salient point (head, left and right shoulder, belly, left and
    /// right hip).
    #[arg(long, value_delimiter = ',', default_value = "1e-2")]
    pub lambda2: Vec<f32>,
    /// Refinement: L2 strength per step.
    #[arg(long, default_value_t = 1e-5)]
    pub l2: f32,
    /// Baseline vote length threshold, metres.
    #[arg(long, default_value_t = 0.5)]
    pub vote_length: f32,
    /// Share of the training bodies held out for validation choices.
    #[arg(long, default_value_t = 0.15)]
    pub validation_fraction: f32,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write the training summary (JSON) here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Reuse the trees of this forest file (skips tree growing; leaves, refinement and choices are recomputed).
    #[arg(long)]
    pub structure: Option<PathBuf>,
}

/// Arguments of `eval joints`.
#[derive(Debug, clap::Args)]
pub struct EvalJointsArgs {
    /// Dataset directory; its test split is evaluated.
    #[arg(long)]
    pub data: PathBuf,
    /// Forest file [default: models/artifacts/joints.jfor] (FILE.float, when present, gives the float rows).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Seed of the per-view pixel sampling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Samples per view [default: what the forest was trained with].
    #[arg(long)]
    pub samples: Option<usize>,
    /// Read the test views through the tracker's height ceiling over the bed planes, metres (0: as rendered).
    #[arg(long, default_value_t = supine_core::tracker::FOREST_CEILING_M)]
    pub ceiling_m: f32,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write the report (JSON) here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the bar chart (PNG) here.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// Peak resident set size of this process in MiB (Linux `VmHWM`), if known.
pub fn peak_rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(t) = threads {
        ensure!(t > 0, "--threads must be at least 1");
        b = b.num_threads(t);
    }
    Ok(b.build()?)
}

/// Run `train joints`.
pub fn run_train(a: &TrainJointsArgs) -> Result<()> {
    let start = std::time::Instant::now();
    ensure!(
        a.samples > 0 && a.depth > 0 && a.candidates > 0,
        "--samples, --depth and --candidates must be positive"
    );
    ensure!(
        (0.0..=1.0).contains(&a.offset_objective_share),
        "--offset-objective-share must be in [0, 1]"
    );
    ensure!(
        a.lambda1 > 0.0
            && a.lambda2.iter().all(|&l| l >= 0.0)
            && a.l2 >= 0.0
            && a.lr > 0.0
            && (0.0..1.0).contains(&a.momentum),
        "refinement parameters out of range"
    );
    ensure!(
        a.vote_length > 0.0 && a.vote_length <= 10.0,
        "--vote-length must be in (0, 10] m"
    );
    ensure!(
        (0.0..1.0).contains(&a.validation_fraction),
        "--validation-fraction must be in [0, 1)"
    );
    let ds = Dataset::open(&a.data)?;
    let cfg = TrainConfig {
        seed: a.seed,
        trees: a.trees,
        samples_per_image: a.samples,
        tree: TreeParams {
            max_depth: a.depth,
            candidates: a.candidates,
            min_split: a.min_split.max(2),
            offset_px_m: a.offset_px_m,
            threshold_mm: a.threshold_mm,
            offset_objective_share: a.offset_objective_share,
            pure_by_offsets: a.pure_by_offsets,
        },
        infer_samples: a.infer_samples,
        tree_images: a.tree_images.max(1),
        validation_fraction: a.validation_fraction,
        refine: RefineParams {
            epochs: a.epochs,
            lr: a.lr,
            momentum: a.momentum,
            lambda1: a.lambda1,
            lambda2: a.lambda2[0],
            lambda2_points: match a.lambda2.len() {
                1 => None,
                n if n == SalientPoint::COUNT => Some(core::array::from_fn(|p| a.lambda2[p])),
                n => anyhow::bail!(
                    "--lambda2 takes one value or {} (one per salient point), not {n}",
                    SalientPoint::COUNT
                ),
            },
            l2: a.l2,
            ..RefineParams::default()
        },
        vote_length_m: a.vote_length,
        ceiling_m: a.ceiling_m,
        ..TrainConfig::default()
    };
    let structure = match &a.structure {
        Some(p) => {
            let b = std::fs::read(p).with_context(|| format!("reading {}", p.display()))?;
            let v = ForestView::parse(&b).with_context(|| format!("loading {}", p.display()))?;
            Some(super::tree::trees_from_view(&v)?)
        }
        None => None,
    };
    let (forest, summary) = pool(a.threads)?.install(|| train_on(&ds, &cfg, structure, true))?;
    let out = a.out.clone().unwrap_or_else(default_path);
    let meta = json!({
        "command": std::env::args().collect::<Vec<_>>().join(" "),
        "seed": a.seed,
        "config": cfg,
        "dataset": {"bodies": ds.manifest.config.bodies, "views": ds.manifest.config.views,
                    "seed": ds.manifest.config.seed, "body_source": ds.manifest.body_source},
        "commit": commit(),
        "error_scale_m": forest.error_scale_m,
    });
    let bytes = forest.to_shipped_bytes(&meta.to_string())?;
    let view = ForestView::parse(&bytes).context("the written forest does not validate")?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    let side = super::sidecar::to_bytes(&forest, view.file().crc())?;
    std::fs::write(sidecar_path(&out), &side)?;
    let wall = start.elapsed().as_secs_f64();
    let rss = peak_rss_mib();
    let report = json!({
        "model": out.display().to_string(),
        "model_bytes": bytes.len(),
        "float_sidecar_bytes": side.len(),
        "nodes": forest.node_count(),
        "leaves": forest.leaf_count(),
        "wall_s": wall,
        "peak_rss_mib": rss,
        "threads": rayon::current_num_threads(),
        "summary": summary,
        "params": forest.params.iter().enumerate().map(|(p, x)| json!({
            "point": SalientPoint::ALL[p].name(),
            "refined_bandwidth_m": x.refined_bandwidth_m,
            "baseline_bandwidth_m": x.baseline_bandwidth_m,
            "vote_length_m": x.vote_length_m})).collect::<Vec<_>>(),
        "seed": a.seed,
        "commit": commit(),
    });
    println!(
        "trained {} trees ({} nodes, {} leaves) on {} images ({} validation) in {:.0} s, peak RSS {} MiB",
        forest.trees.len(),
        forest.node_count(),
        forest.leaf_count(),
        summary.fit_images,
        summary.validation_images,
        wall,
        rss.map_or("?".into(), |r| format!("{r:.0}"))
    );
    println!(
        "E_l scale per point {:?} m (validation); wrote {} ({} bytes) and its float leaves ({} bytes)",
        forest.error_scale_m,
        out.display(),
        bytes.len(),
        side.len()
    );
    if let Some(j) = &a.json {
        std::fs::write(j, serde_json::to_vec_pretty(&report)?)?;
    }
    Ok(())
}

/// Run `eval joints`.
pub fn run_eval(a: &EvalJointsArgs) -> Result<()> {
    super::data::check_ceiling(a.ceiling_m)?;
    let ds = Dataset::open(&a.data)?;
    let path = a.model.clone().unwrap_or_else(default_path);
    let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let view = ForestView::parse(&bytes).with_context(|| format!("loading {}", path.display()))?;
    let side_path = sidecar_path(&path);
    let float = match std::fs::read(&side_path) {
        Ok(b) => {
            Some(FloatLeaves::parse(view, &b).with_context(|| format!("loading {}", side_path.display()))?)
        }
        Err(_) => None,
    };
    let samples = a.samples.unwrap_or(view.samples_per_frame());
    ensure!(
        (1..=supine_core::forest::MAX_SAMPLES).contains(&samples),
        "--samples must be 1..={}",
        supine_core::forest::MAX_SAMPLES
    );
    // The baseline leaves: float from the sidecar, else quantised from the file itself or from FILE.baseline (a
    // version 2 file with the same trees and the baseline kept, which `convert joints --baseline-out` writes).
    let base_path = baseline_path(&path);
    let base_bytes = match (&float, view.has_baseline()) {
        (None, false) => std::fs::read(&base_path).ok(),
        _ => None,
    };
    let base_view = match &base_bytes {
        Some(b) => {
            let v = ForestView::parse(b).with_context(|| format!("loading {}", base_path.display()))?;
            ensure!(
                v.has_baseline(),
                "{} stores no baseline leaves",
                base_path.display()
            );
            let starts = view.tree_starts();
            let per_tree: Vec<u32> = starts.windows(2).map(|w| w[1] - w[0]).collect();
            ensure!(
                v.tree_starts() == starts,
                "{} holds other trees than {}",
                base_path.display(),
                path.display()
            );
            super::encode::check_same_inference(&view, &v, &per_tree, false)
                .with_context(|| format!("{} does not belong to {}", base_path.display(), path.display()))?;
            Some(v)
        }
        None => None,
    };
    let mut cands = Vec::new();
    match &float {
        Some(f) => {
            cands.push(Candidate {
                name: "baseline",
                model: f,
                method: Method::Baseline,
            });
            cands.push(Candidate {
                name: "refined",
                model: f,
                method: Method::Refined,
            });
        }
        None => {
            let baseline: Option<&(dyn supine_core::forest::model::ForestModel + Sync)> =
                if view.has_baseline() {
                    Some(&view)
                } else {
                    base_view
                        .as_ref()
                        .map(|v| v as &(dyn supine_core::forest::model::ForestModel + Sync))
                };
            match baseline {
                Some(b) => {
                    eprintln!(
                        "note: no {} beside the forest: `baseline` uses quantised baseline leaves and `refined` \
                         equals `quantised`",
                        side_path.display()
                    );
                    cands.push(Candidate {
                        name: "baseline",
                        model: b,
                        method: Method::Baseline,
                    });
                }
                None => eprintln!(
                    "note: neither {} nor {} beside the forest, and the file ships refined leaves only: no \
                     `baseline` row (`convert joints --baseline-out` writes one from a version 1 file)",
                    side_path.display(),
                    base_path.display()
                ),
            }
            cands.push(Candidate {
                name: "refined",
                model: &view,
                method: Method::Refined,
            });
        }
    }
    cands.push(Candidate {
        name: "quantised",
        model: &view,
        method: Method::Refined,
    });
    let ev = pool(a.threads)?.install(|| evaluate(&ds, &cands, a.seed, samples, a.ceiling_m, true))?;
    let (table, images) = (ev.table, ev.images);
    print!("{}", text_table(&cands, &table));
    let mut report = methods_json(&cands, &table);
    // Only meaningful against the float leaves (without them `refined` is the quantised file itself).
    if let (Some(apart), Some(_)) = (&ev.apart, &float) {
        print!("{}", apart_text(apart));
        report.insert("quantisation".into(), Value::Object(apart_json(apart)));
    }
    let commit = commit();
    report.insert("seed".into(), json!(a.seed));
    report.insert("images".into(), json!(images));
    report.insert("commit".into(), json!(commit));
    report.insert("model_bytes".into(), json!(bytes.len()));
    report.insert("model".into(), json!(path.display().to_string()));
    report.insert("float_leaves".into(), json!(float.is_some()));
    report.insert("samples_per_view".into(), json!(samples));
    report.insert("ceiling_m".into(), json!(a.ceiling_m));
    report.insert("test_bodies".into(), json!(ds.test.len()));
    report.insert(
        "dataset".into(),
        json!({"dir": a.data.display().to_string(), "bodies": ds.manifest.config.bodies,
               "views": ds.manifest.config.views, "seed": ds.manifest.config.seed,
               "body_source": ds.manifest.body_source}),
    );
    if let Some(m) = view.meta().and_then(|m| serde_json::from_str::<Value>(m).ok()) {
        report.insert("model_meta".into(), m);
    }
    println!(
        "{images} test views of {} bodies, seed {}, commit {commit}, model {} bytes",
        ds.test.len(),
        a.seed,
        bytes.len()
    );
    if let Some(j) = &a.json {
        std::fs::write(j, serde_json::to_vec_pretty(&report)?)?;
    }
    if let Some(p) = &a.png {
        let short = ["HEAD", "L SHOULDER", "R SHOULDER", "BELLY", "L HIP", "R HIP"];
        let panel = |title: &str, f: &dyn Fn(&super::eval::Acc) -> f32, max: f32, dec: usize| Panel {
            title: title.into(),
            max,
            decimals: dec,
            groups: (0..SalientPoint::COUNT)
                .map(|pt| {
                    (
                        short[pt].to_string(),
                        table.iter().map(|t| f(&t[0][pt])).collect(),
                    )
                })
                .collect(),
        };
        let max_rmse = table
            .iter()
            .flat_map(|t| t[0].iter().map(|a| a.rmse_mm() as f32))
            .fold(10.0f32, f32::max);
        let names: Vec<String> = cands.iter().map(|c| c.name.to_uppercase()).collect();
        let names: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
        bar_chart(
            p,
            &format!("JOINT FOREST, {images} HELD-OUT VIEWS ({} BODIES)", ds.test.len()),
            &names,
            &[
                panel("DETECTION RATE WITHIN 3 CM", &|a| a.detect_3cm() as f32, 1.0, 2),
                panel(
                    "RMSE (MM)",
                    &|a| a.rmse_mm() as f32,
                    (max_rmse * 1.15 / 10.0).ceil() * 10.0,
                    0,
                ),
            ],
        )?;
    }
    Ok(())
}
