#!/usr/bin/env bash
# Denoiser training speed with the batch in K shards (--batch-shards K) on T threads, the shipped
# recipe's batch (16 objects × 4 noise levels, width 160, 4 layers, category layers).
# Usage: bash docs/eval/shards/bench.sh BIN SHAPE_DIR OUT [STEPS] [K:T ...]   (data in /work/data/train)
# Default runs: 1:2 2:2 (one shard / two shards, two threads).
B=$1; S=$2; O=$3; N=${4:-200}; shift 4
mkdir -p "$O"
for kt in ${@:-1:2 2:2}; do
  k=${kt%:*}; t=${kt#*:}
  /usr/bin/time -v env RAYON_NUM_THREADS=$t "$B" train diffusion --data /work/data/train --shape "$S" \
    --out "$O/k${k}_t$t" --steps "$N" --batch-objects 16 --noise-levels 4 --lr 5e-4 --lr-final-factor 1 \
    --ema-decay 0 --checkpoint-every 0 --category-layers --batch-shards $k > "$O/k${k}_t$t.log" 2>&1
  python3 -c "
import json; t=json.load(open('$O/k${k}_t$t/diffusion_train.json'))
print('%s shards, %s threads: %d steps in %.1f s = %.2f steps/s, loss ema %.4f' % ($k, $t, t['completed'], t['wall_seconds'], t['completed']/t['wall_seconds'], t['final_loss_ema']))"
  grep -E "Maximum resident" "$O/k${k}_t$t.log"
done
