#!/usr/bin/env bash
# Session 40: the weights directory that ships s14r: the shipped weights with s14r's denoiser and its
# training report in the manifest (shape prior and codebook are the same files), then the manifest's metrics.
cd /work/exp/s40 || exit 1
B=/work/bin/physnap-s39
RAYON_NUM_THREADS=1 $B eval shape --weights ship --data /work/data/train --parts 64 --write-manifest > ship_shape.log 2>&1
RAYON_NUM_THREADS=1 $B eval generative --weights ship --data /work/data/train --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --out ship/eval_generative.json --write-manifest > ship_gen.log 2>&1
echo done > ship.done
