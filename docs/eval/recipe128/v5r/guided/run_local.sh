#!/usr/bin/env bash
# Local remainder of the device run (.dev/run.sh): same units, same flags.
cd /work/exp/s34/local
R=/work/main
one() {
  set -- $1
  w=$R/docs/eval/recipe128/v5r/weights; [ "$1" = shipped ] && w=$R/weights
  o=r/$1_$2_s$3_c$4
  RAYON_NUM_THREADS=1 ./pn eval guided --weights "$w" --clouds /work/data/testset_s1 --data /work/data/train --skip-clouds $4 \
    --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob,uncond --category-aware $2 --seed $3 \
    --out $o > logs/$1_$2_s$3_c$4.log 2>&1
}
export -f one; export R
{ for c in 20 21 23 24 25 26 27 28 29; do echo "v5r yes 1000 $c"; done
  for c in $(seq 0 29); do echo "shipped no 1000 $c"; done; } | xargs -P 2 -I{} bash -c 'one "{}"'
echo finished
