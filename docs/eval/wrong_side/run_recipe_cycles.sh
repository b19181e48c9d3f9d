#!/usr/bin/env bash
# The recipe's two decoder cycles (scripts/reproduce-weights.sh: seed 0 eikonal 0.01, then seed 1
# eikonal 0.03; 3,000 steps each, lr 5e-4, encoder frozen, two slices) with the wrong-side term
# W, on a first prior PRIOR (a shape_prior.safetensors of the recipe's first train shape), then
# eval shape on 64 val parts. Usage: bash run_recipe_cycles.sh BIN DATA PRIOR WORK W
set -euo pipefail
BIN=$1 DATA=$2 PRIOR=$3 WORK=$4 W=$5
mkdir -p "$WORK"
from=$PRIOR
for cycle in 1 2; do
  eik=0.01
  [ "$cycle" = 2 ] && eik=0.03
  out="$WORK/ws${W}_decoder$cycle"
  "$BIN" train shape --data "$DATA" --out "$out" --steps 3000 --seed $((cycle - 1)) \
    --init-from "$from" --freeze-encoder --lr 5e-4 --eikonal "$eik" --wrong-side "$W" \
    --batch-shards 2 --batch-parts 128 --queries-per-part 128 --surface-points 64 --eval-every 1000
  from=$out
done
"$BIN" eval shape --weights "$from" --data "$DATA" --parts 64 --out "$WORK/ws${W}_cycles_val64.json"
