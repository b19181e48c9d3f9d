#!/usr/bin/env bash
# Session 39: after ov10's guided slices, train ov3, then its checks beside ov10's seed-2 generative run.
cd /work/exp/s39 || exit 1
while [ ! -f ov10_guided.done ]; do sleep 20; done
./run_ov3.sh > run_ov3.out 2>&1
B=/work/bin/physnap-s39
RAYON_NUM_THREADS=1 $B eval generative --weights ov10/weights --data /work/data/train --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 --seed 2 --out gen_ov10_2.json > gen_ov10_2.log 2>&1 &
W=ov3/weights TAG=ov3 ./after.sh > after_ov3.out 2>&1
wait
echo done > chain.done
