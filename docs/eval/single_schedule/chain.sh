#!/usr/bin/env bash
# Session 40: after s14's training, the shape-shards benchmark on the idle machine, then s14's checks.
cd /work/exp/s40 || exit 1
while [ ! -f s14.done ]; do sleep 15; done
B=/work/bin/physnap-s40
bash /work/main/docs/eval/shape_shards/bench.sh $B /work/data/train bench 100 1:2 2:2 1:1 > bench.txt 2>&1
CYCLE=/work/main/weights bash /work/main/docs/eval/shape_shards/bench.sh $B /work/data/train bench 100 1:2 2:2 >> bench.txt 2>&1
echo done > bench.done
./after_s14.sh > after_s14.out 2>&1
