#!/usr/bin/env bash
# A decoder cycle on the fixed, fitted codes the denoiser learns (train shape --codes), on the
# outputs of session 54's one-go recipe (R): the decoder of its third cycle (ws10) fine-tuned
# on R/codes (16 views, 50 fitting steps on 512 samples), the encoder frozen, so R's denoiser
# stays valid. Then the shape IoU on the 64 val parts and on all 940, and the recipe's weights
# with only the shape prior swapped ("swap"), for the category check (cat.sh).
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
"$BIN" eval shape --weights "$X/$name" --data "$R/train" --parts 940 --out "$X/${name}_val940.json" \
  > "$X/$name.eval.log" 2>&1
# The recipe's weights with the new shape prior; the manifest's sha256 of that file updated.
sw="$X/${name}_weights"
rm -rf "$sw" && cp -r "$R/weights" "$sw" && rm -f "$sw/eval_generative.json"
cp "$X/$name/shape_prior.safetensors" "$sw/shape_prior.safetensors"
python3 - "$sw" <<'PY'
import hashlib, json, sys
d = sys.argv[1]
m = json.load(open(f"{d}/manifest.json"))
m["shape_prior"]["sha256"] = hashlib.sha256(open(f"{d}/shape_prior.safetensors", "rb").read()).hexdigest()
open(f"{d}/manifest.json", "w").write(json.dumps(m, indent=2))
PY
echo "done $name"
