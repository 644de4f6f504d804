#!/usr/bin/env bash
# Peer check: cantools 45.1.0 (the pinned reference DBC tool) loads core/src/wire/supine.dbc in strict mode,
# decodes `supine wire sample --format candump`, and every decoded signal equals the value
# `supine wire sample --format json` prints (tests/peers/wire_cantools_compare.py). Needs .venv from tests/setup.sh.
set -euo pipefail
cd "$(dirname "$0")/../.."

py=.venv/bin/python
cantools=.venv/bin/cantools
dbc=core/src/wire/supine.dbc
for tool in "$py" "$cantools"; do
    if [[ ! -x $tool ]]; then
        echo "wire_cantools: missing $tool (run tests/setup.sh)" >&2
        exit 1
    fi
done
source tests/peers/cargo-args.bash
timeout 600 "${supine_build[@]}"
bin=target/debug/supine
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

timeout 60 "$py" -c "import cantools, sys; db = cantools.database.load_file(sys.argv[1], strict=True); \
print('wire_cantools: cantools', cantools.__version__, 'loaded', len(db.messages), 'frames')" "$dbc"
timeout 30 "$bin" wire sample --format json >"$tmp/sample.json"
timeout 30 "$bin" wire sample --format candump >"$tmp/candump.log"
timeout 60 "$cantools" decode --single-line "$dbc" <"$tmp/candump.log" >"$tmp/decoded.txt"
timeout 60 "$py" tests/peers/wire_cantools_compare.py "$tmp/sample.json" "$tmp/candump.log" "$tmp/decoded.txt"
