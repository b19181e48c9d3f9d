#!/usr/bin/env bash
# A third decoder cycle on the shipped weights (the recipe's cycle: 3,000 steps, lr 5e-4, eikonal
# 0.03, --wrong-side 10, encoder frozen, two slices, seed 2) with the decoder grown first
# (train shape --init-from grows it function-preservingly), then eval shape on 64 val parts.
# Usage: bash docs/eval/decoder_growth/run.sh BIN DATA WORK TAG [GROWTH FLAGS...]
#   e.g. TAG pe10 with --pe-freqs 10; TAG h256 with --decoder-hidden 256
set -euo pipefail
BIN=$1 DATA=$2 WORK=$3 TAG=$4
shift 4
mkdir -p "$WORK"
out="$WORK/${TAG}_ws10"
"$BIN" train shape --data "$DATA" --out "$out" --steps 3000 --seed 2 --init-from weights \
  --freeze-encoder --lr 5e-4 --eikonal 0.03 --wrong-side 10 --batch-shards 2 \
  --batch-parts 128 --queries-per-part 128 --surface-points 64 --eval-every 1000 "$@"
"$BIN" eval shape --weights "$out" --data "$DATA" --parts 64 --out "$WORK/${TAG}_ws10_val64.json"
