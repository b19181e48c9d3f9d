#!/usr/bin/env bash
# Session 53: ws30c4's category seeds beside the recipe's own eval (seed 12345), then the
# 15-scan guided check of ws30c4 (fcg2's slices run niced since 18:40, same binary).
O=/work/exp/s53/repro4; W=$O/weights; B=/work/bin/physnap-s53; T=/work/data/train
cd /work/exp/s53/gen || exit 1
while [ ! -f $O/stages/denoiser_restart1.done ]; do sleep 10; done
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --per-category 4 --states 4 --points 256 --progress-interval 60 "$@"; }
g --samples 48 --refs 48 --seed 1 --out gen_ws30c4_1.json > gen_1.log 2>&1
g --samples 2 --refs 2 --seed 2 --out gen_ws30c4_2.json > gen_2.log 2>&1 &
g --samples 2 --refs 2 --seed 3 --out gen_ws30c4_3.json > gen_3.log 2>&1
wait
g --samples 2 --refs 2 --seed 4 --out gen_ws30c4_4.json > gen_4.log 2>&1 &
g --samples 2 --refs 2 --seed 5 --out gen_ws30c4_5.json > gen_5.log 2>&1
wait
echo done > gen.done
cd /work/exp/s53/gchk
W=$W TAG=ws30c4 FROM=0 TO=14 VARIANTS=pc+pen+mob BIN=$B bash /work/main/scripts/guided-slices.sh > ws30c4_guided.out 2>&1
echo done > /work/exp/s53/guided.done
