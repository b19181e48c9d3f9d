#!/usr/bin/env bash
# The rest of the 30-scan guided check (scans 3-29), both weights on the same binary, scan by
# scan, so a stop leaves both sides at the same scans; finished slices are skipped on a rerun.
# Started at session 47's end and stopped with it after one slice; session 48 reran it to the
# end (≈ 51 min, 2 processes; a niced training beside it).
for c in $(seq 3 29); do
  for t in "s14r_now /work/main/weights" "lg2 /work/exp/s47/lg2/weights"; do
    set -- $t
    W=$2 TAG=$1 VARIANTS=pc+pen+mob FROM=$c TO=$c P=2 BIN=/work/bin/physnap-s47a bash /work/main/scripts/guided-slices.sh
  done
done
echo done > gchk30.done
