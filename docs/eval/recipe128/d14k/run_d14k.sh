#!/usr/bin/env bash
# Session 35: v5r2's denoiser (7,000 steps) continued by a second cosine cycle to 14,000 steps
# (warm restart at lr 5e-4 at step 7,000, decay to 0.1x, EMA continued), two batch shards;
# then the two decoder cycles installed as shipped, and the generative checks at 3 seeds.
set -x
cd /work/exp/s35 || exit 1
B=${B:-/work/main/target/release/physnap}
T=/work/data/train
RAYON_NUM_THREADS=2 $B train diffusion --data $T --shape /work/exp/s33/p12k --out d14k/weights --batch-objects 16 \
  --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 14000 --lr-decay-start 7000 \
  --lr-final-factor 0.1 --ema-decay 0.999 --resume --batch-shards 2 > d14k_train.log 2>&1 || exit 1
$B train install-shape --shape /work/exp/s33/p12k_cycle1 --weights d14k/weights > d14k_install1.log 2>&1 || exit 1
$B train install-shape --shape /work/exp/s34/cyc2/cycle2 --weights d14k/weights > d14k_install2.log 2>&1 || exit 1
sha256sum d14k/weights/shape_prior.safetensors
echo trained > d14k.done
