#!/usr/bin/env bash
# Session 51: the fcg2 recipe end to end, from scratch, with the script's defaults, in sittings
# (UNTIL stops after a stage; the same command without it continues). Binary: HEAD b3ab06f.
# Sitting 1 (session 51): data and the first prior; sitting 2 (session 51, UNTIL=decoder2): the
# first two decoder cycles. Next: UNTIL= (empty) runs the rest.
cd /work/main || exit 1
PHYSNAP_BIN=/work/bin/physnap-s51a UNTIL=${UNTIL-shape} /usr/bin/time -v \
  bash scripts/reproduce-weights.sh /work/exp/s51/repro >> /work/exp/s51/repro.log 2>&1
echo "exit $?" >> /work/exp/s51/repro.log
