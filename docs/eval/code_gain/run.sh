#!/usr/bin/env bash
# Session 50: candidate fcg2 = fclg2 (fc's fitted codes on the ws10 decoder, layout gain 2, s14r's
# four-run schedule) with the shape codes at twice NAP's feature scale too (--code-gain 2).
# Then the 52 category samples at 32³ (the manifest's protocol), seeds 12345 and 1, default retrieval.
set -x
cd /work/exp/s50/fcg2 || exit 1
B=/work/bin/physnap-s50a; T=/work/data/train; W=weights
c=(--data $T --shape /work/exp/s46/codes_fit --out $W --batch-objects 16 --noise-levels 4
   --lr 5e-4 --checkpoint-every 500 --category-layers --batch-shards 2 --layout-gain 2 --code-gain 2)
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
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --per-category 4 --states 4 --points 256 --samples 2 --refs 2 --progress-interval 60 "$@"; }
g --seed 12345 --out gen32_fcg2_12345.json > gen_12345.log 2>&1 &
g --seed 1 --out gen32_fcg2_1.json > gen_1.log 2>&1
wait
g --seed 12345 --retrieval all --out gen32ra_fcg2_12345.json > genra_12345.log 2>&1 &
g --seed 1 --retrieval all --out gen32ra_fcg2_1.json > genra_1.log 2>&1
wait
echo done > eval.done
