#!/usr/bin/env bash
# Session 31: candidate v5 = 12,000-step 128x128x64 prior + its recipe denoiser (s30) + the
# recipe's eikonal cycle installed; then the shipping checks (same commands as v4's).
set -x
cd /work/exp/s30
B=/work/bin/physnap-s27
T=/work/data/train
cp -r v5/weights v5w0
$B train install-shape --shape p128q128s64_12k_cycle1 --weights v5/weights > v5_install.log 2>&1 || exit 1
$B eval shape --weights v5/weights --data $T --parts 64 --write-manifest > v5_shape.log 2>&1
for s in "" b_ c_; do
  case $s in "") C=/work/data/testset;; b_) C=/work/data/testset_b;; c_) C=/work/data/testset_c;; esac
  for a in no yes; do
    RAYON_NUM_THREADS=1 $B eval guided --weights v5/weights --clouds $C --max-clouds 10 --samples-per-cloud 2 \
      --variants pc+pen+mob --category-aware $a --out ${s}g_v5_$a > ${s}g_v5_$a.log 2>&1 &
  done
  wait
  echo done > ${s}v5_guided.done
done
RAYON_NUM_THREADS=1 $B eval generative --weights v5/weights --data $T --samples 48 --refs 48 --per-category 4 --states 4 --points 256 \
  --out v5/weights/eval_generative.json --write-manifest > v5_gen12345.log 2>&1 &
RAYON_NUM_THREADS=1 $B eval generative --weights v5/weights --data $T --samples 48 --refs 48 --per-category 4 --states 4 --points 256 \
  --seed 1 --out gen_v5_seed1.json > v5_gen1.log 2>&1 &
wait
echo done > v5_all.done
