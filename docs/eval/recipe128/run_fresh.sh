#!/usr/bin/env bash
# Session 31: shipped vs v5 on 30 fresh scans (data testset --seed 1), never used to tune the
# guidance defaults; both blocks, the same commands as the policy check.
cd /work/exp/s30
B=/work/bin/physnap-s27
while [ ! -f v5_all.done ]; do sleep 20; done
for a in no yes; do
  for w in shipped v5; do
    case $w in shipped) W=/work/exp/s30/shipped_w;; v5) W=v5/weights;; esac
    RAYON_NUM_THREADS=1 $B eval guided --weights $W --clouds /work/data/testset_s1 --max-clouds 30 --samples-per-cloud 2 \
      --variants pc+pen+mob --category-aware $a --out s1_g_${w}_$a > s1_g_${w}_$a.log 2>&1 &
  done
  wait
  echo done > s1_$a.done
done
