#!/usr/bin/env bash
# Session 48: candidate fclg2. Candidate fc (session 46: the s14r schedule from scratch on the
# ws10 decoder's fitted codes, /work/exp/s46/codes_fit) with the layout gain of lg2
# (--layout-gain 2). Training only; evaluations are run separately.
set -x
cd /work/exp/s48/fclg2 || exit 1
B=/work/bin/physnap-s47a; T=/work/data/train; W=weights
c=(--data $T --shape /work/exp/s46/codes_fit --out $W --batch-objects 16 --noise-levels 4
   --lr 5e-4 --checkpoint-every 500 --category-layers --batch-shards 2 --layout-gain 2)
d=(--steps 14000 --lr-decay-start 2000 --lr-final-factor 0.1 --ema-decay 0.999 --resume)
s=$(date +%s)
[ -f a.done ] || { RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" --steps 2000 --lr-final-factor 1 --ema-decay 0 --no-codebook > a.log 2>&1 && touch a.done; } || exit 1
[ -f b.done ] || { RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" "${d[@]}" --stop-at 7000 --no-codebook > b.log 2>&1 && touch b.done; } || exit 1
[ -f c.done ] || { RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" "${d[@]}" --overlap-weight 3 --no-codebook > c.log 2>&1 && touch c.done; } || exit 1
[ -f d.done ] || { RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" --steps 18000 --lr-decay-start 14000 --lr-final-factor 0.1 \
  --ema-decay 0.999 --resume --overlap-weight 3 > d.log 2>&1 && touch d.done; } || exit 1
echo "wall $(( $(date +%s) - s )) s" >> train.wall
sha256sum $W/*.safetensors
echo trained > trained.done
