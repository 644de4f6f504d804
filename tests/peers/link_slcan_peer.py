#!/usr/bin/env python3
"""Real-peer checks of supine's links, driven by tests/peers/link_slcan.sh.

python-can's slcan bus and pyserial sit on the far end of a socat pty pair; cantools decodes and encodes frames
with the repository's DBC (core/src/wire/supine.dbc). cantools does not compute the E2E fields, so this helper
checks and fills them itself: byte 0 is CRC-8/SAE-J1850 over (data id low, data id high, bytes 1..7), the data id
being (protocol version << 8) | (frame id - base); byte 1 low nibble is the counter, equal to seq & 0xF.

Subcommands (each exits non-zero with a message on the first mismatch):
  recv-slcan   receive a run of `supine wire send --sink slcan:...`, check E2E fields, decode with cantools,
               compare frames with `supine wire sample --format slcan` and values with `--format json`
  send-slcan   send arm-state and command groups encoded with cantools (plus one damaged frame)
  check-listen check the JSON lines `supine wire listen` printed for what send-slcan sent
  recv-serial  read COBS frames with pyserial and compare byte-exact with `supine wire sample --format cobs-hex`
"""

import argparse
import json
import os
import sys
import time

from supine_wire import BASE, KINDS, e2e_crc


def fail(msg):
    print(f"link_slcan_peer: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)




def open_bus(channel):
    import can

    # sleep_after_open=0: the default waits 2 s (see shared reference B1).
    return can.Bus(interface="slcan", channel=channel, bitrate=500000, sleep_after_open=0, tty_baudrate=921600)


def touch(path):
    if path:
        with open(path, "w") as f:
            f.write("ready\n")


def load_json_lines(path):
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def leaves(value):
    """Scalar leaves of a JSON value, keys ignored."""
    if isinstance(value, dict):
        for v in value.values():
            yield from leaves(v)
    elif isinstance(value, list):
        for v in value:
            yield from leaves(v)
    else:
        yield value


def leaf_matches(json_leaf, raw, scale, choice):
    if isinstance(json_leaf, bool):
        return False
    if isinstance(json_leaf, str):
        return choice is not None and json_leaf == choice
    if isinstance(json_leaf, int):
        return json_leaf == raw
    if isinstance(json_leaf, float):
        return abs(json_leaf - raw * scale) <= 1e-6 * max(1.0, abs(raw * scale)) or json_leaf == raw
    return False


def recv_slcan(args):
    import cantools

    db = cantools.database.load_file(args.dbc)
    sample_json = load_json_lines(args.expect_json)
    with open(args.expect_slcan) as f:
        sample_lines = [line.strip() for line in f if line.strip()]
    want_frames = len(sample_lines)
    bus = open_bus(args.channel)
    touch(args.ready)
    frames = []
    deadline = time.monotonic() + args.timeout
    try:
        while len(frames) < want_frames and time.monotonic() < deadline:
            msg = bus.recv(timeout=0.2)
            if msg is not None:
                frames.append(msg)
    finally:
        bus.shutdown()
    if len(frames) != want_frames:
        fail(f"received {len(frames)} CAN frames through python-can slcan, expected {want_frames}")

    # 1. Frame-exact against `supine wire sample --format slcan`.
    for i, (msg, line) in enumerate(zip(frames, sample_lines)):
        text = ("T%08X" if msg.is_extended_id else "t%03X") % msg.arbitration_id
        text += "%d" % msg.dlc + bytes(msg.data).hex().upper()
        if text != line:
            fail(f"frame {i}: python-can got {text}, `wire sample --format slcan` says {line}")

    # 2. E2E fields, cantools decode, grouping into messages.
    groups = []
    current = None
    for msg in frames:
        data = bytes(msg.data)
        if len(data) != 8:
            fail(f"frame 0x{msg.arbitration_id:X} has {len(data)} bytes, not 8")
        if data[0] != e2e_crc(msg.arbitration_id, data):
            fail(f"frame 0x{msg.arbitration_id:X}: CRC-8 {data[0]:#04x}, expected {e2e_crc(msg.arbitration_id, data):#04x}")
        kind = KINDS[(msg.arbitration_id - BASE) >> 4]
        index = (msg.arbitration_id - BASE) & 0xF
        counter = data[1] & 0x0F
        if index == 0:
            current = {"kind": kind, "counter": counter, "signals": []}
            groups.append(current)
        elif current is None or current["kind"] != kind or current["counter"] != counter:
            fail(f"frame 0x{msg.arbitration_id:X} does not continue the group before it")
        db_msg = db.get_message_by_frame_id(msg.arbitration_id)
        raw = db.decode_message(msg.arbitration_id, data, scaling=False, decode_choices=False)
        named = db.decode_message(msg.arbitration_id, data, scaling=False, decode_choices=True)
        for sig in db_msg.signals:
            if sig.name in ("Crc", "Counter"):
                continue
            choice = named[sig.name]
            choice = str(choice) if not isinstance(choice, (int, float)) else None
            current["signals"].append((f"{db_msg.name}.{sig.name}", int(raw[sig.name]), sig.scale, choice))
            if sig.name == "Seq" and (int(raw[sig.name]) & 0xF) != counter:
                fail(f"{db_msg.name}: counter {counter} is not Seq & 0xF ({raw[sig.name]})")
    if len(groups) != len(sample_json):
        fail(f"{len(groups)} messages rebuilt from CAN, `wire sample --format json` has {len(sample_json)}")

    # 3. Every decoded signal value appears in the sample's JSON for that message.
    for g, expected in zip(groups, sample_json):
        if expected.get("kind") not in (None, g["kind"]):
            fail(f"message kind {g['kind']} on CAN, {expected.get('kind')} in the sample JSON")
        pool = list(leaves(expected))
        for name, raw, scale, choice in g["signals"]:
            for i, leaf in enumerate(pool):
                if leaf_matches(leaf, raw, scale, choice):
                    del pool[i]
                    break
            else:
                fail(f"{g['kind']}: CAN signal {name} = {raw} (choice {choice}) not found in sample JSON {expected}")
    print(f"link_slcan_peer: recv-slcan ok: {len(frames)} frames, {len(groups)} messages match the samples")


ARM_MESSAGES = [
    # seq, timestamp_us, position_mm, orientation_q14 (w, x, y, z): the documented sample, then two more.
    (5121, 1234571200, (690, -120, 905), (819, 16353, 328, -492)),
    (5122, 1234604533, (701, -118, 899), (819, 16353, 328, -492)),
    (5123, 1234637866, (-32768, 32767, 0), (16384, 0, 0, 0)),
]
COMMAND = (12, 1234580000, 4, 2)  # seq, timestamp, command code (set_shape_mode), shape mode (continuous)


def e2e_frame(db, name, signals, seq):
    import can

    db_msg = db.get_message_by_name(name)
    data = bytearray(db.encode_message(name, dict(signals, Crc=0, Counter=seq & 0xF), scaling=False))
    data[0] = e2e_crc(db_msg.frame_id, data)
    return can.Message(arbitration_id=db_msg.frame_id, is_extended_id=False, data=bytes(data))


def send_slcan(args):
    import cantools

    db = cantools.database.load_file(args.dbc)
    frames = []
    for seq, ts, pos, rot in ARM_MESSAGES:
        frames += [
            e2e_frame(db, "ARM_HEAD", {"Seq": seq}, seq),
            e2e_frame(db, "ARM_TIME", {"TimestampUs": ts}, seq),
            e2e_frame(db, "ARM_POS", {"PosX": pos[0], "PosY": pos[1], "PosZ": pos[2]}, seq),
            e2e_frame(db, "ARM_ROT_A", {"RotW": rot[0], "RotX": rot[1], "RotY": rot[2]}, seq),
            e2e_frame(db, "ARM_ROT_B", {"RotZ": rot[3]}, seq),
        ]
    # A damaged frame (CRC wrong) between the groups: must be counted, not crash or decode.
    bad = e2e_frame(db, "ARM_POS", {"PosX": 1, "PosY": 2, "PosZ": 3}, 9)
    bad.data = bytes([bad.data[0] ^ 0x5A]) + bytes(bad.data[1:])
    frames.insert(5, bad)
    seq, ts, code, mode = COMMAND
    frames += [
        e2e_frame(db, "CMD_HEAD", {"Seq": seq, "Command": code, "ShapeMode": mode}, seq),
        e2e_frame(db, "CMD_TIME", {"TimestampUs": ts}, seq),
    ]
    bus = open_bus(args.channel)
    try:
        if args.wait_for:
            deadline = time.monotonic() + args.timeout
            while not os.path.exists(args.wait_for):
                if time.monotonic() > deadline:
                    fail(f"{args.wait_for} never appeared (listener not started?)")
                time.sleep(0.05)
        for f in frames:
            bus.send(f)
            time.sleep(0.002)
        time.sleep(0.2)
    finally:
        bus.shutdown()
    print(f"link_slcan_peer: send-slcan ok: {len(frames)} frames sent")


def check_listen(args):
    lines = load_json_lines(args.lines)
    arm = [m for m in lines if m.get("kind") == "arm_state"]
    cmd = [m for m in lines if m.get("kind") == "command"]
    if len(arm) != len(ARM_MESSAGES) or len(cmd) != 1:
        fail(f"listen printed {len(arm)} arm_state and {len(cmd)} command lines: {lines}")
    for got, (seq, ts, pos, rot) in zip(arm, ARM_MESSAGES):
        want = {"seq": seq, "timestamp_us": ts, "position_mm": list(pos), "orientation_q14": list(rot)}
        for k, v in want.items():
            if got.get(k) != v:
                fail(f"arm_state {seq}: {k} is {got.get(k)}, sent {v}")
    seq, ts, code, mode = COMMAND
    c = cmd[0]
    got = (c.get("seq"), c.get("timestamp_us"), c.get("command"), c.get("command_id"), c.get("arg"))
    if got != (seq, ts, "set_shape_mode", code, mode):
        fail(f"command line {c} does not match what was sent")
    with open(args.report) as f:
        reports = [json.loads(line) for line in f if line.strip().startswith("{")]
    final = [r for r in reports if r.get("command") == "listen" and r.get("stopped")]
    if not final:
        fail(f"no final listen report on stderr: {reports}")
    counters = final[-1]["counters"]
    if counters["rx_errors"]["crc"] < 1:
        fail(f"the damaged frame was not counted as a CRC error: {counters}")
    if final[-1]["sequence"]["lost"] != 0:
        fail(f"listen reports lost messages: {final[-1]['sequence']}")
    print(f"link_slcan_peer: check-listen ok: {len(lines)} JSON lines, errors {counters['rx_errors']}")


def recv_serial(args):
    import serial

    with open(args.expect_hex) as f:
        want = b"".join(bytes.fromhex(line.strip()) for line in f if line.strip())
    port = serial.Serial(args.port, baudrate=921600, timeout=0.2)
    touch(args.ready)
    got = b""
    deadline = time.monotonic() + args.timeout
    try:
        while len(got) < len(want) and time.monotonic() < deadline:
            got += port.read(len(want) - len(got))
    finally:
        port.close()
    if got != want:
        fail(f"serial bytes differ from `wire sample --format cobs-hex`:\n got  {got.hex()}\n want {want.hex()}")
    print(f"link_slcan_peer: recv-serial ok: {len(got)} bytes, byte-exact")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("recv-slcan")
    a.add_argument("--channel", required=True)
    a.add_argument("--dbc", required=True)
    a.add_argument("--expect-json", required=True)
    a.add_argument("--expect-slcan", required=True)
    a.add_argument("--ready")
    a.add_argument("--timeout", type=float, default=10)
    b = sub.add_parser("send-slcan")
    b.add_argument("--channel", required=True)
    b.add_argument("--dbc", required=True)
    b.add_argument("--wait-for")
    b.add_argument("--timeout", type=float, default=10)
    c = sub.add_parser("check-listen")
    c.add_argument("--lines", required=True)
    c.add_argument("--report", required=True)
    d = sub.add_parser("recv-serial")
    d.add_argument("--port", required=True)
    d.add_argument("--expect-hex", required=True)
    d.add_argument("--ready")
    d.add_argument("--timeout", type=float, default=10)
    args = p.parse_args()
    {"recv-slcan": recv_slcan, "send-slcan": send_slcan, "check-listen": check_listen, "recv-serial": recv_serial}[
        args.cmd
    ](args)


if __name__ == "__main__":
    main()
