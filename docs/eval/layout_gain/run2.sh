#!/usr/bin/env bash
# Session 47: candidate lg2, continued (run.sh's first denoiser run, 2,000 constant steps, was left
# running when run.sh was replaced by this script, so that seed 12345's eval also writes the
# candidate's manifest). The shipped schedule (s14r) from scratch on the shipped codes with
# --layout-gain 2, then eval shape and eval generative --write-manifest (seed 12345) beside seed 1
# (48 + 48, 52 category samples), then the category samples alone at seeds 2..6, two at a time.
set -x
cd /work/exp/s47/lg2 || exit 1
while pgrep -f "physnap-s47a train diffusion" > /dev/null; do sleep 5; done
python3 -c "import json,sys; sys.exit(json.load(open('weights/checkpoint.json'))['step'] != 2000)" || exit 1
B=/work/bin/physnap-s47a; T=/work/data/train; W=weights
c=(--data $T --shape /work/exp/s44/codes --out $W --batch-objects 16 --noise-levels 4
   --lr 5e-4 --checkpoint-every 500 --category-layers --batch-shards 2 --layout-gain 2)
d=(--steps 14000 --lr-decay-start 2000 --lr-final-factor 0.1 --ema-decay 0.999 --resume)
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" "${d[@]}" --stop-at 7000 --no-codebook > b.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" "${d[@]}" --overlap-weight 3 --no-codebook > c.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B train diffusion "${c[@]}" --steps 18000 --lr-decay-start 14000 --lr-final-factor 0.1 \
  --ema-decay 0.999 --resume --overlap-weight 3 > d.log 2>&1 || exit 1
python3 -c "import json; print('wall', json.load(open('weights/diffusion_train.json'))['wall_seconds_total'])" > train.wall
sha256sum $W/*.safetensors
echo trained > trained.done
RAYON_NUM_THREADS=2 $B eval shape --weights $W --data $T --parts 64 --write-manifest --out shape_val64.json > shape.log 2>&1
g() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 48 --refs 48 --per-category 4 \
    --states 4 --points 256 "$@"; }
g --out gen_lg2_12345.json --write-manifest > gen_lg2_12345.log 2>&1 &
g --seed 1 --out gen_lg2_1.json > gen_lg2_1.log 2>&1
wait
echo done > gen2.done
cat1() { RAYON_NUM_THREADS=1 $B eval generative --weights $W --data $T --samples 2 --refs 2 --per-category 4 \
    --states 4 --points 256 --seed $1 --out gen_lg2_$1.json > gen_lg2_$1.log 2>&1; }
(cat1 2; cat1 4; cat1 6) &
(cat1 3; cat1 5) &
wait
echo done > lg2.done
