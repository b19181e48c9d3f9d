#!/usr/bin/env bash
# Session 31: v5e (v5's denoiser, the 12k prior's cycle with eikonal 0.03) on scans 0-9, both blocks.
cd /work/exp/s30
B=/work/bin/physnap-s27
while [ ! -f p12k_eik03.done ]; do sleep 20; done
for a in no yes; do
  RAYON_NUM_THREADS=1 $B eval guided --weights v5e --clouds /work/data/testset --max-clouds 10 --samples-per-cloud 2 \
    --variants pc+pen+mob --category-aware $a --out g_v5e_$a > g_v5e_$a.log 2>&1 &
done
wait
echo done > v5e_guided.done
