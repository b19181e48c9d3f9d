#!/bin/bash
# 64³ meshing of the conditioned samples, seeds 2..6 (12345 and 1 done), two at a time, one thread each
run() { RAYON_NUM_THREADS=1 /work/bin/physnap-s45b eval generative --weights /work/main/weights --data /work/data/train --samples 2 --refs 2 --per-category 4 --states 4 --points 256 --seed $1 --resolution 64 --out gen_r64_$1.json > gen_r64_$1.log 2>&1; }
(run 2; run 4; run 6) &
(run 3; run 5) &
wait
