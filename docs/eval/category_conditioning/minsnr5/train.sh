#!/bin/bash
set -e
P=/work/exp/physnap-minsnr
common="--data /work/data/train --shape /work/data/shape --out /work/exp/minsnr5/weights --batch-objects 16 --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --min-snr-gamma 5"
$P train diffusion $common --steps 2000 --lr-final-factor 1 --ema-decay 0
$P train diffusion $common --steps 7000 --lr-decay-start 2000 --lr-final-factor 0.1 --ema-decay 0.999 --resume
echo FINISHED
