#!/usr/bin/env bash
# Finish and check candidate v5r (run_v5r.sh) from the files session 33 committed in v5r/:
# - v5r/p12k: the 12,000-step prior (its codes are v5r/cycle1's codebook: the cycle froze the
#   encoder); v5r/cycle1: the prior after its eikonal cycle;
# - v5r/weights (if stage 2 finished in session 33): the denoiser, cycled decoder installed;
#   else v5r/stage2_checkpoint: stage 2's last checkpoint, resumed here to 7,000 steps.
# Then the checks, with ID_gt beside D_pc on the fresh scans (data testset --seed 1) against
# the shipped weights' runs in docs/eval/id_gt (session 32's machine) or new ones on this one.
# Usage: bash docs/eval/recipe128/run_v5r_finish.sh BIN WORKDIR   (data in /work/data)
set -x
B=${1:-/work/bin/physnap}
W=${2:-/work/exp/v5r}
R=$(cd "$(dirname "$0")" && pwd)/v5r
T=/work/data/train
mkdir -p "$W" && cd "$W" || exit 1
if [ ! -d v5r ]; then
  if [ -d "$R/weights" ]; then
    cp -r "$R/weights" v5r
  else
    mkdir -p p12k v5 && cp "$R/p12k/shape_prior.safetensors" "$R/cycle1/codebook."* p12k/
    cp -r "$R/stage2_checkpoint" v5/weights
    $B train diffusion --data $T --shape p12k --out v5/weights --batch-objects 16 \
      --noise-levels 4 --lr 5e-4 --checkpoint-every 500 --category-layers --steps 7000 --lr-decay-start 2000 \
      --lr-final-factor 0.1 --ema-decay 0.999 --resume > v5_stage2.log 2>&1 || exit 1
    cp -r v5/weights v5r
    $B train install-shape --shape "$R/cycle1" --weights v5r > v5r_install.log 2>&1 || exit 1
    RAYON_NUM_THREADS=2 $B eval shape --weights v5r --data $T --parts 64 --write-manifest > v5r_shape.log 2>&1
  fi
fi
for a in no yes; do
  RAYON_NUM_THREADS=1 $B eval guided --weights v5r --clouds /work/data/testset_s1 --data $T \
    --max-clouds 30 --samples-per-cloud 2 --variants pc+pen+mob --category-aware $a --out v5r_$a > v5r_$a.log 2>&1 &
done
wait
RAYON_NUM_THREADS=1 $B eval generative --weights v5r --data $T --samples 48 --refs 48 --per-category 4 --states 4 \
  --points 256 --out v5r/eval_generative.json --write-manifest > v5r_gen12345.log 2>&1 &
RAYON_NUM_THREADS=1 $B eval generative --weights v5r --data $T --samples 48 --refs 48 --per-category 4 --states 4 \
  --points 256 --seed 1 --out gen_v5r_seed1.json > v5r_gen1.log 2>&1 &
wait
# Compare (unaware; aware against shipped_yes_cg0, the w = 0 default):
#   python3 scripts/compare-guided.py --a v5r_no/guided_table.json --b docs/eval/id_gt/shipped_no/guided_table.json --aware no
#   python3 scripts/compare-guided.py --a v5r_yes/guided_table.json --b docs/eval/id_gt/shipped_yes_cg0/guided_table.json --aware yes
