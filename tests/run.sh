#!/usr/bin/env bash
# The whole test suite of supine, as the README promises: installs what it needs (tests/setup.sh), then runs
# formatting, lints, every Rust test including the ones that need external peers, the peer checks in tests/peers/,
# the fuzz smoke runs and the emulated aarch64 build and tests. Every step runs even if an earlier one failed; the last
# line is "N passed, M failed" over the steps. Exit status 0 only if every step passed.
#
#   tests/run.sh              everything
#   SUPINE_SKIP=cross,fuzz tests/run.sh   skip steps whose names contain these words (local iteration only)
#   SUPINE_BENCH=1 tests/run.sh           also run the quick benchmarks (tests/bench/run.sh --quick)
set -uo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

passed=0
failed=0
failures=()

step() {
    local name=$1
    shift
    local skip=${SUPINE_SKIP:-}
    for word in ${skip//,/ }; do
        if [[ $name == *"$word"* ]]; then
            echo "=== skip $name (SUPINE_SKIP)"
            return 0
        fi
    done
    echo "=== step $name: $*"
    local t0=$SECONDS
    # CPU seconds (user + system, the step's processes and their children) beside the wall time: on a shared
    # machine the wall time depends on the neighbours, the CPU time much less, so step costs compare across runs.
    local TIMEFORMAT="%U %S"
    local times status=0
    times=$(mktemp)
    # The step's stderr goes to fd 3 (run.sh's stderr), so only the `time` report lands in $times.
    { time "$@" 2>&3; } 3>&2 2>"$times" || status=$?
    local cpu
    cpu=$(awk 'END { printf "%.0f", $1 + $2 }' "$times")
    rm -f "$times"
    if ((status == 0)); then
        passed=$((passed + 1))
        echo "=== ok   $name ($((SECONDS - t0)) s, cpu $cpu s)"
    else
        failed=$((failed + 1))
        failures+=("$name")
        echo "=== FAIL $name ($((SECONDS - t0)) s, cpu $cpu s)"
    fi
}

step setup bash tests/setup.sh
# setup.sh puts the venv and cargo tools on these paths.
export PATH="$root/.venv/bin:$HOME/.cargo/bin:$PATH"
export SUPINE_PEERS=1

step fmt cargo fmt --all -- --check
step clippy cargo clippy --workspace --all-targets --all-features -- -D warnings
# --include-ignored: tests that need peers (python-can, cantools, libOpenNI2, ptys) are #[ignore]d for plain
# `cargo test` on a Rust-only machine and run here, where setup.sh has installed those peers.
step test cargo test --workspace --all-features -- --include-ignored
# supine-core against a sysroot with neither std nor alloc (see the script for why this target).
step nostd bash tests/nostd-check.sh
for peer in tests/peers/*.sh; do
    [[ -e $peer ]] || continue
    step "peer:$(basename "$peer" .sh)" bash "$peer"
done
if [[ -x tests/fuzz-smoke.sh ]]; then
    step fuzz tests/fuzz-smoke.sh
fi
# Opt-in (SUPINE_BENCH=1): the quick side-by-side benchmarks (tests/bench/run.sh --quick, ~4 min on a built tree,
# plus the release and bench builds on a fresh one); figures only, no pass/fail threshold beyond running cleanly.
if [[ ${SUPINE_BENCH:-0} == 1 ]]; then
    step bench-quick tests/bench/run.sh --quick
fi
# cross/test's `same:` checks compare the aarch64 binary's output with an x86-64 build of the same source: the test
# step's target/debug/supine (the peers' binary too; cargo finds it fresh, see tests/peers/cargo-args.bash) instead
# of a head-profile build for x86_64 that nothing else used.
cross_test() {
    cargo test -q --workspace --all-features --no-run && cross/test aarch64 --same-bin target/debug/supine
}
if [[ -x cross/setup ]]; then
    step cross-setup cross/setup
    step cross-build cross/build aarch64
    step cross-test cross_test
    # The head-computer package: built from the cross build, installed, reinstalled, removed and purged in a scratch root.
    step cross-package cross/package aarch64 --verify
fi

echo
if ((failed > 0)); then
    echo "failed steps: ${failures[*]}"
fi
echo "steps: $passed passed, $failed failed"
((failed == 0))
