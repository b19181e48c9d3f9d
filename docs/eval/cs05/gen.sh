#!/usr/bin/env bash
# Session 44: eval generative (48 + 48, 4 per category, 4 states, 256 points) of candidate TAG at
# the given seeds, two at a time on one thread each. Usage: gen.sh TAG SEED [SEED ...]
cd /work/exp/s44 || exit 1
B=/work/bin/physnap-s44; T=/work/data/train; TAG=$1; shift
for s in "$@"; do
  RAYON_NUM_THREADS=1 $B eval generative --weights $TAG/weights --data $T --samples 48 --refs 48 \
    --per-category 4 --states 4 --points 256 --seed $s --out gen_${TAG}_$s.json > gen_${TAG}_$s.log 2>&1 &
  [ $(jobs -r | wc -l) -ge 2 ] && wait -n
done
wait
