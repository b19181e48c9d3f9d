#!/bin/bash
# Guided check of the candidate on scans 0-9 (data/testset), both blocks, as the shipped runs
B=/work/bin/physnap-s27
cd /work/main
for a in no yes; do
  RAYON_NUM_THREADS=1 $B eval guided --weights /work/exp/s27/v2/weights --clouds /work/data/testset --max-clouds 10 --samples-per-cloud 2 --variants pc+pen+mob --category-aware $a --out /work/exp/s27/guided/v2_$a > /work/exp/s27/guided/v2_$a.log 2>&1 &
done
wait
echo done > /work/exp/s27/guided.done
