#!/usr/bin/env bash
# Session 35: d14k guided, seed set 1000, both blocks, one scan per process, niced (beside CI).
cd /work/exp/s35 || exit 1
one() {
  set -- $1
  o=r/d14k_$1_s$2_c$3
  [ -f $o/guided_table.json ] && return
  RAYON_NUM_THREADS=1 /work/bin/physnap-s35 eval guided --weights d14k_ship --clouds /work/data/testset_s1 --data /work/data/train \
    --skip-clouds $3 --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob,uncond --category-aware $1 --seed $2 \
    --out $o > logs/d14k_$1_s$2_c$3.log 2>&1
}
export -f one
for c in $(seq 0 29); do echo "no 1000 $c"; echo "yes 1000 $c"; done | xargs -P ${P:-2} -I{} bash -c 'one "{}"'
echo finished > s1000.done
