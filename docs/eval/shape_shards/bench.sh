#!/usr/bin/env bash
# Shape-prior training speed with each step's parts in K slices (--batch-shards K) on T threads, the
# recipe's batch (128 parts x 128 queries x 64 surface points, host backward pass).
# Usage: bash docs/eval/shape_shards/bench.sh BIN DATA OUT [STEPS] [K:T ...] (default 1:2 2:2)
# CYCLE=WEIGHTS_DIR benchmarks the recipe's decoder cycle instead (--init-from WEIGHTS_DIR
# --freeze-encoder --lr 5e-4 --eikonal 0.03).
B=$1; D=$2; O=$3; N=${4:-150}; shift 4
mkdir -p "$O"
extra=()
[ -n "${CYCLE:-}" ] && extra=(--init-from "$CYCLE" --freeze-encoder --lr 5e-4 --eikonal 0.03)
for kt in ${@:-1:2 2:2}; do
  k=${kt%:*}; t=${kt#*:}
  o="$O/k${k}_t$t${CYCLE:+_cycle}"
  /usr/bin/time -v env RAYON_NUM_THREADS=$t "$B" train shape --data "$D" --out "$o" --steps "$N" --seed 0 \
    --batch-parts 128 --queries-per-part 128 --surface-points 64 --eval-every 0 --val-parts 0 \
    --checkpoint-every 0 --batch-shards "$k" "${extra[@]}" > "$o.log" 2>&1
  python3 -c "
import json; t=json.load(open('$o/shape_train.json'))
print('%s shards, %s threads%s: %d steps in %.1f s of steps = %.3f s/step, final loss %.5f' % ($k, $t, ' (cycle)' if '${CYCLE:-}' else '', t['steps'], t['train_s'], t['train_s']/t['steps'], t['final_loss']))"
  grep -E "Maximum resident" "$o.log"
done
