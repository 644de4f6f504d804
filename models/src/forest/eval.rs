//! Evaluation of joint forests on the held-out test bodies (paper Fig. 6): per method and salient point the
//! detection rate within 3 cm (Fig. 6a) and within 10 cm (Shotton/Girshick), the RMSE (Fig. 6b) and the mean 3D
//! error, over all views and apart for views with and without the robot arm. Single frames, no prior. Every
//! method sees the same sampled pixels of a view (same seed). Where both `refined` (float leaves) and `quantised`
//! are evaluated, it also counts the views where the two answer more than 2 cm / 5 cm apart: the quantisation's
//! cost in views that change, which a few gross-error flips hide in an RMSE. Cost: one inference per view and
//! method.

use super::data::view_planes;
use super::train::image_seed;
use crate::dataset::Dataset;
use anyhow::{Result, ensure};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use serde_json::{Map, Value, json};
use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;
use supine_core::forest::infer::{InferConfig, Method, Workspace, estimate_above};
use supine_core::forest::model::ForestModel;
use supine_core::salient::SalientPoint;
use supine_core::time::Timestamp;

const P: usize = SalientPoint::COUNT;
/// Subsets reported.
pub const SUBSETS: [&str; 3] = ["all", "with_arm", "without_arm"];

/// One method to evaluate: its report name, forest and which leaves vote.
pub struct Candidate<'a> {
    /// `baseline`, `refined` or `quantised`.
    pub name: &'static str,
    /// The forest.
    pub model: &'a (dyn ForestModel + Sync),
    /// Which leaves vote.
    pub method: Method,
}

/// Error sums of one (method, subset, point).
#[derive(Debug, Clone, Copy, Default)]
pub struct Acc {
    /// Views.
    pub n: u32,
    /// Within 3 cm.
    pub n3: u32,
    /// Within 10 cm.
    pub n10: u32,
    /// Views without an estimate.
    pub missing: u32,
    /// Sum of errors, m.
    pub sum: f64,
    /// Sum of squared errors, m^2.
    pub sum2: f64,
}

impl Acc {
    fn add(&mut self, e: Option<f32>) {
        self.n += 1;
        match e {
            None => self.missing += 1,
            Some(e) => {
                self.n3 += u32::from(e <= 0.03);
                self.n10 += u32::from(e <= 0.10);
                self.sum += e as f64;
                self.sum2 += (e as f64) * (e as f64);
            }
        }
    }
    fn merge(&mut self, o: &Acc) {
        self.n += o.n;
        self.n3 += o.n3;
        self.n10 += o.n10;
        self.missing += o.missing;
        self.sum += o.sum;
        self.sum2 += o.sum2;
    }
    /// Detection rate within 3 cm.
    pub fn detect_3cm(&self) -> f64 {
        self.n3 as f64 / self.n.max(1) as f64
    }
    /// Detection rate within 10 cm.
    pub fn detect_10cm(&self) -> f64 {
        self.n10 as f64 / self.n.max(1) as f64
    }
    /// RMSE over views with an estimate, mm.
    pub fn rmse_mm(&self) -> f64 {
        let k = (self.n - self.missing).max(1) as f64;
        (self.sum2 / k).sqrt() * 1000.0
    }
    /// Mean error over views with an estimate, mm.
    pub fn mean_mm(&self) -> f64 {
        let k = (self.n - self.missing).max(1) as f64;
        self.sum / k * 1000.0
    }
}

/// `acc[method][subset][point]`.
pub type Table = Vec<[[Acc; P]; 3]>;

/// Views where `quantised` answers apart from `refined`, per subset and point.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Apart {
    /// Views where both give an estimate.
    pub both: u32,
    /// Of those, the ones more than 2 cm apart.
    pub over_2cm: u32,
    /// Of those, the ones more than 5 cm apart.
    pub over_5cm: u32,
}

impl Apart {
    fn add(&mut self, d: f32) {
        self.both += 1;
        self.over_2cm += u32::from(d > 0.02);
        self.over_5cm += u32::from(d > 0.05);
    }
    fn merge(&mut self, o: &Apart) {
        self.both += o.both;
        self.over_2cm += o.over_2cm;
        self.over_5cm += o.over_5cm;
    }
}

/// What [`evaluate`] measured.
pub struct Evaluation {
    /// Per method, subset and point.
    pub table: Table,
    /// `quantised` against `refined` (`apart[subset][point]`), when both were evaluated.
    pub apart: Option<[[Apart; P]; 3]>,
    /// Test views.
    pub images: usize,
}

/// Evaluate `cands` on the test split of `ds`.
pub fn evaluate(
    ds: &Dataset,
    cands: &[Candidate<'_>],
    seed: u64,
    samples: usize,
    ceiling_m: f32,
    progress: bool,
) -> Result<Evaluation> {
    ensure!(!ds.test.is_empty(), "the dataset has no test bodies");
    let index = |name| cands.iter().position(|c| c.name == name);
    let pair = index("refined").zip(index("quantised"));
    let k = Intrinsics::KINECT_V1;
    let bar = ProgressBar::with_draw_target(
        Some(ds.test.len() as u64),
        if progress {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    bar.set_style(
        ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message("eval bodies");
    let mut table: Table = vec![[[Acc::default(); P]; 3]; cands.len()];
    let mut apart = [[Apart::default(); P]; 3];
    let mut images = 0usize;
    for chunk in ds.test.chunks(8) {
        let recs: Vec<_> = chunk.par_iter().map(|&b| ds.read_body(b)).collect();
        for rec in recs {
            let rec = rec?;
            let body = rec.truth.body_index;
            let per_view: Vec<(Table, [[Apart; P]; 3])> = rec
                .views
                .par_iter()
                .map_init(
                    || Box::new(Workspace::new()),
                    |ws, v| {
                        let full = v.full_depth(k.width as usize, k.height as usize);
                        let mut t: Table = vec![[[Acc::default(); P]; 3]; cands.len()];
                        let mut a = [[Apart::default(); P]; 3];
                        let Ok(frame) = DepthFrame::new(&full, k.width, k.height, Timestamp::default(), 0)
                        else {
                            return (t, a);
                        };
                        let mut answers = vec![[None; P]; cands.len()];
                        let planes = view_planes(&v.truth);
                        let sub = if v.truth.probe.is_some() { 1 } else { 2 };
                        for (ci, c) in cands.iter().enumerate() {
                            let cfg = InferConfig {
                                samples,
                                seed: image_seed(seed, body, v.truth.view),
                                method: c.method,
                            };
                            let est =
                                estimate_above(c.model, &frame, &k, &planes, ceiling_m, &cfg, &[None; P], ws);
                            for p in 0..P {
                                answers[ci][p] = est[p].map(|x| x.position);
                                let e = est[p].map(|x| {
                                    (x.position.coords - nalgebra::Vector3::from(v.truth.salient_camera[p]))
                                        .norm()
                                });
                                t[ci][0][p].add(e);
                                t[ci][sub][p].add(e);
                            }
                        }
                        if let Some((r, q)) = pair {
                            for p in 0..P {
                                if let (Some(x), Some(y)) = (answers[r][p], answers[q][p]) {
                                    let d = (x - y).norm();
                                    a[0][p].add(d);
                                    a[sub][p].add(d);
                                }
                            }
                        }
                        (t, a)
                    },
                )
                .collect();
            images += per_view.len();
            for (t, a) in per_view {
                for s in 0..3 {
                    for p in 0..P {
                        for (ci, m) in t.iter().enumerate() {
                            table[ci][s][p].merge(&m[s][p]);
                        }
                        apart[s][p].merge(&a[s][p]);
                    }
                }
            }
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    Ok(Evaluation {
        table,
        apart: pair.map(|_| apart),
        images,
    })
}

/// The report's `quantisation` JSON: per subset and point, views where `quantised` and `refined` answer more
/// than 2 cm / 5 cm apart.
pub fn apart_json(apart: &[[Apart; P]; 3]) -> Map<String, Value> {
    let mut out = Map::new();
    for (si, sub) in SUBSETS.iter().enumerate() {
        let mut m = Map::new();
        for (p, a) in apart[si].iter().enumerate() {
            m.insert(
                SalientPoint::ALL[p].name().into(),
                json!({"views": a.both, "apart_2cm": a.over_2cm, "apart_5cm": a.over_5cm}),
            );
        }
        out.insert((*sub).into(), Value::Object(m));
    }
    out
}

/// The stdout lines for [`apart_json`].
pub fn apart_text(apart: &[[Apart; P]; 3]) -> String {
    let mut s = String::from("\n[quantised vs refined: views more than 2 cm / 5 cm apart]\n");
    s += &format!("{:<12}", "subset");
    for p in SalientPoint::ALL {
        s += &format!(" {:>15}", p.name());
    }
    s.push('\n');
    for (si, sub) in SUBSETS.iter().enumerate() {
        s += &format!("{sub:<12}");
        for a in &apart[si] {
            s += &format!(
                " {:>15}",
                format!("{} / {} of {}", a.over_2cm, a.over_5cm, a.both)
            );
        }
        s.push('\n');
    }
    s
}

fn round(x: f64, d: i32) -> f64 {
    let f = 10f64.powi(d);
    (x * f).round() / f
}

fn subset_json(accs: &[Acc; P]) -> Map<String, Value> {
    let mut m = Map::new();
    let mut mean = 0.0;
    let mut missing = 0;
    for (p, a) in accs.iter().enumerate() {
        m.insert(
            SalientPoint::ALL[p].name().into(),
            json!({
                "detect_3cm": round(a.detect_3cm(), 4),
                "detect_10cm": round(a.detect_10cm(), 4),
                "rmse_mm": round(a.rmse_mm(), 2),
                "mean_error_mm": round(a.mean_mm(), 2),
                "views": a.n,
                "missing": a.missing,
            }),
        );
        mean += a.mean_mm() / P as f64;
        missing += a.missing;
    }
    m.insert("mean_error_mm".into(), json!(round(mean, 2)));
    m.insert("views".into(), json!(accs[0].n));
    m.insert("missing".into(), json!(missing));
    m
}

/// The report's per-method JSON (keys of `docs/design/cli.md`).
pub fn methods_json(cands: &[Candidate<'_>], table: &Table) -> Map<String, Value> {
    let mut out = Map::new();
    for (c, t) in cands.iter().zip(table) {
        let mut m = subset_json(&t[0]);
        m.insert("with_arm".into(), Value::Object(subset_json(&t[1])));
        m.insert("without_arm".into(), Value::Object(subset_json(&t[2])));
        out.insert(c.name.into(), Value::Object(m));
    }
    out
}

/// The stdout table.
pub fn text_table(cands: &[Candidate<'_>], table: &Table) -> String {
    let mut s = String::new();
    for (si, sub) in SUBSETS.iter().enumerate() {
        s += &format!(
            "\n[{sub}: {} views]\n{:<10} {:<15} {:>9} {:>10} {:>9} {:>9}\n",
            table[0][si][0].n, "method", "point", "det<3cm", "det<10cm", "rmse_mm", "mean_mm"
        );
        for (c, t) in cands.iter().zip(table) {
            let mut mean = 0.0;
            for p in 0..P {
                let a = &t[si][p];
                mean += a.mean_mm() / P as f64;
                s += &format!(
                    "{:<10} {:<15} {:>9.3} {:>10.3} {:>9.1} {:>9.1}\n",
                    c.name,
                    SalientPoint::ALL[p].name(),
                    a.detect_3cm(),
                    a.detect_10cm(),
                    a.rmse_mm(),
                    a.mean_mm()
                );
            }
            s += &format!("{:<10} {:<15} {:>51.1}\n", c.name, "mean", mean);
        }
    }
    s
}
