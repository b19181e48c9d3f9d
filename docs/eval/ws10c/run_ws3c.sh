#!/usr/bin/env bash
# Session 42: the W = 3 third cycle (session 41's cycle3_ws3) installed into the shipped weights,
# then eval generative at seeds 12345 and 1 (category accuracy is what ws10c lost).
cd /work/exp/s42/ws3c || exit 1
B=/work/bin/physnap-s39; T=/work/data/train; W=weights
/work/bin/physnap-s42b train install-shape --shape /work/exp/s41/ws/cycle3_ws3 --weights $W > install.log 2>&1
RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --out gen_12345.json > gen_12345.log 2>&1 &
RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
  --states 4 --points 256 --seed 1 --out gen_1.json > gen_1.log 2>&1
wait
echo done > run.done
