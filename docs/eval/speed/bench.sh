#!/usr/bin/env bash
# Session 52: a training stage at the recipe's settings, timed, for binaries A B ... (each a
# physnap build); what they write must be equal byte for byte (the speed-ups change no value).
# Run on an otherwise idle machine. BENCH_ENV adds environment (e.g. MIMALLOC_PURGE_DELAY=-1).
#   bash docs/eval/speed/bench.sh shape DATA STEPS WORK BIN...       (the first prior's steps)
#   bash docs/eval/speed/bench.sh diffusion DATA CODES STEPS WORK BIN... (the denoiser's first run;
#                                                                    CODES: a train encode output)
#   bash docs/eval/speed/bench.sh encode DATA WEIGHTS VIEWS WORK BIN...  (the fitted encoding;
#        ≈ 20 min a binary here whatever VIEWS: the 50 fitting steps are per part and dominate)
set -u
kind=$1; data=$2; shift 2
case $kind in
  shape) steps=$1; work=$2; shift 2; file=shape_prior.safetensors ;;
  diffusion) codes=$1; steps=$2; work=$3; shift 3; file=denoiser.safetensors ;;
  encode) weights=$1; views=$2; work=$3; shift 3; file=codebook.npy ;;
  *) echo "unknown kind '$kind' (shape, diffusion or encode)" >&2; exit 2 ;;
esac
mkdir -p "$work"
for b in "$@"; do
  n=$kind-$(basename "$b")
  out=$work/$n
  rm -rf "$out"
  case $kind in
    shape) args=(train shape --data "$data" --out "$out" --steps "$steps" --seed 0 --decoder-backward host
                 --batch-shards 2 --eval-every 1000000 --batch-parts 128 --queries-per-part 128
                 --surface-points 64 --progress-interval 0) ;;
    diffusion) args=(train diffusion --data "$data" --shape "$codes" --out "$out" --batch-objects 16
                     --noise-levels 4 --lr 5e-4 --checkpoint-every 100000 --category-layers --layout-gain 2
                     --code-gain 2 --steps "$steps" --lr-final-factor 1 --ema-decay 0 --batch-shards 2
                     --no-codebook --progress-interval 0) ;;
    encode) args=(train encode --weights "$weights" --data "$data" --out "$out" --encoder-views "$views"
                  --fit-steps 50 --fit-queries 512) ;;
  esac
  t0=$(date +%s.%N)
  # shellcheck disable=SC2086
  env ${BENCH_ENV:-} /usr/bin/time -f "%M KiB peak" -o "$out.rss" "$b" "${args[@]}" > "$out.log" 2>&1 ||
    { echo "$n failed"; tail "$out.log"; continue; }
  t1=$(date +%s.%N)
  printf '%s\t%.1f s\t%s\t%s\n' "$n" "$(echo "$t1 - $t0" | bc)" "$(sha256sum < "$out/$file" | cut -c1-16)" "$(cat "$out.rss")"
done
