"""Compare `cantools decode --single-line supine.dbc` output with `supine wire sample --format json`.

Usage: wire_cantools_compare.py SAMPLE_JSON CANDUMP_LOG CANTOOLS_OUTPUT

The expected value of every DBC signal is derived here from the JSON message fields (physical units), by a
table written independently of the Rust encoder. Crc is recomputed in Python (CRC-8/SAE-J1850 over the data id
0x0100 | (id - 0x100), little-endian, then bytes 1..7) and Counter must equal seq & 0xF. Every signal cantools
printed must be expected, and every expected signal must be printed. Exit 1 with a list of differences otherwise.
"""

import json
import re
import sys

from supine_wire import BASE, KIND_BLOCK, crc8_sae_j1850

POINT_FRAMES = [("head", "POINT_HEAD", "ConfHead"), ("left_shoulder", "POINT_L_SHOULDER", "ConfLShoulder"),
                ("right_shoulder", "POINT_R_SHOULDER", "ConfRShoulder"), ("belly", "POINT_BELLY", "ConfBelly"),
                ("left_hip", "POINT_L_HIP", "ConfLHip"), ("right_hip", "POINT_R_HIP", "ConfRHip")]


def xyz(out, frame, prefix, v):
    for axis, c in zip("XYZ", v):
        out[(frame, prefix + axis)] = c


def quat(out, prefix, q):
    for name, c in zip(["RotW", "RotX", "RotY"], q[:3]):
        out[(prefix + "_ROT_A", name)] = c
    out[(prefix + "_ROT_B", "RotZ")] = q[3]


def expected(m):
    """{(frame, signal): value} for one JSON message; numbers physical, enums by name."""
    k = m["kind"]
    prefix = {"command": "CMD", "arm_state": "ARM", "torso_pose": "TORSO", "probe": "PROBE",
              "salient_points": "POINTS", "health": "HEALTH", "body_shape": "SHAPE"}[k]
    out = {(prefix + "_HEAD", "Seq"): m["seq"], (prefix + "_TIME", "TimestampUs"): m["timestamp_us"]}
    if k == "torso_pose":
        out[("TORSO_HEAD", "Confidence")] = m["confidence_pct"]
        xyz(out, "TORSO_POS", "Pos", m["position_mm"])
        quat(out, "TORSO", m["orientation"])
    elif k == "arm_state":
        xyz(out, "ARM_POS", "Pos", m["position_mm"])
        quat(out, "ARM", m["orientation"])
    elif k == "salient_points":
        for name, frame, conf in POINT_FRAMES:
            p = m["points"][name]
            xyz(out, frame, "Pos", p["position_mm"])
            out[("POINTS_CONF", conf)] = p["confidence_pct"]
    elif k == "probe":
        out[("PROBE_HEAD", "Region")] = m["region"]
        out[("PROBE_HEAD", "SignedDistance")] = m["signed_distance_mm"]
        xyz(out, "PROBE_TIP", "Tip", m["tip_mm"])
        xyz(out, "PROBE_NEAREST", "Nearest", m["nearest_mm"])
        xyz(out, "PROBE_NORMAL", "Normal", m["normal"])
    elif k == "health":
        out[("HEALTH_HEAD", "State")] = m["state"]
        out[("HEALTH_HEAD", "FrameRate")] = m["frame_rate_hz"]
        out[("HEALTH_LATENCY", "LatencyUs")] = m["latency_us"]
        out[("HEALTH_OVERRUNS", "BudgetOverruns")] = m["budget_overruns"]
        out[("HEALTH_DROPPED", "DroppedFrames")] = m["dropped_frames"]
    elif k == "body_shape":
        out[("SHAPE_HEAD", "Revision")] = m["revision"]
        for i, c in enumerate(m["coefficients"]):
            out[("SHAPE_COEF_%d" % (i // 3), "Coef%d" % i)] = c
    elif k == "command":
        out[("CMD_HEAD", "Command")] = m["command"]
        out[("CMD_HEAD", "ShapeMode")] = m["shape_mode"] or "frozen"
    else:
        raise SystemExit("unknown kind in JSON: %s" % k)
    return prefix, out


LINE = re.compile(r"^\((?P<ts>[0-9.]+)\)\s+\S+\s+(?P<id>[0-9A-Fa-f]+)#(?P<data>[0-9A-Fa-f]*)\s+::\s+"
                  r"(?P<name>\w+)\((?P<sigs>.*)\)\s*$")


def parse_value(text):
    v = text.strip().split(" ")[0]
    try:
        return float(v)
    except ValueError:
        return v.strip("'\"")


def main():
    sample_path, candump_path, decoded_path = sys.argv[1:4]
    messages = [json.loads(l) for l in open(sample_path) if l.strip()]
    frames = [l for l in open(candump_path) if l.strip()]
    decoded = [l.rstrip("\n") for l in open(decoded_path) if l.strip()]
    errors = []
    if len(decoded) != len(frames):
        errors.append("cantools printed %d lines for %d frames" % (len(decoded), len(frames)))
    want = {}
    seq_of_prefix = {}
    for m in messages:
        prefix, exp = expected(m)
        want.update(exp)
        seq_of_prefix[prefix] = m["seq"]
    compared = 0
    for line in decoded:
        mt = LINE.match(line)
        if not mt:
            errors.append("cantools could not decode: %s" % line)
            continue
        fid, data, name = int(mt["id"], 16), bytes.fromhex(mt["data"]), mt["name"]
        if len(data) != 8:
            errors.append("%s: %d data bytes" % (name, len(data)))
            continue
        seq = seq_of_prefix[name.split("_")[0] if not name.startswith("POINT_") else "POINTS"]
        data_id = 0x0100 | (fid - BASE)
        for sig in mt["sigs"].split(", "):
            key, _, value = sig.partition(": ")
            got = parse_value(value)
            if key == "Crc":
                exp = crc8_sae_j1850([data_id & 0xFF, data_id >> 8] + list(data[1:]))
            elif key == "Counter":
                exp = seq & 0xF
            elif (name, key) in want:
                exp = want.pop((name, key))
            else:
                errors.append("%s.%s = %r has no expected value" % (name, key, got))
                continue
            ok = (abs(got - exp) < 1e-6) if isinstance(exp, (int, float)) and isinstance(got, float) else got == exp
            if not ok:
                errors.append("%s.%s: cantools %r, supine json %r" % (name, key, got, exp))
            compared += 1
    for (frame, sig), v in sorted(want.items()):
        errors.append("%s.%s = %r never decoded by cantools" % (frame, sig, v))
    if errors:
        print("wire_cantools: %d differences" % len(errors))
        for e in errors:
            print("  " + e)
        return 1
    print("wire_cantools: %d frames, %d signals of %d messages agree" % (len(frames), compared, len(messages)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
