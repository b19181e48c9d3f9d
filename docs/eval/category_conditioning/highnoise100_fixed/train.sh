#!/bin/bash
# Shipped denoiser recipe + --high-noise-cap 100. Both runs take --resume, so re-running this
# script continues from the last checkpoint (every 500 steps).
set -e
P=${P:-/work/exp/physnap-hn2}
common="--data /work/data/train --shape /work/data/shape --out /work/exp/hn100b/weights --batch-objects 16 --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --high-noise-cap 100"
step=$(python3 -c "import json;print(json.load(open('/work/exp/hn100b/weights/checkpoint.json'))['step'])" 2>/dev/null || echo 0)
if [ "$step" -lt 2000 ]; then
  $P train diffusion $common --steps 2000 --lr-final-factor 1 --ema-decay 0 --resume
fi
$P train diffusion $common --steps 7000 --lr-decay-start 2000 --lr-final-factor 0.1 --ema-decay 0.999 --resume
echo FINISHED
