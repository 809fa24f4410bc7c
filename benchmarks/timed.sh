#!/usr/bin/env bash
# Time one stage of a long job: run COMMAND, then append its wall time to TIMINGS in the format of
# the timings.txt benchmarks/reproduce.sh writes ("stage  wall s", header first), which
# `kbcli bench verdicts --timings TIMINGS` shows beside the verdicts (make model-quality uses it).
#
#   benchmarks/timed.sh TIMINGS STAGE COMMAND [ARG...]
set -euo pipefail
timings=$1
name=$2
shift 2
t0=$(date +%s%N)
"$@"
t1=$(date +%s%N)
[[ -s $timings ]] || printf '%-10s %10s\n' stage "wall s" > "$timings"
printf '%-10s %10.1f\n' "$name" "$(awk -v ns="$((t1 - t0))" 'BEGIN { print ns / 1e9 }')" >> "$timings"
