#!/usr/bin/env bash
# A decoder cycle on the shipped weights' own fitted codes (train shape --codes): fcg2's codes
# made again from its shape prior (train encode as the recipe, 16 views, 50 fitting steps on
# 512 samples; the shipped codebook's rows must be among them), the shipped decoder trained
# 3,000 steps on them with the encoder frozen (eikonal 0.03, --wrong-side W, seed 3), installed
# into a copy of the shipped weights (train install-shape: same encoder, so the codes and the
# denoiser stay; the retrieval codebook rebuilt), then the shape IoU on the 64 val parts and on
# all 940. The category check is cat.sh on "$X/fcg2_${name}_weights".
# Usage: W=10 STEPS=3000 bash fcg2.sh      (BIN: a physnap built with train shape --codes)
set -euo pipefail
BIN=${BIN:-/work/bin/physnap-codes}
SHIPPED=${SHIPPED:-/work/main/weights}
PRIOR=${PRIOR:-/work/exp/s52/codes}   # a train shape output holding fcg2's shape prior (its sha256 e7899b83…), for train encode
T=${T:-/work/exp/s54/repro/train}     # the imported data set (sha256 74b7f4e3…, as every run)
X=${X:-/work/exp/fixed_codes}
W=${W:-10}
EIK=${EIK:-0.03}
STEPS=${STEPS:-3000}
name=dc_w${W}_e${EIK}_s${STEPS}
export MIMALLOC_PURGE_DELAY=-1
mkdir -p "$X"
codes="$X/fcg2_codes"
[ -f "$codes/codebook.npy" ] || "$BIN" train encode --weights "$PRIOR" --data "$T" --out "$codes" \
  --encoder-views 16 --fit-steps 50 --fit-queries 512 > "$X/fcg2_encode.log" 2>&1
# The shipped retrieval codebook's rows (the codes that mesh at 16³) are among the new codes,
# bit for bit: these are the codes fcg2's denoiser learned.
python3 - "$SHIPPED/codebook.safetensors" "$codes/codebook.npy" <<'PY'
import json, struct, sys
f = open(sys.argv[1], "rb"); n = struct.unpack("<Q", f.read(8))[0]; h = json.loads(f.read(n))
a, b = h["codes"]["data_offsets"]; f.seek(8 + n + a); raw = f.read(b - a)
npy = open(sys.argv[2], "rb").read(); hl = struct.unpack("<H", npy[8:10])[0]; data = npy[10 + hl:]
have = {data[i:i + 512] for i in range(0, len(data), 512)}
rows = [raw[i:i + 512] for i in range(0, len(raw), 512)]
found = sum(r in have for r in rows)
print(f"shipped codebook rows among the new codes: {found} of {len(rows)}")
sys.exit(0 if found == len(rows) else 1)
PY
/usr/bin/time -v "$BIN" train shape --data "$T" --out "$X/fcg2_$name" --steps "$STEPS" --seed 3 \
  --init-from "$SHIPPED" --freeze-encoder --codes "$codes" --lr 5e-4 \
  --eikonal "$EIK" --wrong-side "$W" --batch-shards 2 \
  --batch-parts 128 --queries-per-part 128 --surface-points 64 --eval-every 0 --val-parts 64 \
  > "$X/fcg2_$name.train.log" 2>&1
wd="$X/fcg2_${name}_weights"
rm -rf "$wd" && cp -r "$SHIPPED" "$wd" && rm -f "$wd/eval_generative.json" "$wd/README.md"
"$BIN" train install-shape --shape "$X/fcg2_$name" --weights "$wd" > "$X/fcg2_$name.install.log" 2>&1
"$BIN" eval shape --weights "$wd" --data "$T" --parts 64 --out "$X/fcg2_${name}_val64.json" \
  > "$X/fcg2_$name.eval64.log" 2>&1
"$BIN" eval shape --weights "$wd" --data "$T" --parts 940 --out "$X/fcg2_${name}_val940.json" \
  > "$X/fcg2_$name.eval940.log" 2>&1
echo "done fcg2_$name"
