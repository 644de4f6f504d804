//! `supine-models eval tracking`'s report on the committed demo sequence with full occlusion: the keys
//! `../shared/design/cli.md` promises, and the per-stage latency (init, forest, ICP, output), which must split each
//! frame's processing time and stay within the whole frame's percentiles.

use clap::Parser;
use serde_json::Value;
use std::ffi::OsString;
use std::path::Path;
use std::process::ExitCode;
use supine_core::tracker::budget::Stage;
use supine_models::eval::tracking::{self, TrackingEvalArgs};

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    args: TrackingEvalArgs,
}

fn ms(v: &Value, path: &str) -> f64 {
    v.pointer(path)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| panic!("{path} missing or not a number"))
}

/// The report of `eval tracking` (the feedback variant, an idle machine's budget, and `extra`) on the committed demo
/// sequence with full occlusion; `tag` names its temporary file.
fn demo_report(tag: &str, extra: &[&str]) -> Value {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("artifacts/demo/occlusion");
    let out = std::env::temp_dir().join(format!("eval-tracking-{tag}-{}.json", std::process::id()));
    let mut args: Vec<OsString> = ["eval-tracking", "--data"].map(OsString::from).to_vec();
    args.push(data.into());
    args.push("--json".into());
    args.push(out.clone().into());
    args.extend(
        ["--variants", "forest_icp_feedback", "--budget-ms", "1000"]
            .iter()
            .chain(extra)
            .map(OsString::from),
    );
    let cli = Cli::parse_from(args);
    assert_eq!(tracking::run(&cli.args), ExitCode::SUCCESS);
    let report: Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let _ = std::fs::remove_file(&out);
    report
}

#[test]
fn the_report_has_the_contracts_keys_and_each_stages_latency() {
    let report = demo_report("report", &[]);
    assert!(report["commit"].is_string());
    let summary = &report["forest_icp_feedback"];
    for key in [
        "frames",
        "tracked_fraction",
        "torso_surface_error_mm_mean",
        "point_error_mm_mean",
        "probe_error_mm_mean",
        "probe_distance_error_mm_mean",
        "recovery_frames",
        "states",
        "latency_ms_p50",
        "latency_ms_p99",
        "budget_overruns",
    ] {
        assert!(!summary[key].is_null(), "summary lacks {key}");
    }
    let seqs = report["sequences"].as_array().unwrap();
    assert_eq!(seqs.len(), 1);
    let one = &seqs[0]["variants"]["forest_icp_feedback"];
    // The stages split every frame's time.
    let frames = one["per_frame"].as_array().unwrap();
    assert_eq!(frames.len(), 88);
    for f in frames {
        let parts: f64 = f["stage_ms"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .sum();
        assert!(
            (parts - f["ms"].as_f64().unwrap()).abs() < 0.01,
            "frame {}: {parts} against {}",
            f["frame"],
            f["ms"]
        );
    }
    // No stage's percentile can exceed the whole frame's (each frame's stage time is at most its total); the
    // tracked frames run the ICP, and the forest runs on the frames that need its start (acquisitions, the full
    // occlusion's frames), a minority of them.
    for st in Stage::ALL.map(Stage::name) {
        for q in ["p50", "p99"] {
            let stage = ms(one, &format!("/stage_ms_{q}/{st}"));
            let total = ms(one, &format!("/latency_ms_{q}"));
            assert!(
                (0.0..=total).contains(&stage),
                "{st} {q}: {stage} ms against the frame's {total}"
            );
            // One sequence: the summary's figure is the sequence's.
            assert_eq!(stage, ms(summary, &format!("/stage_ms_{q}/{st}")), "{st} {q}");
        }
    }
    assert!(ms(one, "/stage_ms_p99/forest") > 0.0);
    assert!(ms(one, "/stage_ms_p50/icp") > 0.0);
    // Pooled over one sequence's frames, the percentiles are the sequence's own.
    for q in ["p50", "p99"] {
        let pooled = ms(summary, &format!("/latency_ms_{q}_pooled"));
        assert_eq!(pooled, ms(one, &format!("/latency_ms_{q}")), "{q}");
    }
    // The demo has one full occlusion; the count of recoveries within the target follows its recovery.
    assert_eq!(summary["full_occlusions"], 1);
    let recovered = u64::from(ms(one, "/recovery_frames") <= 5.0);
    assert_eq!(summary["recovered_within_target"].as_u64(), Some(recovered));
    let held = one["tracked_before_occlusion"]
        .as_bool()
        .expect("the demo has a full occlusion");
    assert_eq!(
        summary["full_occlusions_tracked_before"].as_u64(),
        Some(u64::from(held))
    );
    assert_eq!(
        summary["recovered_within_target_tracked_before"].as_u64(),
        Some(if held { recovered } else { 0 })
    );
    // The demo's patient neither rolls nor shifts: no motion to follow, counted as none.
    assert!(one["motion"].is_null());
    for kind in ["roll", "shift"] {
        assert_eq!(summary["motions_followed"][kind]["of"], 0, "{kind}");
    }
}

#[test]
fn the_oracle_start_fit_is_reported_on_every_fifth_tracked_frame_and_stays_near_the_truth() {
    let report = demo_report("oracle", &["--oracle-start"]);
    let frames = report["sequences"][0]["variants"]["forest_icp_feedback"]["per_frame"]
        .as_array()
        .unwrap();
    let mut near = Vec::new();
    for f in frames {
        let i = f["frame"].as_u64().unwrap() as usize;
        let o = &f["oracle_fit"];
        let expected = i.is_multiple_of(tracking::ORACLE_EVERY) && !f["torso_mm"].is_null();
        assert_eq!(!o.is_null(), expected, "frame {i}: {o}");
        if expected {
            assert!((0.0..=1.0).contains(&ms(o, "/support")), "frame {i}: {o}");
            assert!(ms(o, "/pairs") > 0.0, "frame {i}: {o}");
            // Started at the best rigid pose of a well-tracked patient, the fit stays about as close to the truth
            // as the tracker's own pose.
            near.push(ms(o, "/torso_mm") - ms(f, "/torso_mm"));
        }
    }
    assert!(near.len() >= 5, "{} oracle fits", near.len());
    near.sort_by(f64::total_cmp);
    let median = near[near.len() / 2];
    assert!(
        median.abs() < 3.0,
        "oracle-start fit's torso error minus the tracker's: median {median} mm"
    );
}
