#!/usr/bin/env bash
# Train the weights on one GPU (Vulkan) inside a fixed wall-clock budget, with the shipped recipe's
# shape of schedule (scripts/reproduce-weights.sh) and as many shape-prior steps as fit.
#
#   PHYSNAP_BIN=physnap-gpu bash scripts/device-train.sh OUT [BUDGET_S]
#
# PHYSNAP_BIN is a binary built with `cargo build --release --features gpu` (it needs a Vulkan
# loader, libvulkan.so.1, and the GPU's Vulkan driver at run time). BUDGET_S
# (default 540) is the wall time the whole script may take. It:
#   1. makes the data set (data synth OBJECTS = 3000 objects, seed 0 + data import, as the
#      shipped weights);
#   2. probes the GPU: PROBE (200) steps of train shape and of train diffusion, timed;
#   3. from the measured rates, gives the denoiser the shipped 7,000 steps (2,000 at a constant
#      learning rate, then --resume with cosine decay and a weight EMA) and the shape prior as
#      many steps as the rest of the budget holds (at most SHAPE_MAX, default 30000); when the
#      denoiser would take over 60 % of the budget, it trains the shape prior alone;
#   4. leaves OUT/weights (a drop-in weights/ without eval metrics; run eval generative
#      --write-manifest on it) or, shape prior alone, OUT/shape, and OUT/plan.json with the
#      measured rates and the step counts chosen.
# Stops at the first failure (a GPU that cannot start, say) so that little device time is lost.
set -euo pipefail

OUT=${1:?usage: device-train.sh OUT [BUDGET_S]}
BUDGET=${2:-540}
BIN=${PHYSNAP_BIN:?set PHYSNAP_BIN to a physnap binary built with --features gpu}
SHAPE_MAX=${SHAPE_MAX:-30000}
OBJECTS=${OBJECTS:-3000}
PROBE=${PROBE:-200}
DEVICE=${DEVICE:-gpu}
start=$(date +%s.%N)
elapsed() { python3 -c "import time; print(round(time.time() - $start, 1))"; }
run() {
  echo "+ [$(elapsed) s] physnap $*" >&2
  "$BIN" "$@"
}
mkdir -p "$OUT"
run data synth --out "$OUT/synth" --objects "$OBJECTS" --seed 0 >/dev/null
run data import --partnet-mobility "$OUT/synth" --out "$OUT/train" >/dev/null

t=$(elapsed)
run train shape --device "$DEVICE" --data "$OUT/train" --out "$OUT/probe_shape" --steps "$PROBE" \
  --seed 0 --eval-every 0 --checkpoint-every 0
shape_s=$(python3 -c "print(round($(elapsed) - $t, 1))")
t=$(elapsed)
run train diffusion --device "$DEVICE" --data "$OUT/train" --shape "$OUT/probe_shape" \
  --out "$OUT/probe_diffusion" --steps "$PROBE" --batch-objects 16 --noise-levels 4 --lr 5e-4 \
  --checkpoint-every 0 --category-layers --ema-decay 0
diff_s=$(python3 -c "print(round($(elapsed) - $t, 1))")

plan=$(python3 - "$BUDGET" "$(elapsed)" "$shape_s" "$diff_s" "$SHAPE_MAX" "$OUT" <<'EOF'
import json, sys
budget, used, shape_s, diff_s, shape_max = map(float, sys.argv[1:6])
out = sys.argv[6]
shape = json.load(open(f"{out}/probe_shape/shape_train.json"))
diff = json.load(open(f"{out}/probe_diffusion/diffusion_train.json"))
# Step rates from the probes' own step time (the first steps include kernel compilation and
# autotuning, so they are conservative); everything else a probe took (loading, the final
# evaluation, the codebook) is charged again as each later run's fixed cost. Margin 30 s.
shape_rate = shape["steps"] / shape["train_s"]
diff_rate = diff["steps"] / diff["wall_seconds"]
shape_fixed = shape_s - shape["train_s"]
diff_fixed = diff_s - diff["wall_seconds"]
left = budget - used - 30
need_d = 7000 / diff_rate + 2 * diff_fixed  # two runs
denoiser = need_d <= 0.6 * left
rest = left - (need_d if denoiser else 0) - shape_fixed
shape_steps = int(min(shape_max, max(0, rest * shape_rate)) // 100 * 100)
print(json.dumps({"budget_s": budget, "used_s": used, "probe_shape_s": shape_s,
                  "probe_diffusion_s": diff_s, "shape_steps_per_s": shape_rate,
                  "diffusion_steps_per_s": diff_rate, "shape_fixed_s": shape_fixed,
                  "diffusion_fixed_s": diff_fixed, "denoiser_s": need_d,
                  "denoiser": denoiser, "shape_steps": shape_steps}))
EOF
)
echo "$plan" | tee "$OUT/plan.json" >&2
shape_steps=$(python3 -c "import json,sys; print(json.loads(sys.argv[1])['shape_steps'])" "$plan")
denoiser=$(python3 -c "import json,sys; print(int(json.loads(sys.argv[1])['denoiser']))" "$plan")
if [ "$shape_steps" -lt "${MIN_SHAPE:-1000}" ]; then
  echo "too little budget left for the shape prior ($shape_steps steps)" >&2
  exit 3
fi
eval_every=$(( shape_steps / 2 ))
run train shape --device "$DEVICE" --data "$OUT/train" --out "$OUT/shape" --steps "$shape_steps" \
  --seed 0 --eval-every "$eval_every" --checkpoint-every 0
if [ "$denoiser" = 1 ]; then
  common=(--device "$DEVICE" --data "$OUT/train" --shape "$OUT/shape" --out "$OUT/weights"
          --batch-objects 16 --noise-levels 4 --lr 5e-4 --checkpoint-every 1000 --category-layers)
  run train diffusion "${common[@]}" --steps 2000 --lr-final-factor 1 --ema-decay 0
  run train diffusion "${common[@]}" --steps 7000 --lr-decay-start 2000 --lr-final-factor 0.1 \
    --ema-decay 0.999 --resume
fi
echo "done in $(elapsed) s" >&2
