#!/usr/bin/env bash
# Session 51: time the recipe's `train encode` (16 views, 50 fitting steps on 512 samples, all
# 9,284 parts) on 2 otherwise idle cores, and check it makes the shipped codes bit for bit.
cd /work/exp/s51 || exit 1
rm -rf enc_all
/usr/bin/time -v /work/bin/physnap-s50a train encode --weights /work/exp/s45/ws/cycle3_ws10 \
  --data /work/data/train --out enc_all --encoder-views 16 --fit-steps 50 --fit-queries 512 \
  --progress-interval 120 > enc.log 2>&1
cmp enc_all/codebook.npy /work/exp/s46/codes_fit/codebook.npy && echo "codes identical" >> enc.log
echo done > enc.done
