#!/usr/bin/env bash
# Session 29: cycle 2 on v3w1 with a stronger eikonal weight (0.05 instead of 0.01), to test whether a
# steeper field fixes the 64-part prior's worse scan alignment; then install, eval shape and the guided check
cd /work/exp/s29
B=/work/bin/physnap-s27
RAYON_NUM_THREADS=1 $B train shape --data /work/exp/s28/v3/train --out v3_cycle2e5 --steps 3000 --seed 1 \
  --init-from /work/exp/s28/v3w1 --freeze-encoder --lr 5e-4 --batch-parts 64 --queries-per-part 512 --surface-points 128 \
  --eval-every 2000 --eikonal 0.05 --progress-interval 60 > v3_cycle2e5.log 2>&1
echo $? > v3_cycle2e5.rc
rm -rf v3w2e5 && cp -r /work/exp/s28/v3w1 v3w2e5 && rm -f v3w2e5/eval_generative.json
$B train install-shape --shape v3_cycle2e5 --weights v3w2e5 > v3w2e5_install.log 2>&1
$B eval shape --weights v3w2e5 --data /work/exp/s28/v3/train --parts 64 --write-manifest > v3w2e5_shape.log 2>&1
for a in no yes; do
RAYON_NUM_THREADS=1 $B eval guided --weights v3w2e5 --clouds /work/data/testset --max-clouds 10 --samples-per-cloud 2 \
  --variants pc+pen+mob --category-aware $a --out g_v3w2e5_$a > g_v3w2e5_$a.log 2>&1 &
done
wait
echo done > cycle2e5.done
