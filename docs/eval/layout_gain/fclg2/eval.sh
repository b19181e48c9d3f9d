#!/usr/bin/env bash
# Session 48: evaluate candidate fclg2 once run.sh has trained it: eval shape (64 val parts, the
# codebook's encoding), eval generative 48 + 48 at seeds 12345 and 1 side by side, then the 52
# category samples alone at seeds 2 and 3.
cd /work/exp/s48/fclg2 || exit 1
while [ ! -f trained.done ]; do sleep 20; done
B=/work/bin/physnap-s47a; T=/work/data/train; W=weights
RAYON_NUM_THREADS=2 $B eval shape --weights $W --data $T --parts 64 --out shape_val64.json > shape.log 2>&1
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --per-category 4 --states 4 --points 256 "$@"; }
g --samples 48 --refs 48 --out gen_fclg2_12345.json > gen_12345.log 2>&1 &
g --samples 48 --refs 48 --seed 1 --out gen_fclg2_1.json > gen_1.log 2>&1
wait
g --samples 2 --refs 2 --seed 2 --out gen_fclg2_2.json > gen_2.log 2>&1 &
g --samples 2 --refs 2 --seed 3 --out gen_fclg2_3.json > gen_3.log 2>&1
wait
echo done > eval.done
