#!/usr/bin/env bash
# Session 50: after the guided check, seeds 6, 7 and 8 at once (three processes on two cores).
cd /work/exp/s50/fcg2 || exit 1
while [ ! -f guided.done ]; do sleep 10; done
B=/work/bin/physnap-s50a; T=/work/data/train; W=weights
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --per-category 4 --states 4 --points 256 --samples 2 --refs 2 --progress-interval 60 --seed $1 --out gen32_fcg2_$1.json > gen_$1.log 2>&1; }
g 6 & g 7 & g 8
wait
echo done > seeds678.done
