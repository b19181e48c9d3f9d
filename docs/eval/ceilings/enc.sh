#!/usr/bin/env bash
# Session 45: encoder-only cycles (--freeze-decoder) on the ws10 decoder cycle, then eval shape.
set -euo pipefail
B=/work/bin/physnap-s45b; T=/work/data/train; W=/work/exp/s45/ws
for sp in 64 256; do
  out=$W/enc_sp$sp
  $B train shape --data $T --out $out --steps 3000 --seed 3 --init-from $W/cycle3_ws10 \
    --freeze-decoder --lr 5e-4 --eikonal 0.03 --wrong-side 10 --batch-shards 2 --batch-parts 128 \
    --queries-per-part 128 --surface-points $sp --eval-every 1000 --progress-interval 120
  $B eval shape --weights $out --data $T --parts 64 --out $W/enc_sp${sp}_val64.json
done
