#!/usr/bin/env bash
# Session 42: the shipped weights (s14r) at two more eval generative seeds (3, 4), to see how far
# its 80.8 % pooled category accuracy (seeds 12345 / 1 / 2) carries.
cd /work/exp/s42/s14r_more || exit 1
B=/work/bin/physnap-s39; T=/work/data/train; W=/work/main/weights
for s in 3 4; do
  RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 --seed $s --out gen_s14r_$s.json > gen_$s.log 2>&1 &
done
wait
