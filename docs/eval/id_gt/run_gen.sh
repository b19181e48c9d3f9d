#!/bin/bash
# Session 32: the manifest's eval generative command on this machine, seeds 12345 (the recorded
# one) and 1, to see how far the recorded figures move on another CPU. (Its wait matched no
# process at the time, so it ran at once, beside the two cycle1 runs.)
cd /work/exp/s32
while pgrep -f "out shipped_yes_cg" > /dev/null; do sleep 20; done
for s in 12345 1; do
  RAYON_NUM_THREADS=1 /work/bin/physnap-s32 eval generative --weights /work/main/weights --data /work/data/train \
    --samples 48 --refs 48 --per-category 4 --states 4 --points 256 --seed $s --out gen_seed$s.json > gen_seed$s.log 2>&1 &
done
wait
