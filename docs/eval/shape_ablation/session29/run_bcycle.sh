#!/usr/bin/env bash
# Session 29: one eikonal decoder cycle (the recipe's cycle command) on the 128 x 128 x 64 first prior, same layout flags
cd /work/exp/s29
B=/work/bin/physnap-s27
RAYON_NUM_THREADS=1 $B train shape --data /work/data/train --out p128q128s64_6k_cycle1 --steps 3000 --seed 0 \
  --init-from p128q128s64_6k --freeze-encoder --lr 5e-4 --batch-parts 128 --queries-per-part 128 --surface-points 64 \
  --eval-every 1000 --eikonal 0.01 --progress-interval 60 > p128q128s64_6k_cycle1.log 2>&1
RAYON_NUM_THREADS=1 $B eval shape --weights p128q128s64_6k_cycle1 --data /work/data/train --parts 64 --out p128q128s64_6k_cycle1/val64.json > p128q128s64_6k_cycle1.eval.log 2>&1
echo done > bcycle.done
