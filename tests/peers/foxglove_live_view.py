#!/usr/bin/env python3
"""A Foxglove WebSocket client for `supine replay --view`: connects with the foxglove.websocket.v1 subprotocol,
checks serverInfo and the advertised channels (topics, schema names, JSON schemas), subscribes to every channel,
and checks the message-data frames that arrive: opcode 1, a known subscription id, log times increasing per channel,
JSON payloads (the depth image decodes to w*h*2 bytes).

Usage: foxglove_live_view.py ws://HOST:PORT --frames N [--connect-timeout S]
Exit 0 when N depth frames arrived and every check held, 1 otherwise (one line per failed check).
"""

import argparse
import base64
import json
import struct
import sys
import time

from websockets.sync.client import connect

EXPECTED = {
    "/depth": "foxglove.RawImage",
    "/depth/calibration": "foxglove.CameraCalibration",
    "/scene": "foxglove.SceneUpdate",
    "/tf": "foxglove.FrameTransforms",
    "/packets": "supine.Packet",
    "/tracker": "supine.TrackerStatus",
}


def open_ws(url, timeout):
    deadline = time.monotonic() + timeout
    while True:
        try:
            return connect(url, subprotocols=["foxglove.websocket.v1"], open_timeout=5, max_size=None)
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("--frames", type=int, required=True)
    ap.add_argument("--connect-timeout", type=float, default=30.0)
    args = ap.parse_args()
    with open_ws(args.url, args.connect_timeout) as ws:
        failures, counts = check(ws, args.frames)
    for f_ in failures:
        print(f"foxglove_live_view: {f_}")
    if not failures:
        per = ", ".join(f"{t} {n}" for t, n in sorted(counts.items()))
        print(f"foxglove_live_view: {args.url}: ok ({per})")
    return 1 if failures else 0


def check(ws, frames):
    failures = []
    if ws.subprotocol != "foxglove.websocket.v1":
        failures.append(f"subprotocol {ws.subprotocol!r}")
    info = json.loads(ws.recv(timeout=10))
    if info.get("op") != "serverInfo":
        failures.append(f"first message is {info.get('op')!r}, not serverInfo")
    adv = json.loads(ws.recv(timeout=10))
    if adv.get("op") != "advertise":
        failures.append(f"second message is {adv.get('op')!r}, not advertise")
    channels = {c["id"]: c for c in adv.get("channels", [])}
    by_topic = {c["topic"]: c for c in channels.values()}
    for topic, schema_name in EXPECTED.items():
        c = by_topic.get(topic)
        if c is None:
            failures.append(f"{topic} not advertised")
            continue
        if c["schemaName"] != schema_name or c["encoding"] != "json" or c.get("schemaEncoding") != "jsonschema":
            failures.append(f"{topic}: advertised {c['schemaName']} {c['encoding']} {c.get('schemaEncoding')}")
        json.loads(c["schema"])  # the schema itself is JSON
    subs = {100 + i: cid for i, cid in enumerate(channels)}
    ws.send(json.dumps({"op": "subscribe",
                        "subscriptions": [{"id": s, "channelId": c} for s, c in subs.items()]}))
    last = {}
    counts = {}
    depth_frames = 0
    deadline = time.monotonic() + 120
    while depth_frames < frames and time.monotonic() < deadline:
        msg = ws.recv(timeout=30)
        if isinstance(msg, str):
            op = json.loads(msg).get("op")
            if op == "status":
                print(f"foxglove_live_view: server status: {msg}")
                continue
            failures.append(f"unexpected text message {op!r}")
            continue
        if msg[0] != 1:
            failures.append(f"binary opcode {msg[0]}")
            continue
        sub, log_ns = struct.unpack_from("<IQ", msg, 1)
        if sub not in subs:
            failures.append(f"unknown subscription id {sub}")
            continue
        topic = channels[subs[sub]]["topic"]
        if topic != "/packets" and log_ns <= last.get(topic, -1):
            failures.append(f"{topic}: log time {log_ns} after {last[topic]}")
        last[topic] = log_ns
        counts[topic] = counts.get(topic, 0) + 1
        payload = json.loads(msg[13:])
        if topic == "/depth":
            raw = base64.b64decode(payload["data"])
            if len(raw) != payload["width"] * payload["height"] * 2:
                failures.append(f"/depth: {len(raw)} bytes for {payload['width']}x{payload['height']}")
            depth_frames += 1
    if depth_frames < frames:
        failures.append(f"{depth_frames} depth frames arrived, {frames} expected")
    return failures, counts


if __name__ == "__main__":
    sys.exit(main())
