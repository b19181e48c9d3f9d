#!/usr/bin/env bash
# The shipping protocol's evaluations of the fcg2 weights with the decoder trained on their
# codes (fcg2.sh's "$X/fcg2_${name}_weights"): eval shape on the manifest's 64 val parts and
# eval generative 48 + 48 at seed 12345, both --write-manifest (as the recipe's EVAL stage), on
# one thread each beside seed 1's 48 + 48 (1-NNA and the category samples), then the category
# samples at seeds 2-5 two at a time (cat.sh).
set -euo pipefail
BIN=${BIN:-/work/bin/physnap-codes}
T=${T:-/work/exp/s54/repro/train}
X=${X:-/work/exp/fixed_codes}
WD=${WD:-$X/fcg2_dc_w10_e0.03_s3000_weights}
TAG=${TAG:-fcg2dc}
here=$(dirname "$0")
"$BIN" eval shape --weights "$WD" --data "$T" --parts 64 --write-manifest \
  --out "$X/${TAG}_manifest_val64.json" > "$X/${TAG}_manifest_val64.log" 2>&1
RAYON_NUM_THREADS=1 "$BIN" eval generative --weights "$WD" --data "$T" --samples 48 --refs 48 \
  --per-category 4 --states 4 --points 256 --seed 12345 --write-manifest \
  --out "$WD/eval_generative.json" > "$X/gen_${TAG}_12345.log" 2>&1 &
BIN=$BIN T=$T bash "$here/cat.sh" "$WD" "$TAG" 1
wait
BIN=$BIN T=$T bash "$here/cat.sh" "$WD" "$TAG" 2 3 4 5
echo "evals done"
