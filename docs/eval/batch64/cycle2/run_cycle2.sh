#!/usr/bin/env bash
# Session 29: the recipe's decoder cycle 2 on s28's v3w1 (64-part first prior + cycle 1 installed),
# same command the script runs for cycle 2 with SHAPE_FLAGS="--batch-parts 64 --queries-per-part 512 --surface-points 128 --eval-every 2000"
cd /work/exp/s29
B=/work/bin/physnap-s27
RAYON_NUM_THREADS=1 $B train shape --data /work/exp/s28/v3/train --out v3_cycle2 --steps 3000 --seed 1 \
  --init-from /work/exp/s28/v3w1 --freeze-encoder --lr 5e-4 --batch-parts 64 --queries-per-part 512 --surface-points 128 \
  --eval-every 2000 --eikonal 0.01 --progress-interval 60 > v3_cycle2.log 2>&1
echo $? > v3_cycle2.rc
rm -rf v3w2 && cp -r /work/exp/s28/v3w1 v3w2 && rm -f v3w2/eval_generative.json
$B train install-shape --shape v3_cycle2 --weights v3w2 > v3w2_install.log 2>&1
$B eval shape --weights v3w2 --data /work/exp/s28/v3/train --parts 64 --write-manifest > v3w2_shape.log 2>&1
echo done > cycle2.done
