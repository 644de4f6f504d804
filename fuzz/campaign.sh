#!/usr/bin/env bash
# A fuzzing campaign: every cargo-fuzz target in fuzz/fuzz_targets/, one after the other, each for
# ${SUPINE_FUZZ_RUNS:-10000000} executions or at most ${SUPINE_FUZZ_MAX_SECONDS:-900} seconds, whichever comes first,
# niced (${SUPINE_FUZZ_NICE:-10}). Corpora grow in fuzz/corpus/TARGET and crash inputs land in fuzz/artifacts/TARGET
# (both git-ignored); logs in fuzz/target/campaign-TARGET.log. The figures (executions, time, coverage, features,
# corpus size, crashes) replace the table between the campaign markers in docs/FUZZING.md.
#
#   fuzz/campaign.sh                 # every target
#   fuzz/campaign.sh serial oni_reader
#
# Exit 1 if a target does not build, a .rs file in fuzz_targets/ is not a registered target, or any target crashed.
# CI keeps running tests/fuzz-smoke.sh (seconds per target); this is the long, once-in-a-while run.
set -euo pipefail
cd "$(dirname "$0")/.."

runs=${SUPINE_FUZZ_RUNS:-10000000}
max_secs=${SUPINE_FUZZ_MAX_SECONDS:-900}
niceness=${SUPINE_FUZZ_NICE:-10}
doc=${SUPINE_FUZZ_DOC:-docs/FUZZING.md}
export PATH="$HOME/.cargo/bin:$PATH"

if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "campaign: cargo-fuzz is not installed (run tests/setup.sh or: cargo install --locked cargo-fuzz)" >&2
    exit 1
fi
if rustup run nightly rustc --version >/dev/null 2>&1; then
    fuzz=(cargo +nightly fuzz)
    toolchain=$(rustup run nightly rustc --version)
else
    export RUSTC_BOOTSTRAP=1
    fuzz=(cargo fuzz)
    toolchain="$(rustc --version) with RUSTC_BOOTSTRAP=1"
fi

# Every source file in fuzz_targets/ must be a registered target, so a new one cannot be silently skipped.
mapfile -t registered < <("${fuzz[@]}" list --fuzz-dir fuzz)
for f in fuzz/fuzz_targets/*.rs; do
    name=$(basename "$f" .rs)
    if ! printf '%s\n' "${registered[@]}" | grep -qx "$name"; then
        echo "campaign: $f is not a [[bin]] of fuzz/Cargo.toml (cargo fuzz list does not show it)" >&2
        exit 1
    fi
done
if (($# > 0)); then targets=("$@"); else targets=("${registered[@]}"); fi

mkdir -p fuzz/target fuzz/corpus
rows=()
crashed=()
for t in "${targets[@]}"; do
    log="fuzz/target/campaign-$t.log"
    mkdir -p "fuzz/corpus/$t" "fuzz/artifacts/$t"
    before=$(find "fuzz/artifacts/$t" -type f | wc -l)
    # Built just before its run, so a long campaign fuzzes the sources as they are when each target starts.
    echo "campaign: building $t ($toolchain)"
    commit=$(git rev-parse --short HEAD)
    git diff --quiet HEAD -- core drivers fuzz || commit="$commit+dirty"
    nice -n "$niceness" "${fuzz[@]}" build --fuzz-dir fuzz "$t"
    echo "campaign: $t: up to $runs executions or $max_secs s (log $log)"
    t0=$(date +%s)
    status=0
    # The outer timeout only guards against a hung run; libFuzzer stops itself at -runs or -max_total_time.
    # Committed seeds (fuzz/seeds/TARGET, where present) are read as well; new inputs go to the corpus.
    seeds=()
    [[ -d fuzz/seeds/$t ]] && seeds=("fuzz/seeds/$t")
    timeout $((max_secs + 300)) nice -n "$niceness" "${fuzz[@]}" run --fuzz-dir fuzz "$t" "fuzz/corpus/$t" "${seeds[@]}" -- \
        -runs="$runs" -max_total_time="$max_secs" -print_final_stats=1 -close_fd_mask=3 >"$log" 2>&1 || status=$?
    secs=$(($(date +%s) - t0))
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1 || true)
    rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1 || true)
    last=$(grep -E '(DONE|#[0-9]+).*cov: [0-9]+' "$log" | tail -1 || true)
    cov=$(grep -o 'cov: [0-9]*' <<<"$last" | grep -o '[0-9]*' || true)
    ft=$(grep -o 'ft: [0-9]*' <<<"$last" | grep -o '[0-9]*' || true)
    corpus=$(find "fuzz/corpus/$t" -type f | wc -l)
    crashes=$(($(find "fuzz/artifacts/$t" -type f | wc -l) - before))
    if ((status != 0)) && ((crashes == 0)); then crashes="run failed (exit $status)"; fi
    if [[ "$crashes" != 0 ]]; then crashed+=("$t"); fi
    reached="yes"
    if [[ -z "$execs" ]] || ((execs < runs)); then reached="no (stopped at the ${max_secs} s cap)"; fi
    echo "campaign: $t: ${execs:-?} executions in ${secs} s, cov ${cov:-?}, ft ${ft:-?}, corpus $corpus, crashes $crashes"
    rows+=("| \`$t\` | $(date -u '+%Y-%m-%d %H:%M') | \`$commit\` | $toolchain | ${execs:-?} | $reached | $secs | ${rate:-?} | ${cov:-?} | ${ft:-?} | $corpus | $crashes |")
done

# Rewrite the table between the markers: the rows of the targets just run replace their old rows, the other
# targets' rows stay (so one target can be rerun alone).
host="$(nproc) shared cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
new_rows=$(printf '%s\n' "${rows[@]}")
if [[ ! -f "$doc" ]] || ! grep -q '<!-- campaign:begin' "$doc"; then
    printf '\n## Campaign figures\n\n<!-- campaign:begin (written by fuzz/campaign.sh) -->\n<!-- campaign:end -->\n' >>"$doc"
fi
header="| target | date (UTC) | commit | toolchain | executions | target reached? | time (s) | exec/s | coverage (cov) | features (ft) | corpus files | crashes |"
NEW_ROWS="$new_rows" HEADER="$header" HOST="$host" awk '
    function name(row) { split(row, f, "|"); gsub(/[ `]/, "", f[2]); return f[2] }
    BEGIN { n = split(ENVIRON["NEW_ROWS"], fresh, "\n"); for (i = 1; i <= n; i++) seen[name(fresh[i])] = 1 }
    /<!-- campaign:begin/ { print; inside = 1; next }
    inside && /^\| `/ { if (!(name($0) in seen)) kept[++k] = $0; next }
    inside && !/<!-- campaign:end -->/ { next }
    /<!-- campaign:end -->/ {
        print "Host: " ENVIRON["HOST"] ". Niced, one target at a time."
        print ""
        print ENVIRON["HEADER"]
        print "|---|---|---|---|---:|---|---:|---:|---:|---:|---:|---|"
        for (i = 1; i <= k; i++) print kept[i]
        for (i = 1; i <= n; i++) print fresh[i]
        inside = 0
    }
    { print }
' "$doc" >"$doc.tmp"
mv "$doc.tmp" "$doc"
echo "campaign: figures written to $doc"

if ((${#crashed[@]} > 0)); then
    echo "campaign: crashes or failed runs in: ${crashed[*]} (inputs in fuzz/artifacts/)" >&2
    exit 1
fi
