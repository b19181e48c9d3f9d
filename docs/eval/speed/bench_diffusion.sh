#!/usr/bin/env bash
# Session 52: train diffusion steps at the recipe's first denoiser stage, timed, for binaries
# A B ... ; their denoisers must be equal byte for byte. CODES: a train encode output.
#   bash docs/eval/speed/bench_diffusion.sh DATA CODES STEPS WORK BIN...
set -u
data=$1; codes=$2; steps=$3; work=$4; shift 4
mkdir -p "$work"
for b in "$@"; do
  n=$(basename "$b")
  rm -rf "$work/d_$n"
  t0=$(date +%s.%N)
  env ${BENCH_ENV:-} "$b" train diffusion --data "$data" --shape "$codes" --out "$work/d_$n" \
    --batch-objects 16 --noise-levels 4 --lr 5e-4 --checkpoint-every 100000 --category-layers \
    --layout-gain 2 --code-gain 2 --steps "$steps" --lr-final-factor 1 --ema-decay 0 \
    --batch-shards 2 --no-codebook --progress-interval 0 > "$work/d_$n.log" 2>&1 || { echo "$n failed"; tail "$work/d_$n.log"; }
  t1=$(date +%s.%N)
  printf '%s\t%.1f s\t%s\n' "$n" "$(echo "$t1 - $t0" | bc)" "$(sha256sum < "$work/d_$n/denoiser.safetensors" | cut -c1-16)"
done
