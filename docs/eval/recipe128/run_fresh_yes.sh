#!/usr/bin/env bash
# Session 31: the fresh scans' category-aware block, first 15 scans x 2 (time), shipped and v5.
cd /work/exp/s30
B=/work/bin/physnap-s27
while pgrep -f "weights v5e" > /dev/null; do sleep 10; done
RAYON_NUM_THREADS=1 $B eval guided --weights /work/exp/s30/shipped_w --clouds /work/data/testset_s1 --max-clouds 15 --samples-per-cloud 2 \
  --variants pc+pen+mob --category-aware yes --out s1_g_shipped_yes > s1_g_shipped_yes.log 2>&1 &
while pgrep -f "shipped_w --clouds /work/data/testset_s1 --max-clouds 30" > /dev/null; do sleep 10; done
RAYON_NUM_THREADS=1 $B eval guided --weights v5/weights --clouds /work/data/testset_s1 --max-clouds 15 --samples-per-cloud 2 \
  --variants pc+pen+mob --category-aware yes --out s1_g_v5_yes > s1_g_v5_yes.log 2>&1 &
wait
echo done > s1_yes.done
