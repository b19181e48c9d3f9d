#!/usr/bin/env bash
# Session 52: train encode with the recipe's fitting (50 Adam steps on 512 samples) on VIEWS
# encoder views (the recipe: 16), timed, for binaries A B ...; ≈ 20 min a binary here whatever
# VIEWS: the 50 fitting steps are per part, not per view, and dominate;
# the codes must be equal byte for byte. WEIGHTS: a shape prior folder (weights/).
#   bash docs/eval/speed/bench_encode.sh DATA WEIGHTS VIEWS WORK BIN...
set -u
data=$1; weights=$2; views=$3; work=$4; shift 4
mkdir -p "$work"
for b in "$@"; do
  n=$(basename "$b")
  rm -rf "$work/e_$n"
  t0=$(date +%s.%N)
  env ${BENCH_ENV:-} /usr/bin/time -f "%M KiB peak" "$b" train encode --weights "$weights" --data "$data" \
    --out "$work/e_$n" --encoder-views "$views" --fit-steps 50 --fit-queries 512 > "$work/e_$n.log" 2>&1 || { echo "$n failed"; tail "$work/e_$n.log"; }
  t1=$(date +%s.%N)
  printf '%s\t%.1f s\t%s\t%s\n' "$n" "$(echo "$t1 - $t0" | bc)" "$(sha256sum < "$work/e_$n/codebook.npy" | cut -c1-16)" "$(tail -1 "$work/e_$n.log")"
done
