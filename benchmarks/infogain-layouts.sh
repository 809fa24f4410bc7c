#!/usr/bin/env bash
# Issue 27's adaptation target: infogain with each layout's 800-reach default model (kbcli learn
# with no --model-class: auto, active exploration, ideal mode, --seed 0) reaches 2 px in at most 7
# touches, median over the displacement categories. For every layout this learns the model, then
# prints kbcli bench adapt's learned section (random and infogain, EXPERIMENTS runs per category):
# the "<2px" column is the median number of touches to 2 px. About 3 minutes per layout on 2 cores.
#
#   benchmarks/infogain-layouts.sh                      # every layout, into build/infogain-layouts/
#   LAYOUTS="hex pads" EXPERIMENTS=50 benchmarks/infogain-layouts.sh
set -euo pipefail
cd "$(dirname "$0")/.."
KBCLI=${KBCLI:-.venv/bin/kbcli}
OUT=${OUT:-build/infogain-layouts}
LAYOUTS=${LAYOUTS:-grid hex piano pads polygons}
EXPERIMENTS=${EXPERIMENTS:-20}
BUDGET=${BUDGET:-800}
mkdir -p "$OUT"
for L in $LAYOUTS; do
    if [[ ! -f $OUT/kb-$L.h5 ]]; then
        if [[ $L == polygons ]]; then  # its keys come from a file
            "$KBCLI" keyboard --config pipelines/layouts/polygons.toml -o "$OUT/kb-$L.h5"
        else
            "$KBCLI" keyboard --layout "$L" -o "$OUT/kb-$L.h5"
        fi
    fi
    [[ -f $OUT/m-$L.h5 ]] || "$KBCLI" learn --keyboard "$OUT/kb-$L.h5" --budget "$BUDGET" --seed 0 \
        -o "$OUT/m-$L.h5"
    "$KBCLI" bench --json "$OUT/adapt-$L.json" adapt --section learned --model "$OUT/m-$L.h5" \
        --strategy random --strategy infogain --experiments "$EXPERIMENTS"
done
