#!/usr/bin/env bash
# Session 36: d14k's denoiser (EMA weights; the raw weights and Adam state were lost with the
# machine) continued by a third cosine cycle to 21,000 steps (warm restart at 5e-4 at step
# 14,000, decay to 0.1x, EMA restarted from d14k), two batch shards. Codes: the shipped
# encoder's (`train encode`), the same the denoiser was trained on.
set -x
cd /work/exp/s36 || exit 1
B=/work/bin/physnap-s36
RAYON_NUM_THREADS=2 $B train diffusion --data /work/data/train --shape codes --out d21k/weights --batch-objects 16 \
  --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 21000 --lr-decay-start 14000 \
  --lr-final-factor 0.1 --ema-decay 0.999 --resume --batch-shards 2 > d21k_train.log 2>&1 || exit 1
sha256sum d21k/weights/*.safetensors
echo trained > d21k.done
