#!/usr/bin/env bash
# Session 30 (started 19:39, may be cut by the session's end): the recipe's second denoiser run on
# the 12,000-step prior's codes. v5_stage1/ keeps the stage-1 checkpoint untouched.
cd /work/exp/s30
/work/bin/physnap-s27 train diffusion --data /work/data/train --shape p128q128s64_12k --out v5/weights --batch-objects 16 \
  --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 7000 --lr-decay-start 2000 \
  --lr-final-factor 0.1 --ema-decay 0.999 --resume > v5_stage2.log 2>&1
echo $? > v5_stage2.rc
