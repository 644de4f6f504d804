//! The calibration figure (docs/calibration.svg): translation, rotation and torso-mapping error against the number
//! of poses, with and without a patient, each sequence a dot and the mean a line. Plain SVG text, no dependency.

use super::calibration::{Outcome, POSE_COUNTS};
use std::fmt::Write;

const PANEL_W: f32 = 260.0;
const PANEL_H: f32 = 200.0;
const MARGIN: f32 = 50.0;

/// One panel: title, the value it plots, its target line (NaN: none).
type Panel = (&'static str, fn(&Outcome) -> Option<f32>, f32);

/// The figure as an SVG document.
pub fn calibration_svg(outcomes: &[Outcome]) -> String {
    let panels: [Panel; 3] = [
        (
            "translation error (mm), target 5",
            |o| o.translation_error_mm,
            5.0,
        ),
        ("rotation error (deg), target 0.3", |o| o.rotation_error_deg, 0.3),
        (
            "probe-mapping error at the torso (mm)",
            |o| o.torso_mapping_error_mm,
            f32::NAN,
        ),
    ];
    let width = MARGIN + 3.0 * (PANEL_W + MARGIN);
    let height = PANEL_H + 2.0 * MARGIN + 20.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" font-size="11">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let series = [
        (true, "#c0392b", "still patient"),
        (false, "#2471a3", "empty bed"),
    ];
    for (i, (title, get, target)) in panels.iter().enumerate() {
        let x0 = MARGIN + i as f32 * (PANEL_W + MARGIN);
        let y0 = MARGIN;
        let values: Vec<f32> = outcomes.iter().filter_map(get).collect();
        let top = values
            .iter()
            .cloned()
            .fold(if target.is_finite() { *target * 1.2 } else { 0.0 }, f32::max)
            .max(1e-3)
            * 1.1;
        let px = |k: usize| x0 + 30.0 + k as f32 * (PANEL_W - 60.0) / (POSE_COUNTS.len() - 1) as f32;
        let py = |v: f32| y0 + PANEL_H - v / top * PANEL_H;
        let _ = writeln!(
            s,
            r##"<rect x="{x0}" y="{y0}" width="{PANEL_W}" height="{PANEL_H}" fill="none" stroke="#444"/>"##
        );
        let _ = writeln!(
            s,
            r#"<text x="{x0}" y="{}" font-weight="bold">{title}</text>"#,
            y0 - 10.0
        );
        for t in 0..=4 {
            let v = top * t as f32 / 4.0;
            let _ = writeln!(
                s,
                r##"<text x="{}" y="{}" text-anchor="end" fill="#444">{v:.2}</text><line x1="{x0}" x2="{}" y1="{y}" y2="{y}" stroke="#ddd"/>"##,
                x0 - 4.0,
                py(v) + 4.0,
                x0 + PANEL_W,
                y = py(v)
            );
        }
        for (k, n) in POSE_COUNTS.iter().enumerate() {
            let _ = writeln!(
                s,
                r#"<text x="{}" y="{}" text-anchor="middle">{n} poses</text>"#,
                px(k),
                y0 + PANEL_H + 16.0
            );
        }
        if target.is_finite() {
            let _ = writeln!(
                s,
                r##"<line x1="{x0}" x2="{}" y1="{y}" y2="{y}" stroke="#27ae60" stroke-dasharray="5,3"/>"##,
                x0 + PANEL_W,
                y = py(*target)
            );
        }
        for (si, (patient, colour, _)) in series.iter().enumerate() {
            let mut line = Vec::new();
            for (k, n) in POSE_COUNTS.iter().enumerate() {
                let vals: Vec<f32> = outcomes
                    .iter()
                    .filter(|o| o.patient == *patient && o.poses == *n)
                    .filter_map(get)
                    .collect();
                let dx = if si == 0 { -5.0 } else { 5.0 };
                for v in &vals {
                    let _ = writeln!(
                        s,
                        r#"<circle cx="{}" cy="{}" r="2.5" fill="{colour}" fill-opacity="0.5"/>"#,
                        px(k) + dx,
                        py(*v)
                    );
                }
                if !vals.is_empty() {
                    line.push(format!(
                        "{},{}",
                        px(k) + dx,
                        py(vals.iter().sum::<f32>() / vals.len() as f32)
                    ));
                }
            }
            if line.len() > 1 {
                let _ = writeln!(
                    s,
                    r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="2"/>"#,
                    line.join(" ")
                );
            }
        }
    }
    for (si, (_, colour, label)) in series.iter().enumerate() {
        let x = MARGIN + si as f32 * 140.0;
        let y = height - 12.0;
        let _ = writeln!(
            s,
            r#"<circle cx="{x}" cy="{}" r="4" fill="{colour}"/><text x="{}" y="{y}">{label} (dots: sequences, line: mean)</text>"#,
            y - 4.0,
            x + 8.0
        );
    }
    s.push_str("</svg>\n");
    s
}
