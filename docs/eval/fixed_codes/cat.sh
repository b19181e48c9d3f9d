#!/usr/bin/env bash
# Category accuracy (and 1-NNA at seed 1) of weights directory WD at the seeds given, two
# evaluations at a time on the 2 cores, the protocol of the chimera (EVALUATION.md).
#   bash cat.sh WD TAG SEED...      (BIN, T: the binary and the imported data set)
set -euo pipefail
BIN=${BIN:-/work/bin/physnap-codes}
T=${T:-/work/exp/s54/repro/train}
WD=$1 TAG=$2
shift 2
X=$(dirname "$WD")
g() {
  local s=$1 n=2
  [ "$s" = 1 ] && n=48
  RAYON_NUM_THREADS=1 "$BIN" eval generative --weights "$WD" --data "$T" --per-category 4 \
    --states 4 --points 256 --samples $n --refs $n --seed "$s" --out "$X/gen_${TAG}_$s.json" \
    > "$X/gen_${TAG}_$s.log" 2>&1
}
seeds=("$@")
for ((i = 0; i < ${#seeds[@]}; i += 2)); do
  g "${seeds[$i]}" &
  [ -n "${seeds[$((i + 1))]:-}" ] && g "${seeds[$((i + 1))]}"
  wait
done
