#!/usr/bin/env bash
# Session 42: the W = 0 third cycle (session 41's cycle3_ws0) installed into the shipped weights,
# then eval generative at seeds 12345 and 1 (is the category accuracy ws10c and ws3c lost the decoder or noise?).
cd /work/exp/s42/ws0c || exit 1
B=/work/bin/physnap-s39; T=/work/data/train; W=weights
/work/bin/physnap-s42b train install-shape --shape /work/exp/s41/ws/cycle3_ws0 --weights $W > install.log 2>&1
RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --out gen_12345.json > gen_12345.log 2>&1 &
RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --seed 1 --out gen_1.json > gen_1.log 2>&1
wait
echo done > run.done
