#!/usr/bin/env bash
# Session 50: fcg2's 52 category samples at 32³, default retrieval, seeds from $@ two at a time.
cd /work/exp/s50/fcg2 || exit 1
B=/work/bin/physnap-s50a; T=/work/data/train; W=weights
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --per-category 4 --states 4 --points 256 --samples 2 --refs 2 --progress-interval 60 --seed $1 --out gen32_fcg2_$1.json > gen_$1.log 2>&1; }
export -f g; export B T W
printf '%s\n' "$@" | xargs -P 2 -I{} bash -c 'g {}'
