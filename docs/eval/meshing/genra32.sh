#!/bin/bash
# usage: genra32.sh TAG WEIGHTS SEED — the 52 category samples only, 32³ (the manifest's protocol), --retrieval all, 1 thread
tag=$1; w=$2; s=$3
RAYON_NUM_THREADS=1 /work/bin/physnap-s47a eval generative --weights $w --data /work/data/train \
  --samples 2 --refs 2 --per-category 4 --states 4 --points 256 --seed $s --retrieval all \
  --progress-interval 60 --out gen32ra_${tag}_$s.json > gen32ra_${tag}_$s.log 2>&1
