#!/usr/bin/env bash
# Session 29: guided check of v3w2 (64-part first prior + two eikonal cycles) at the shipped defaults,
# scans 0-9 x 2 in both blocks, paired with the shipped weights' runs /work/exp/guided/cand2_{no,yes}
cd /work/exp/s29
B=/work/bin/physnap-s27
for a in no yes; do
RAYON_NUM_THREADS=1 $B eval guided --weights v3w2 --clouds /work/data/testset --max-clouds 10 --samples-per-cloud 2 \
  --variants pc+pen+mob --category-aware $a --out g_v3w2_$a > g_v3w2_$a.log 2>&1 &
done
wait
echo done > guided.done
