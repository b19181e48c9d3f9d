#!/usr/bin/env bash
# Session 51: the whole val split (940 parts) with codes fitted 100 steps (the codebook's is 50):
# does the decoder reach 0.85 on the full split when the fit runs longer?
cd /work/exp/s51/ship || exit 1
RAYON_NUM_THREADS=1 /work/bin/physnap-s50a eval shape --weights weights --data /work/data/train --parts 940 --fit-codes 100 --out shape_val940_fit100.json --progress-interval 120 > full100.log 2>&1
echo done > full.done
