#!/bin/bash
tag=$1; w=$2
RAYON_NUM_THREADS=1 /work/bin/physnap-s47a eval reconstruction --weights $w --data /work/data/train \
  --resolution 64 --progress-interval 60 --out recon64_$tag.json > recon64_$tag.log 2>&1
