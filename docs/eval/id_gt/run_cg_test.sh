#!/bin/bash
# Session 32: the category-aware block on the 30 test scans (data testset --seed 0), shipped
# weights, category guidance w = 0 against the default w = 2, with ID_gt: the check of the
# fresh-scan finding on a second scan set.
cd /work/exp/s32
for w in 0 2; do
  RAYON_NUM_THREADS=1 /work/bin/physnap-s32 eval guided --weights /work/main/weights \
    --clouds /work/data/testset --data /work/data/train --max-clouds 30 --samples-per-cloud 2 \
    --variants pc+pen+mob --category-aware yes --category-guidance $w --out test_yes_cg$w > test_yes_cg$w.log 2>&1 &
done
wait
