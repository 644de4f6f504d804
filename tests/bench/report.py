#!/usr/bin/env python3
"""Collects what tests/bench/run.sh measured (criterion stage medians, the ICP and forest comparisons, the frame bench
when it exists, instruction counts when asked) into one JSON report with the issue's keys, and writes the Markdown
page (docs/BENCHMARKS.md for a full run) with PNG plots. Only reads files; measures nothing itself.
"""
import argparse
import glob
import json
import os
import platform
import subprocess

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

STAGES = [
    ("clip", "clip: volume of interest over all 307 k pixels"),
    ("forest_sample_descend", "forest: 512 samples, lockstep descent through every tree"),
    ("mean_shift", "mean-shift: votes and six modes"),
    ("forest_total", "forest + mean-shift (`estimate`)"),
    ("canonical_view", "canonical view"),
    ("subspace_projection", "subspace projection"),
    ("icp_iteration", "one ICP iteration (1.2 k torso points)"),
    ("probe_mapping", "probe mapping"),
    ("packet_encode", "packet encode: pose, salient points, probe"),
]
# Stages that make up one tracking frame (forest_total already contains sampling, descent and mean-shift; the
# canonical view and subspace projection run in the init phase only).
# The whole-image clip pass is left out: the forest applies the clip to each sampled pixel (inside `forest_total`)
# and ICP rejects by the mattress plane per model point, so a tracking frame need not visit every pixel.
FRAME_STAGES = ["forest_total", "icp_iteration", "probe_mapping", "packet_encode"]
KINECT_MS = 1000.0 / 30.0
PAPER_MS = 100.0
# Instructions per cycle assumed for the boards (an assumption, not a measurement; see the page).
BOARDS = [("Cortex-A72 at 1.5 GHz (Raspberry Pi 4)", 1.5e9, 1.0), ("Cortex-A76 at 2.4 GHz (Raspberry Pi 5)", 2.4e9, 1.5)]
METHODS = [
    ("supine", "supine (projective point-to-plane, ≤10 iterations, early stop)"),
    ("open3d_default", "Open3D registration_icp point-to-plane, defaults (30 iterations, 1e-6), 0.1 m"),
    ("open3d_tuned", "Open3D point-to-plane, tuned (≤10 iterations, 1e-4, 0.05 m)"),
    ("small_gicp_plane", "small_gicp point-to-plane (k-d tree + normals included), 0.1 m"),
    ("small_gicp_gicp", "small_gicp GICP (k-d tree + covariances included), 0.1 m"),
]


def load(path):
    try:
        with open(path) as f:
            return json.load(f)
    except FileNotFoundError:
        return None


def sh(*cmd):
    try:
        return subprocess.run(cmd, capture_output=True, text=True, check=False).stdout.strip()
    except OSError:
        return ""


def machine():
    model = ""
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    mem = ""
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemTotal"):
                mem = f"{int(line.split()[1]) / 1024 / 1024:.0f} GiB"
    return {"cpu": model, "cores": os.cpu_count(), "memory": mem, "kernel": platform.release(),
            "rustc": sh("rustc", "-V"), "python": platform.python_version(),
            "load_average_at_report": [round(x, 1) for x in os.getloadavg()]}


def criterion_median_ns(group, name):
    est = load(os.path.join("target", "criterion", group, name, "new", "estimates.json"))
    return None if est is None else est["median"]["point_estimate"]


def frame_distribution():
    """p50/p99 (ms) over criterion's samples of the `frame` bench (each sample is a mean over its iterations)."""
    files = sorted(glob.glob(os.path.join("target", "criterion", "frame*", "**", "new", "sample.json"), recursive=True))
    if not files:
        return None, None
    s = load(files[0])
    per = sorted(t / n for t, n in zip(s["times"], s["iters"]))
    pick = lambda q: per[min(len(per) - 1, int(q * len(per)))] / 1e6  # noqa: E731
    return pick(0.5), pick(0.99)


def fmt(x, spec=".2f", none="–"):
    return none if x is None else format(x, spec)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--work", required=True)
    ap.add_argument("--mode", required=True)
    ap.add_argument("--frame-bench", default="")
    ap.add_argument("--seconds", type=int, default=0)
    ap.add_argument("--json", required=True)
    ap.add_argument("--md", required=True)
    ap.add_argument("--png-dir", required=True)
    a = ap.parse_args()
    w = a.work
    icp = load(os.path.join(w, "icp.json"))
    forest = load(os.path.join(w, "forest.json"))
    fsup = load(os.path.join(w, "forest", "supine.json"))
    insn = load(os.path.join(w, "instructions.json"))
    stages = {n: criterion_median_ns("stages", n) for n, _ in STAGES}
    with open(os.path.join(w, "commands.txt")) as f:
        # Relative to the repository root (run.sh runs there), so the page reads the same on every checkout.
        commands = [line.rstrip("\n").replace(os.getcwd() + "/", "") for line in f if line.strip()]
    commit = sh("git", "rev-parse", "--short", "HEAD")
    if sh("git", "status", "--porcelain", "--untracked-files=no"):
        commit += " (with uncommitted changes)"

    report = {"mode": a.mode, "commit": commit, "machine": machine(), "wall_s": a.seconds,
              "stages_ns_median": stages}
    for k in ("icp_speedup_vs_open3d", "icp_speedup_vs_open3d_tuned", "icp_speedup_vs_small_gicp",
              "icp_speedup_vs_small_gicp_gicp", "icp_pose_error_ratio_vs_open3d",
              "icp_pose_error_ratio_vs_open3d_tuned", "icp_pose_error_ratio_vs_small_gicp",
              "icp_pose_error_ratio_vs_small_gicp_gicp"):
        report[k] = icp.get(k) if icp else None
    report["icp_problems"] = icp["problems"] if icp else 0
    report["icp_summary"] = icp["summary"] if icp else None
    for k in ("forest_speedup_vs_sklearn", "forest_size_ratio_vs_sklearn", "forest_train_speedup_vs_sklearn",
              "forest_error_ratio_vs_sklearn"):
        report[k] = forest.get(k) if forest else None
    if forest and fsup:
        report["forest"] = {
            "supine": {k: fsup[k] for k in ("train_s", "model_bytes", "frame_ms_median", "frame_ms_p90",
                                            "joint_error_mm_mean", "joint_error_mm", "train_samples",
                                            "test_images", "nodes", "leaves")},
            "sklearn": {k: forest[k] for k in ("train_s", "model_bytes", "frame_ms_median", "frame_ms_p90",
                                               "joint_error_mm_mean", "joint_error_mm", "nodes")},
            "config": fsup["config"],
            "sklearn_version": forest["sklearn_version"],
        }
    # Whole frame: per-frame samples of `supine frame-bench` (thread CPU time: other processes on the shared machine
    # do not count; wall time beside it), criterion's `frame` bench as a cross-check (means per batch only).
    fb = load(os.path.join(w, "frame_bench.json"))
    crit50 = crit99 = None
    if a.frame_bench:
        crit50, crit99 = frame_distribution()
    report["frame_ms_p50"] = fb["frame_ms_p50"] if fb else None
    report["frame_ms_p99"] = fb["frame_ms_p99"] if fb else None
    report["frame_ms_mean"] = fb["frame_ms_mean"] if fb else None
    report["frame_wall_ms_p50"] = fb["frame_wall_ms_p50"] if fb else None
    report["frame_wall_ms_p99"] = fb["frame_wall_ms_p99"] if fb else None
    report["frame_samples"] = fb["frames"] if fb else 0
    report["frame_criterion_ms_p50"] = crit50
    report["frame_criterion_ms_p99"] = crit99
    report["frame_bench_peak_rss_mib"] = fb["peak_rss_kib"] / 1024 if fb and fb.get("peak_rss_kib") else None
    rss_txt = os.path.join(w, "demo_rss_kib.txt")
    rss = None
    if os.path.exists(rss_txt):
        with open(rss_txt) as f:
            nums = [line.strip() for line in f if line.strip().isdigit()]
            rss = int(nums[-1]) / 1024 if nums else None
    report["frame_peak_rss_mib"] = rss
    if not fb:
        report["frame_missing"] = "supine frame-bench did not run"
    report["frame_instructions_aarch64"] = None
    report["frame_instructions_x86_64"] = None
    report["frame_instructions_x86_64_callgrind"] = None
    if insn:
        by = {x["workload"]: x for x in insn["workloads"]}
        tf = by.get("tracker-frame")
        if tf:
            report["frame_instructions_aarch64"] = tf["aarch64_per_item"]
            report["frame_instructions_x86_64"] = tf["x86_64_per_item"]
            report["frame_instructions_x86_64_callgrind"] = tf["x86_64_callgrind_per_item"]
        demo = by.get("demo-frame")
        report["demo_frame_instructions_aarch64"] = demo["aarch64_per_item"] if demo else None
        report["demo_frame_instructions_x86_64_callgrind"] = demo["x86_64_callgrind_per_item"] if demo else None
        report["instructions_commit"] = insn.get("commit")
    if report["frame_instructions_aarch64"] is None:
        report["frame_instructions_missing"] = (
            "cross/count-instructions did not run (tests/bench/run.sh --no-instructions, or --quick without "
            "--instructions)" if not insn else "no tracker-frame workload in the instruction counts")
    n_a64 = report["frame_instructions_aarch64"]
    report["frame_fps_implied"] = ({b: hz * ipc / n_a64 for b, hz, ipc in BOARDS} if n_a64 else None)
    partial = [stages[n] for n in FRAME_STAGES]
    stage_sum_ms = sum(partial) / 1e6 if all(x is not None for x in partial) else None
    report["existing_stages_sum_ms"] = stage_sum_ms
    report["existing_stages_sum_of"] = FRAME_STAGES
    with open(a.json, "w") as f:
        json.dump(report, f, indent=1)

    os.makedirs(a.png_dir, exist_ok=True)
    rel = os.path.relpath(a.png_dir, os.path.dirname(os.path.abspath(a.md)))
    # Plots.
    names = [n for n, _ in STAGES if stages[n] is not None]
    if names:
        fig, ax = plt.subplots(figsize=(7, 3.6))
        ax.barh(names[::-1], [stages[n] / 1000.0 for n in names][::-1], color="#4878a8")
        ax.set_xscale("log")
        ax.set_xlabel("median µs per call, one core (log)")
        ax.set_title("supine per-frame stages (criterion)")
        fig.tight_layout()
        fig.savefig(os.path.join(a.png_dir, "stages.png"), dpi=110)
        plt.close(fig)
    if icp:
        fig, ax = plt.subplots(figsize=(7, 4.2))
        for (m, label), c in zip(METHODS, ["#d1495b", "#00798c", "#66a182", "#edae49", "#8d6a9f"]):
            xs = [r[m]["time_s"] * 1e3 for r in icp["results"] if not r[m].get("failed")]
            ys = [r[m]["pose_error_mm"] for r in icp["results"] if not r[m].get("failed")]
            ax.scatter(xs, ys, s=14, color=c, label=m, alpha=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ms per registration, one thread (log)")
        ax.set_ylabel("pose error, RMS over model points, mm (log)")
        ax.set_title(f"ICP on {icp['problems']} torso-vs-depth problems")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(os.path.join(a.png_dir, "icp.png"), dpi=110)
        plt.close(fig)
    if forest and fsup:
        fig, axs = plt.subplots(1, 4, figsize=(10, 2.8))
        for ax, (key, label) in zip(axs, [("frame_ms_median", "ms per frame"), ("model_bytes", "model MB"),
                                          ("train_s", "training s"), ("joint_error_mm_mean", "joint error mm")]):
            vals = [fsup[key], forest[key]]
            if key == "model_bytes":
                vals = [v / 1e6 for v in vals]
            ax.bar(["supine", "sklearn"], vals, color=["#d1495b", "#00798c"])
            ax.set_title(label, fontsize=9)
        fig.tight_layout()
        fig.savefig(os.path.join(a.png_dir, "forest.png"), dpi=110)
        plt.close(fig)

    m = report["machine"]
    L = []
    L.append("# Benchmarks: supine side by side with Open3D, small_gicp and scikit-learn\n")
    L.append(f"Generated by `tests/bench/run.sh{' --quick' if a.mode == 'quick' else ''}` ({a.mode} run, "
             f"{a.seconds} s) at commit `{commit}`; regenerate with the same command. Machine: {m['cpu']}, "
             f"{m['cores']} cores (shared with other builds while measuring, so times are upper bounds), "
             f"{m['memory']}, Linux {m['kernel']}, {m['rustc']}, Python {m['python']}; load average "
             f"{m['load_average_at_report'][1]} (5 min) when the report was written. Every figure is one thread "
             "(Rust sides pinned to CPU 0 with `taskset -c 0`, peers with `OMP_NUM_THREADS=1` / `n_jobs=1`).\n")
    L.append("## Targets\n")
    L.append("| target | figure | status |\n| --- | --- | --- |")
    sp, er = report["icp_speedup_vs_open3d"], report["icp_pose_error_ratio_vs_open3d"]
    ok = sp is not None and er is not None and sp >= 10 and er <= 1
    L.append(f"| ICP ≥10× faster than Open3D point-to-plane at ≤ its pose error (medians over problems) | "
             f"{fmt(sp, '.1f')}× faster, pose error ratio {fmt(er, '.2f')} (tuned Open3D: "
             f"{fmt(report['icp_speedup_vs_open3d_tuned'], '.1f')}×, {fmt(report['icp_pose_error_ratio_vs_open3d_tuned'], '.2f')}) | "
             f"{'met' if ok else 'not met'} |")
    L.append(f"| small_gicp, reported the same way | point-to-plane {fmt(report['icp_speedup_vs_small_gicp'], '.1f')}×"
             f" ({fmt(report['icp_pose_error_ratio_vs_small_gicp'], '.2f')}), GICP "
             f"{fmt(report['icp_speedup_vs_small_gicp_gicp'], '.1f')}× ({fmt(report['icp_pose_error_ratio_vs_small_gicp_gicp'], '.2f')}) | reported |")
    fs, fz, fe = (report["forest_speedup_vs_sklearn"], report["forest_size_ratio_vs_sklearn"],
                  report["forest_error_ratio_vs_sklearn"])
    fok = fs is not None and fs >= 10 and fe is not None and fe <= 1
    L.append(f"| forest inference ≥10× faster than scikit-learn's at ≤ its joint error | {fmt(fs, '.1f')}×, error "
             f"ratio (ours/theirs) {fmt(fe, '.2f')} | {'met' if fok else 'not met'} |")
    L.append(f"| forest model ≥5× smaller (stretch 10×) | {fmt(fz, '.1f')}× | "
             f"{'met' + (' (stretch met)' if fz and fz >= 10 else '') if fz and fz >= 5 else 'not met'} |")
    p50, p99 = report["frame_ms_p50"], report["frame_ms_p99"]
    L.append(f"| whole frame p50 ≤ 2 ms on one core | {fmt(p50, '.3f')} ms (p99 {fmt(p99, '.3f')} ms; thread CPU "
             f"time per frame, `supine frame-bench`) | "
             f"{('not measured: ' + report['frame_missing']) if p50 is None else ('met' if p50 <= 2 else 'not met')} |")
    fps = report["frame_fps_implied"]
    if n_a64:
        a72 = fps[BOARDS[0][0]]
        L.append(f"| aarch64 instructions per frame imply ≥200 frames/s on a Cortex-A72 at 1.5 GHz | "
                 f"{n_a64 / 1e6:.2f} M instructions/frame → {a72:.0f} frames/s at IPC {BOARDS[0][2]} | "
                 f"{'met' if a72 >= 200 else 'not met'} |\n")
    else:
        L.append("| aarch64 instructions per frame imply ≥200 frames/s on a Cortex-A72 at 1.5 GHz | – | not measured: "
                 f"{report['frame_instructions_missing']} |\n")

    L.append("## Per-frame stages (criterion)\n")
    L.append("`cargo bench -p supine-models --bench stages` on frame 30 of the committed demo recording (robot arm "
             "over the torso) with the committed default models; median per call, one core.\n")
    L.append("| stage | median |\n| --- | ---: |")
    for n, label in STAGES:
        v = stages[n]
        L.append(f"| {label} (`{n}`) | {fmt(None if v is None else v / 1000.0, '.1f')} µs |")
    L.append("")
    if stage_sum_ms is not None:
        L.append(f"The existing stages of one tracking frame ({', '.join(FRAME_STAGES)}) add up to "
                 f"**{stage_sum_ms:.3f} ms**, {KINECT_MS / stage_sum_ms:.0f}× inside the Kinect's 33 ms and "
                 f"{PAPER_MS / stage_sum_ms:.0f}× inside the paper's 100 ms; a pass of the clip over every pixel "
                 f"would add {fmt(stages['clip'] and stages['clip'] / 1e6, '.3f')} ms (the forest clips only its "
                 "samples, ICP tests the mattress plane per model point). This is not the whole frame: the "
                 "tracker runs several ICP iterations, the feedback loop and the state machine. Parts can sum to "
                 "more than their whole here (`forest_sample_descend` + `mean_shift` vs `forest_total`): the "
                 "machine was shared, and medians move by tens of percent between runs.\n")
    L.append(f"![stages]({rel}/stages.png)\n")

    L.append("## Whole frame\n")
    if fb:
        L.append(f"`supine frame-bench --frames {fb['frames']}` (release build, pinned to one core): the committed demo "
                 f"recording ({fb['decoded_frames']} frames) is decoded into memory first, the tracker runs its init "
                 f"phase ({fb['init_frames']} frames), then {fb['frames']} calls of `Tracker::process` (joint forest "
                 "with the feedback prior, torso ICP, probe mapping, packets, state machine) and the serial encoding "
                 "of their packets follow on the recording played forth and back, with the committed default models "
                 "and the arm state from the truth's probe pose. The tracker reads a virtual clock set to the "
                 "frames' times, so its decisions do not depend on the machine's speed. Each frame is one sample: "
                 "the thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`, what the figures below use: other processes on "
                 "this shared machine do not count, though they still empty the caches) and the wall time. "
                 f"{fb['tracked_frames']} of {fb['frames']} measured frames were tracking.\n")
        L.append("| per frame | p50 | p99 | mean |\n| --- | ---: | ---: | ---: |")
        L.append(f"| thread CPU time | {fmt(fb['frame_ms_p50'], '.3f')} ms | {fmt(fb['frame_ms_p99'], '.3f')} ms | "
                 f"{fmt(fb['frame_ms_mean'], '.3f')} ms |")
        L.append(f"| wall time (includes waiting for the shared cores) | {fmt(fb['frame_wall_ms_p50'], '.3f')} ms | "
                 f"{fmt(fb['frame_wall_ms_p99'], '.3f')} ms | {fmt(fb['frame_wall_ms_mean'], '.3f')} ms |")
        if crit50 is not None:
            L.append(f"| criterion `frame` bench ({a.frame_bench}), per-sample means | {fmt(crit50, '.3f')} ms | "
                     f"{fmt(crit99, '.3f')} ms | |")
        L.append("")
        L.append(f"p50 {fmt(p50, '.3f')} ms is {KINECT_MS / p50:.0f}× inside the Kinect's 33 ms frame and "
                 f"{PAPER_MS / p50:.0f}× inside the paper's 100 ms; p99 {fmt(p99, '.3f')} ms is "
                 f"{KINECT_MS / p99:.0f}× and {PAPER_MS / p99:.0f}×.\n")
        rss_line = []
        if report["frame_peak_rss_mib"] is not None:
            rss_line.append(f"peak RSS of `supine demo` (the whole streaming pipeline over the 60-frame recording: "
                            f"models, tracker scratch, .oni reader; GNU time `%M`): "
                            f"**{report['frame_peak_rss_mib']:.1f} MiB**")
        if report["frame_bench_peak_rss_mib"] is not None:
            rss_line.append(f"of `supine frame-bench`: {report['frame_bench_peak_rss_mib']:.1f} MiB (VmHWM; it also "
                            f"holds the {fb['decoded_bytes'] / 2**20:.1f} MiB of decoded frames)")
        if rss_line:
            L.append("Memory: " + "; ".join(rss_line) + ".\n")
    else:
        L.append(f"Not measured: {report.get('frame_missing')}.\n")
    L.append("Frames per second on the head computer follow as IPC × clock / (aarch64 instructions per frame), "
             "with these assumed IPCs (assumptions, not measurements: the A72 is a 3-wide and the A76 a 4-wide "
             "out-of-order core per Arm's published microarchitecture descriptions; sustained IPC on branchy "
             "per-pixel code is usually below the width, so 1.0 and 1.5 are deliberately conservative):\n")
    if n_a64:
        L.append("Instructions per steady-state tracking frame, `cross/count-instructions` workload `tracker-frame` "
                 "(`supine frame-bench --frames N` under qemu-user 7.2 with the instruction-counting TCG plugin, the "
                 "head profile's binaries; N and 2N frames differenced, so decoding the recording, loading the "
                 "models and the init phase cancel out; x86-64 also natively under callgrind): aarch64 "
                 f"**{n_a64:,.0f}**, x86-64 {fmt(report['frame_instructions_x86_64'], ',.0f')} (callgrind "
                 f"{fmt(report['frame_instructions_x86_64_callgrind'], ',.0f')}).\n")
        L.append("| board | clock | assumed IPC | frames/s implied | ms per frame | × inside 33 ms | × inside 100 ms |")
        L.append("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
        for b, hz, ipc in BOARDS:
            f_ = fps[b]
            L.append(f"| {b} | {hz / 1e9:.1f} GHz | {ipc} | {f_:.0f} | {1000 / f_:.2f} | {KINECT_MS * f_ / 1000:.1f} | "
                     f"{PAPER_MS * f_ / 1000:.1f} |")
        L.append("")
    else:
        L.append("| board | clock | assumed IPC |\n| --- | ---: | ---: |")
        for b, hz, ipc in BOARDS:
            L.append(f"| {b} | {hz / 1e9:.1f} GHz | {ipc} |")
        L.append("")
    L.append(f"At IPC 1.0 and 1.5 GHz, the 200 frames/s target means at most {1.5e9 / 200 / 1e6:.1f} M aarch64 "
             "instructions per frame.")
    if report.get("demo_frame_instructions_aarch64") is not None:
        L.append(f" For comparison, `supine demo`'s per-frame work including the .oni decompression (workload "
                 f"`demo-frame`, which a live sensor does not need) costs "
                 f"{fmt(report.get('demo_frame_instructions_aarch64'), ',.0f')} aarch64 instructions.")
    L.append("\n")

    if icp:
        s = icp["summary"]
        L.append("## ICP: supine vs Open3D and small_gicp\n")
        L.append(f"{icp['problems']} problems (`supine-bench icp`, seed 1400): one rendered Kinect view of a "
                 "generated patient who was never trained on (the dataset generator with the Kinect noise model; "
                 "half of the views with the robot arm over the torso) against the torso model: the body model's "
                 "torso subset (~1.2 k vertices) in that patient's true shape and pose, in its `torso` frame, so the "
                 "true `camera_from_torso` puts the model on the rendered surface and the pose error measures "
                 "registration alone. The start pose is the truth perturbed by 5° about a random axis and 3 cm in "
                 "a random direction (seeded); every method gets the same one. supine reads the depth image "
                 "(projective association); the peers get the same model points (those facing the camera at the "
                 "start pose, as supine's association skips the rest) and every depth pixel above the mattress as "
                 "a point cloud with the same depth-neighbour normals supine computes (given to Open3D "
                 "precomputed and untimed; small_gicp estimates its own, timed). Pose error: RMS distance of all "
                 "model points between the found and the true pose. RMSE: one yardstick for all, the "
                 f"nearest-neighbour inlier RMSE within {icp['eval_inlier_m'] * 1000:.0f} mm (Open3D's "
                 "`evaluate_registration`). Times are medians of repeated runs per problem; table cells are medians "
                 f"over problems. Versions: Open3D {icp['versions']['open3d']}, small_gicp "
                 f"{icp['versions']['small_gicp']}.\n")
        L.append("| method | ms / registration | iterations | pose error mm | translation mm | rotation ° | "
                 "inlier RMSE mm | pose error with arm / without | failed |")
        L.append("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        for m, label in METHODS:
            x = s[m]
            L.append(f"| {label} | {fmt(x['time_s'] and x['time_s'] * 1e3, '.3f')} | {fmt(x['iterations'], '.0f')} | "
                     f"{fmt(x['pose_error_mm'], '.1f')} | {fmt(x['translation_error_mm'], '.1f')} | "
                     f"{fmt(x['rotation_error_deg'], '.2f')} | {fmt(x['inlier_rmse_mm'], '.2f')} | "
                     f"{fmt(x['with_arm']['pose_error_mm'], '.1f')} / {fmt(x['without_arm']['pose_error_mm'], '.1f')} | "
                     f"{x['failed']} |")
        st = [r["start"]["pose_error_mm"] for r in icp["results"]]
        L.append(f"\nStart poses: median pose error {sorted(st)[len(st) // 2]:.1f} mm. Speedups (peer's time over "
                 "supine's, median over problems): "
                 f"Open3D defaults {fmt(report['icp_speedup_vs_open3d'], '.1f')}×, tuned "
                 f"{fmt(report['icp_speedup_vs_open3d_tuned'], '.1f')}×, small_gicp point-to-plane "
                 f"{fmt(report['icp_speedup_vs_small_gicp'], '.1f')}×, GICP "
                 f"{fmt(report['icp_speedup_vs_small_gicp_gicp'], '.1f')}×. Where the peers' time goes: each call "
                 "builds a nearest-neighbour structure over the whole cloud above the mattress (60-95 k points), "
                 "which supine's projective association does not need; cropping or downsampling the cloud first "
                 "would make them faster and is a choice a user of those libraries would make (not done here: "
                 "every method gets the same points).\n")
        L.append(f"![icp]({rel}/icp.png)\n")

    if forest and fsup:
        c = fsup["config"]
        L.append("## Joint forest: supine vs scikit-learn\n")
        L.append(f"Dataset: {c['bodies']} bodies × {c['views']} views (seed {c['seed']}, 30 % of the views with the "
                 f"arm, 70/30 body split); {fsup['train_samples']} training samples ({c['samples']} per image, the "
                 f"fitting bodies' images as supine's trainer samples them); {fsup['test_images']} held-out images. "
                 f"Both forests: {c['trees']} trees, depth ≤{c['depth']}, minimum split {c['min_split']}, "
                 f"{c['candidates']} candidate features per split. supine grows body-part classification trees and "
                 f"refines its leaves globally ({c['epochs']} epochs), then quantises; scikit-learn "
                 f"{report['forest']['sklearn_version']} `RandomForestRegressor` regresses the 18 offsets to the six "
                 f"points from a precomputed bank of {c['bank']} depth-difference features (offset pairs drawn like "
                 "supine's candidates). Per frame, from the depth image to the six points, 512 samples, one thread, "
                 "after a warm-up pass: supine samples, descends and runs its mean-shift; scikit-learn gets the same "
                 "sampled pixels for free, computes the bank with numpy (checked equal to supine's features), "
                 "predicts, and runs the same mean-shift in numpy. Joint error: mean 3D error over the six points "
                 "and the held-out images (a point without an estimate counts 0.5 m). Model size: supine's `.jfor` "
                 "file, scikit-learn's pickle.\n")
        fr = report["forest"]
        L.append("| | supine | scikit-learn | ratio (theirs / ours) |\n| --- | ---: | ---: | ---: |")
        L.append(f"| ms per frame (median) | {fr['supine']['frame_ms_median']:.3f} | "
                 f"{fr['sklearn']['frame_ms_median']:.3f} | {fmt(fs, '.1f')}× |")
        L.append(f"| model bytes | {fr['supine']['model_bytes']:,} | {fr['sklearn']['model_bytes']:,} | {fmt(fz, '.1f')}× |")
        L.append(f"| training s (one thread) | {fr['supine']['train_s']:.1f} | {fr['sklearn']['train_s']:.1f} | "
                 f"{fmt(report['forest_train_speedup_vs_sklearn'], '.2f')}× |")
        L.append(f"| joint error mm (mean) | {fr['supine']['joint_error_mm_mean']:.1f} | "
                 f"{fr['sklearn']['joint_error_mm_mean']:.1f} | {fmt(fe and 1 / fe, '.2f')} |")
        L.append(f"| nodes | {fr['supine']['nodes']:,} | {fr['sklearn']['nodes']:,} | |")
        L.append("")
        L.append("| point | supine mm | scikit-learn mm |\n| --- | ---: | ---: |")
        for k, v in fr["supine"]["joint_error_mm"].items():
            L.append(f"| {k} | {v:.1f} | {fr['sklearn']['joint_error_mm'][k]:.1f} |")
        L.append(f"\n![forest]({rel}/forest.png)\n")

    L.append("## Commands\n")
    L.append("```sh")
    L.extend(commands)
    L.append("```\n")
    L.append("Working files (problems, point sets, per-problem results) are under `target/bench/<mode>/`; the JSON "
             "report is `target/bench/<mode>/report.json` (`--json FILE` copies it).")
    with open(a.md, "w") as f:
        f.write("\n".join(L) + "\n")


if __name__ == "__main__":
    main()
