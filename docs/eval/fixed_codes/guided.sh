#!/usr/bin/env bash
# The guided check of fcg2dc against fcg2 (the shipped weights before), both on the same binary
# (guided samples differ between builds): the 30 fresh test scans of the earlier checks, both
# blocks (without and with the category), seed set 0, pc+pen+mob, 2 samples a scan, one thread
# a process, two processes (scripts/guided-slices.sh), scan by scan with both weights at each
# scan before the next, so a stop leaves both sides at the same scans; finished slices are
# skipped on a rerun. Session 55 ran it as FROM=0 TO=2, then FROM=3 TO=29 (stopped at the
# session's end; README.md here has the scans that finished). Compare with
# scripts/compare-guided.py (README.md here).
set -euo pipefail
BIN=${BIN:-/work/bin/physnap-codes}
OLD=${OLD:-/work/exp/s53/fcg2_weights}   # a copy of fcg2, the weights shipped before
NEW=${NEW:-/work/exp/fixed_codes/fcg2_dc_w10_e0.03_s3000_weights}
WORK=${WORK:-/work/exp/fixed_codes/guided}
mkdir -p "$WORK"
root=$(cd "$(dirname "$0")/../../.." && pwd)
for c in $(seq "${FROM:-0}" "${TO:-29}"); do
  for t in "fcg2 $OLD" "fcg2dc $NEW"; do
    set -- $t
    W=$2 TAG=$1 VARIANTS=pc+pen+mob FROM=$c TO=$c P=2 BIN=$BIN WORK=$WORK \
      bash "$root/scripts/guided-slices.sh"
  done
done
echo "guided done"
