#!/usr/bin/env bash
# Reproduces EVALUATION.md "Fidelity levers": the real-asset benchmark's guided row with each
# fidelity lever alone and all together, on the benchmark set of scripts/real-assets.sh.
#
#   bash scripts/eval/real-levers.sh [DATA] [OUT] [VIEWS]
#
# Defaults: DATA=real, OUT=out/levers, VIEWS=1 (the first view of each of the 25 objects; 0:
# all 75 scans). Each configuration is one `physnap eval real --rows guided` run:
#
#   none     --repair off --scan-camera ignore --scale off   (the pipeline without the levers)
#   camera   --repair off --scan-camera use    --scale off   (ℓ_free from the scan's camera)
#   repair   --repair on  --scan-camera ignore --scale off   (joint repair + part removal)
#   scale    --repair off --scan-camera ignore --scale auto  (the scale hypothesis)
#   all      --repair on  --scan-camera use    --scale off   (camera + repair)
#   nocamera --scan-camera ignore                             (the defaults without the camera)
#   default  (no flags: repair on, camera used, scale auto)
#
# A stopped run resumes (eval real skips finished scans). PHYSNAP_BIN names the binary
# (default: physnap on PATH); PHYSNAP_PYTHON the Python with mujoco (default: DATA/venv's).
# Prints one summary line per configuration from OUT/<config>/real.json.
set -euo pipefail
DATA=${1:-real}
OUT=${2:-out/levers}
VIEWS=${3:-1}
BIN=${PHYSNAP_BIN:-physnap}
PY=${PHYSNAP_PYTHON:-$DATA/venv/bin/python}
[ -x "$PY" ] || PY=python3
run() {
  local name=$1
  shift
  "$BIN" eval real --data "$DATA" --out "$OUT/$name" --rows guided --views "$VIEWS" \
    --python "$PY" "$@" >"$OUT/$name.log" 2>&1
}
mkdir -p "$OUT"
configs=${PHYSNAP_LEVERS:-"none camera repair scale all nocamera default"}
for c in $configs; do
  case $c in
    none) run none --repair off --scan-camera ignore --scale off ;;
    camera) run camera --repair off --scan-camera use --scale off ;;
    repair) run repair --repair on --scan-camera ignore --scale off ;;
    scale) run scale --repair off --scan-camera ignore --scale auto ;;
    all) run all --repair on --scan-camera use --scale off ;;
    nocamera) run nocamera --scan-camera ignore ;;
    default) run default ;;
    *) echo "unknown configuration $c" >&2; exit 2 ;;
  esac
done
python3 - "$OUT" $configs <<'PY'
import json, sys
out, configs = sys.argv[1], sys.argv[2:]
print("config | parts exact | joint types | axis ≤10° | pivot ≤0.05 | chamfer/diag | sim-clean | s median")
for c in configs:
    r = json.load(open(f"{out}/{c}/real.json"))["rows"][0]["overall"]
    pct = lambda k: "—" if r[k] is None else f"{100 * r[k]:.0f} %"
    print(f"{c} | {pct('parts_exact')} | {pct('joint_types_exact')} | {pct('axis_within_10deg')} | "
          f"{r['pivot_within_0_05_count']}/{r['gt_revolute']} | {r['chamfer_diag_median']:.3f} | "
          f"{pct('sim_clean')} | {r['seconds_median']:.1f}")
PY
