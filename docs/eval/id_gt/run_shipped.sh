#!/bin/bash
# Session 32: the shipped weights on the 30 fresh scans (data testset --seed 1), both blocks,
# guided and unguided, with ID_gt (--data). Data as in EVALUATION.md's top section.
cd /work/exp/s32
for b in no yes; do
  RAYON_NUM_THREADS=1 /work/bin/physnap-s32 eval guided --weights /work/main/weights \
    --clouds /work/data/testset_s1 --data /work/data/train --max-clouds 30 --samples-per-cloud 2 \
    --variants pc+pen+mob,uncond --category-aware $b --out shipped_$b > shipped_$b.log 2>&1 &
done
wait
