#!/usr/bin/env bash
# Session 40: checks of candidate s14 (one cosine schedule, 14,000 steps, overlap penalty from 7,000):
# eval generative at seeds 12345 and 1 side by side (48 + 48, as every candidate before), then
# 48 unguided samples for the box statistics.
cd /work/exp/s40 || exit 1
B=/work/bin/physnap-s39; T=/work/data/train; W=s14/weights; TAG=s14
while [ ! -f s14.done ]; do sleep 15; done
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $1 --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 "${@:2}"; }
g $W --out gen_${TAG}_12345.json > gen_${TAG}_12345.log 2>&1 &
g $W --seed 1 --out gen_${TAG}_1.json > gen_${TAG}_1.log 2>&1
wait
echo done > gen01.done
RAYON_NUM_THREADS=2 $B generate --weights $W --samples 48 --seed 12345 --resolution 32 --out unc_$TAG > unc_$TAG.log 2>&1
python3 boxes.py test '/work/exp/s37/datatest/*.json' ov3 '/work/exp/s39/unc_ov3/sample_*/object.json' \
  $TAG "unc_$TAG/sample_*/object.json" > boxes_$TAG.md
echo done > after_s14.done
