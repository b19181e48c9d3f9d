#!/usr/bin/env bash
# Session 30: 128x128x64 at twice the steps (12,000), beside v4's denoiser; checkpoints every 1,000
# so a session end can be resumed (--resume).
cd /work/exp/s30
RAYON_NUM_THREADS=1 /work/bin/physnap-s27 train shape --data /work/data/train --out p128q128s64_12k --steps 12000 --seed 0 \
  --batch-parts 128 --queries-per-part 128 --surface-points 64 --decoder-backward host --eval-every 4000 \
  --checkpoint-every 1000 --progress-interval 60 > p128q128s64_12k.log 2>&1
echo $? > p12k.rc
RAYON_NUM_THREADS=1 /work/bin/physnap-s27 eval shape --weights p128q128s64_12k --data /work/data/train --parts 64 \
  --out p128q128s64_12k/val64.json > p128q128s64_12k.eval.log 2>&1
echo done > p12k.done
