#!/usr/bin/env bash
# Reproduce the shipped weights/ from scratch with one command:
#
#   bash scripts/reproduce-weights.sh [OUT]        # default OUT: repro
#
# Interrupted, the same command goes on where it stopped: every finished stage is skipped (it
# left OUT/stages/NAME.done), train shape and the denoiser's resumed runs continue from their
# last checkpoint and any other stage starts again. OUT/stages.tsv gives each stage's wall
# seconds (of its last attempt; the train reports keep the cumulative training time); a rerun
# with other knobs than OUT/recipe.knobs is refused, naming the knob. UNTIL=NAME stops after
# that stage (a stage name of stages.tsv: synth, import, shape, decoderN, encode,
# decoder_codes, denoiser_stage1, denoiser_stage2, denoiser_decay, denoiser_restartN, eval_shape,
# eval_generative), to split the recipe into several runs; it is not one of the knobs a rerun
# must repeat.
#
# data synth -> data import -> train shape (12,000 steps, 128 parts x 128 queries x 64 surface
# points a batch, host backward pass, the parts of each step in two slices) -> three more cosine
# cycles of the shape prior's decoder with its encoder frozen (train shape --init-from the
# previous run --freeze-encoder at lr 5e-4: cycle 1 seed 0 eikonal 0.01, cycle 2 seed 1 eikonal
# 0.03, cycle 3 seed 2 eikonal 0.03 with the wrong-side term --wrong-side 10) -> train encode:
# every part's code from the last cycle, the mean of 16 encoder views fitted 50 Adam steps on
# 512 SDF samples with the decoder frozen (ENCODER_VIEWS, FIT_STEPS, FIT_QUERIES) -> one more
# decoder cycle on exactly those codes (train shape --codes, encoder frozen, 3,000 steps, seed
# 3, eikonal 0.03, --wrong-side 10: the decoder learns to decode the codes the denoiser learns,
# and they stay valid; CODES_DECODER_*) -> train diffusion on those codes (four runs: 2,000
# steps at a constant learning rate, then --resume with one cosine decay and a weight EMA to
# 14,000 steps in two runs, the second (7,000 -> 14,000) with the box-overlap penalty
# --overlap-weight 3, then one more cosine cycle (warm restart) to 18,000 steps with the
# penalty; the denoiser adds its category to every graph layer, --category-layers, and trains
# the part layout and the shape codes at twice NAP's feature scale, --layout-gain 2 --code-gain
# 2; each step's batch in two slices; the last run builds the retrieval codebook) -> eval shape
# and eval generative --write-manifest.
# OUT/weights is then a drop-in replacement for weights/ (weights/README.md). The shipped files
# were trained stage by stage with these commands, not by one run of this script: the first
# prior and its first two cycles with the single pass (SHAPE_SHARDS=1: the same loss up to
# float rounding, 1.33x / 1.18x slower per step), and the cycle on the codes (decoder_codes)
# after the denoiser, which does not read the decoder. A run matches their quality, not their
# bytes.
# Timing on 2 cores from scratch: ≈ 2 h 47 min of training plus ≈ 10 min of evaluations
# (BENCHMARKS.md "Training"), ≈ 2 h 55 min on a 13 % slower host: inside a 3-hour budget.
#
# Knobs (environment; the defaults are the shipped recipe, smaller values make a smoke run;
# the values that give earlier weights are in CHANGELOG.md):
#   PHYSNAP_BIN   physnap binary (default: cargo build --release, then target/release/physnap)
#   OBJECTS (3000)  SHAPE_STEPS (12000)  STAGE1 (2000)  STAGE2 (7000: the decay in two runs, the
#   second resumed at STAGE2; 0: one run)  STEPS (14000)  BATCH_OBJECTS (16)  CHECKPOINT_EVERY (500)
#   IMPORT_FLAGS ("")  SHAPE_FLAGS ("", added to every train shape)  DENOISER_FLAGS ("", added
#   to every train diffusion)
#   LAYOUT_GAIN (2: every train diffusion's --layout-gain, the part boxes' and centres' spread
#   in model space; 1: NAP's scaling)
#   CODE_GAIN (2: every train diffusion's --code-gain, the shape codes' spread in model space;
#   1: NAP's scaling)
#   SHAPE_BATCH ("--batch-parts 128 --queries-per-part 128 --surface-points 64": the batch of
#   the first prior and of every decoder cycle; "" gives train shape's defaults, 16 x 2048 x 512)
#   SHAPE_BACKWARD (host, as shipped: how the first prior's decoder gradients are computed;
#   burn: burn's autodiff, the same gradients up to float rounding, ≈ 1.6x slower per step)
#   SHAPE_SHARDS (2: each train shape step's parts in two slices on the two cores; 1: the single
#   pass the shipped prior and first cycles were trained with)
#   DENOISER_SHARDS (2: each denoiser step's batch in two slices, ≈ 2.1x the single pass; 1: the
#   single pass)
#   DECAY_OVERLAP (3, as shipped: the --overlap-weight of the decay run that ends at STEPS)
#   RESTART_STEPS ("18000", as shipped: a list of step counts, each one more cosine cycle (warm
#   restart at --lr, decay to 0.1x) from the previous count to it; 0: none)
#   RESTART_OVERLAP ("3", as shipped: one train diffusion --overlap-weight per restart cycle;
#   ignored without restarts)
#   RESTART_SHARDS (2: the restart cycles' batch slices)
#   DECODER_STEPS (3000; 0: no decoder cycle)  DECODER_CYCLES (3, as shipped; 0: none)
#   DECODER_EIKONAL ("0.01 0.03 0.03": the eikonal weight of each cycle, one value per cycle; 0
#   is the plain cycle, which raises the shape IoU more but aligns guided fits worse)
#   DECODER_WRONG_SIDE ("0 0 10": the --wrong-side weight of each cycle, one value per cycle;
#   the third cycle's 10 closes walls under a grid cell)
#   DECODER_FLAGS ("": more flags for every decoder cycle, the one on the codes too)
#   CODES_DECODER_STEPS (3000; 0: none)  CODES_DECODER_EIKONAL (0.03)  CODES_DECODER_WRONG_SIDE
#   (10): the decoder cycle on the fitted codes after train encode (stage decoder_codes, train
#   shape --codes): shape IoU on all 940 val parts 0.843 -> 0.865
#   ENCODER_VIEWS (16)  FIT_STEPS (50)  FIT_QUERIES (512): train encode's --encoder-views,
#   --fit-steps and --fit-queries, how the codes the denoiser learns are made (1, 0, 2048:
#   NAP's encoding)
#   EVAL (1: run eval shape and eval generative; 0: skip)
#   UNTIL ("": run every stage; a stage name: stop after it, above)
set -euo pipefail

OUT=${1:-repro}
OBJECTS=${OBJECTS:-3000}
SHAPE_STEPS=${SHAPE_STEPS:-12000}
STAGE1=${STAGE1:-2000}
STAGE2=${STAGE2:-7000}
STEPS=${STEPS:-14000}
BATCH_OBJECTS=${BATCH_OBJECTS:-16}
CHECKPOINT_EVERY=${CHECKPOINT_EVERY:-500}
IMPORT_FLAGS=${IMPORT_FLAGS:-}
SHAPE_FLAGS=${SHAPE_FLAGS:-}
DENOISER_FLAGS=${DENOISER_FLAGS:-}
DECODER_STEPS=${DECODER_STEPS:-3000}
DECODER_FLAGS=${DECODER_FLAGS:-}
CODES_DECODER_STEPS=${CODES_DECODER_STEPS:-3000}
CODES_DECODER_EIKONAL=${CODES_DECODER_EIKONAL:-0.03}
CODES_DECODER_WRONG_SIDE=${CODES_DECODER_WRONG_SIDE:-10}
DECODER_CYCLES=${DECODER_CYCLES:-3}
DECODER_EIKONAL=${DECODER_EIKONAL-"0.01 0.03 0.03"}
DECODER_WRONG_SIDE=${DECODER_WRONG_SIDE-"0 0 10"}
SHAPE_BATCH=${SHAPE_BATCH-"--batch-parts 128 --queries-per-part 128 --surface-points 64"}
SHAPE_BACKWARD=${SHAPE_BACKWARD:-host}
DENOISER_SHARDS=${DENOISER_SHARDS:-2}
RESTART_STEPS=${RESTART_STEPS-"18000"}
RESTART_OVERLAP=${RESTART_OVERLAP-"3"}
RESTART_SHARDS=${RESTART_SHARDS:-2}
DECAY_OVERLAP=${DECAY_OVERLAP:-3}
SHAPE_SHARDS=${SHAPE_SHARDS:-2}
EVAL=${EVAL:-1}
UNTIL=${UNTIL:-}
# mimalloc keeps the memory it frees instead of handing it back to the kernel after 10 ms: the
# trainers free and re-allocate the same large buffers every step, and each return cost page
# faults and the kernel's page zeroing. The same weights byte for byte, 3 % (train diffusion)
# to 6 % (train shape) less wall time (BENCHMARKS.md "Faster training steps").
# Set MIMALLOC_PURGE_DELAY to another value to override.
export MIMALLOC_PURGE_DELAY=${MIMALLOC_PURGE_DELAY:--1}
ENCODER_VIEWS=${ENCODER_VIEWS:-16}
FIT_STEPS=${FIT_STEPS:-50}
FIT_QUERIES=${FIT_QUERIES:-512}
LAYOUT_GAIN=${LAYOUT_GAIN:-2}
CODE_GAIN=${CODE_GAIN:-2}

if ! [[ "$DECODER_CYCLES" =~ ^[0-9]+$ ]]; then
  echo "invalid DECODER_CYCLES: need a whole number of decoder cycles (0 for none), got '$DECODER_CYCLES'" >&2
  exit 2
fi
# A knob holding one non-negative number per decoder cycle: $1 the knob, $2 what each number
# is, $3 the array that receives them.
per_cycle() {
  local knob=$1 what=$2
  local -n list=$3
  read -r -a list <<< "${!knob}"
  for w in "${list[@]}"; do
    if ! [[ "$w" =~ ^[0-9]*\.?[0-9]+$ ]]; then
      echo "invalid $knob: need one non-negative number per decoder cycle, got '$w' in '${!knob}'" >&2
      exit 2
    fi
  done
  if [ "$DECODER_STEPS" != 0 ] && [ "${#list[@]}" != "$DECODER_CYCLES" ]; then
    echo "invalid $knob: need one $what per decoder cycle ($DECODER_CYCLES), got ${#list[@]}: '${!knob}'" >&2
    exit 2
  fi
}
eikonal=()
wrong_side=()
per_cycle DECODER_EIKONAL "eikonal weight" eikonal
per_cycle DECODER_WRONG_SIDE "wrong-side weight" wrong_side
for knob in ENCODER_VIEWS FIT_STEPS FIT_QUERIES CODES_DECODER_STEPS; do
  if ! [[ "${!knob}" =~ ^[0-9]+$ ]]; then
    echo "invalid $knob: need a whole number (train encode and train shape check its range), got '${!knob}'" >&2
    exit 2
  fi
done
for knob in DENOISER_SHARDS RESTART_SHARDS SHAPE_SHARDS; do
  if ! [[ "${!knob}" =~ ^[1-9][0-9]*$ ]]; then
    echo "invalid $knob: need a whole number of batch slices, at least 1, got '${!knob}'" >&2
    exit 2
  fi
done
for knob in CODES_DECODER_EIKONAL CODES_DECODER_WRONG_SIDE; do
  if ! [[ "${!knob}" =~ ^[0-9]*\.?[0-9]+$ ]]; then
    echo "invalid $knob: need a non-negative number (train shape checks its range), got '${!knob}'" >&2
    exit 2
  fi
done
for knob in LAYOUT_GAIN CODE_GAIN; do
  if ! [[ "${!knob}" =~ ^[0-9]*\.?[0-9]+$ ]]; then
    echo "invalid $knob: need a positive number (train diffusion checks its range), got '${!knob}'" >&2
    exit 2
  fi
done
if [ -n "$UNTIL" ] && ! [[ "$UNTIL" =~ ^(synth|import|shape|decoder[0-9]+|encode|decoder_codes|denoiser_(stage1|stage2|decay|restart[0-9]+)|eval_shape|eval_generative)$ ]]; then
  echo "invalid UNTIL: need a stage name (synth, import, shape, decoderN, encode, decoder_codes, denoiser_stage1, denoiser_stage2, denoiser_decay, denoiser_restartN, eval_shape, eval_generative), got '$UNTIL'" >&2
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
restarts=()
[ "$RESTART_STEPS" != 0 ] && read -r -a restarts <<< "$RESTART_STEPS"
prev=$STEPS
for r in "${restarts[@]}"; do
  if ! [[ "$r" =~ ^[0-9]+$ ]] || ! [ "$prev" -lt "$r" ]; then
    echo "invalid RESTART_STEPS: need increasing step counts above STEPS (or 0 for no restart), got $STEPS, '$RESTART_STEPS'" >&2
    exit 2
  fi
  prev=$r
done
overlap=()
[ "${#restarts[@]}" != 0 ] && read -r -a overlap <<< "$RESTART_OVERLAP"
if [ "${#overlap[@]}" != 0 ] && [ "${#overlap[@]}" != "${#restarts[@]}" ]; then
  echo "invalid RESTART_OVERLAP: need one overlap weight per restart cycle (${#restarts[@]}), got ${#overlap[@]}: '$RESTART_OVERLAP'" >&2
  exit 2
fi
for w in "${overlap[@]}"; do
  if ! [[ "$w" =~ ^[0-9]*\.?[0-9]+$ ]]; then
    echo "invalid RESTART_OVERLAP: need one non-negative number per restart cycle, got '$w' in '$RESTART_OVERLAP'" >&2
    exit 2
  fi
done
if ! [[ "$DECAY_OVERLAP" =~ ^[0-9]*\.?[0-9]+$ ]]; then
  echo "invalid DECAY_OVERLAP: need a non-negative number (the box-overlap penalty of the run that ends at STEPS), got '$DECAY_OVERLAP'" >&2
  exit 2
fi
# The knobs a run into OUT was started with are kept in OUT/recipe.knobs; a rerun into the same
# OUT must use the same ones (a recipe continued with other knobs would mix two recipes).
knobs=(OBJECTS SHAPE_STEPS STAGE1 STAGE2 STEPS BATCH_OBJECTS CHECKPOINT_EVERY IMPORT_FLAGS
       SHAPE_FLAGS DENOISER_FLAGS DECODER_STEPS DECODER_FLAGS DECODER_CYCLES DECODER_EIKONAL
       DECODER_WRONG_SIDE SHAPE_BATCH SHAPE_BACKWARD DENOISER_SHARDS RESTART_STEPS
       RESTART_OVERLAP RESTART_SHARDS DECAY_OVERLAP SHAPE_SHARDS ENCODER_VIEWS FIT_STEPS
       FIT_QUERIES LAYOUT_GAIN CODE_GAIN CODES_DECODER_STEPS CODES_DECODER_EIKONAL
       CODES_DECODER_WRONG_SIDE)
if [ -f "$OUT/recipe.knobs" ]; then
  while IFS= read -r line; do
    k=${line%%=*}
    [[ " ${knobs[*]} " == *" $k "* ]] || continue
    if [ "$line" != "$k=${!k}" ]; then
      echo "invalid $k for $OUT: its recipe was started with $line, this run has $k=${!k} (continue it with the same knobs, or use another OUT)" >&2
      exit 2
    fi
  done < "$OUT/recipe.knobs"
fi
# Each stage that finishes leaves OUT/stages/NAME.done and a line in OUT/stages.tsv (name,
# wall seconds, command), and a rerun into the same OUT skips it: an interrupted recipe goes on
# from the stage it stopped in (train shape and the denoiser's resumed runs from their last
# checkpoint, any other stage from its start), and stages.tsv times each stage's last attempt.
run() {
  local name=$1
  shift
  if [ -f "$OUT/stages/$name.done" ]; then
    echo "= $name done before, skipped: physnap $*" >&2
    return
  fi
  echo "+ physnap $*" >&2
  local t0
  t0=$(date +%s)
  "$PHYSNAP_BIN" "$@"
  printf '%s\t%s\t%s\n' "$name" "$(( $(date +%s) - t0 ))" "physnap $*" >> "$OUT/stages.tsv"
  touch "$OUT/stages/$name.done"
  if [ "$name" = "$UNTIL" ]; then
    echo "stopped after stage $name (UNTIL); the same command without UNTIL goes on from here" >&2
    exit 0
  fi
}

# A train shape stage interrupted after a checkpoint (every 1,000 steps) goes on from it:
# --resume, the same batch stream; Adam's moments restart there, so the prior is close to, not
# bit for bit, an uninterrupted run's.
resume_shape() {
  if [ -f "$1/shape_checkpoint.json" ]; then echo --resume; fi
}

mkdir -p "$OUT/stages"
[ -f "$OUT/recipe.knobs" ] || for k in "${knobs[@]}"; do printf '%s=%s\n' "$k" "${!k}"; done > "$OUT/recipe.knobs"
start=$(date +%s)
run synth data synth --out "$OUT/synth" --objects "$OBJECTS" --seed 0
# shellcheck disable=SC2086
run import data import --partnet-mobility "$OUT/synth" --out "$OUT/train" $IMPORT_FLAGS
# The shipped shape prior's decoder gradients came from the host backward pass (train shape's
# default); burn's autodiff gives the same gradients up to float rounding, but rounding
# differences grow over training, so the recipe names the shipped path. The val IoU is logged
# every 4,000 steps, as in the shipped prior's run (every 1,000 costs ≈ 1.5 min more).
# shellcheck disable=SC2086,SC2046
run shape train shape --data "$OUT/train" --out "$OUT/shape" --steps "$SHAPE_STEPS" --seed 0 \
  --decoder-backward "$SHAPE_BACKWARD" --batch-shards "$SHAPE_SHARDS" --eval-every 4000 \
  $SHAPE_BATCH $SHAPE_FLAGS $(resume_shape "$OUT/shape")
# The decoder limits the shape IoU most (EVALUATION.md); cycles with the encoder frozen improve
# it while the encoder, and with NAP's encoding every code, stays as the first prior made it.
# The eikonal term keeps the decoder's field steep where guidance moves the codes: without it
# guided scan completion aligns worse. After the first cycle (0.01) the 12,000-step prior's
# fields are still flatter near the surface than its meshes (sqrt(E_pc)/D_pc 0.74 on guided
# fits, against 0.94 for the weights before) and fits align 15 % worse; the second, stronger
# cycle (0.03) brings that back to 0.92 (EVALUATION.md). Cycle i uses seed i - 1 (its query
# draws), the i-th DECODER_EIKONAL and DECODER_WRONG_SIDE weights, and starts from the
# previous run.
last="$OUT/shape"
if [ "$DECODER_STEPS" != 0 ]; then
  for ((cycle = 1; cycle <= DECODER_CYCLES; cycle++)); do
    # shellcheck disable=SC2086,SC2046
    run "decoder$cycle" train shape --data "$OUT/train" --out "$OUT/shape_decoder$cycle" --steps "$DECODER_STEPS" \
      --seed $((cycle - 1)) --init-from "$last" --freeze-encoder --lr 5e-4 \
      --eikonal "${eikonal[$((cycle - 1))]}" --wrong-side "${wrong_side[$((cycle - 1))]}" \
      --batch-shards "$SHAPE_SHARDS" $SHAPE_BATCH $SHAPE_FLAGS $DECODER_FLAGS \
      $(resume_shape "$OUT/shape_decoder$cycle")
    last="$OUT/shape_decoder$cycle"
  done
fi
# Every part's code by the last decoder (the denoiser learns these; the report records the
# encoding and the runs the prior continued, which the manifest keeps).
run encode train encode --weights "$last" --data "$OUT/train" --out "$OUT/codes" \
  --encoder-views "$ENCODER_VIEWS" --fit-steps "$FIT_STEPS" --fit-queries "$FIT_QUERIES"
# One more decoder cycle, on exactly those codes (train shape --codes; the encoder, which the
# fitting started from, frozen): the cycles above trained the decoder on the encoder's one-view
# codes, while the denoiser generates, and eval shape measures, the fitted ones. The codes do
# not change, so the denoiser below learns the same codes either way; its --shape directory
# then holds this decoder and a copy of the codes. One evaluation at the end (--eval-every 0).
shape="$OUT/codes"
if [ "$CODES_DECODER_STEPS" != 0 ]; then
  # shellcheck disable=SC2086,SC2046
  run decoder_codes train shape --data "$OUT/train" --out "$OUT/shape_codes" --steps "$CODES_DECODER_STEPS" \
    --seed "$DECODER_CYCLES" --init-from "$last" --freeze-encoder --codes "$OUT/codes" --lr 5e-4 \
    --eikonal "$CODES_DECODER_EIKONAL" --wrong-side "$CODES_DECODER_WRONG_SIDE" --eval-every 0 \
    --batch-shards "$SHAPE_SHARDS" $SHAPE_BATCH $SHAPE_FLAGS $DECODER_FLAGS \
    $(resume_shape "$OUT/shape_codes")
  shape="$OUT/shape_codes"
fi
common=(--data "$OUT/train" --shape "$shape" --out "$OUT/weights"
        --batch-objects "$BATCH_OBJECTS" --noise-levels 4 --lr 5e-4
        --checkpoint-every "$CHECKPOINT_EVERY" --category-layers --layout-gain "$LAYOUT_GAIN"
        --code-gain "$CODE_GAIN")
# Only the last denoiser run builds the retrieval codebook (≈ 1 min): every other one is
# continued by another.
# Stage 1: constant learning rate, no EMA.
# shellcheck disable=SC2086
run denoiser_stage1 train diffusion "${common[@]}" --steps "$STAGE1" --lr-final-factor 1 --ema-decay 0 \
  --batch-shards "$DENOISER_SHARDS" --no-codebook $DENOISER_FLAGS
# Then: cosine decay from STAGE1 to 0.1 x lr over the run to STEPS, EMA 0.999 from STAGE1 (in
# two runs when STAGE2 is set; DECAY_OVERLAP is the box-overlap penalty of the run that ends at
# STEPS).
decay=(--steps "$STEPS" --lr-decay-start "$STAGE1" --lr-final-factor 0.1 --ema-decay 0.999 --resume
       --batch-shards "$DENOISER_SHARDS")
if [ "$STAGE2" != 0 ]; then
  # shellcheck disable=SC2086
  run denoiser_stage2 train diffusion "${common[@]}" "${decay[@]}" --stop-at "$STAGE2" --no-codebook $DENOISER_FLAGS
fi
decay_codebook=(--no-codebook)
[ "${#restarts[@]}" = 0 ] && decay_codebook=()
# shellcheck disable=SC2086
run denoiser_decay train diffusion "${common[@]}" "${decay[@]}" --overlap-weight "$DECAY_OVERLAP" \
  "${decay_codebook[@]}" $DENOISER_FLAGS
# More cosine cycles (warm restarts): back to lr at the previous count, cosine decay to 0.1 x lr
# at the next, the weight EMA continued. The one decay to 14,000 reaches category accuracy
# 65-71 %; the 4,000-step restart after it 81-83 %: the restart is what lifts it.
prev=$STEPS
for k in "${!restarts[@]}"; do
  cb=(--no-codebook)
  [ "$k" = $((${#restarts[@]} - 1)) ] && cb=()
  # shellcheck disable=SC2086
  run "denoiser_restart$((k + 1))" train diffusion "${common[@]}" --steps "${restarts[$k]}" --lr-decay-start "$prev" \
    --lr-final-factor 0.1 --ema-decay 0.999 --resume --batch-shards "$RESTART_SHARDS" \
    --overlap-weight "${overlap[$k]:-0}" "${cb[@]}" $DENOISER_FLAGS
  prev=${restarts[$k]}
done
if [ "$EVAL" = 1 ]; then
  run eval_shape eval shape --weights "$OUT/weights" --data "$OUT/train" --parts 64 --write-manifest
  run eval_generative eval generative --weights "$OUT/weights" --data "$OUT/train" --samples 48 --refs 48 \
    --per-category 4 --states 4 --points 256 --out "$OUT/weights/eval_generative.json" \
    --write-manifest
fi
total=$(awk -F'\t' '{ s += $2 } END { print s + 0 }' "$OUT/stages.tsv")
echo "weights in $OUT/weights (this run $(( ($(date +%s) - start) / 60 )) min; every stage, \
$(( total / 60 )) min in all, in $OUT/stages.tsv)" >&2
