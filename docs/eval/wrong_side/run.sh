#!/usr/bin/env bash
# A third decoder cycle on the shipped weights, with and without the wrong-side term
# (train shape --wrong-side W), then eval shape on each (64 val parts, 64³), and the shipped
# decoder for reference. Usage: bash docs/eval/wrong_side/run.sh BIN DATA WORK [W...]
# (default W: 0 3 10). Each cycle: 3,000 steps, the recipe's cycle batch and settings (lr 5e-4,
# eikonal 0.03, frozen encoder, two slices), seed 2 (cycles 1 and 2 of the recipe used 0, 1).
set -euo pipefail
BIN=$1 DATA=$2 WORK=$3
shift 3
weights=("$@")
[ "${#weights[@]}" = 0 ] && weights=(0 3 10)
mkdir -p "$WORK"
"$BIN" eval shape --weights weights --data "$DATA" --parts 64 --out "$WORK/shipped_val64.json"
for w in "${weights[@]}"; do
  out="$WORK/cycle3_ws$w"
  "$BIN" train shape --data "$DATA" --out "$out" --steps 3000 --seed 2 --init-from weights \
    --freeze-encoder --lr 5e-4 --eikonal 0.03 --wrong-side "$w" --batch-shards 2 \
    --batch-parts 128 --queries-per-part 128 --surface-points 64 --eval-every 1000
  "$BIN" eval shape --weights "$out" --data "$DATA" --parts 64 --out "$WORK/cycle3_ws${w}_val64.json"
done
