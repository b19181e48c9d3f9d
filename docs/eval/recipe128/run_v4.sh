#!/usr/bin/env bash
# Session 30: the recipe's denoiser (both runs, exactly the script's commands) on s29's
# 128x128x64 6k shape prior, then s29's eikonal cycle 1 installed (the same command the script
# runs with DECODER_CYCLES=1), then the shipping checks.
set -x
cd /work/exp/s30
B=/work/bin/physnap-s27
S=/work/exp/s29/p128q128s64_6k
T=/work/data/train
common=(--data $T --shape $S --out v4/weights --batch-objects 16 --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers)
date +%s > v4.start
$B train diffusion "${common[@]}" --steps 2000 --lr-final-factor 1 --ema-decay 0 > v4_stage1.log 2>&1 || exit 1
$B train diffusion "${common[@]}" --steps 7000 --lr-decay-start 2000 --lr-final-factor 0.1 --ema-decay 0.999 --resume > v4_stage2.log 2>&1 || exit 1
date +%s > v4.denoiser.end
cp -r v4/weights v4w0
$B train install-shape --shape /work/exp/s29/p128q128s64_6k_cycle1 --weights v4/weights > v4_install.log 2>&1 || exit 1
$B eval shape --weights v4/weights --data $T --parts 64 --write-manifest > v4_shape.log 2>&1
RAYON_NUM_THREADS=1 $B eval guided --weights v4/weights --clouds /work/data/testset --max-clouds 10 --samples-per-cloud 2 \
  --variants pc+pen+mob --category-aware no --out g_v4_no > g_v4_no.log 2>&1 &
RAYON_NUM_THREADS=1 $B eval guided --weights v4/weights --clouds /work/data/testset --max-clouds 10 --samples-per-cloud 2 \
  --variants pc+pen+mob --category-aware yes --out g_v4_yes > g_v4_yes.log 2>&1 &
wait
echo done > guided.done
RAYON_NUM_THREADS=1 $B eval generative --weights v4/weights --data $T --samples 48 --refs 48 --per-category 4 --states 4 --points 256 \
  --out v4/weights/eval_generative.json --write-manifest > v4_gen12345.log 2>&1 &
RAYON_NUM_THREADS=1 $B eval generative --weights v4/weights --data $T --samples 48 --refs 48 --per-category 4 --states 4 --points 256 \
  --seed 1 --out gen_v4_seed1.json > v4_gen1.log 2>&1 &
wait
RAYON_NUM_THREADS=2 $B eval generative --weights v4/weights --data $T --samples 48 --refs 48 --per-category 4 --states 4 --points 256 \
  --seed 2 --out gen_v4_seed2.json > v4_gen2.log 2>&1
echo done > all.done
