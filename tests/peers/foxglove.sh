#!/usr/bin/env bash
# The Foxglove outputs read back by independent Python peers (tests/run.sh runs it as step peer:foxglove; about
# 15 s once the test step has built everything):
#  1. the MCAP of the committed demo with ground-truth overlays (written by the foxglove unit test) and the MCAPs
#     of `supine replay --record` on the demo recording and on the real ROS 2 bag in shared/ (when present), read
#     by the `mcap` package: schemas, counts, monotonic log times (foxglove_mcap.py);
#  2. the live view of `supine replay --view` read by a `websockets` client (foxglove_live_view.py);
#  3. the same two outputs of the service, `supine run --config … --record OUT.mcap` on the demo recording and
#     `supine run --view` on it looped (ended with SIGTERM once the client has its frames).
# Needs the venv of tests/setup.sh (mcap, websockets); shared/ is beside the checkout or at $SUPINE_SHARED_DIR.
# Usage: tests/peers/foxglove.sh [PATH-TO-SUPINE-BINARY]
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
py=${SUPINE_PYTHON:-$root/.venv/bin/python}
peers=$root/tests/peers
# Under tests/run.sh (SUPINE_PEERS=1) reuse the test step's build instead of building another (see cargo-args.bash).
source "$peers/cargo-args.bash"
if [[ $# -ge 1 ]]; then
    supine=$1
else
    "${supine_build[@]}"
    supine=$root/target/debug/supine
fi
tmp=$(mktemp -d)
viewer=
cleanup() {
    if [[ -n $viewer ]]; then kill "$viewer" 2>/dev/null || true; fi
    rm -rf "$tmp"
}
trap cleanup EXIT

SUPINE_KEEP_MCAP=$tmp/overlays.mcap cargo test -q "${supine_cargo[@]}" mcap_recording_of_the_demo >/dev/null
"$py" "$peers/foxglove_mcap.py" "$tmp/overlays.mcap" --frames 60 --overlays

"$supine" replay models/artifacts/demo/sequence.oni --record "$tmp/demo.mcap" >/dev/null
"$py" "$peers/foxglove_mcap.py" "$tmp/demo.mcap" --frames 60

bag=${SUPINE_SHARED_DIR:-$root/../shared}/realdata/mcap/tue_person_depth_16UC1.mcap
if [[ -f $bag ]]; then
    "$supine" replay "$bag" --record "$tmp/tue.mcap" >/dev/null
    "$py" "$peers/foxglove_mcap.py" "$tmp/tue.mcap" --frames 5
else
    echo "foxglove: shared/realdata not available: the ROS 2 bag replay is skipped"
fi

# A free port: bind 0, read it, release it (the replay binds it a moment later).
port=$("$py" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$supine" replay models/artifacts/demo/sequence.oni --realtime --view "127.0.0.1:$port" --view-wait 60 \
    >"$tmp/replay.out" 2>&1 &
viewer=$!
"$py" "$peers/foxglove_live_view.py" "ws://127.0.0.1:$port" --frames 20
wait "$viewer" || { cat "$tmp/replay.out"; echo "foxglove: replay --view failed"; exit 1; }
viewer=

# The service: a config on the demo recording with a file link (1 s frame budget: the outputs thread shares the
# machine, and this checks the channels, not the budget).
models=$root/models/artifacts
service_config() {
    cat >"$tmp/run.toml" <<EOF
source = "file:$models/demo/sequence.oni"
loop_source = $1
link = "file:$tmp/packets.bin"
[models]
dir = "$models"
body = "body.sbm"
joints = "joints.jfor"
shape = "shape.ssm"
[budget]
frame_ms = 1000.0
[log]
filter = "warn"
EOF
}
service_config false
"$supine" run --config "$tmp/run.toml" --record "$tmp/run.mcap" 2>"$tmp/run.err" ||
    { cat "$tmp/run.err"; echo "foxglove: run --record failed"; exit 1; }
# The service drops frames rather than wait for the recorder: count what it says it wrote.
recorded=$(sed -n 's/.*Foxglove outputs: \([0-9]*\) frames recorded.*/\1/p' "$tmp/run.err")
[[ -n $recorded && $recorded -gt 0 ]] || { cat "$tmp/run.err"; echo "foxglove: run --record wrote no frame"; exit 1; }
"$py" "$peers/foxglove_mcap.py" "$tmp/run.mcap" --frames "$recorded"

service_config true
port=$("$py" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$supine" run --config "$tmp/run.toml" --view "127.0.0.1:$port" --view-wait 60 >"$tmp/run-view.out" 2>&1 &
viewer=$!
"$py" "$peers/foxglove_live_view.py" "ws://127.0.0.1:$port" --frames 20
kill -TERM "$viewer"
wait "$viewer" || { cat "$tmp/run-view.out"; echo "foxglove: run --view failed"; exit 1; }
viewer=
echo "foxglove: ok"
