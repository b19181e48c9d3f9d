#!/usr/bin/env bash
# v5r2 (v5r + a second eikonal cycle at w = 0.03) on the 30 fresh scans, both blocks, seed sets 0 then 1000,
# one scan per process, 2 at a time (same flags as the v5r runs).
cd "${1:-/work/exp/s34/cyc2}"
mkdir -p r logs
one() {
  set -- $1
  o=r/v5r2_$1_s$2_c$3
  [ -f $o/guided_table.json ] && return
  RAYON_NUM_THREADS=1 /work/bin/physnap-s34 eval guided --weights v5r2 --clouds /work/data/testset_s1 --data /work/data/train \
    --skip-clouds $3 --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob,uncond --category-aware $1 --seed $2 \
    --out $o > logs/v5r2_$1_s$2_c$3.log 2>&1
}
export -f one
for s in 0 1000; do for c in $(seq 0 29); do echo "no $s $c"; echo "yes $s $c"; done; done | xargs -P 2 -I{} bash -c 'one "{}"'
echo finished
