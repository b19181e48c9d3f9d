#!/usr/bin/env bash
# Reproduce the shipped weights/ from scratch with one command:
#
#   bash scripts/reproduce-weights.sh [OUT]        # default OUT: repro
#
# data synth -> data import -> train shape -> train diffusion (two runs, exactly how the
# shipped denoiser was trained: 2,000 steps at a constant learning rate, then --resume with a
# cosine decay and a weight EMA to 7,000 steps; the denoiser adds its category to every graph
# layer, --category-layers) -> retrieval codebook (written by train diffusion) -> two more
# cosine cycles of the shape prior's decoder with its encoder frozen and an eikonal term
# (train shape --init-from OUT/weights --freeze-encoder --eikonal 0.01 at lr 5e-4, seeds 0
# and 1; the shipped decoder since 2026-11-27), each installed with train install-shape (the
# codes, and so the denoiser, stay valid) -> eval shape and eval generative --write-manifest.
# OUT/weights is then a drop-in replacement for weights/.
# About 2 h 40–48 min on 2 idle cores with the evaluations, 2 h 28–36 min without (BENCHMARKS.md
# "Training the shipped weights"), of which each decoder cycle is about 27 min
# (DECODER_CYCLES=1: the recipe of the first 2026-11-27 weights; DECODER_STEPS=0 or
# DECODER_CYCLES=0: no cycle, the recipe before 2026-11-27).
#
# Knobs (environment; the defaults are the shipped recipe, smaller values make a smoke run):
#   PHYSNAP_BIN   physnap binary (default: cargo build --release, then target/release/physnap)
#   OBJECTS (3000)  SHAPE_STEPS (3000)  STAGE1 (2000)  STAGE2 (0: no stop between; N: a third run
#   resumed at N, as the weights shipped before 2026-11-26 were made)  STEPS (7000)
#   BATCH_OBJECTS (16)  CHECKPOINT_EVERY (500)  IMPORT_FLAGS ("")  SHAPE_FLAGS ("")
#   DENOISER_FLAGS ("")  DECODER_STEPS (3000, as shipped; 0: no decoder cycle)
#   DECODER_CYCLES (2, as shipped; 0: none)
#   SHAPE_BACKWARD (burn, as shipped: how the first shape prior's decoder gradients are computed;
#   host: the trainer's default, the same gradients up to float rounding, ≈ 1.6x faster per step)
#   DECODER_FLAGS ("--eikonal 0.01", as shipped; set it empty for the plain cycle, which raises
#   the shape IoU more, 0.621 against 0.588, but aligns guided fits worse, EVALUATION.md)
#   EVAL (1: run eval generative; 0: skip)
set -euo pipefail

OUT=${1:-repro}
OBJECTS=${OBJECTS:-3000}
SHAPE_STEPS=${SHAPE_STEPS:-3000}
STAGE1=${STAGE1:-2000}
STAGE2=${STAGE2:-0}
STEPS=${STEPS:-7000}
BATCH_OBJECTS=${BATCH_OBJECTS:-16}
CHECKPOINT_EVERY=${CHECKPOINT_EVERY:-500}
IMPORT_FLAGS=${IMPORT_FLAGS:-}
SHAPE_FLAGS=${SHAPE_FLAGS:-}
DENOISER_FLAGS=${DENOISER_FLAGS:-}
DECODER_STEPS=${DECODER_STEPS:-3000}
DECODER_FLAGS=${DECODER_FLAGS-"--eikonal 0.01"}
DECODER_CYCLES=${DECODER_CYCLES:-2}
SHAPE_BACKWARD=${SHAPE_BACKWARD:-burn}
EVAL=${EVAL:-1}

if ! [[ "$DECODER_CYCLES" =~ ^[0-9]+$ ]]; then
  echo "invalid DECODER_CYCLES: need a whole number of decoder cycles (0 for none), got '$DECODER_CYCLES'" >&2
  exit 2
fi
if [ "$SHAPE_BACKWARD" != burn ] && [ "$SHAPE_BACKWARD" != host ]; then
  echo "invalid SHAPE_BACKWARD: need burn or host, got '$SHAPE_BACKWARD'" >&2
  exit 2
fi
if [ -z "${PHYSNAP_BIN:-}" ]; then
  cargo build --release --locked
  PHYSNAP_BIN=target/release/physnap
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
# The shipped shape prior was trained with burn's autodiff through the decoder; the default
# host backward pass gives the same gradients up to float rounding and is ≈ 1.6x faster per
# step, but rounding differences grow over training, so the recipe names the shipped path
# (SHAPE_BACKWARD=host trades that for speed).
# shellcheck disable=SC2086
run train shape --data "$OUT/train" --out "$OUT/shape" --steps "$SHAPE_STEPS" --seed 0 \
  --decoder-backward "$SHAPE_BACKWARD" $SHAPE_FLAGS
common=(--data "$OUT/train" --shape "$OUT/shape" --out "$OUT/weights"
        --batch-objects "$BATCH_OBJECTS" --noise-levels 4 --lr 5e-4
        --checkpoint-every "$CHECKPOINT_EVERY" --category-layers)
# Stage 1: constant learning rate, no EMA.
# shellcheck disable=SC2086
run train diffusion "${common[@]}" --steps "$STAGE1" --lr-final-factor 1 --ema-decay 0 $DENOISER_FLAGS
# Then: cosine decay from STAGE1 to 0.1 x lr over the run to STEPS, EMA 0.999 from STAGE1 (in
# two runs when STAGE2 is set).
decay=(--steps "$STEPS" --lr-decay-start "$STAGE1" --lr-final-factor 0.1 --ema-decay 0.999 --resume)
if [ "$STAGE2" != 0 ]; then
  # shellcheck disable=SC2086
  run train diffusion "${common[@]}" "${decay[@]}" --stop-at "$STAGE2" $DENOISER_FLAGS
fi
# shellcheck disable=SC2086
run train diffusion "${common[@]}" "${decay[@]}" $DENOISER_FLAGS
if [ "$DECODER_STEPS" != 0 ]; then
  # The decoder limits the shape IoU most (EVALUATION.md); further cycles with the encoder
  # frozen improve it while every code, and so the denoiser just trained, stays valid. The
  # eikonal term keeps the decoder's field steep where guidance moves the codes: without it
  # guided scan completion aligns worse. Cycle i uses seed i - 1 (its query draws) and starts
  # from the decoder the previous cycle installed.
  for ((cycle = 1; cycle <= DECODER_CYCLES; cycle++)); do
    # shellcheck disable=SC2086
    run train shape --data "$OUT/train" --out "$OUT/shape_decoder$cycle" --steps "$DECODER_STEPS" \
      --seed $((cycle - 1)) --init-from "$OUT/weights" --freeze-encoder --lr 5e-4 $SHAPE_FLAGS \
      $DECODER_FLAGS
    run train install-shape --shape "$OUT/shape_decoder$cycle" --weights "$OUT/weights"
  done
fi
if [ "$EVAL" = 1 ]; then
  run eval shape --weights "$OUT/weights" --data "$OUT/train" --parts 64 --write-manifest
  run eval generative --weights "$OUT/weights" --data "$OUT/train" --samples 48 --refs 48 \
    --per-category 4 --states 4 --points 256 --out "$OUT/weights/eval_generative.json" \
    --write-manifest
fi
echo "weights in $OUT/weights ($(( ($(date +%s) - start) / 60 )) min)" >&2
