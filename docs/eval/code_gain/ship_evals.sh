#!/usr/bin/env bash
# Session 51: the ship figures of candidate fcg2, written to its manifest by the product's own
# --write-manifest (shape first, then generative: both rewrite manifest.json).
cd /work/exp/s51/ship || exit 1
B=/work/bin/physnap-s50a; T=/work/data/train; W=weights
RAYON_NUM_THREADS=1 $B eval shape --weights $W --data $T --parts 64 --write-manifest --out shape_val64.json --progress-interval 60 > shape.log 2>&1
RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --per-category 4 --states 4 --points 256 --samples 48 --refs 48 --seed 12345 --write-manifest --out eval_generative.json --progress-interval 60 > gen.log 2>&1
echo done > chain.done
