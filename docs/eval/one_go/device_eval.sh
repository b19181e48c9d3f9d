#!/usr/bin/env bash
# Session 52: the evaluations of a weights folder on the device machine's 16 CPU cores (no GPU
# code: only its cores), so that the one-go recipe run on this machine can be scored inside the
# session. The binary travels gzipped in .carry/ (built here at the session's HEAD); the data are
# made there by the recipe's own synth + import, which give data/train byte for byte.
#   bash docs/eval/one_go/device_eval.sh WEIGHTS TAG [SEED...]
set -u
W=$1; TAG=$2; shift 2
B=/tmp/physnap
gunzip -c .carry/physnap.gz > $B && chmod +x $B || exit 1
echo "cores $(nproc); $(grep -m1 'model name' /proc/cpuinfo)"
t0=$(date +%s)
$B data synth --out /tmp/synth --objects 3000 --seed 0 > /dev/null &&
  $B data import --partnet-mobility /tmp/synth --out /tmp/train > /dev/null || exit 1
echo "data $(( $(date +%s) - t0 )) s; dataset.json $(sha256sum < /tmp/train/dataset.json | cut -c1-16)"
export RAYON_NUM_THREADS=${THREADS:-16}
t0=$(date +%s)
$B eval shape --weights "$W" --data /tmp/train --parts "${PARTS:-64}" --out "$OUT/${TAG}_shape.json" \
  > "$OUT/${TAG}_shape.log" 2>&1
echo "eval shape rc $? in $(( $(date +%s) - t0 )) s"
for s in "$@"; do
  t0=$(date +%s)
  $B eval generative --weights "$W" --data /tmp/train --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 --seed "$s" --out "$OUT/${TAG}_gen_$s.json" > "$OUT/${TAG}_gen_$s.log" 2>&1
  echo "eval generative seed $s rc $? in $(( $(date +%s) - t0 )) s"
done
python3 - "$OUT" <<'PY'
import json, sys, glob
for f in sorted(glob.glob(sys.argv[1] + "/*.json")):
    d = json.load(open(f))
    name = f.split("/")[-1]
    if "mean_iou" in d:
        print(name, "IoU", round(d["mean_iou"], 4), "L1", d["l1"], "parts", len(d["parts"]), "fit", d.get("fit_codes"))
    else:
        u, c = d["unconditional"], d["conditional"]
        print(name, "MMD", round(u["mmd"], 4), "COV", u["cov"], "1-NNA", round(u["one_nna"], 3),
              "valid", u["valid_rate"], "category", round(c["accuracy"] * c["samples"]), "/", c["samples"])
PY
