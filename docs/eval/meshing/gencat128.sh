#!/bin/bash
# usage: gencat128.sh TAG WEIGHTS SEED — the 52 category samples only, meshed at 128³, 1 thread
tag=$1; w=$2; s=$3
RAYON_NUM_THREADS=1 /work/bin/physnap-s47a eval generative --weights $w --data /work/data/train \
  --samples 2 --refs 2 --per-category 4 --states 4 --points 256 --seed $s --resolution 128 \
  --progress-interval 60 --out gen128_${tag}_$s.json > gen128_${tag}_$s.log 2>&1
