#!/usr/bin/env bash
# Builds every cargo-fuzz target in fuzz/ and runs each for ${SUPINE_FUZZ_SECONDS:-10} seconds, ${SUPINE_FUZZ_JOBS}
# (default: nproc) targets at a time: one libFuzzer run is one process on one core. Works with a
# nightly toolchain (`cargo +nightly fuzz`) when rustup has one, else with stable and RUSTC_BOOTSTRAP=1 (which
# unlocks the -Z sanitizer flags cargo-fuzz passes). Fails if cargo-fuzz is missing (tests/setup.sh installs it),
# if a target does not build, or if any target finds a crash. Corpora accumulate in fuzz/corpus/ (git-ignored).
set -euo pipefail
cd "$(dirname "$0")/.."

secs=${SUPINE_FUZZ_SECONDS:-10}
jobs=${SUPINE_FUZZ_JOBS:-$(nproc)}
[[ $jobs =~ ^[1-9][0-9]*$ ]] || { echo "fuzz-smoke: SUPINE_FUZZ_JOBS must be a positive integer, not '$jobs'" >&2; exit 1; }
export PATH="$HOME/.cargo/bin:$PATH"
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz-smoke: cargo-fuzz is not installed (run tests/setup.sh or: cargo install --locked cargo-fuzz)" >&2
    exit 1
fi
if rustup run nightly rustc --version >/dev/null 2>&1; then
    fuzz=(cargo +nightly fuzz)
    echo "fuzz-smoke: using nightly ($(rustup run nightly rustc --version))"
else
    export RUSTC_BOOTSTRAP=1
    fuzz=(cargo fuzz)
    echo "fuzz-smoke: no nightly toolchain; using $(rustc --version) with RUSTC_BOOTSTRAP=1"
fi

mapfile -t targets < <("${fuzz[@]}" list --fuzz-dir fuzz)
if ((${#targets[@]} == 0)); then
    echo "fuzz-smoke: no fuzz targets found in fuzz/" >&2
    exit 1
fi
echo "fuzz-smoke: building ${targets[*]}"
"${fuzz[@]}" build --fuzz-dir fuzz

# run_one TARGET: one smoke run, its stderr in fuzz/target/smoke-TARGET.log; the exit status is libFuzzer's.
run_one() {
    local t=$1 seeds=()
    # Committed seeds (fuzz/seeds/TARGET, where present) join the accumulated corpus as read-only inputs.
    [[ -d fuzz/seeds/$t ]] && seeds=("fuzz/corpus/$t" "fuzz/seeds/$t") && mkdir -p "fuzz/corpus/$t"
    # The outer timeout only guards against a hung run; libFuzzer stops itself after max_total_time.
    timeout $((secs + 120)) "${fuzz[@]}" run --fuzz-dir fuzz "$t" "${seeds[@]}" -- \
        -max_total_time="$secs" -print_final_stats=1 2>"fuzz/target/smoke-$t.log"
}

mkdir -p fuzz/target
failed=()
for ((first = 0; first < ${#targets[@]}; first += jobs)); do
    batch=("${targets[@]:first:jobs}")
    echo "fuzz-smoke: running ${batch[*]} for ${secs} s"
    pids=()
    for t in "${batch[@]}"; do
        run_one "$t" &
        pids+=($!)
    done
    for i in "${!batch[@]}"; do
        t=${batch[i]}
        log="fuzz/target/smoke-$t.log"
        if ! wait "${pids[i]}"; then
            echo "fuzz-smoke: $t FAILED; last lines of $log:" >&2
            tail -40 "$log" >&2
            failed+=("$t")
            continue
        fi
        execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo '?')
        echo "fuzz-smoke: $t ok, $execs executions"
    done
done
if ((${#failed[@]} > 0)); then
    echo "fuzz-smoke: failing targets: ${failed[*]}" >&2
    exit 1
fi
echo "fuzz-smoke: all ${#targets[@]} targets ok"
