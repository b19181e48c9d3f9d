#!/bin/bash
# Session 29: more parts per step (128) at equal per-step work, and at half the decoder work with twice the steps
B=/work/bin/physnap-s27
cd /work/exp/s29
RAYON_NUM_THREADS=1 $B train shape --data /work/data/train --out p128q256s64 --steps 3000 --seed 0 --batch-parts 128 --queries-per-part 256 --surface-points 64 --decoder-backward host --eval-every 1000 --progress-interval 60 > p128q256s64.log 2>&1 &
RAYON_NUM_THREADS=1 $B train shape --data /work/data/train --out p128q128s64_6k --steps 6000 --seed 0 --batch-parts 128 --queries-per-part 128 --surface-points 64 --decoder-backward host --eval-every 2000 --progress-interval 60 > p128q128s64_6k.log 2>&1 &
wait
for d in p128q256s64 p128q128s64_6k; do RAYON_NUM_THREADS=2 $B eval shape --weights $d --data /work/data/train --parts 64 --out $d/val64.json > $d.eval.log 2>&1; done
