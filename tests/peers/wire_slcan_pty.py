"""SLCAN over a pty pair, read by python-can's real slcan interface.

Usage: wire_slcan_pty.py SUPINE_BINARY

socat makes a raw pty pair; python-can opens one end as an SLCAN adapter (`can.Bus(interface='slcan', ...)`);
`supine wire sample --format slcan` is written into the other end. python-can must receive exactly the frames of
`supine wire sample --format candump`, in order, and nothing else. Every wait has a timeout.
"""

import os
import subprocess
import sys
import tempfile
import time

import can

TIMEOUT_S = 20


def candump_frames(binary):
    out = subprocess.run([binary, "wire", "sample", "--format", "candump"], check=True, capture_output=True,
                         timeout=TIMEOUT_S).stdout.decode()
    frames = []
    for line in out.splitlines():
        ident, _, data = line.split()[2].partition("#")
        frames.append((int(ident, 16), bytes.fromhex(data)))
    return frames


def main():
    binary = sys.argv[1]
    want = candump_frames(binary)
    with tempfile.TemporaryDirectory() as tmp:
        a, b = os.path.join(tmp, "ttyA"), os.path.join(tmp, "ttyB")
        socat = subprocess.Popen(["socat", "pty,raw,echo=0,link=%s,b921600" % a, "pty,raw,echo=0,link=%s,b921600" % b],
                                 stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + TIMEOUT_S
            while not (os.path.exists(a) and os.path.exists(b)):
                if time.monotonic() > deadline or socat.poll() is not None:
                    print("wire_slcan_pty: socat did not create the pty pair")
                    return 1
                time.sleep(0.05)
            bus = can.Bus(interface="slcan", channel=b, sleep_after_open=0, tty_baudrate=921600)
            try:
                with open(a, "wb", buffering=0) as tty:
                    subprocess.run([binary, "wire", "sample", "--format", "slcan"], stdout=tty, check=True,
                                   timeout=TIMEOUT_S)
                got = []
                deadline = time.monotonic() + TIMEOUT_S
                while len(got) < len(want) and time.monotonic() < deadline:
                    msg = bus.recv(timeout=0.5)
                    if msg is not None:
                        got.append(msg)
                # Anything after the expected frames would be a framing error on our side.
                extra = bus.recv(timeout=0.5)
            finally:
                bus.shutdown()
        finally:
            socat.terminate()
            socat.wait(timeout=TIMEOUT_S)
    errors = []
    if extra is not None:
        errors.append("unexpected extra frame %r" % extra)
    if len(got) != len(want):
        errors.append("received %d frames, expected %d" % (len(got), len(want)))
    for i, (msg, (ident, data)) in enumerate(zip(got, want)):
        seen = (msg.arbitration_id, bytes(msg.data), msg.is_extended_id, msg.is_remote_frame, msg.dlc)
        if seen != (ident, data, False, False, len(data)):
            errors.append("frame %d: python-can %r, candump %03X#%s" % (i, seen, ident, data.hex().upper()))
    if errors:
        print("wire_slcan_pty: %d problems" % len(errors))
        for e in errors:
            print("  " + e)
        return 1
    print("wire_slcan_pty: python-can %s received all %d frames over a pty, identical to candump"
          % (can.__version__, len(got)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
