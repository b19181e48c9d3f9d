#!/bin/bash
# eval shape of the ws10 decoder on the 64 val parts: 16 views, 50 fitting steps on 512 samples,
# pull toward the encoder's code λ = $1; then train encode of the 921-part subset (codes for
# the movement/spread statistics)
l=$1
cd /work/exp/s49/prox
RAYON_NUM_THREADS=1 /work/bin/physnap-s49a eval shape --weights /work/exp/s45/ws/cycle3_ws10 --data /work/data/train --parts 64 \
  --encoder-views 16 --fit-codes 50 --fit-queries 512 --fit-prox $l --out val64_p$l.json > val64_p$l.log 2>&1
RAYON_NUM_THREADS=1 /work/bin/physnap-s49a train encode --weights /work/exp/s45/ws/cycle3_ws10 --data /work/exp/s49/sub300 \
  --out sub_p$l --encoder-views 16 --fit-steps 50 --fit-queries 512 --fit-prox $l --progress-interval 0 > sub_p$l.log 2>&1
