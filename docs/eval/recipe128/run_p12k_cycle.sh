#!/usr/bin/env bash
# Session 30: the recipe's eikonal cycle 1 on the 12,000-step 128x128x64 prior, once it is done.
cd /work/exp/s30
while [ ! -f p12k.done ]; do sleep 20; done
RAYON_NUM_THREADS=1 /work/bin/physnap-s27 train shape --data /work/data/train --out p128q128s64_12k_cycle1 --steps 3000 --seed 0 \
  --init-from p128q128s64_12k --freeze-encoder --lr 5e-4 --batch-parts 128 --queries-per-part 128 --surface-points 64 \
  --eval-every 1000 --eikonal 0.01 --progress-interval 60 > p128q128s64_12k_cycle1.log 2>&1
echo $? > p12k_cycle.rc
RAYON_NUM_THREADS=2 /work/bin/physnap-s27 eval shape --weights p128q128s64_12k_cycle1 --data /work/data/train --parts 64 \
  --out p128q128s64_12k_cycle1/val64.json > p128q128s64_12k_cycle1.eval.log 2>&1
echo done > p12k_cycle.done
