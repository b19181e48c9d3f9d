#!/bin/bash
# usage: genra64full.sh TAG WEIGHTS SEED — eval generative 48 + 48 at 64³ with --retrieval all, 1 thread
tag=$1; w=$2; s=$3
RAYON_NUM_THREADS=1 /work/bin/physnap-s47a eval generative --weights $w --data /work/data/train \
  --samples 48 --refs 48 --per-category 4 --states 4 --points 256 --seed $s --resolution 64 --retrieval all \
  --progress-interval 60 --out gen64rafull_${tag}_$s.json > gen64rafull_${tag}_$s.log 2>&1
