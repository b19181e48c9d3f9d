#!/usr/bin/env bash
# Session 33: once stage 2 is done, install the cycled decoder into v5r's weights, measure the
# shape IoU, then the first guided check on the fresh scans (slice of 10 x 2, both blocks) with
# ID_gt, beside session 32's shipped runs on this machine (docs/eval/id_gt/shipped_no and
# shipped_yes_cg0, the same seeds).
cd /work/exp/s33
B=/work/bin/physnap-s33
T=/work/data/train
while [ ! -f v5_stage2.rc ]; do sleep 15; done
[ "$(cat v5_stage2.rc)" = 0 ] || exit 1
while pgrep -f "out p12k_cycle1" > /dev/null; do sleep 15; done
grep -q "trained" p12k_cycle1.log || exit 1
cp -r v5/weights v5r_w0
cp -r v5/weights v5r
$B train install-shape --shape p12k_cycle1 --weights v5r > v5r_install.log 2>&1 || exit 1
RAYON_NUM_THREADS=2 $B eval shape --weights v5r --data $T --parts 64 --write-manifest > v5r_shape.log 2>&1
for a in no yes; do
  RAYON_NUM_THREADS=1 $B eval guided --weights v5r --clouds /work/data/testset_s1 --data $T \
    --max-clouds 10 --samples-per-cloud 2 --variants pc+pen+mob --category-aware $a --out v5r_$a > v5r_$a.log 2>&1 &
done
wait
echo done > v5r_checks.done
