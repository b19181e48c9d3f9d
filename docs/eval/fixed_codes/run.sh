#!/usr/bin/env bash
# A decoder cycle on the fixed, fitted codes the denoiser learns (train shape --codes), on the
# outputs of session 54's one-go recipe (R): the decoder of its third cycle (ws10) trained 3,000
# steps on R/codes (16 views, 50 fitting steps on 512 samples) with the encoder frozen, so R's
# denoiser stays valid; then the shape IoU on the manifest's 64 val parts. (Session 55 started
# the 940-part evaluation too and stopped it to free the cores for fcg2.sh, the shippable run.)
# Usage: W=10 STEPS=3000 bash run.sh      (BIN: a physnap built with train shape --codes)
set -euo pipefail
BIN=${BIN:-/work/bin/physnap-codes}
R=${R:-/work/exp/s54/repro}
X=${X:-/work/exp/fixed_codes}
W=${W:-10}
EIK=${EIK:-0.03}
STEPS=${STEPS:-3000}
name=dc_w${W}_e${EIK}_s${STEPS}
mkdir -p "$X"
export MIMALLOC_PURGE_DELAY=-1
/usr/bin/time -v "$BIN" train shape --data "$R/train" --out "$X/$name" --steps "$STEPS" --seed 3 \
  --init-from "$R/shape_decoder3" --freeze-encoder --codes "$R/codes" --lr 5e-4 \
  --eikonal "$EIK" --wrong-side "$W" --batch-shards 2 \
  --batch-parts 128 --queries-per-part 128 --surface-points 64 --eval-every 0 --val-parts 64 \
  > "$X/$name.train.log" 2>&1
"$BIN" eval shape --weights "$X/$name" --data "$R/train" --parts 64 --out "$X/A_val64.json" \
  > "$X/A_val64.log" 2>&1
echo "done $name"
