#!/usr/bin/env python3
"""Forest peer of the supine benchmark (issue 14): scikit-learn RandomForestRegressor with the same trees, depth and
minimum split as supine's forest, trained on a precomputed bank of depth-difference features of the very samples
supine's trainer used (`supine-bench forest` wrote them); per frame, from the depth image to the six points: the bank
computed with numpy at the same 512 sampled pixels, predict, then the same weighted mean-shift as supine's
(kernel (1 - q/32)^16, 3 bandwidths, supine's per-point bandwidths). One thread. Model size is its pickle.

Usage: forest_peers.py DIR [--repeats N] [--json FILE]
"""
import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"

import argparse
import json
import pickle
import sys
import time

import numpy as np
from sklearn.ensemble import RandomForestRegressor

BACKGROUND_MM = 10_000
MIN_SCALE_DEPTH_MM = 100
MAX_ITERATIONS = 12
P = 6
NAMES = ["head", "left_shoulder", "right_shoulder", "belly", "left_hip", "right_hip"]


def bank_features(depth, px, bank):
    """supine_core::forest::feature in numpy: f = d(x + u/d) - d(x + v/d), integer maths, off-image = background."""
    h, w = depth.shape
    x = px[:, 0].astype(np.int64)[:, None]
    y = px[:, 1].astype(np.int64)[:, None]
    d = np.maximum(px[:, 2].astype(np.int64), MIN_SCALE_DEPTH_MM)[:, None]
    s = ((1000 << 16) + d // 2) // d

    def probe(ox, oy):
        qx = x + ((ox[None, :] * s + (1 << 15)) >> 16)
        qy = y + ((oy[None, :] * s + (1 << 15)) >> 16)
        inside = (qx >= 0) & (qx < w) & (qy >= 0) & (qy < h)
        z = depth[np.clip(qy, 0, h - 1), np.clip(qx, 0, w - 1)].astype(np.int64)
        z = np.where(inside & (z != 0), z, BACKGROUND_MM)
        return z

    b = bank.astype(np.int64)
    f = probe(b[:, 0], b[:, 1]) - probe(b[:, 2], b[:, 3])
    return np.clip(f, -32768, 32767).astype(np.float32)


def mean_shift(votes, h):
    """supine_core::forest::meanshift::mean_shift with unit weights and no prior."""
    if len(votes) == 0:
        return None
    inv2h2 = 0.5 / (h * h)
    cut2 = 9.0 * h * h
    best = None
    for c in (votes[0], votes.mean(0)):
        c = c.copy()
        dens = 0.0
        for _ in range(MAX_ITERATIONS):
            q = ((votes - c) ** 2).sum(1)
            m = q < cut2
            k = (1.0 - q[m] * inv2h2 / 16.0) ** 16
            w = k.sum()
            n = (k[:, None] * votes[m]).sum(0) / w if w > 0 else c
            moved = ((n - c) ** 2).sum()
            c, dens = n, w
            if moved < 1e-6:
                break
        if best is None or dens > best[1]:
            best = (c, dens)
    return best[0]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json")
    a = ap.parse_args()
    d = a.dir
    with open(os.path.join(d, "supine.json")) as f:
        sup = json.load(f)
    cfg = sup["config"]
    x = np.load(os.path.join(d, "x_train.npy")).astype(np.float32)
    y = np.load(os.path.join(d, "y_train.npy"))
    bank = np.load(os.path.join(d, "bank.npy"))
    depth = np.load(os.path.join(d, "test_depth.npy"))
    pixels = np.load(os.path.join(d, "test_pixels.npy"))
    points = np.load(os.path.join(d, "test_points.npy"))
    truth = np.load(os.path.join(d, "test_truth.npy"))
    counts = sup["samples_drawn"]
    bw = sup["refined_bandwidth_m"]
    # The numpy bank must read exactly what the Rust bank reads.
    ref0 = np.load(os.path.join(d, "test0_bank.npy")).astype(np.float32)
    mine0 = bank_features(depth[0], pixels[0, : counts[0]], bank)
    bank_matches = bool(np.array_equal(ref0, mine0))
    if not bank_matches:
        print("forest_peers: the numpy feature bank differs from supine's", file=sys.stderr)
        sys.exit(1)

    rf = RandomForestRegressor(n_estimators=cfg["trees"], max_depth=cfg["depth"], min_samples_split=cfg["min_split"],
                               max_features=cfg["candidates"], n_jobs=1, random_state=cfg["seed"] % (2**32))
    print(f"forest_peers: fitting scikit-learn on {len(x)} samples x {x.shape[1]} features", file=sys.stderr)
    t0 = time.perf_counter()
    rf.fit(x, y)
    train_s = time.perf_counter() - t0
    model_bytes = len(pickle.dumps(rf, protocol=pickle.HIGHEST_PROTOCOL))
    del x, y

    def frame(i):
        n = counts[i]
        f = bank_features(depth[i], pixels[i, :n], bank)
        off = rf.predict(f).reshape(n, P, 3)
        p = points[i, :n].astype(np.float64)
        return [mean_shift(p + off[:, j, :], bw[j]) for j in range(P)]

    est, times = [], []
    for rep in range(a.repeats + 1):
        for i in range(len(depth)):
            t0 = time.perf_counter()
            e = frame(i)
            dt = time.perf_counter() - t0
            if rep > 0:
                times.append(dt)
            if rep == 1:
                est.append(e)
    per = np.zeros(P)
    for e, t in zip(est, truth):
        for j in range(P):
            per[j] += (0.5 if e[j] is None else float(np.linalg.norm(e[j] - t[j]))) * 1000.0 / len(est)
    times = np.sort(times)
    out = {
        "sklearn_version": __import__("sklearn").__version__,
        "train_s": train_s,
        "train_threads": 1,
        "model_bytes": model_bytes,
        "nodes": int(sum(t.tree_.node_count for t in rf.estimators_)),
        "frame_ms_median": float(np.median(times) * 1000.0),
        "frame_ms_p90": float(times[int(len(times) * 0.9)] * 1000.0),
        "joint_error_mm_mean": float(per.mean()),
        "joint_error_mm": dict(zip(NAMES, map(float, per))),
        "bank_matches_rust": bank_matches,
        "test_images": len(depth),
    }
    s = sup
    out["forest_speedup_vs_sklearn"] = out["frame_ms_median"] / s["frame_ms_median"]
    out["forest_size_ratio_vs_sklearn"] = out["model_bytes"] / s["model_bytes"]
    out["forest_train_speedup_vs_sklearn"] = out["train_s"] / s["train_s"]
    out["forest_error_ratio_vs_sklearn"] = s["joint_error_mm_mean"] / out["joint_error_mm_mean"]
    text = json.dumps(out, indent=1)
    if a.json:
        with open(a.json, "w") as f:
            f.write(text)
    else:
        print(text)


if __name__ == "__main__":
    main()
