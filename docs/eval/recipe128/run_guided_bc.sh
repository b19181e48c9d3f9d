#!/usr/bin/env bash
# Session 30: v4's guided check on the other 20 test scans (testset_b, testset_c), both blocks,
# the same commands as the shipped weights' b_/c_cand2 runs.
cd /work/exp/s30
B=/work/bin/physnap-s27
for s in b c; do
  for a in no yes; do
    RAYON_NUM_THREADS=1 $B eval guided --weights v4/weights --clouds /work/data/testset_$s --max-clouds 10 --samples-per-cloud 2 \
      --variants pc+pen+mob --category-aware $a --out ${s}_g_v4_$a > ${s}_g_v4_$a.log 2>&1 &
  done
  wait
done
echo done > guided_bc.done
