#!/usr/bin/env python3
"""Read back an MCAP file written by `supine replay --record` (or the foxglove unit test) with the Python `mcap`
package and check what Foxglove relies on: every channel's schema name and encoding, message counts per channel,
log times that never go back, and decodable payloads (the depth image's base64 is w*h*2 bytes).

Usage: foxglove_mcap.py FILE --frames N [--overlays]
  --frames N    messages expected on each per-frame channel
  --overlays    the scene must hold the torso mesh, salient points and probe, and the transforms camera->torso
Exit 0 when every check holds, 1 with one line per failed check otherwise.
"""

import argparse
import base64
import json
import sys

from mcap.reader import make_reader

EXPECTED = {
    "/depth": "foxglove.RawImage",
    "/depth/calibration": "foxglove.CameraCalibration",
    "/scene": "foxglove.SceneUpdate",
    "/tf": "foxglove.FrameTransforms",
    "/packets": "supine.Packet",
    "/tracker": "supine.TrackerStatus",
}
PER_FRAME = ["/depth", "/depth/calibration", "/scene", "/tf", "/tracker"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("file")
    ap.add_argument("--frames", type=int, required=True)
    ap.add_argument("--overlays", action="store_true")
    args = ap.parse_args()
    failures = []
    counts = {}
    last_log = -1
    went_back = 0
    entity_ids = set()
    tf_pairs = set()
    with open(args.file, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            failures.append("no summary section")
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            counts[topic] = counts.get(topic, 0) + 1
            if message.log_time < last_log:
                went_back += 1
            last_log = message.log_time
            want = EXPECTED.get(topic)
            if want is None:
                failures.append(f"unexpected channel {topic}")
                continue
            if schema is None or schema.name != want:
                failures.append(f"{topic}: schema {schema.name if schema else None!r}, expected {want!r}")
            if schema is not None and schema.encoding != "jsonschema":
                failures.append(f"{topic}: schema encoding {schema.encoding!r}")
            if channel.message_encoding != "json":
                failures.append(f"{topic}: message encoding {channel.message_encoding!r}")
            try:
                payload = json.loads(message.data)
            except ValueError as e:
                failures.append(f"{topic}: payload is not JSON ({e})")
                continue
            if topic == "/depth":
                raw = base64.b64decode(payload["data"])
                if payload["encoding"] != "16UC1" or len(raw) != payload["width"] * payload["height"] * 2:
                    failures.append(f"/depth: {payload['encoding']} with {len(raw)} bytes for "
                                    f"{payload['width']}x{payload['height']}")
                stamp = payload["timestamp"]["sec"] * 1_000_000_000 + payload["timestamp"]["nsec"]
                if stamp != message.log_time:
                    failures.append(f"/depth: header stamp {stamp} != log time {message.log_time}")
            elif topic == "/scene":
                for e in payload["entities"]:
                    entity_ids.add(e["id"])
            elif topic == "/tf":
                for t in payload["transforms"]:
                    tf_pairs.add((t["parent_frame_id"], t["child_frame_id"]))
    if went_back:
        failures.append(f"log time went back {went_back} times")
    for topic in PER_FRAME:
        if counts.get(topic, 0) != args.frames:
            failures.append(f"{topic}: {counts.get(topic, 0)} messages, expected {args.frames}")
    if summary is not None and summary.statistics is not None:
        total = sum(counts.values())
        if summary.statistics.message_count != total:
            failures.append(f"statistics count {summary.statistics.message_count} messages, read {total}")
    if args.overlays:
        for want in ("torso", "salient_points", "probe"):
            if want not in entity_ids:
                failures.append(f"/scene: no {want!r} entity")
        if ("camera", "torso") not in tf_pairs:
            failures.append("/tf: no camera -> torso transform")
        if counts.get("/packets", 0) < args.frames:
            failures.append(f"/packets: {counts.get('/packets', 0)} messages, at least {args.frames} expected")
    for f_ in failures:
        print(f"foxglove_mcap: {args.file}: {f_}")
    if not failures:
        per = ", ".join(f"{t} {n}" for t, n in sorted(counts.items()))
        print(f"foxglove_mcap: {args.file}: ok ({per})")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
