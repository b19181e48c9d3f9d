#!/usr/bin/env bash
# Session 39: checks of a candidate $TAG (weights $W): unguided box layouts (48, DDIM 200, seed 12345),
# then eval generative at seeds 12345 and 1 side by side (48 + 48, as every candidate before).
cd /work/exp/s39 || exit 1
B=/work/bin/physnap-s39; T=/work/data/train
RAYON_NUM_THREADS=2 $B generate --weights $W --samples 48 --seed 12345 --resolution 32 --out unc_$TAG > unc_$TAG.log 2>&1
python3 boxes.py test '/work/exp/s37/datatest/*.json' d21k '/work/exp/s37/unc_d21k/sample_*/object.json' \
  $TAG "unc_$TAG/sample_*/object.json" > boxes_$TAG.md
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $1 --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 "${@:2}"; }
g $W --out gen_${TAG}_12345.json > gen_${TAG}_12345.log 2>&1 &
g $W --seed 1 --out gen_${TAG}_1.json > gen_${TAG}_1.log 2>&1
wait
echo done > after_$TAG.done
