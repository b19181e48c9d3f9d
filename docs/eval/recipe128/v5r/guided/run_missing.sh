#!/usr/bin/env bash
# The three v5r no/s1000 scans the device's two runs left out (xargs finishes out of order).
cd /work/exp/s34/local
for c in 11 14 15; do
  RAYON_NUM_THREADS=1 ./pn eval guided --weights /work/main/docs/eval/recipe128/v5r/weights --clouds /work/data/testset_s1 --data /work/data/train --skip-clouds $c \
    --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob,uncond --category-aware no --seed 1000 \
    --out r/v5r_no_s1000_c$c > logs/v5r_no_s1000_c$c.log 2>&1
done
