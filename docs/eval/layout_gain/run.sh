#!/usr/bin/env bash
# Session 47: candidate lg2. The shipped schedule (s14r: 2,000 constant, cosine to 14,000 with the
# box-overlap penalty from 7,000, one warm restart to 18,000) trained from scratch on the shipped
# codes with --layout-gain 2 (box and centre feature scales halved), then eval generative at
# seeds 12345 and 1 (48 + 48 and 52 category samples) side by side, then the category samples
# alone at seeds 2..6, two at a time.
set -x
cd /work/exp/s47/lg2 || exit 1
B=/work/bin/physnap-s47a; T=/work/data/train; W=weights
c=(--data $T --shape /work/exp/s44/codes --out $W --batch-objects 16 --noise-levels 4
   --lr 5e-4 --checkpoint-every 500 --category-layers --batch-shards 2 --layout-gain 2)
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
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 "$@"; }
g --out gen_lg2_12345.json > gen_lg2_12345.log 2>&1 &
g --seed 1 --out gen_lg2_1.json > gen_lg2_1.log 2>&1
wait
echo done > gen2.done
c() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 2 --refs 2 --per-category 4 \
    --states 4 --points 256 --seed $1 --out gen_lg2_$1.json > gen_lg2_$1.log 2>&1; }
(c 2; c 4; c 6) &
(c 3; c 5) &
wait
echo done > lg2.done
