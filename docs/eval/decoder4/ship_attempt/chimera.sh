#!/usr/bin/env bash
# The "chimera" of the fifty-third session: the shipped fcg2 weights with only the shape prior
# replaced by ws30c4's decoder (../ws30s3/; the same frozen encoder, so every code stays
# valid). The denoiser and the retrieval codebook stay fcg2's: codes fitted by the ws10
# decoder (the codebook's rows were chosen as the codes that mesh non-empty at 16³ with ws10).
# `train install-shape` would rebuild the codebook from ws30s3's own codebook.npy (encoder
# codes, and not committed), so the manifest's sha256 is updated by hand instead; its
# training.shape and metrics.shape still describe fcg2's decoder (an experiment, not a ship).
#   bash docs/eval/decoder4/ship_attempt/chimera.sh OUT_DIR BIN DATA
set -euo pipefail
OUT=$1 B=$2 T=$3
rm -rf "$OUT"; cp -r weights "$OUT"; rm -f "$OUT/eval_generative.json"
cp docs/eval/decoder4/ws30s3/shape_prior.safetensors "$OUT/"
python3 - "$OUT" <<'P'
import hashlib, json, sys
d = sys.argv[1]
m = json.load(open(f'{d}/manifest.json'))
m['shape_prior']['sha256'] = hashlib.sha256(open(f'{d}/shape_prior.safetensors', 'rb').read()).hexdigest()
open(f'{d}/manifest.json', 'w').write(json.dumps(m, indent=2))
P
g() { RAYON_NUM_THREADS=1 "$B" eval generative --weights "$OUT" --data "$T" --per-category 4 --states 4 --points 256 "$@"; }
g --samples 2 --refs 2 --seed 12345 --out chimera_12345.json &
g --samples 2 --refs 2 --seed 2 --out chimera_2.json
wait
g --samples 48 --refs 48 --seed 1 --out chimera_1.json &
g --samples 2 --refs 2 --seed 3 --out chimera_3.json
wait
# Run after the first four, the same way (README.md "seeds 4 / 5"):
g --samples 2 --refs 2 --seed 4 --out chimera_4.json &
g --samples 2 --refs 2 --seed 5 --out chimera_5.json
wait
