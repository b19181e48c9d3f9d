#!/usr/bin/env bash
# Session 31: the recipe's cycle on the 12,000-step prior with a stronger eikonal term (0.03 instead of 0.01),
# to test whether v5's guided regression is the field flattening at the scan points.
cd /work/exp/s30
RAYON_NUM_THREADS=1 /work/bin/physnap-s27 train shape --data /work/data/train --out p12k_eik03 --steps 3000 --seed 0 \
  --init-from p128q128s64_12k --freeze-encoder --lr 5e-4 --batch-parts 128 --queries-per-part 128 --surface-points 64 \
  --eval-every 1000 --eikonal 0.03 --progress-interval 60 > p12k_eik03.log 2>&1
echo $? > p12k_eik03.rc
cp -r v5w0 v5e
/work/bin/physnap-s27 train install-shape --shape p12k_eik03 --weights v5e > v5e_install.log 2>&1
RAYON_NUM_THREADS=1 /work/bin/physnap-s27 eval shape --weights v5e --data /work/data/train --parts 64 --write-manifest > v5e_shape.log 2>&1
echo done > p12k_eik03.done
