#!/bin/bash
# Session 32: the one-cycle decoder (IoU 0.588, the weights of a877736^: same denoiser and codes
# as the shipped weights) on the 30 fresh scans, both blocks, with ID_gt.
cd /work/exp/s32
# cycle1_w was made with: mkdir cycle1_w && git -C /work/main archive a877736^ weights | tar -x -C cycle1_w
while pgrep -f "out shipped_" > /dev/null; do sleep 20; done
for b in no yes; do
  RAYON_NUM_THREADS=1 /work/bin/physnap-s32 eval guided --weights cycle1_w/weights \
    --clouds /work/data/testset_s1 --data /work/data/train --max-clouds 30 --samples-per-cloud 2 \
    --variants pc+pen+mob --category-aware $b --out cycle1_$b > cycle1_$b.log 2>&1 &
done
wait
