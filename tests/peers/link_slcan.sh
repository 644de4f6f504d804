#!/usr/bin/env bash
# Real-peer checks of supine's links over socat pty pairs (see link_slcan_peer.py for what each check compares):
#  (a) `supine wire send --sink slcan:PTY` received by python-can's slcan bus, decoded with cantools and the repo's
#      DBC, compared with `supine wire sample --format slcan` (frame-exact) and `--format json` (values);
#  (b) `supine wire listen --link slcan:PTY` receiving arm-state and command groups that python-can sends
#      (encoded with cantools, E2E fields filled in), plus one damaged frame that must be counted;
#  (c) `supine wire send --sink serial:PTY` read by pyserial, byte-exact against `--format cobs-hex`.
# Fails loudly when a peer is missing; every wait has a timeout; background processes are cleaned up.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)
py=${SUPINE_PYTHON:-$root/.venv/bin/python}
helper=$root/tests/peers/link_slcan_peer.py
dbc=$root/core/src/wire/supine.dbc

die() {
    echo "link_slcan: FAIL: $*" >&2
    exit 1
}

[[ -x $py ]] || die "no Python venv at $py (run tests/setup.sh)"
"$py" -c 'import can, serial, cantools' 2>/dev/null || die "python-can, pyserial or cantools missing in $py (run tests/setup.sh)"
command -v socat >/dev/null || die "socat is not installed (tests/deps/apt.txt; run tests/setup.sh)"
[[ -f $dbc ]] || die "DBC not found at $dbc"

source "$root/tests/peers/cargo-args.bash"
"${supine_build[@]}"
bin=$root/target/debug/supine

tmp=$(mktemp -d)
pids=()
cleanup() {
    for pid in "${pids[@]}"; do
        kill "$pid" 2>/dev/null || true
    done
    for pid in "${pids[@]}"; do
        wait "$pid" 2>/dev/null || true
    done
    rm -rf "$tmp"
}
trap cleanup EXIT

# A socat pty pair: $tmp/NAME.a and $tmp/NAME.b, raw, no echo.
pty_pair() {
    local name=$1
    socat -d -d "pty,raw,echo=0,link=$tmp/$name.a,b921600" "pty,raw,echo=0,link=$tmp/$name.b,b921600" \
        2>"$tmp/socat-$name.log" &
    pids+=($!)
    for _ in $(seq 100); do
        [[ -e $tmp/$name.a && -e $tmp/$name.b ]] && return 0
        sleep 0.05
    done
    cat "$tmp/socat-$name.log" >&2
    die "socat did not create the pty pair $name"
}

# Wait (up to $2 s) until file $1 exists and is non-empty.
wait_file() {
    for _ in $(seq $(($2 * 20))); do
        [[ -s $1 ]] && return 0
        sleep 0.05
    done
    die "timed out waiting for $1"
}

"$bin" wire sample --format json >"$tmp/sample.jsonl" || die "supine wire sample --format json failed"
"$bin" wire sample --format slcan | tr '\r' '\n' >"$tmp/sample.slcan" || die "supine wire sample --format slcan failed"
"$bin" wire sample --format cobs-hex >"$tmp/sample.hex" || die "supine wire sample --format cobs-hex failed"

echo "--- (a) supine wire send --sink slcan -> python-can slcan + cantools"
pty_pair a
timeout 30 "$py" "$helper" recv-slcan --channel "$tmp/a.b" --dbc "$dbc" --expect-json "$tmp/sample.jsonl" \
    --expect-slcan "$tmp/sample.slcan" --ready "$tmp/a.ready" --timeout 15 &
recv=$!
pids+=($recv)
wait_file "$tmp/a.ready" 15
timeout 20 "$bin" wire send --sink "slcan:$tmp/a.a" --count 1 2>"$tmp/send-a.log" || {
    cat "$tmp/send-a.log" >&2
    die "(a) supine wire send failed"
}
wait "$recv" || die "(a) python-can/cantools check failed"
grep -q '"closed_cleanly":true' "$tmp/send-a.log" || die "(a) send did not close cleanly: $(cat "$tmp/send-a.log")"

echo "--- (b) python-can slcan (cantools-encoded arm state) -> supine wire listen --link slcan"
pty_pair b
timeout 30 "$bin" wire listen --link "slcan:$tmp/b.a" --count 4 --idle-timeout 10 \
    >"$tmp/listen.jsonl" 2>"$tmp/listen.err" &
listen=$!
pids+=($listen)
wait_file "$tmp/listen.err" 15
timeout 30 "$py" "$helper" send-slcan --channel "$tmp/b.b" --dbc "$dbc" || die "(b) python-can sender failed"
wait "$listen" || {
    cat "$tmp/listen.err" >&2
    die "(b) supine wire listen failed"
}
"$py" "$helper" check-listen --lines "$tmp/listen.jsonl" --report "$tmp/listen.err" || {
    cat "$tmp/listen.jsonl" "$tmp/listen.err" >&2
    die "(b) listen output check failed"
}

echo "--- (c) supine wire send --sink serial -> pyserial, byte-exact COBS"
pty_pair c
timeout 30 "$py" "$helper" recv-serial --port "$tmp/c.b" --expect-hex "$tmp/sample.hex" --ready "$tmp/c.ready" \
    --timeout 15 &
recv=$!
pids+=($recv)
wait_file "$tmp/c.ready" 15
timeout 20 "$bin" wire send --sink "serial:$tmp/c.a@921600" --count 1 2>"$tmp/send-c.log" || {
    cat "$tmp/send-c.log" >&2
    die "(c) supine wire send failed"
}
wait "$recv" || die "(c) pyserial byte-exact check failed"

echo "link_slcan: all peer checks passed"
