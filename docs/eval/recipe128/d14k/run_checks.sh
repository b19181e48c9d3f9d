#!/usr/bin/env bash
# Session 35: checks of d14k (the shipped v5r2 weights with the denoiser continued to 14,000
# steps): guided seed set 0 on the 30 fresh scans, both blocks, one scan per process, plus
# eval generative at seed 2, and the manifest's metrics (eval shape, eval generative at 12345).
cd /work/exp/s35 || exit 1
B=/work/bin/physnap-s35; T=/work/data/train; W=d14k_ship
mkdir -p r logs
(
  RAYON_NUM_THREADS=1 $B eval shape --weights $W --data $T --parts 64 --write-manifest > shape.log 2>&1
  RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 --out $W/eval_generative.json --write-manifest > gen_ship.log 2>&1
  RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 --seed 2 --out gen_d14k_seed2.json > gen_d14k_2.log 2>&1
  echo done > gen2.done
) &
one() {
  set -- $1
  o=r/d14k_$1_s$2_c$3
  [ -f $o/guided_table.json ] && return
  RAYON_NUM_THREADS=1 /work/bin/physnap-s35 eval guided --weights d14k_ship --clouds /work/data/testset_s1 --data /work/data/train \
    --skip-clouds $3 --max-clouds 1 --samples-per-cloud 2 --variants pc+pen+mob,uncond --category-aware $1 --seed $2 \
    --out $o > logs/d14k_$1_s$2_c$3.log 2>&1
}
export -f one
for c in $(seq 0 29); do echo "no 0 $c"; echo "yes 0 $c"; done | xargs -P 2 -I{} bash -c 'one "{}"'
wait
echo finished > checks.done
