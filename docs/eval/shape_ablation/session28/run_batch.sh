#!/bin/bash
# Session 28: batch composition at the shipped schedule (3,000 steps, cosine, seed 0, host backward)
B=/work/bin/physnap-s27
cd /work/exp/s28
RAYON_NUM_THREADS=1 $B train shape --data /work/data/train --out p64q512s128 --steps 3000 --seed 0 --batch-parts 64 --queries-per-part 512 --surface-points 128 --decoder-backward host --eval-every 1000 --progress-interval 60 > p64q512s128.log 2>&1 &
RAYON_NUM_THREADS=1 $B train shape --data /work/data/train --out p32q1024s256 --steps 3000 --seed 0 --batch-parts 32 --queries-per-part 1024 --surface-points 256 --decoder-backward host --eval-every 1000 --progress-interval 60 > p32q1024s256.log 2>&1 &
wait
