#!/usr/bin/env bash
# Session 46: candidate fc. The shipped schedule (s14r: 2,000 constant, cosine to 14,000 with the
# box-overlap penalty from 7,000, one warm restart to 18,000) trained from scratch on the codes
# of ws10's decoder made by the fitted encoding (train encode --encoder-views 16 --fit-steps 50
# --fit-queries 512), then eval shape (the codebook's encoding) and eval generative at seeds
# 12345 and 1 side by side.
set -x
cd /work/exp/s46/fc || exit 1
while pgrep -f "train encode --weights /work/exp/s45/ws/cycle3_ws10" > /dev/null; do sleep 10; done
[ -f ../codes_fit/shape_train.json ] || exit 1
B=/work/bin/physnap-s46a   # this session's build (d60e9c1); T=/work/data/train; W=weights
c=(--data $T --shape /work/exp/s46/codes_fit --out $W --batch-objects 16 --noise-levels 4
   --lr 5e-4 --checkpoint-every 500 --category-layers --batch-shards 2)
d=(--steps 14000 --lr-decay-start 2000 --lr-final-factor 0.1 --ema-decay 0.999 --resume)
s=$(date +%s)
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" --steps 2000 --lr-final-factor 1 --ema-decay 0 --no-codebook > a.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" "${d[@]}" --stop-at 7000 --no-codebook > b.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" "${d[@]}" --overlap-weight 3 --no-codebook > c.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" --steps 18000 --lr-decay-start 14000 --lr-final-factor 0.1 \
  --ema-decay 0.999 --resume --overlap-weight 3 > d.log 2>&1 || exit 1
echo "wall $(( $(date +%s) - s )) s" > train.wall
sha256sum $W/*.safetensors
echo trained > trained.done
RAYON_NUM_THREADS=2 $B eval shape --weights $W --data $T --parts 64 --out shape_val64.json > shape.log 2>&1
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 "$@"; }
g --out gen_fc_12345.json > gen_fc_12345.log 2>&1 &
g --seed 1 --out gen_fc_1.json > gen_fc_1.log 2>&1
wait
echo done > fc.done
