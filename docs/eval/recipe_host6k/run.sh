#!/usr/bin/env bash
cd /work/exp/s27
date +%s > v2.start
PHYSNAP_BIN=/work/bin/physnap-s27 SHAPE_STEPS=6000 SHAPE_BACKWARD=host SHAPE_FLAGS="--eval-every 2000" DECODER_CYCLES=1 \
  /usr/bin/time -v bash /work/main/scripts/reproduce-weights.sh /work/exp/s27/v2 > v2.log 2>&1
echo $? > v2.rc
date +%s > v2.end
