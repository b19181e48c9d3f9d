#!/usr/bin/env bash
# Session 54: scripts/reproduce-weights.sh in one go, from scratch, with its defaults (fcg2's
# recipe) and its evaluations (EVAL=1), on 2 otherwise idle cores (nothing else was started
# beside it but git and an editor). Binary: session 53's build of the same source as this
# commit (no change to src/, Cargo.* or the script since), copied so later builds cannot touch it.
cd /work/main || exit 1
date -u +"start %FT%TZ" >> /work/exp/s54/repro.log
PHYSNAP_BIN=/work/bin/physnap-s53 EVAL=1 /usr/bin/time -v \
  bash scripts/reproduce-weights.sh /work/exp/s54/repro >> /work/exp/s54/repro.log 2>&1
echo "exit $?" >> /work/exp/s54/repro.log
date -u +"end %FT%TZ" >> /work/exp/s54/repro.log
