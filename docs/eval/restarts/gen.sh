#!/usr/bin/env bash
# Session 43: eval generative (48 + 48, 4 per category, 4 states, 256 points) of candidate TAG at
# the given seeds, two at a time on one thread each. Usage: [WORK=DIR] [BIN=physnap] gen.sh TAG SEED...
# (session 43: WORK=/work/exp/s43 and session 39's binary, the defaults; session 44's cs05:
# WORK=/work/exp/s44 BIN=/work/bin/physnap-s44)
cd "${WORK:-/work/exp/s43}" || exit 1
B=${BIN:-/work/bin/physnap-s39}; T=/work/data/train; TAG=$1; shift
for s in "$@"; do
  RAYON_NUM_THREADS=1 $B eval generative --weights $TAG/weights --data $T --samples 48 --refs 48 \
    --per-category 4 --states 4 --points 256 --seed $s --out gen_${TAG}_$s.json > gen_${TAG}_$s.log 2>&1 &
  [ $(jobs -r | wc -l) -ge 2 ] && wait -n
done
wait
