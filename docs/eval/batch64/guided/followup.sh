#!/usr/bin/env bash
# Session 28 follow-up (left running at the session's end): v3's weights with the eikonal cycle
# installed, then the checks the shipping policy needs. Results for the next session.
set -x
cd /work/exp/s28
B=/work/bin/physnap-s27
rm -rf v3w1 && cp -r v3/weights v3w1
$B train install-shape --shape v3_cycle1 --weights v3w1 > v3w1_install.log 2>&1
$B eval shape --weights v3w1 --data v3/train --parts 64 --write-manifest > v3w1_shape.log 2>&1
RAYON_NUM_THREADS=1 $B eval guided --weights v3w1 --clouds /work/data/testset --max-clouds 10 --samples-per-cloud 2 \
  --variants pc+pen+mob --category-aware no --out g_v3w1_no > g_v3w1_no.log 2>&1 &
RAYON_NUM_THREADS=1 $B eval guided --weights v3w1 --clouds /work/data/testset --max-clouds 10 --samples-per-cloud 2 \
  --variants pc+pen+mob --category-aware yes --out g_v3w1_yes > g_v3w1_yes.log 2>&1 &
wait
$B eval generative --weights v3w1 --data v3/train --samples 48 --refs 48 --per-category 4 --states 4 --points 256 \
  --out v3w1/eval_generative.json --write-manifest > v3w1_generative.log 2>&1
echo done > followup.done
