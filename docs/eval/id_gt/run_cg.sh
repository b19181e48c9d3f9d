#!/bin/bash
# Session 32: the shipped weights, category-aware block on the 30 fresh scans, with category
# guidance w = 0 (plain conditioning) and w = 1 instead of the default 2; ID_gt and D_pc.
cd /work/exp/s32
while pgrep -f "out cycle1_" > /dev/null; do sleep 20; done
for w in 0 1; do
  RAYON_NUM_THREADS=1 /work/bin/physnap-s32 eval guided --weights /work/main/weights \
    --clouds /work/data/testset_s1 --data /work/data/train --max-clouds 30 --samples-per-cloud 2 \
    --variants pc+pen+mob --category-aware yes --category-guidance $w --out shipped_yes_cg$w > shipped_yes_cg$w.log 2>&1 &
done
wait
