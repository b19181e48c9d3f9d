#!/usr/bin/env bash
# Session 40: s14 (one cosine schedule to 14,000, penalty from 7,000) continued by one warm-restart
# cycle 14,000 -> 18,000 (5e-4 -> 0.1x, EMA continued) with the box-overlap penalty lambda 3, two
# batch shards; then eval generative at seeds 12345 and 1 side by side.
cd /work/exp/s40 || exit 1
while [ ! -f after_s14.done ]; do sleep 10; done
B=/work/bin/physnap-s39; T=/work/data/train; W=s14r/weights
mkdir -p s14r && cp -r s14/weights s14r/
RAYON_NUM_THREADS=2 $B train diffusion --data $T --shape /work/exp/s36/codes --out $W --batch-objects 16 \
  --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 18000 --lr-decay-start 14000 \
  --lr-final-factor 0.1 --ema-decay 0.999 --resume --batch-shards 2 --overlap-weight 3 --overlap-max-t 300 \
  > s14r_train.log 2>&1 || exit 1
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $1 --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 "${@:2}"; }
g $W --out gen_s14r_12345.json > gen_s14r_12345.log 2>&1 &
g $W --seed 1 --out gen_s14r_1.json > gen_s14r_1.log 2>&1
wait
echo done > s14r.done
