#!/usr/bin/env bash
# Session 39: d21k continued by a fourth cosine cycle (21,000 -> 24,500, warm restart at 5e-4,
# decay to 0.1x) with the box-overlap penalty on x̂0 (lambda 10, t < 300), two batch shards.
set -x
cd /work/exp/s39 || exit 1
B=/work/bin/physnap-s39
RAYON_NUM_THREADS=2 $B train diffusion --data /work/data/train --shape /work/exp/s36/codes --out ov10/weights --batch-objects 16 \
  --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 24500 --lr-decay-start 21000 \
  --lr-final-factor 0.1 --ema-decay 0.999 --resume --batch-shards 2 --overlap-weight 10 --overlap-max-t 300 > ov10_train.log 2>&1 || exit 1
sha256sum ov10/weights/*.safetensors
echo trained > ov10.done
