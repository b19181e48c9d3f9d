#!/usr/bin/env bash
# Session 50: after seeds 4-5, fcg2's 48 + 48 runs (1-NNA, MMD, COV) at seeds 12345 and 1, 32³;
# then the 30-scan guided check beside lg2's slices (same binary, s47a).
cd /work/exp/s50/fcg2 || exit 1
while pgrep -f "gen32_fcg2_[45].json" > /dev/null; do sleep 10; done
B=/work/bin/physnap-s50a; T=/work/data/train; W=weights
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --per-category 4 --states 4 --points 256 --samples 48 --refs 48 --progress-interval 60 "$@"; }
g --seed 12345 --out genfull_fcg2_12345.json > genfull_12345.log 2>&1 &
g --seed 1 --out genfull_fcg2_1.json > genfull_1.log 2>&1
wait
echo done > full.done
W=/work/exp/s50/fcg2/weights TAG=fcg2 WORK=/work/exp/s47/gchk VARIANTS=pc+pen+mob BIN=/work/bin/physnap-s47a \
  bash /work/main/scripts/guided-slices.sh > guided.out 2>&1
echo done > guided.done
