#!/usr/bin/env bash
# Session 52: scripts/reproduce-weights.sh in one go, from scratch, with its defaults (fcg2's
# recipe), on 2 idle cores; the evaluations (EVAL=0 here) run afterwards, eval_device.sh.
# Binary: the session's HEAD built with `cargo build --release --locked` (the script's own
# build), copied so that later builds cannot touch it.
cd /work/main || exit 1
PHYSNAP_BIN=/work/bin/physnap-s52 EVAL=0 /usr/bin/time -v \
  bash scripts/reproduce-weights.sh /work/exp/s52/repro >> /work/exp/s52/repro.log 2>&1
echo "exit $?" >> /work/exp/s52/repro.log
