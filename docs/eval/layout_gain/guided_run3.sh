#!/usr/bin/env bash
# Session 47: guided slices of the shipped weights and of lg2 with the same binary, scans 0-2, both
# blocks, seed set 0, pc+pen+mob (run.sh aimed at scans 0-4 and was cut to 0-2 for time).
while pgrep -f "eval guided" > /dev/null; do sleep 5; done
for t in "s14r_now /work/main/weights" "lg2 /work/exp/s47/lg2/weights"; do
  set -- $t
  W=$2 TAG=$1 VARIANTS=pc+pen+mob FROM=0 TO=2 P=2 BIN=/work/bin/physnap-s47a bash /work/main/scripts/guided-slices.sh
done
echo done > gchk.done
