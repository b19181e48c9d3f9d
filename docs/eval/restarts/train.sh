#!/usr/bin/env bash
# Session 43: the shipped denoiser (s14r, 18,000 steps) continued by two more warm-restart cycles
# 18,000 -> 22,000 (s22) and 22,000 -> 26,000 (s26), each 5e-4 -> 0.1x, EMA continued, the
# box-overlap penalty lambda 3, two batch shards, as s14r's own restart cycle.
cd /work/exp/s43 || exit 1
B=/work/bin/physnap-s43; T=/work/data/train
prev=18000; src=/work/exp/s40/s14r/weights
for s in 22000 26000; do
  tag=s$((s / 1000)); mkdir -p $tag && rm -rf $tag/weights && cp -r $src $tag/weights
  RAYON_NUM_THREADS=2 $B train diffusion --data $T --shape /work/exp/s36/codes --out $tag/weights \
    --batch-objects 16 --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps $s \
    --lr-decay-start $prev --lr-final-factor 0.1 --ema-decay 0.999 --resume --batch-shards 2 \
    --overlap-weight 3 --overlap-max-t 300 > ${tag}_train.log 2>&1 || exit 1
  prev=$s; src=$tag/weights
done
echo done > train.done
