#!/usr/bin/env bash
# Rebuild candidate v5r2's weights directory from the committed pieces (the repository carries only
# what differs from v5r, to stay small): v5r's denoiser and files, this decoder (shape_prior), this
# manifest, then the retrieval codebook rebuilt from v5r's codes (the cycle froze the encoder, so
# the codes are v5r/cycle1's, byte for byte). `train codebook` writes the codebook's new sha256
# into the manifest (the file's bytes may differ from the original: physnap now sorts the
# safetensors header's metadata).
# Usage: bash docs/eval/recipe128/v5r2/assemble.sh BIN OUT_WEIGHTS_DIR
set -euo pipefail
B=$1; W=$2
R=$(cd "$(dirname "$0")/.." && pwd)
S=$(mktemp -d)
cp -r "$R/v5r/weights" "$W"
cp "$R/v5r2/shape_prior.safetensors" "$R/v5r2/manifest.json" "$W/"
cp "$R/v5r2/shape_prior.safetensors" "$S/"
cp "$R/v5r2/cycle2_shape_train.json" "$S/shape_train.json"
cp "$R/v5r/cycle1/codebook.npy" "$R/v5r/cycle1/codebook.json" "$S/"
"$B" train codebook --shape "$S" --weights "$W"
rm -rf "$S"
