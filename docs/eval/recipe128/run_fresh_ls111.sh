#!/usr/bin/env bash
# Session 31: v5 with the paper's loss weights (--loss-scales 1,1,1) on the first 15 fresh scans x 2, both blocks.
cd /work/exp/s30
B=/work/bin/physnap-s27
for a in no yes; do
  RAYON_NUM_THREADS=1 $B eval guided --weights v5/weights --clouds /work/data/testset_s1 --max-clouds 15 --samples-per-cloud 2 \
    --variants pc+pen+mob --category-aware $a --loss-scales 1,1,1 --out s1_g_v5_ls111_$a > s1_g_v5_ls111_$a.log 2>&1 &
done
wait
echo done > s1_ls111.done
