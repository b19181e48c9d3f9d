#!/usr/bin/env bash
# The guided check of guided.sh continued over scans 3-29 (the 30 fresh scans of the earlier
# checks), scan by scan, both weights at each scan before the next, so a stop leaves both
# sides at the same scans; finished slices are skipped on a rerun.
set -euo pipefail
BIN=${BIN:-/work/bin/physnap-codes}
OLD=${OLD:-/work/exp/s53/fcg2_weights}
NEW=${NEW:-/work/exp/fixed_codes/fcg2_dc_w10_e0.03_s3000_weights}
WORK=${WORK:-/work/exp/fixed_codes/guided}
root=$(cd "$(dirname "$0")/../../.." && pwd)
for c in $(seq "${FROM:-3}" "${TO:-29}"); do
  for t in "fcg2 $OLD" "fcg2dc $NEW"; do
    set -- $t
    W=$2 TAG=$1 VARIANTS=pc+pen+mob FROM=$c TO=$c P=2 BIN=$BIN WORK=$WORK \
      bash "$root/scripts/guided-slices.sh"
  done
done
echo "guided_more done"
