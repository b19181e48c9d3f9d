#!/usr/bin/env bash
# Session 52: a fourth decoder cycle on the shipped shape prior (fcg2's ws10 decoder, encoder
# frozen), then the shape IoU on the whole val split with fitted codes (the manifest's encoding:
# 16 views, 50 fitting steps on 512 samples; a train shape output's own default is NAP's),
# against the shipped 0.843.
#   bash docs/eval/decoder4/run.sh BIN DATA WORK NAME SEED "EXTRA FLAGS"
set -u
B=$1; T=$2; W=$3; N=$4; S=$5; X=${6:-}
mkdir -p "$W"
export MIMALLOC_PURGE_DELAY=-1
# shellcheck disable=SC2086
/usr/bin/time -v "$B" train shape --data "$T" --out "$W/$N" --steps 3000 --seed "$S" --init-from weights \
  --freeze-encoder --lr 5e-4 --eikonal 0.03 --batch-shards 2 --batch-parts 128 --queries-per-part 128 \
  --surface-points 64 --eval-every 1000 --progress-interval 120 $X > "$W/$N.train.log" 2>&1 || exit 1
"$B" eval shape --weights "$W/$N" --data "$T" --parts 940 --encoder-views 16 --fit-codes 50 --fit-queries 512 --out "$W/${N}_val940.json" \
  --progress-interval 120 > "$W/$N.eval.log" 2>&1 || exit 1
tail -3 "$W/$N.eval.log"
