#!/usr/bin/env python3
"""ICP peers of the supine benchmark (issue 14): Open3D registration_icp point-to-plane (defaults and a tuned
setting) and small_gicp (GICP and point-to-plane) on the problems `supine-bench icp` wrote, one thread each, from the
same start pose and the same points; then one evaluation of every method's final pose (supine's included): pose error
against the truth, and a common inlier RMSE.

Usage: icp_peers.py DIR [--repeats N] [--json FILE]
"""
import os

# One thread for every peer: set before the libraries start their thread pools.
for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"

import argparse
import importlib.metadata
import json
import sys
import tempfile
import time

import numpy as np
import open3d as o3d
import small_gicp

# A common yardstick for every method's final pose: nearest-neighbour inlier RMSE within this distance.
EVAL_INLIER_M = 0.02
MAX_CORR_M = 0.1  # supine's correspondence limit (the paper's 0.1 m)


def rows(m):
    return np.asarray(m, dtype=np.float64).reshape(4, 4)


def pose_errors(t, truth, model):
    """RMS displacement of the model points (mm), torso-origin translation error (mm), rotation error (deg)."""
    p = np.c_[model, np.ones(len(model))]
    d = (p @ t.T)[:, :3] - (p @ truth.T)[:, :3]
    rms = float(np.sqrt((d * d).sum(1).mean()) * 1000.0)
    dt = float(np.linalg.norm(t[:3, 3] - truth[:3, 3]) * 1000.0)
    r = t[:3, :3] @ truth[:3, :3].T
    ang = float(np.degrees(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))
    return rms, dt, ang


def front_facing(model, normals, start):
    """Model points facing the camera at the start pose (supine's association skips the others too)."""
    r, t = start[:3, :3], start[:3, 3]
    p = model @ r.T + t
    n = normals @ r.T
    return model[(n * p).sum(1) < 0.0]


def count_o3d_iterations(src, tgt, max_corr, init, crit):
    """Open3D reports no iteration count: run once more (untimed) at debug verbosity and count its log lines."""
    fd = sys.stdout.fileno()
    saved = os.dup(fd)
    with tempfile.TemporaryFile(mode="w+b") as log:
        sys.stdout.flush()
        os.dup2(log.fileno(), fd)
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Debug)
        try:
            o3d.pipelines.registration.registration_icp(
                src, tgt, max_corr, init, o3d.pipelines.registration.TransformationEstimationPointToPlane(), crit)
        finally:
            o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
            sys.stdout.flush()
            os.dup2(saved, fd)
            os.close(saved)
        log.seek(0)
        text = log.read().decode("utf-8", "replace")
    return text.count("ICP Iteration #")


def timed(fn, repeats):
    out, times = None, []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, float(np.median(times))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json")
    a = ap.parse_args()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    with open(os.path.join(a.dir, "problems.json")) as f:
        ps = json.load(f)
    with open(os.path.join(a.dir, "supine.json")) as f:
        sup = {r["id"]: r for r in json.load(f)["results"]}
    reg = o3d.pipelines.registration
    methods = {
        "open3d_default": dict(max_corr=MAX_CORR_M, crit=reg.ICPConvergenceCriteria()),
        "open3d_tuned": dict(max_corr=0.05, crit=reg.ICPConvergenceCriteria(
            relative_fitness=1e-4, relative_rmse=1e-4, max_iteration=10)),
    }
    results = []
    for i, p in enumerate(ps["problems"]):
        model = np.load(os.path.join(a.dir, p["model"])).astype(np.float64)
        mnorm = np.load(os.path.join(a.dir, p["model_normals"])).astype(np.float64)
        tgt_pts = np.load(os.path.join(a.dir, p["target"])).astype(np.float64)
        tgt_nrm = np.load(os.path.join(a.dir, p["target_normals"])).astype(np.float64)
        truth, start = rows(p["truth"]), rows(p["start"])
        src_pts = front_facing(model, mnorm, start)
        src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src_pts))
        tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt_pts))
        tgt.normals = o3d.utility.Vector3dVector(tgt_nrm)
        row = {"id": p["id"], "arm": p["arm"], "source_points": len(src_pts), "target_points": len(tgt_pts)}
        finals = {}
        s = sup[p["id"]]
        finals["supine"] = (rows(s["pose"]) if s["pose"] is not None else None, s["time_s"], s["iterations"], {})
        for name, m in methods.items():
            r, dt = timed(lambda: reg.registration_icp(src, tgt, m["max_corr"], start,
                                                       reg.TransformationEstimationPointToPlane(), m["crit"]),
                          a.repeats)
            it = count_o3d_iterations(src, tgt, m["max_corr"], start, m["crit"])
            finals[name] = (np.asarray(r.transformation), dt, it, {"fitness": r.fitness})
        # small_gicp: preprocessing (k-d tree, normals/covariances of both clouds) is part of its registration.
        for name, kind in (("small_gicp_gicp", "GICP"), ("small_gicp_plane", "PLANE_ICP")):
            def run(kind=kind):
                t0 = time.perf_counter()
                tg = small_gicp.PointCloud(tgt_pts)
                tree = small_gicp.KdTree(tg, num_threads=1)
                small_gicp.estimate_normals_covariances(tg, tree, num_neighbors=20, num_threads=1)
                sc = small_gicp.PointCloud(src_pts)
                if kind == "GICP":
                    small_gicp.estimate_covariances(sc, num_neighbors=20, num_threads=1)
                t1 = time.perf_counter()
                res = small_gicp.align(tg, sc, tree, start, registration_type=kind,
                                       max_correspondence_distance=MAX_CORR_M, num_threads=1, max_iterations=20)
                return res, time.perf_counter() - t1, t1 - t0
            (res, align_s, prep_s), dt = timed(run, a.repeats)
            finals[name] = (np.asarray(res.T_target_source), dt, int(res.iterations),
                            {"align_only_s": align_s, "preprocess_s": prep_s, "converged": bool(res.converged)})
        for name, (t, dt, it, extra) in finals.items():
            if t is None:
                row[name] = {"failed": True, "time_s": dt}
                continue
            e = reg.evaluate_registration(src, tgt, EVAL_INLIER_M, t)
            rms, dtr, ang = pose_errors(t, truth, model)
            row[name] = dict(time_s=dt, iterations=it, pose_error_mm=rms, translation_error_mm=dtr,
                             rotation_error_deg=ang, inlier_rmse_mm=float(e.inlier_rmse * 1000.0),
                             inlier_fitness=float(e.fitness), failed=False, **extra)
        s0 = pose_errors(start, truth, model)
        row["start"] = dict(pose_error_mm=s0[0], translation_error_mm=s0[1], rotation_error_deg=s0[2])
        results.append(row)
        print(f"icp {i + 1}/{len(ps['problems'])} {p['id']}: " + ", ".join(
            f"{n} {row[n].get('time_s', 0) * 1e3:.2f} ms {row[n].get('pose_error_mm', float('nan')):.1f} mm"
            for n in finals), file=sys.stderr)
    names = list(finals)
    summary = {}
    for n in names:
        ok = [r[n] for r in results if not r[n].get("failed")]
        summary[n] = {k: float(np.median([r[k] for r in ok])) if ok else None
                      for k in ("time_s", "iterations", "pose_error_mm", "translation_error_mm",
                                "rotation_error_deg", "inlier_rmse_mm")}
        summary[n]["failed"] = sum(1 for r in results if r[n].get("failed"))
        for cond, arm in (("with_arm", True), ("without_arm", False)):
            sub = [r[n] for r in results if r["arm"] == arm and not r[n].get("failed")]
            summary[n][cond] = {k: float(np.median([r[k] for r in sub])) if sub else None
                                for k in ("time_s", "pose_error_mm", "inlier_rmse_mm")}

    def ratio(peer, key, ours_over=False):
        vals = []
        for r in results:
            if r["supine"].get("failed") or r[peer].get("failed"):
                continue
            q = r["supine"][key] / r[peer][key] if ours_over else r[peer][key] / r["supine"][key]
            vals.append(q)
        return float(np.median(vals)) if vals else None

    out = {
        "problems": len(results),
        "versions": {"open3d": o3d.__version__, "small_gicp": importlib.metadata.version("small_gicp"),
                     "numpy": np.__version__},
        "eval_inlier_m": EVAL_INLIER_M,
        "summary": summary,
        "icp_speedup_vs_open3d": ratio("open3d_default", "time_s"),
        "icp_speedup_vs_open3d_tuned": ratio("open3d_tuned", "time_s"),
        "icp_speedup_vs_small_gicp": ratio("small_gicp_plane", "time_s"),
        "icp_speedup_vs_small_gicp_gicp": ratio("small_gicp_gicp", "time_s"),
        "icp_pose_error_ratio_vs_open3d": ratio("open3d_default", "pose_error_mm", ours_over=True),
        "icp_pose_error_ratio_vs_open3d_tuned": ratio("open3d_tuned", "pose_error_mm", ours_over=True),
        "icp_pose_error_ratio_vs_small_gicp": ratio("small_gicp_plane", "pose_error_mm", ours_over=True),
        "icp_pose_error_ratio_vs_small_gicp_gicp": ratio("small_gicp_gicp", "pose_error_mm", ours_over=True),
        "results": results,
    }
    text = json.dumps(out, indent=1)
    if a.json:
        with open(a.json, "w") as f:
            f.write(text)
    else:
        print(text)


if __name__ == "__main__":
    main()
