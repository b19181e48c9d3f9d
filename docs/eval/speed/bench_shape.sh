#!/usr/bin/env bash
# Session 52: train shape steps at the recipe's first-prior settings, timed, for binaries A B ...
# (each a physnap build); the priors they write must be equal byte for byte (the speed-ups change
# no value). Run on an otherwise idle machine:
#   bash docs/eval/speed/bench_shape.sh DATA STEPS WORK BIN...
set -u
data=$1; steps=$2; work=$3; shift 3
mkdir -p "$work"
for b in "$@"; do
  n=$(basename "$b")
  rm -rf "$work/$n"
  t0=$(date +%s.%N)
  env ${BENCH_ENV:-} /usr/bin/time -f "%M KiB peak" -o "$work/$n.rss" "$b" train shape --data "$data" --out "$work/$n" --steps "$steps" --seed 0 \
    --decoder-backward host --batch-shards 2 --eval-every 1000000 --batch-parts 128 \
    --queries-per-part 128 --surface-points 64 --progress-interval 0 > "$work/$n.log" 2>&1 || { echo "$n failed"; tail "$work/$n.log"; }
  t1=$(date +%s.%N)
  printf '%s\t%.1f s\t%s\t%s\n' "$n" "$(echo "$t1 - $t0" | bc)" "$(sha256sum < "$work/$n/shape_prior.safetensors" | cut -c1-16)" "$(cat "$work/$n.rss")"
done
