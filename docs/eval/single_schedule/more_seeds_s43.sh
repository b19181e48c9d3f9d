#!/usr/bin/env bash
# Session 43: the shipped weights (s14r) at two more eval generative seeds (5, 6), after session
# 42's seeds 3 and 4 (more_seeds_s42.sh): seven seeds in all. The same command and binary as
# every s14r figure (docs/eval/restarts/gen.sh; s14r/weights links to the resumable folder).
cd /work/exp/s43 || exit 1
mkdir -p s14r && ln -sfn /work/exp/s40/s14r/weights s14r/weights
./gen.sh s14r 5 6
