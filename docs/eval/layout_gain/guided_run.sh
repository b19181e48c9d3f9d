#!/usr/bin/env bash
# Session 47: guided slices of lg2 and of the shipped weights with the same binary, scans 0-4, both
# blocks, seed set 0, pc+pen+mob (scan 0 of s14r_now was run first, alone, as a reproduction check).
for t in "s14r_now /work/main/weights" "lg2 /work/exp/s47/lg2/weights"; do
  set -- $t
  W=$2 TAG=$1 VARIANTS=pc+pen+mob FROM=0 TO=4 P=2 BIN=/work/bin/physnap-s47a bash /work/main/scripts/guided-slices.sh
done
echo done > gchk.done
