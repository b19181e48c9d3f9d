#!/usr/bin/env bash
# Session 42: ws10c's generation checks once its guided slices are done: eval shape and
# eval generative --write-manifest (seed 12345) on the candidate weights, seeds 1 and 2 beside.
cd /work/exp/s42/ws10c || exit 1
while [ ! -f ws10c_guided.done ]; do sleep 20; done
B=/work/bin/physnap-s39; T=/work/data/train; W=weights
/work/bin/physnap-s42b eval shape --weights $W --data $T --parts 64 --write-manifest --out shape_val64.json > shape.log 2>&1
(RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --out $W/eval_generative.json --write-manifest > gen_12345.log 2>&1
 RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --seed 2 --out gen_2.json > gen_2.log 2>&1) &
RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --seed 1 --out gen_1.json > gen_1.log 2>&1
wait
echo done > after.done
