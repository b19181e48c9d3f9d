#!/usr/bin/env bash
# Session 40: one cosine schedule instead of warm restarts, to fit the 3-hour budget:
# 2,000 constant steps (no EMA), cosine 2,000 -> 14,000 (0.1x, EMA 0.999) in two runs, the
# second (7,000 -> 14,000) with the box-overlap penalty lambda 3. Two batch shards throughout.
# Codes: the shipped encoder's (/work/exp/s36/codes).
set -x
cd /work/exp/s40 || exit 1
B=/work/bin/physnap-s39
c=(--data /work/data/train --shape /work/exp/s36/codes --out s14/weights --batch-objects 16 --noise-levels 4
   --lr 5e-4 --checkpoint-every 500 --category-layers --batch-shards 2)
d=(--steps 14000 --lr-decay-start 2000 --lr-final-factor 0.1 --ema-decay 0.999 --resume)
s=$(date +%s)
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" --steps 2000 --lr-final-factor 1 --ema-decay 0 > s14_a.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" "${d[@]}" --stop-at 7000 > s14_b.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" "${d[@]}" --overlap-weight 3 --overlap-max-t 300 > s14_c.log 2>&1 || exit 1
echo "wall $(( $(date +%s) - s )) s" > s14.wall
sha256sum s14/weights/*.safetensors
echo trained > s14.done
