#!/usr/bin/env bash
# Benchmarks of supine side by side with what users would pick instead (issue 14): criterion medians of every
# per-frame stage, supine's ICP against Open3D and small_gicp, supine's joint forest against scikit-learn, and the
# whole tracking frame (criterion `frame` bench; per-frame samples from `supine frame-bench`; peak RSS of
# `supine demo`; instructions per frame on aarch64 and x86-64 from cross/count-instructions). Installs its Python
# peers into .venv
# (tests/bench/requirements.txt), writes the JSON report and regenerates docs/BENCHMARKS.md (+ PNG plots in
# docs/bench/) from a full run; a --quick run writes its report under target/bench/quick/ and leaves docs/ alone.
#
#   tests/bench/run.sh [--quick] [--json FILE] [--instructions | --no-instructions]
#
#   --quick            small problem sets and short criterion runs (under 10 minutes on the 2-core machine)
#   --json FILE        also copy the JSON report here (default: target/bench/{full,quick}/report.json)
#   --instructions     count instructions per frame (cross/count-instructions, every workload; builds both cross
#                      targets first, a few minutes): the default of a full run, off for --quick
#   --no-instructions  skip the count (frame_instructions_aarch64 is then null)
#   --instructions-from FILE
#                      take the counts from a `cross/count-instructions --json FILE` run made at the same commit
#                      instead of counting again (the page names the file's commit)
#
# Single-threaded everywhere: the Rust sides run pinned to CPU 0 with one rayon thread, the Python peers with
# OMP/BLAS at one thread and n_jobs=1.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)

quick=0
json=""
instructions=-1
insn_from=""
while (($#)); do
    case $1 in
    --quick) quick=1 ;;
    --json) [[ $# -ge 2 ]] || { echo "tests/bench/run.sh: --json needs a file" >&2; exit 2; }; json=$2; shift ;;
    --instructions) instructions=1 ;;
    --no-instructions) instructions=0 ;;
    --instructions-from)
        [[ $# -ge 2 && -f $2 ]] || { echo "tests/bench/run.sh: --instructions-from needs an existing file" >&2; exit 2; }
        insn_from=$(realpath "$2"); instructions=0; shift ;;
    -h | --help) sed -n '2,22p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "tests/bench/run.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
    shift
done

mode=full
((quick)) && mode=quick
((instructions >= 0)) || instructions=$((1 - quick))
work=$root/target/bench/$mode
rm -rf "$work"
mkdir -p "$work"
log() { echo "=== bench: $*" >&2; }
t_start=$SECONDS

# Python peers, pinned, in the project's venv (idempotent, like tests/setup.sh).
if [[ ! -x .venv/bin/python ]]; then
    log "creating .venv"
    python3 -m venv .venv
fi
stamp=.venv/.bench-requirements.sha256
want=$(sha256sum tests/bench/requirements.txt | cut -d' ' -f1)
if [[ ! -f $stamp || $(cat "$stamp") != "$want" ]]; then
    log "installing the Python peers into .venv"
    .venv/bin/python -m pip install -q --disable-pip-version-check -r tests/bench/requirements.txt
    echo "$want" >"$stamp"
fi
py=$root/.venv/bin/python
pin=(taskset -c 0)
command -v taskset >/dev/null 2>&1 || pin=()

commands=()
run() {
    commands+=("$*")
    log "$*"
    "$@"
}

# 1. Criterion: every per-frame stage that exists.
if ((quick)); then crit=(--warm-up-time 1 --measurement-time 2); else crit=(--warm-up-time 3 --measurement-time 10); fi
# Built first on every core, then measured pinned to one.
run cargo bench -q -p supine-models --bench stages --no-run
run "${pin[@]}" cargo bench -q -p supine-models --bench stages -- "${crit[@]}" >"$work/stages.txt"

# 2. The whole frame: the tracker's criterion bench named `frame`, when it exists.
frame_bench=""
for crate in core models; do
    if grep -q '^name = "frame"' "$crate/Cargo.toml" 2>/dev/null; then
        frame_bench=$crate
    fi
done
if [[ -n $frame_bench ]]; then
    pkg=supine-core
    [[ $frame_bench == models ]] && pkg=supine-models
    run cargo bench -q -p "$pkg" --bench frame --no-run
    run "${pin[@]}" cargo bench -q -p "$pkg" --bench frame -- "${crit[@]}" >"$work/frame.txt"
fi
# Per-frame samples of the tracker alone (the demo recording decoded first, init done, then one thread-CPU-time
# and one wall-time sample per Tracker::process), and the peak RSS of the whole streaming pipeline (`supine demo`).
if ((quick)); then frame_n=300; else frame_n=3000; fi
run cargo build -q --release -p supine
run "${pin[@]}" target/release/supine frame-bench --frames "$frame_n" --json "$work/frame_bench.json" >"$work/frame_bench.txt"
if [[ -x /usr/bin/time ]]; then
    run /usr/bin/time -f %M -o "$work/demo_rss_kib.txt" "${pin[@]}" target/release/supine demo >"$work/demo.txt"
fi
if ((instructions)); then
    run cross/count-instructions --json "$work/instructions.json" >"$work/instructions.txt"
elif [[ -n $insn_from ]]; then
    cp "$insn_from" "$work/instructions.json"
    commands+=("cross/count-instructions --json FILE  # counted separately, at commit $(python3 -c 'import json,sys; print(json.load(open(sys.argv[1])).get("commit"))' "$insn_from")")
fi

# 3. ICP: problems from held-out sequences, supine's registrations, then the peers on the same files.
run cargo build -q --release -p supine-models --bin supine-bench
bench=$root/target/release/supine-bench
if ((quick)); then
    icp_args=(--bodies 3 --views 2 --repeats 11)
    icp_peer_repeats=3
    forest_args=(--bodies 8 --views 4 --depth 12 --epochs 8 --test-images 12 --repeats 3)
else
    icp_args=(--bodies 8 --views 3 --repeats 21)
    icp_peer_repeats=3
    forest_args=(--bodies 24 --views 8 --depth 20 --epochs 32 --test-images 48 --repeats 5)
fi
run "${pin[@]}" "$bench" icp --out "$work/icp" --seed 1400 "${icp_args[@]}"
run "${pin[@]}" "$py" tests/bench/icp_peers.py "$work/icp" --repeats "$icp_peer_repeats" --json "$work/icp.json"

# 4. Forest: supine's trainer and inference, then scikit-learn on the same samples.
run "${pin[@]}" "$bench" forest --out "$work/forest" --seed 1414 "${forest_args[@]}"
run "${pin[@]}" "$py" tests/bench/forest_peers.py "$work/forest" --repeats 3 --json "$work/forest.json"

# 5. The report: JSON, and docs/BENCHMARKS.md with plots from a full run.
docs_args=()
if ((quick)); then
    docs_args=(--md "$work/BENCHMARKS.md" --png-dir "$work/plots")
else
    docs_args=(--md docs/BENCHMARKS.md --png-dir docs/bench)
fi
printf '%s\n' "${commands[@]}" >"$work/commands.txt"
"$py" tests/bench/report.py --work "$work" --mode "$mode" --frame-bench "${frame_bench:-}" \
    --seconds $((SECONDS - t_start)) --json "$work/report.json" "${docs_args[@]}"
if [[ -n $json ]]; then
    cp "$work/report.json" "$json"
    log "wrote $json"
fi
log "done in $((SECONDS - t_start)) s ($mode): $work/report.json"
