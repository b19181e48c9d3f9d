#!/usr/bin/env bash
# Session 47: the 52 category samples of s14r (the shipped weights) and lg2 at seeds 7 and 8, two at a time.
B=/work/bin/physnap-s47a; T=/work/data/train
c() { RAYON_NUM_THREADS=1 $B eval generative --weights $2 --data $T --samples 2 --refs 2 --per-category 4 \
    --states 4 --points 256 --seed $3 --out gen_$1_$3.json > gen_$1_$3.log 2>&1; }
(c s14r /work/main/weights 7; c s14r /work/main/weights 8) &
(c lg2 /work/exp/s47/lg2/weights 7; c lg2 /work/exp/s47/lg2/weights 8) &
wait
echo done > more.done
