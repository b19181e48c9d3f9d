#!/usr/bin/env bash
# Session 40: s14r's remaining checks: guided slices (30 fresh scans x 2, seed set 0, both blocks,
# pc+pen+mob, the s39 binary as ov3's), eval generative seed 2 and the unguided box statistics beside them.
cd /work/exp/s40 || exit 1
B=/work/bin/physnap-s39; T=/work/data/train; W=s14r/weights; TAG=s14r
(RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 --seed 2 --out gen_s14r_2.json > gen_s14r_2.log 2>&1
 RAYON_NUM_THREADS=1 $B generate --weights $W --samples 48 --seed 12345 --resolution 32 --out unc_$TAG > unc_$TAG.log 2>&1
 python3 boxes.py test '/work/exp/s37/datatest/*.json' ov3 '/work/exp/s39/unc_ov3/sample_*/object.json' \
  s14 'unc_s14/sample_*/object.json' $TAG "unc_$TAG/sample_*/object.json" > boxes_$TAG.md) &
W=$W TAG=$TAG VARIANTS=pc+pen+mob BIN=$B WORK=/work/exp/s40 bash /work/main/scripts/guided-slices.sh > guided_$TAG.out 2>&1
wait
echo done > after_s14r.done
