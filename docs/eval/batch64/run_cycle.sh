#!/usr/bin/env bash
# Session 28: the recipe's decoder cycle 1 on v3's first prior, run beside its denoiser
# (same command the script runs with DECODER_CYCLES=1, from v3/shape: the same shape prior as v3/weights).
cd /work/exp/s28
RAYON_NUM_THREADS=1 /work/bin/physnap-s27 train shape --data v3/train --out v3_cycle1 --steps 3000 --seed 0 \
  --init-from v3/shape --freeze-encoder --lr 5e-4 --batch-parts 64 --queries-per-part 512 --surface-points 128 \
  --eval-every 2000 --eikonal 0.01 --progress-interval 60 > v3_cycle1.log 2>&1
echo $? > v3_cycle1.rc
