#!/usr/bin/env bash
# Reproduce the shipped weights/ from scratch with one command:
#
#   bash scripts/reproduce-weights.sh [OUT]        # default OUT: repro
#
# data synth -> data import -> train shape (15,000 steps, resumed once at step 11,000) ->
# train diffusion (two stages, exactly how the shipped denoiser was trained: 2,000 steps at a
# constant learning rate, then cosine decay and a weight EMA to 7,000 steps) -> retrieval
# codebook (written by train diffusion) -> eval generative --write-manifest. Adam's moments
# restart at each resume, so the stops are part of the recipe. OUT/weights is then a drop-in
# replacement for weights/. About 2 h 50 min on 2 idle cores (BENCHMARKS.md "Training the
# shipped weights").
#
# Knobs (environment; the defaults are the shipped recipe, smaller values make a smoke run):
#   PHYSNAP_BIN   physnap binary (default: cargo build --release, then target/release/physnap)
#   OBJECTS (3000)  SHAPE_STEPS (15000)  SHAPE_STOP (11000; 0: no stop)
#   STAGE1 (2000)  STAGE2 (0: no stop between; the previous weights stopped at 3500)  STEPS (7000)
#   BATCH_OBJECTS (16)  CHECKPOINT_EVERY (500)  IMPORT_FLAGS ("")  SHAPE_FLAGS ("")
#   DENOISER_FLAGS ("")  EVAL (1: run eval generative; 0: skip)
set -euo pipefail

OUT=${1:-repro}
OBJECTS=${OBJECTS:-3000}
SHAPE_STEPS=${SHAPE_STEPS:-15000}
SHAPE_STOP=${SHAPE_STOP:-11000}
STAGE1=${STAGE1:-2000}
STAGE2=${STAGE2:-0}
STEPS=${STEPS:-7000}
BATCH_OBJECTS=${BATCH_OBJECTS:-16}
CHECKPOINT_EVERY=${CHECKPOINT_EVERY:-500}
IMPORT_FLAGS=${IMPORT_FLAGS:-}
SHAPE_FLAGS=${SHAPE_FLAGS:-}
DENOISER_FLAGS=${DENOISER_FLAGS:-}
EVAL=${EVAL:-1}

if [ -z "${PHYSNAP_BIN:-}" ]; then
  cargo build --release --locked
  PHYSNAP_BIN=target/release/physnap
fi
if [ "$SHAPE_STOP" != 0 ] && ! [ "$SHAPE_STOP" -lt "$SHAPE_STEPS" ]; then
  echo "invalid shape stop: need SHAPE_STOP < SHAPE_STEPS (or SHAPE_STOP=0), got $SHAPE_STOP, $SHAPE_STEPS" >&2
  exit 2
fi
if [ "$STAGE2" = 0 ]; then
  if ! [ "$STAGE1" -lt "$STEPS" ]; then
    echo "invalid stages: need STAGE1 < STEPS, got $STAGE1, $STEPS" >&2
    exit 2
  fi
elif ! [ "$STAGE1" -lt "$STAGE2" ] || ! [ "$STAGE2" -lt "$STEPS" ]; then
  echo "invalid stages: need STAGE1 < STAGE2 < STEPS (or STAGE2=0), got $STAGE1, $STAGE2, $STEPS" >&2
  exit 2
fi
run() {
  echo "+ physnap $*" >&2
  "$PHYSNAP_BIN" "$@"
}

mkdir -p "$OUT"
start=$(date +%s)
run data synth --out "$OUT/synth" --objects "$OBJECTS" --seed 0
# shellcheck disable=SC2086
run data import --partnet-mobility "$OUT/synth" --out "$OUT/train" $IMPORT_FLAGS
# The shape prior: host backward pass (the default), cosine lr over SHAPE_STEPS, val IoU every
# 3,000 steps, a checkpoint every 1,000; stopped once at SHAPE_STOP and resumed.
shape=(train shape --data "$OUT/train" --out "$OUT/shape" --steps "$SHAPE_STEPS" --seed 0
       --eval-every 3000 --checkpoint-every 1000)
if [ "$SHAPE_STOP" != 0 ]; then
  # shellcheck disable=SC2086
  run "${shape[@]}" --stop-at "$SHAPE_STOP" $SHAPE_FLAGS
  # shellcheck disable=SC2086
  run "${shape[@]}" --resume $SHAPE_FLAGS
else
  # shellcheck disable=SC2086
  run "${shape[@]}" $SHAPE_FLAGS
fi
common=(--data "$OUT/train" --shape "$OUT/shape" --out "$OUT/weights"
        --batch-objects "$BATCH_OBJECTS" --noise-levels 4 --lr 5e-4
        --checkpoint-every "$CHECKPOINT_EVERY")
# Stage 1: constant learning rate, no EMA.
# shellcheck disable=SC2086
run train diffusion "${common[@]}" --steps "$STAGE1" --lr-final-factor 1 --ema-decay 0 $DENOISER_FLAGS
# Stages 2 and 3: cosine decay from STAGE1 to 0.1 x lr over the run to STEPS, EMA 0.999 from
# STAGE1; resumed once at STAGE2.
decay=(--steps "$STEPS" --lr-decay-start "$STAGE1" --lr-final-factor 0.1 --ema-decay 0.999 --resume)
if [ "$STAGE2" != 0 ]; then
  # shellcheck disable=SC2086
  run train diffusion "${common[@]}" "${decay[@]}" --stop-at "$STAGE2" $DENOISER_FLAGS
fi
# shellcheck disable=SC2086
run train diffusion "${common[@]}" "${decay[@]}" $DENOISER_FLAGS
if [ "$EVAL" = 1 ]; then
  run eval generative --weights "$OUT/weights" --data "$OUT/train" --samples 48 --refs 48 \
    --per-category 4 --states 4 --points 256 --out "$OUT/weights/eval_generative.json" \
    --write-manifest
fi
echo "weights in $OUT/weights ($(( ($(date +%s) - start) / 60 )) min)" >&2
