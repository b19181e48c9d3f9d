#!/usr/bin/env bash
# v5r + a second eikonal decoder cycle at w = 0.03 (seed 1), from v5r's cycled decoder; the encoder
# frozen, so the codes and the denoiser stay valid. Then install into a copy and measure the shape IoU.
cd "${1:-/work/exp/s34/cyc2}"
B=/work/bin/physnap-s34; T=/work/data/train
RAYON_NUM_THREADS=2 $B train shape --data $T --out cycle2 --steps 3000 --seed 1 --init-from v5r_base \
  --freeze-encoder --lr 5e-4 --batch-parts 128 --queries-per-part 128 --surface-points 64 \
  --eval-every 1000 --eikonal 0.03 --checkpoint-every 500 --progress-interval 60 > cycle2.log 2>&1 || exit 1
cp -r v5r_base v5r2
$B train install-shape --shape cycle2 --weights v5r2 > install.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B eval shape --weights v5r2 --data $T --parts 64 --write-manifest > shape.log 2>&1
echo done
