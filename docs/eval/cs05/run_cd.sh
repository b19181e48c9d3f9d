#!/usr/bin/env bash
# Session 44: the shipped denoiser's recipe (s14r: 2,000 constant steps, cosine 2,000 -> 14,000
# in two runs, the second with the box-overlap penalty 3, one warm restart 14,000 -> 18,000 with
# the penalty; two batch shards; --category-layers), trained from scratch with the category
# dropout lowered from 0.2 to 0.05 (cs05). Codes: the shipped encoder's (train encode).
set -x
cd /work/exp/s44 || exit 1
B=/work/bin/physnap-s44; T=/work/data/train; tag=cs05
[ -f /work/data/train/dataset.json ] || {
  $B data synth --out /work/data/synth --objects 3000 --seed 0 > data.log 2>&1 || exit 1
  $B data import --partnet-mobility /work/data/synth --out /work/data/train >> data.log 2>&1 || exit 1; }
[ -f codes/codebook.npy ] || $B train encode --weights /work/main/weights --data $T --out codes > encode.log 2>&1 || exit 1
c=(--data $T --shape codes --out $tag/weights --batch-objects 16 --noise-levels 4
   --lr 5e-4 --checkpoint-every 500 --category-layers --batch-shards 2 --category-dropout 0.05)
d=(--steps 14000 --lr-decay-start 2000 --lr-final-factor 0.1 --ema-decay 0.999 --resume)
s=$(date +%s)
export RAYON_NUM_THREADS=2
$B train diffusion "${c[@]}" --steps 2000 --lr-final-factor 1 --ema-decay 0 --no-codebook > ${tag}_a.log 2>&1 || exit 1
$B train diffusion "${c[@]}" "${d[@]}" --stop-at 7000 --no-codebook > ${tag}_b.log 2>&1 || exit 1
$B train diffusion "${c[@]}" "${d[@]}" --overlap-weight 3 --overlap-max-t 300 --no-codebook > ${tag}_c.log 2>&1 || exit 1
$B train diffusion "${c[@]}" --steps 18000 --lr-decay-start 14000 --lr-final-factor 0.1 --ema-decay 0.999 \
  --resume --overlap-weight 3 --overlap-max-t 300 > ${tag}_d.log 2>&1 || exit 1
echo "wall $(( $(date +%s) - s )) s" > $tag.wall
$B eval denoiser --weights $tag/weights --data $T --shape codes --out den_${tag}_val.json > den_${tag}_val.txt 2>&1
echo trained > $tag.done
