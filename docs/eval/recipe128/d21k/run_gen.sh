#!/usr/bin/env bash
# Session 36: d21k's generative checks: seeds 12345 (into its manifest) and 1 side by side,
# then seed 2 for d21k and d14k side by side (48 + 48, as every candidate before).
cd /work/exp/s36 || exit 1
B=/work/bin/physnap-s36; T=/work/data/train; W=d21k/weights
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $1 --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 "${@:2}"; }
RAYON_NUM_THREADS=1 $B eval shape --weights $W --data $T --parts 64 --write-manifest > shape.log 2>&1
g $W --out $W/eval_generative.json --write-manifest > gen_d21k_12345.log 2>&1 &
g $W --seed 1 --out gen_d21k_seed1.json > gen_d21k_1.log 2>&1
wait
g $W --seed 2 --out gen_d21k_seed2.json > gen_d21k_2.log 2>&1 &
g d14k_ship --seed 2 --out gen_d14k_seed2.json > gen_d14k_2.log 2>&1
wait
echo done > gen.done
