#!/usr/bin/env bash
# Peer check: python-can 4.6.1's slcan interface (with pyserial) reads `supine wire sample --format slcan` through a
# socat pty pair and must receive exactly the frames of `--format candump` (tests/peers/wire_slcan_pty.py).
# Needs socat (tests/deps/apt.txt) and .venv from tests/setup.sh; fails if either is missing.
set -euo pipefail
cd "$(dirname "$0")/../.."

py=.venv/bin/python
if [[ ! -x $py ]]; then
    echo "wire_slcan_pty: missing $py (run tests/setup.sh)" >&2
    exit 1
fi
if ! command -v socat >/dev/null 2>&1; then
    echo "wire_slcan_pty: socat is not installed (tests/deps/apt.txt; run tests/setup.sh)" >&2
    exit 1
fi
timeout 60 "$py" -c "import can, serial" || {
    echo "wire_slcan_pty: python-can or pyserial missing from .venv (run tests/setup.sh)" >&2
    exit 1
}
source tests/peers/cargo-args.bash
timeout 600 "${supine_build[@]}"
timeout 120 "$py" tests/peers/wire_slcan_pty.py target/debug/supine
