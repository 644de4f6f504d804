//! `supine-models noise-report`: how close the synthetic Kinect noise is to real frames. Both sides are measured by
//! the same depth-only statistics ([`stats`]) inside one depth window, and every scalar statistic is judged: within
//! 25 % of the real value, or inside the real frames' own spread (min–max over frames), counts as close.
//!
//! Cost: ~3 ms per 640x480 frame measured, plus decoding ([`sources`]).

pub mod cli;
pub mod plot;
pub mod sources;
pub mod stats;

use serde::Serialize;
use stats::{ANGLE_BINS_DEG, Counts, DEPTH_BINS_MM, STEP_BANDS_MM, histogram_median, hole_width_fit};

/// Relative tolerance of the comparison.
pub const TOLERANCE: f64 = 0.25;

/// One side of the report (real or synthetic).
#[derive(Debug, Clone, Serialize)]
pub struct Side {
    /// What was read.
    pub source: String,
    /// Frames measured.
    pub frames: u32,
    /// Pooled counts over all frames.
    pub counts: Counts,
    /// The judged statistics, pooled over all frames.
    pub scalars: Vec<(String, Option<f64>)>,
    /// Per statistic: `[min, max]` over single frames (`None` where no frame defines it).
    pub spread: Vec<Option<[f64; 2]>>,
    /// Invalid share of smooth-surface pixels per incidence-angle bin ([`ANGLE_BINS_DEG`]).
    pub invalid_by_angle: Vec<Option<f64>>,
    /// Invalid share of smooth-surface pixels per depth bin ([`DEPTH_BINS_MM`]).
    pub invalid_by_depth: Vec<Option<f64>>,
}

/// One judged statistic side by side.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Statistic name.
    pub statistic: String,
    /// Pooled real value.
    pub real: Option<f64>,
    /// Real per-frame `[min, max]`.
    pub real_spread: Option<[f64; 2]>,
    /// Pooled synthetic value.
    pub synthetic: Option<f64>,
    /// Synthetic relative to real, minus one.
    pub relative_error: Option<f64>,
    /// Within 25 % of the real value or inside the real spread (`None` where either side lacks it, and for the
    /// scene statistics, [`SCENE_STATISTICS`]).
    pub close: Option<bool>,
}

/// The whole report.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Depth window of the comparison, mm.
    pub window_mm: [u16; 2],
    /// A depth step larger than this is a jump, mm.
    pub jump_mm: u16,
    /// Angle bin upper bounds, degrees.
    pub angle_bins_deg: Vec<f32>,
    /// Depth bin upper bounds, mm.
    pub depth_bins_mm: Vec<u16>,
    /// Real frames.
    pub real: Side,
    /// Synthetic frames.
    pub synthetic: Side,
    /// The judged statistics side by side.
    pub rows: Vec<Row>,
    /// Rows that are close / rows with both sides defined.
    pub close: [usize; 2],
}

/// The judged scalar statistics of `c`, by name.
pub fn scalars(c: &Counts) -> Vec<(String, Option<f64>)> {
    let some_if = |ok: bool, v: f64| ok.then_some(v);
    let smooth: u64 = c.smooth_holes.iter().sum();
    let right: u64 = c.edge_holes_near_right.iter().sum();
    let left: u64 = c.edge_holes_near_left.iter().sum();
    let big = c.big_holes[0] + c.big_holes[1];
    let mut v = vec![
        (
            "smooth_holes_per_1000_px".to_string(),
            some_if(c.valid_px >= 1000, c.smooth_holes_per_kpx()),
        ),
        (
            "smooth_hole_median_px".into(),
            histogram_median(&c.smooth_holes).map(f64::from),
        ),
        (
            "smooth_hole_mean_px".into(),
            some_if(smooth > 0, c.smooth_hole_mean_px()),
        ),
    ];
    for (side, name) in [(0, "right"), (1, "left")] {
        let fit = hole_width_fit(&c.hole_fit[side]);
        v.push((format!("jump_hole_baseline_mm_near_{name}"), fit.map(|f| f.0)));
        v.push((format!("jump_hole_extra_px_near_{name}"), fit.map(|f| f.1)));
    }
    for (band, step) in STEP_BANDS_MM.iter().zip(c.steps_mm()) {
        v.push((format!("quantisation_step_mm_at_{band}"), step.map(f64::from)));
    }
    let border = c.border_mean_px();
    for (i, side) in ["left", "top", "right", "bottom"].iter().enumerate() {
        v.push((format!("registration_border_px_{side}"), border.map(|b| b[i])));
    }
    // Scene content more than sensor (how many and how large the depth steps are, and on which side the near
    // surface lies): reported, not judged.
    v.push((
        "mixed_px_per_jump".into(),
        some_if(c.jumps > 0, c.mixed_per_jump()),
    ));
    v.push((
        "big_jumps_with_hole_share".into(),
        some_if(big + c.big_jumps > 0, c.big_hole_share()),
    ));
    v.push((
        "big_jump_holes_near_right_share".into(),
        some_if(big > 0, c.big_holes_near_right_share()),
    ));
    v.push((
        "jumps_per_1000_px".into(),
        some_if(c.valid_px >= 1000, c.jumps_per_kpx()),
    ));
    v.push((
        "edge_holes_per_jump".into(),
        some_if(c.jumps > 0, c.edge_holes_per_jump()),
    ));
    v.push((
        "edge_holes_near_right_share".into(),
        some_if(right + left > 0, c.edge_holes_near_right_share()),
    ));
    v.push((
        "edge_hole_median_px_near_right".into(),
        histogram_median(&c.edge_holes_near_right).map(f64::from),
    ));
    v.push((
        "edge_hole_median_px_near_left".into(),
        histogram_median(&c.edge_holes_near_left).map(f64::from),
    ));
    let bands = &c.big_by_band;
    let (near_right, all_big) = bands
        .iter()
        .fold((0, 0), |(r, a), x| (r + x[0] + x[2], a + x.iter().sum::<u64>()));
    v.push((
        "big_discontinuities_near_right_share".into(),
        some_if(all_big > 0, near_right as f64 / all_big.max(1) as f64),
    ));
    let gaps = &c.jumps_by_gap;
    let flat = |g: &[[u64; 4]]| {
        let (m, n) = g.iter().fold((0, 0), |(m, n), x| (m + x[3], n + x[2]));
        some_if(n >= 20, m as f64 / n.max(1) as f64)
    };
    v.push(("mixed_px_per_flat_jump".into(), flat(gaps)));
    // The sensor's own properties: split by step size and side, where the scenes' different mixes of steps (and
    // of near sides) no longer enter. A band or side with under 20 steps is left undefined.
    // Per band: `[jumps near right, jumps near left, holes near right, holes near left]`.
    let share = |b: &[[u64; 4]], side: usize| {
        let (holes, all) = b
            .iter()
            .fold((0, 0), |(h, a), x| (h + x[2 + side], a + x[2 + side] + x[side]));
        some_if(all >= 20, holes as f64 / all.max(1) as f64)
    };
    for (name, b) in [
        ("0.10_0.15", &bands[0..1]),
        ("0.15_0.25", &bands[1..2]),
        ("0.25_up", &bands[2..]),
    ] {
        for (side, s) in ["right", "left"].iter().enumerate() {
            v.push((
                format!("big_jumps_with_hole_share_{name}_near_{s}"),
                share(b, side),
            ));
        }
    }
    v.push(("mixed_px_per_flat_jump_80_160mm".into(), flat(&gaps[0..1])));
    v.push(("mixed_px_per_flat_jump_160_320mm".into(), flat(&gaps[1..2])));
    v.push(("mixed_px_per_flat_jump_320mm_up".into(), flat(&gaps[2..])));
    v
}

/// Statistics that depend on the scene's content more than on the sensor: shown, not judged. The pooled mixed
/// pixels and hole shares count every step the scene has (a patient's bed seen obliquely has many steep slopes and
/// small steps, people standing before a far background have large flat-sided steps, and more near-left ones); the
/// same properties split by step size and side are judged instead.
pub const SCENE_STATISTICS: [&str; 10] = [
    "mixed_px_per_jump",
    "big_jumps_with_hole_share",
    "big_jump_holes_near_right_share",
    "jumps_per_1000_px",
    "edge_holes_per_jump",
    "edge_holes_near_right_share",
    "edge_hole_median_px_near_right",
    "edge_hole_median_px_near_left",
    "big_discontinuities_near_right_share",
    "mixed_px_per_flat_jump",
];

/// Build one side from per-frame counts.
pub fn side(source: String, frames: &[Counts]) -> Side {
    let mut pooled = Counts::new();
    for f in frames {
        pooled.add(f);
    }
    let mut values = scalars(&pooled);
    let per_frame: Vec<Vec<Option<f64>>> = frames
        .iter()
        .map(|f| scalars(f).into_iter().map(|(_, v)| v).collect())
        .collect();
    // Quantisation levels of frames from different devices interleave when pooled: the median of frames instead.
    for (i, (name, v)) in values.iter_mut().enumerate() {
        if name.starts_with("quantisation_step") {
            let mut vals: Vec<f64> = per_frame.iter().filter_map(|p| p[i]).collect();
            vals.sort_by(f64::total_cmp);
            *v = (!vals.is_empty()).then(|| vals[vals.len() / 2]);
        }
    }
    let spread = (0..values.len())
        .map(|i| {
            let vals: Vec<f64> = per_frame.iter().filter_map(|p| p[i]).collect();
            (!vals.is_empty()).then(|| {
                [
                    vals.iter().cloned().fold(f64::INFINITY, f64::min),
                    vals.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
                ]
            })
        })
        .collect();
    Side {
        source,
        frames: pooled.frames,
        invalid_by_angle: Counts::invalid_fraction(&pooled.by_angle),
        invalid_by_depth: Counts::invalid_fraction(&pooled.by_depth),
        counts: pooled,
        scalars: values,
        spread,
    }
}

/// Compare the two sides.
pub fn compare(window_mm: [u16; 2], real: Side, synthetic: Side) -> Report {
    let rows: Vec<Row> = real
        .scalars
        .iter()
        .zip(&real.spread)
        .zip(&synthetic.scalars)
        .map(|(((name, r), spread), (_, s))| {
            let relative_error = match (r, s) {
                (Some(r), Some(s)) if *r != 0.0 => Some(s / r - 1.0),
                _ => None,
            };
            let close = match (r, s) {
                _ if SCENE_STATISTICS.contains(&name.as_str()) => None,
                (Some(r), Some(s)) => Some(
                    (s - r).abs() <= TOLERANCE * r.abs() + 1e-9
                        || spread.is_some_and(|[lo, hi]| (lo..=hi).contains(s)),
                ),
                _ => None,
            };
            Row {
                statistic: name.clone(),
                real: *r,
                real_spread: *spread,
                synthetic: *s,
                relative_error,
                close,
            }
        })
        .collect();
    let defined = rows.iter().filter(|r| r.close.is_some()).count();
    let ok = rows.iter().filter(|r| r.close == Some(true)).count();
    Report {
        window_mm,
        jump_mm: stats::JUMP_MM,
        angle_bins_deg: ANGLE_BINS_DEG.to_vec(),
        depth_bins_mm: DEPTH_BINS_MM.to_vec(),
        real,
        synthetic,
        rows,
        close: [ok, defined],
    }
}

impl Report {
    /// The report as a Markdown table (what `docs/noise-report.md` holds).
    pub fn markdown(&self) -> String {
        let f = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
        let mut s = format!(
            "Real: {} ({} frames). Synthetic: {} ({} frames). Depth window {}–{} mm, jump > {} mm.\n\n\
             | statistic | real | real spread (per frame) | synthetic | synthetic/real − 1 | close |\n\
             | --- | --- | --- | --- | --- | --- |\n",
            self.real.source,
            self.real.frames,
            self.synthetic.source,
            self.synthetic.frames,
            self.window_mm[0],
            self.window_mm[1],
            self.jump_mm
        );
        for r in &self.rows {
            s += &format!(
                "| {} | {} | {} | {} | {} | {} |\n",
                r.statistic,
                f(r.real),
                r.real_spread
                    .map_or("–".into(), |[a, b]| format!("{a:.3} – {b:.3}")),
                f(r.synthetic),
                r.relative_error
                    .map_or("–".into(), |e| format!("{:+.0} %", 100.0 * e)),
                match r.close {
                    Some(true) => "yes",
                    Some(false) => "**no**",
                    None if SCENE_STATISTICS.contains(&r.statistic.as_str()) => "(scene)",
                    None => "–",
                }
            );
        }
        s += &format!("\n{} of {} statistics close.\n\n", self.close[0], self.close[1]);
        s += "| invalid share of smooth surfaces | real | synthetic |\n| --- | --- | --- |\n";
        let mut lo = 0.0;
        for (i, b) in ANGLE_BINS_DEG.iter().enumerate() {
            s += &format!(
                "| incidence {lo:.0}–{b:.0}° | {} | {} |\n",
                f(self.real.invalid_by_angle[i]),
                f(self.synthetic.invalid_by_angle[i])
            );
            lo = *b;
        }
        let mut lo = 0u16;
        for (i, b) in DEPTH_BINS_MM.iter().enumerate() {
            let hi = if *b == u16::MAX {
                "…".to_string()
            } else {
                format!("{b}")
            };
            s += &format!(
                "| depth {lo}–{hi} mm | {} | {} |\n",
                f(self.real.invalid_by_depth[i]),
                f(self.synthetic.invalid_by_depth[i])
            );
            lo = *b;
        }
        s
    }
}
