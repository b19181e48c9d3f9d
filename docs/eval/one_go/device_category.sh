#!/usr/bin/env bash
# Session 52: more seeds of the shipped weights' category accuracy, on the device machine's 16 CPU
# cores (no GPU code), one process of THREADS (5) threads per seed. --samples 1: the conditioned samples
# are seeded apart from the unconditional ones (seed + 1,000,000 (category index + 1)), so they
# are exactly the conditioned samples of the full protocol run at that seed.
#   bash docs/eval/one_go/device_category.sh WEIGHTS SEED...
set -u
W=$1; shift
B=/tmp/physnap
gunzip -c .carry/physnap.gz > $B && chmod +x $B || exit 1
$B data synth --out /tmp/synth --objects 3000 --seed 0 > /dev/null &&
  $B data import --partnet-mobility /tmp/synth --out /tmp/train > /dev/null || exit 1
for s in "$@"; do
  ( t0=$(date +%s)
    RAYON_NUM_THREADS=${THREADS:-5} $B eval generative --weights "$W" --data /tmp/train --samples 1 --refs 48 \
      --per-category 4 --states 4 --points 256 --seed "$s" --out "$OUT/cat_$s.json" > "$OUT/cat_$s.log" 2>&1
    echo "seed $s rc $? in $(( $(date +%s) - t0 )) s" ) &
done
wait
python3 - "$OUT" <<'PY'
import json, sys, glob
for f in sorted(glob.glob(sys.argv[1] + "/cat_*.json")):
    c = json.load(open(f))["conditional"]
    print(f.split("/")[-1], round(c["accuracy"] * c["samples"]), "/", c["samples"],
          {x["category"]: x["hits"] for x in c["categories"]})
PY
