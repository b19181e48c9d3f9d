#!/bin/bash
# Device sweep: guidance step clamp × category-aware block, eval guided pc+pen+mob, 8 scans × 2.
set -u
D=target/device; B=$D/physnap
[ -f /tmp/train/dataset.json ] || { $B data synth --out /tmp/synth --objects 3000 --seed 0 >/dev/null 2>&1; $B data import --partnet-mobility /tmp/synth --out /tmp/train >/dev/null 2>&1; }
$B data testset --data /tmp/train --out /tmp/testset --count 30 --seed 0 > /dev/null 2>&1 || exit 4
sha256sum /tmp/testset/testset.json
run() { name=$1; shift
  ( s=$(date +%s); RAYON_NUM_THREADS=2 $B eval guided --weights weights --clouds /tmp/testset --data /tmp/train \
     --max-clouds 8 --samples-per-cloud 2 --variants pc+pen+mob --progress-interval 0 --out $OUT/$name "$@" > $OUT/$name.log 2>&1
    echo "$name rc=$? $(( $(date +%s) - s )) s" ) & }
for c in 0.05 0.03 0.02; do
  run c${c}_no --guidance-max-step $c --category-aware no
  run c${c}_yes --guidance-max-step $c --category-aware yes
done
wait
for d in $OUT/c*/; do echo "== $d"; grep -E "pc\+pen\+mob" $d/guided_table.md | head -3; done
