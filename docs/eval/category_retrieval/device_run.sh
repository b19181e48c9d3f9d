#!/bin/bash
# Device sweep: category retrieval × category guidance w, eval generative, 4 threads each.
set -u
D=target/device; B=$D/physnap; W=$D/wcat
nproc; free -g | head -2
$B --version || exit 3
T0=$(date +%s)
$B data synth --out /tmp/synth --objects 3000 --seed 0 > $OUT/synth.log 2>&1 || { tail $OUT/synth.log; exit 4; }
$B data import --partnet-mobility /tmp/synth --out /tmp/train > $OUT/import.log 2>&1 || { tail $OUT/import.log; exit 5; }
sha256sum /tmp/train/dataset.json
echo "data $(( $(date +%s) - T0 )) s"
run() { name=$1; shift
  ( s=$(date +%s); RAYON_NUM_THREADS=4 $B eval generative --weights $W --data /tmp/train --samples 2 --refs 48 \
     --per-category 4 --states 4 --points 256 --out $OUT/$name.json "$@" > $OUT/$name.log 2>&1
    echo "$name rc=$? $(( $(date +%s) - s )) s" ) & }
run base_w2 --retrieval auto
run cat_w1 --retrieval category --category-guidance 1
run cat_w0 --retrieval category --category-guidance 0
run all_w2 --retrieval all
wait
for f in $OUT/*.log; do echo "== $f"; grep -E "category accuracy|nearest instead|accuracy" $f | head -20; done
