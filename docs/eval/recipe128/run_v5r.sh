#!/usr/bin/env bash
# Session 33: candidate v5 rebuilt (v5r) with session 30/31's commands (run_p12k.sh,
# run_p12k_cycle.sh, run_d12k_stage1.sh, run_d12k_stage2.sh). What ran, in order: the 12,000-step
# prior on two threads; then its eikonal cycle and the denoiser's stage 1 side by side on one
# thread each (the denoiser reads the encoder's codes, which the cycle leaves frozen); then
# stage 2 on two threads. Data: physnap data synth --objects 3000 --seed 0 + data import.
cd /work/exp/s33 || exit 1
B=/work/bin/physnap-s32   # the binary at a0b920d
T=/work/data/train
RAYON_NUM_THREADS=2 $B train shape --data $T --out p12k --steps 12000 --seed 0 \
  --batch-parts 128 --queries-per-part 128 --surface-points 64 --decoder-backward host --eval-every 4000 \
  --checkpoint-every 1000 --progress-interval 60 > p12k.log 2>&1 || exit 1
RAYON_NUM_THREADS=1 $B eval shape --weights p12k --data $T --parts 64 --out p12k/val64.json
RAYON_NUM_THREADS=1 $B train shape --data $T --out p12k_cycle1 --steps 3000 --seed 0 \
  --init-from p12k --freeze-encoder --lr 5e-4 --batch-parts 128 --queries-per-part 128 --surface-points 64 \
  --eval-every 1000 --eikonal 0.01 --checkpoint-every 500 --progress-interval 60 > p12k_cycle1.log 2>&1 &
RAYON_NUM_THREADS=1 $B train diffusion --data $T --shape p12k --out v5/weights --batch-objects 16 \
  --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 2000 --lr-final-factor 1 --ema-decay 0 > v5_stage1.log 2>&1
cp -r v5 v5_stage1
RAYON_NUM_THREADS=2 $B train diffusion --data $T --shape p12k --out v5/weights --batch-objects 16 \
  --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 7000 --lr-decay-start 2000 \
  --lr-final-factor 0.1 --ema-decay 0.999 --resume > v5_stage2.log 2>&1
wait
# Then, in session 33, the cycled decoder into a copy of the weights and the shape check:
cp -r v5/weights v5r
$B train install-shape --shape p12k_cycle1 --weights v5r > v5r_install.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B eval shape --weights v5r --data $T --parts 64 --write-manifest > v5r_shape.log 2>&1
# The guided and generative checks: run_v5r_finish.sh.
