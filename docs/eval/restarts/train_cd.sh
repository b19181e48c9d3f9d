#!/usr/bin/env bash
# Session 43: s14r continued by one warm-restart cycle 18,000 -> 22,000 as s22, but with the
# category dropout lowered from 0.2 to 0.05 (cd05): does the category carry more of the
# prediction (eval denoiser's gain) and the category accuracy rise?
cd /work/exp/s43 || exit 1
B=/work/bin/physnap-s43b; T=/work/data/train; tag=cd05
mkdir -p $tag && rm -rf $tag/weights && cp -r /work/exp/s40/s14r/weights $tag/weights
RAYON_NUM_THREADS=2 $B train diffusion --data $T --shape /work/exp/s36/codes --out $tag/weights \
  --batch-objects 16 --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 22000 \
  --lr-decay-start 18000 --lr-final-factor 0.1 --ema-decay 0.999 --resume --batch-shards 2 \
  --overlap-weight 3 --overlap-max-t 300 --category-dropout 0.05 > ${tag}_train.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B eval denoiser --weights $tag/weights --data $T --shape /work/exp/s36/codes \
  --out den_${tag}_val.json > den_${tag}_val.txt 2>&1
./gen.sh $tag 12345 1
echo done > $tag.done
