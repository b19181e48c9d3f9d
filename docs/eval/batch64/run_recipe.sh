#!/usr/bin/env bash
# Session 28: the recipe with 64 parts x 512 queries x 128 encoder points per step for the first prior
# (6,000 host steps as the s27 variant, no decoder cycle so it ends inside the session).
cd /work/exp/s28
date +%s > v3.start
PHYSNAP_BIN=/work/bin/physnap-s27 SHAPE_STEPS=6000 SHAPE_BACKWARD=host \
  SHAPE_FLAGS="--batch-parts 64 --queries-per-part 512 --surface-points 128 --eval-every 2000" DECODER_CYCLES=0 \
  /usr/bin/time -v bash /work/main/scripts/reproduce-weights.sh /work/exp/s28/v3 > v3.log 2>&1
echo $? > v3.rc
date +%s > v3.end
