#!/usr/bin/env bash
# Reproduce the paper from nothing and time each stage: keyboard -> learn -> evaluate -> report.
# This is the recipe of `make reproduce`; it prints the wall time of every stage at the end (and
# writes it to $OUT/timings.txt, with the machine's load average before and after).
# pipelines/paper.toml names the methods: `paper` (the paper's KDE posterior, maximum-likelihood
# estimate, random and active), `kbcli` (ours, with infogain) and a large-displacement ablation.
#
#   benchmarks/reproduce.sh                  # both modes (ideal, dynamics), full paper scale
#   MODE=ideal benchmarks/reproduce.sh       # ideal mode only (Sect. IV-A/B)
#   JOBS=1 benchmarks/reproduce.sh           # experiments in one process (default: 2 local processes)
#   SCHEDULER=tcp://HOST:8786 benchmarks/reproduce.sh   # ... or on a Dask cluster
#   EXPERIMENTS=5 benchmarks/reproduce.sh    # a quick look: 5 runs per parametrization
#   METHODS="paper kbcli" benchmarks/reproduce.sh   # only these methods of the config (make
#                                            # reproduce: the paper's and ours; default: all)
#   EVAL=earlier.h5 METHODS="paper-v1 paper-likelihood" LEARN=missing benchmarks/reproduce.sh
#                                            # the earlier readings kept in paper.toml
#                                            # (make reproduce-earlier)
#   CONFIG=pipelines/ablations.toml EVAL=ablations.h5 LEARN=missing benchmarks/reproduce.sh
#                                            # the ablation ladder (make reproduce-ablations;
#                                            # MODE=dynamics EVAL=ablations-dynamics.h5: one mode)
#   OWN_MODEL=own-model.h5 benchmarks/reproduce.sh  # also the dynamics claims on that model's
#                                            # evaluation ($OUT/own-eval.h5, made first)
#
# The report is written for $OUT/eval.h5 (when it exists), reading beside it the ablation ladder
# $OUT/ablations*.h5 (one file, or one per mode) and the evaluation with the robot's own model
# $OUT/own-eval.h5 when they exist.
# Then the verdicts (with what explains each difference, when the ladder exists) and the timings
# are kept as a result file, $OUT/reproduce.json (`kbcli bench
# --json ... verdicts`, the format of benchmarks/results/*.json: `make results-reproduce` stores it
# for the documentation's results page).
#
# An interrupted run continues where it stopped when started again (evaluate --resume).
set -euo pipefail
cd "$(dirname "$0")/.."

KBCLI=${KBCLI:-.venv/bin/kbcli}
OUT=${OUT:-build}
REPORT=${REPORT:-report}
JOBS=${JOBS:-2}
MODE=${MODE:-}
METHODS=${METHODS:-${METHOD:-}}
EXPERIMENTS=${EXPERIMENTS:-}
SCHEDULER=${SCHEDULER:-}
SEED=${SEED:-0}
CONFIG=${CONFIG:-pipelines/paper.toml}
EVAL=${EVAL:-eval.h5}
LEARN=${LEARN:-always}        # always, or missing: learn only when $OUT/model.h5 does not exist
mkdir -p "$OUT"

names=()
times=()
load_before=$(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo "?")
stage() {
    local name=$1
    shift
    echo "== $name: $*" >&2
    local t0 t1
    t0=$(date +%s%N)
    "$@"
    t1=$(date +%s%N)
    names+=("$name")
    times+=("$(( (t1 - t0) / 1000000 ))")
}

eval_args=(--config "$CONFIG" --model "$OUT/model.h5" -o "$OUT/$EVAL" --resume)
[[ -n $MODE ]] && eval_args+=(--mode "$MODE")
for m in $METHODS; do eval_args+=(--method "$m"); done
[[ -n $EXPERIMENTS ]] && eval_args+=(--experiments "$EXPERIMENTS")
if [[ -n $SCHEDULER ]]; then eval_args+=(--scheduler "$SCHEDULER"); else eval_args+=(--jobs "$JOBS"); fi

if [[ $LEARN == always || ! -f $OUT/model.h5 ]]; then
    stage keyboard "$KBCLI" keyboard --config pipelines/keyboard.toml -o "$OUT/keyboard.h5"
    stage learn "$KBCLI" learn --keyboard "$OUT/keyboard.h5" -o "$OUT/model.h5" --seed "$SEED"
fi
stage evaluate "$KBCLI" evaluate "${eval_args[@]}"
timings="$OUT/timings.txt"
[[ $EVAL != eval.h5 ]] && timings="$OUT/timings-${EVAL%.h5}.txt"
report_args=("$OUT/eval.h5" -o "$REPORT")
ladders=()  # the ablation ladder: ablations.h5 (both modes) or ablations-MODE.h5 (one mode each)
for f in "$OUT"/ablations*.h5; do [[ -f $f ]] && ladders+=(--ablations "$f"); done
report_args+=("${ladders[@]}")
[[ -f $OUT/own-eval.h5 ]] && report_args+=(--own-model "$OUT/own-eval.h5")
if [[ -f $OUT/eval.h5 ]]; then
    stage report "$KBCLI" report "${report_args[@]}"
else
    echo "== report: skipped ($OUT/eval.h5 not made yet: make reproduce writes it)" >&2
fi

{
    printf '%-10s %10s\n' stage "wall s"
    total=0
    for i in "${!names[@]}"; do
        printf '%-10s %10.1f\n' "${names[$i]}" "$(echo "${times[$i]}" | awk '{print $1 / 1000}')"
        total=$(( total + times[i] ))
    done
    printf '%-10s %10.1f\n' total "$(echo "$total" | awk '{print $1 / 1000}')"
    if [[ -n $SCHEDULER ]]; then where="scheduler $SCHEDULER"; else where="jobs $JOBS"; fi
    echo "(config: $CONFIG; mode: ${MODE:-ideal+dynamics}; methods: ${METHODS:-all of the config}; $where;" \
         "experiments per parametrization: ${EXPERIMENTS:-config})"
    echo "(load average, 1/5/15 min: $load_before before, $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null || echo "?") after; $(nproc 2>/dev/null || echo "?") cores)"
} | tee "$timings"

if [[ $EVAL == eval.h5 && -f $OUT/eval.h5 ]]; then
    verdict_args=("$OUT/eval.h5" --timings "$timings")
    [[ -f $OUT/own-eval.h5 ]] && verdict_args+=(--own-model "$OUT/own-eval.h5")
    verdict_args+=("${ladders[@]}")
    "$KBCLI" bench --json "$OUT/reproduce.json" verdicts "${verdict_args[@]}" > /dev/null
fi
