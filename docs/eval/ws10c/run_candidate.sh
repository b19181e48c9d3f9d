#!/usr/bin/env bash
# Session 42: one of session 41's third decoder cycles installed into a copy of the shipped
# weights, then eval generative at seeds 12345 and 1 (category accuracy is what ws10c lost).
# Usage: bash run_candidate.sh TAG CYCLE, run as
#   bash run_candidate.sh ws3c /work/exp/s41/ws/cycle3_ws3   (W = 3)
#   bash run_candidate.sh ws0c /work/exp/s41/ws/cycle3_ws0   (W = 0, a plain third cycle)
set -euo pipefail
TAG=$1 CYCLE=$2
mkdir -p "/work/exp/s42/$TAG" && cd "/work/exp/s42/$TAG"
cp -r /work/main/weights weights
B=/work/bin/physnap-s39; T=/work/data/train; W=weights
/work/bin/physnap-s42b train install-shape --shape "$CYCLE" --weights $W > install.log 2>&1
RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --out gen_12345.json > gen_12345.log 2>&1 &
RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --seed 1 --out gen_1.json > gen_1.log 2>&1
wait
