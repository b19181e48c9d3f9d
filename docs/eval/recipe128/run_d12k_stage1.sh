#!/usr/bin/env bash
# Session 30: the recipe's denoiser stage 1 (2,000 steps, constant lr, no EMA) on the 12,000-step
# 128x128x64 prior's codes; stage 2 (--resume to 7,000) is left for the next session, as the
# recipe resumes there anyway.
cd /work/exp/s30
/work/bin/physnap-s27 train diffusion --data /work/data/train --shape p128q128s64_12k --out v5/weights --batch-objects 16 \
  --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 2000 --lr-final-factor 1 --ema-decay 0 > v5_stage1.log 2>&1
echo $? > v5_stage1.rc
