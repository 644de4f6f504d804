#!/usr/bin/env bash
# Retrain the committed default joint forest and regenerate its report, in one command:
#   models/retrain-joints.sh [DATA_DIR]        (default DATA_DIR: target/joints-data)
# 1. renders the default dataset (150 bodies x 20 views, seed 1, whole frames, the patient resting on the back:
#    `--rest trunk`; skipped when DATA_DIR already holds it, refused when DATA_DIR holds another dataset),
# 2. trains (seed 0; 4 trees, 2048 training samples per image, 512 per frame at inference, at least 150 samples to
#    split, every fitting image in each tree, views read through the tracker's 0.6 m height ceiling, the refinement's
#    lambda2 1e-4 for the belly and the right hip and 1e-2 for the other points: chosen on validation bodies,
#    docs/joint-forest.md) into models/artifacts/joints.jfor (+ joints.jfor.float, the float
#    leaves for the report),
# 3. evaluates on the held-out 30 % of bodies into docs/joint-forest-eval.json and docs/joint-forest-fig6.png.
# Bigger runs are a flag away: BODIES=4000 VIEWS=12 models/retrain-joints.sh /big/disk/hvp
# The paper's Table 1 forest (3 trees, 512 samples): TRAIN_ARGS="--trees 3 --samples 512 --min-split 50" models/retrain-joints.sh
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${1:-target/joints-data}
BODIES=${BODIES:-150}
VIEWS=${VIEWS:-20}
DATASET_ARGS=${DATASET_ARGS:---crop-margin 640 --rest trunk}
TRAIN_ARGS=${TRAIN_ARGS:---trees 4 --samples 2048 --infer-samples 512 --min-split 150 --tree-images 1800 --lambda2 1e-2,1e-2,1e-2,1e-4,1e-2,1e-4}
cargo build --release -p supine-models --bin supine-models
BIN=target/release/supine-models
if [[ ! -f "$DATA/dataset.json" ]]; then
    nice -n 10 "$BIN" dataset --bodies "$BODIES" --views "$VIEWS" --seed 1 $DATASET_ARGS --out "$DATA"
elif ! grep -q "\"bodies\": $BODIES," "$DATA/dataset.json" || ! grep -q "\"views\": $VIEWS," "$DATA/dataset.json" \
    || ! grep -q '"seed": 1,' "$DATA/dataset.json" \
    || { [[ "$DATASET_ARGS" == *"--rest trunk"* ]] && ! grep -q '"rest": "trunk"' "$DATA/dataset.json"; }; then
    echo "error: $DATA holds another dataset than $BODIES bodies x $VIEWS views, seed 1 ($DATASET_ARGS); give another DATA_DIR or remove it" >&2
    exit 1
fi
nice -n 10 "$BIN" train joints --data "$DATA" --seed 0 $TRAIN_ARGS --json docs/joint-forest-train.json
nice -n 10 "$BIN" eval joints --data "$DATA" --seed 0 --json docs/joint-forest-eval.json \
    --png docs/joint-forest-fig6.png > "$DATA/eval.txt"
cp "$DATA/eval.txt" docs/joint-forest-eval.txt
