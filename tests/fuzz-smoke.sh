#!/usr/bin/env bash
# Builds every cargo-fuzz target in fuzz/ and runs each for ${SUPINE_FUZZ_SECONDS:-20} seconds. Works with a
# nightly toolchain (`cargo +nightly fuzz`) when rustup has one, else with stable and RUSTC_BOOTSTRAP=1 (which
# unlocks the -Z sanitizer flags cargo-fuzz passes). Fails if cargo-fuzz is missing (tests/setup.sh installs it),
# if a target does not build, or if any target finds a crash. Corpora accumulate in fuzz/corpus/ (git-ignored).
set -euo pipefail
cd "$(dirname "$0")/.."

secs=${SUPINE_FUZZ_SECONDS:-20}
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

failed=()
for t in "${targets[@]}"; do
    log="fuzz/target/smoke-$t.log"
    mkdir -p fuzz/target
    echo "fuzz-smoke: running $t for ${secs} s"
    # The outer timeout only guards against a hung run; libFuzzer stops itself after max_total_time.
    # Committed seeds (fuzz/seeds/TARGET, where present) join the accumulated corpus as read-only inputs.
    seeds=()
    [[ -d fuzz/seeds/$t ]] && seeds=("fuzz/corpus/$t" "fuzz/seeds/$t") && mkdir -p "fuzz/corpus/$t"
    if ! timeout $((secs + 120)) "${fuzz[@]}" run --fuzz-dir fuzz "$t" "${seeds[@]}" -- \
        -max_total_time="$secs" -print_final_stats=1 2>"$log"; then
        echo "fuzz-smoke: $t FAILED; last lines of $log:" >&2
        tail -40 "$log" >&2
        failed+=("$t")
        continue
    fi
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo '?')
    echo "fuzz-smoke: $t ok, $execs executions"
done
if ((${#failed[@]} > 0)); then
    echo "fuzz-smoke: failing targets: ${failed[*]}" >&2
    exit 1
fi
echo "fuzz-smoke: all ${#targets[@]} targets ok"
